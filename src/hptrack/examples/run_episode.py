"""Fly one 900 s mission with a planner and print the final uncertainty U per target.

python3 run_episode.py [--planner mcts] [--targets 4] [--seed 0]
"""

from __future__ import annotations

import argparse

import hptrack


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planner", default="mcts", help="a name of `hptrack planners`")
    parser.add_argument("--targets", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    scenario = hptrack.random_scenario(n_targets=args.targets, seed=args.seed)
    record = hptrack.run_episode(scenario, hptrack.make_planner(args.planner))
    for target, logdet in zip(scenario.target_ids, record.per_target_logdet, strict=True):
        print(f"{target}: log det Sigma_xy = {logdet:7.3f} log m^4")
    never = scenario.never_observed_uncertainty()
    print(f"U = {record.uncertainty:.3f} (never observed: {never:.3f})")


if __name__ == "__main__":
    main()
