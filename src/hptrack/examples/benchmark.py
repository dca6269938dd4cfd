"""A small benchmark: planners side by side on the same random scenarios (mean U per n).

python3 benchmark.py [--planners mcts,greedy,stationary] [--targets 2,3] [--scenarios 3]
"""

from __future__ import annotations

import argparse

import hptrack


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", default="mcts,greedy,stationary")
    parser.add_argument("--targets", default="2,3")
    parser.add_argument("--scenarios", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=20_000, help="mcts simulations/search")
    args = parser.parse_args()

    planners = args.planners.split(",")
    counts = [int(n) for n in args.targets.split(",")]
    options = {"mcts": {"iterations": args.iterations}} if "mcts" in planners else {}
    summary = hptrack.benchmark(planners, counts, args.scenarios, options=options)
    print("planner     " + "".join(f"{'n=' + str(n):>10}" for n in counts))
    for planner in planners:
        cells = "".join(f"{summary[planner][n]['mean']:10.2f}" for n in counts)
        print(f"{planner:<12}{cells}")


if __name__ == "__main__":
    main()
