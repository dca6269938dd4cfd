"""Plan one decision: which target the hierarchical planner pursues first, from the priors.

python3 plan_once.py [--targets 4] [--seed 0] [--iterations 100000]
"""

from __future__ import annotations

import argparse

import hptrack


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iterations", type=int, default=100_000, help="simulations per search")
    args = parser.parse_args()

    scenario = hptrack.random_scenario(n_targets=args.targets, seed=args.seed)
    decision = hptrack.plan(scenario, "mcts", iterations=args.iterations)
    subtask = decision.subtask or {}
    print(f"pursue {decision.target}: fly towards {decision.waypoint.round(1)} m")
    print(
        f"intercept in {subtask.get('intercept_time', 0.0):.1f} s, "
        f"p_find {subtask.get('p_find', 0.0):.3f} by t_cutoff {subtask.get('t_cutoff', 0.0):.1f} s"
    )


if __name__ == "__main__":
    main()
