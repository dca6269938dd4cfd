"""Speed and quality of the ARVI and A* baselines on random homogeneous scenarios.

For each planner and number of targets ``n``, flies whole missions (900 s, 1800 steps) of the
paper's random homogeneous scenarios (seeds ``first_seed ..``) and prints, per ``n``:

* the decision time (one search, replanning after every primitive): mean, 95th percentile and
  maximum over every decision of every mission;
* how often the deterministic cap bound (A*: ``max_expansions``; ARVI: ``max_nodes_per_level``)
  and the mean number of nodes expanded per decision;
* the mission's wall time (planning plus simulation);
* ``U`` against the scenario's never-observed score.

Numba kernels are compiled (or loaded from the cache) before any timing. Run on one core:

    python3 benchmarks/bench_baselines.py --planners arvi,astar --targets 2,3,4,5,6 --scenarios 3

Planner options as ``-o PLANNER.KEY=VALUE`` (e.g. ``-o arvi.horizon=8``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hptrack.cli.common import planner_options
from hptrack.registry import make_planner
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode


def warm_up(planner_names: list[str], options: dict) -> None:
    """Compile (or load) every kernel with a short mission, so timings exclude it."""
    scenario = random_scenario(2, seed=10_000, homogeneous=True, budget=20.0)
    for name in planner_names:
        run_episode(scenario, make_planner(name, options.get(name, {})))


def measure(name: str, n_targets: int, seeds: range, options: dict) -> dict:
    """Fly one mission per seed; decision and mission statistics."""
    times, expanded, capped, walls, u, never = [], [], [], [], [], []
    for seed in seeds:
        scenario = random_scenario(n_targets, seed=seed, homogeneous=True)
        planner = make_planner(name, options)
        start = time.perf_counter()
        record = run_episode(scenario, planner, belief_stride=scenario.mission_spec().n_steps)
        walls.append(time.perf_counter() - start)
        times += [d.planning_time_s for d in planner.decisions]
        expanded += [d.nodes_expanded for d in planner.decisions]
        capped += [d.capped for d in planner.decisions]
        u.append(record.uncertainty)
        never.append(scenario.never_observed_uncertainty())
    times_ms = 1e3 * np.array(times)
    return {
        "mean_ms": times_ms.mean(),
        "p95_ms": np.percentile(times_ms, 95),
        "max_ms": times_ms.max(),
        "capped": np.mean(capped),
        "expanded": np.mean(expanded),
        "mission_s": np.mean(walls),
        "mission_max_s": np.max(walls),
        "u": np.mean(u),
        "never": np.mean(never),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--planners", default="arvi,astar")
    parser.add_argument("--targets", default="2,3,4,5,6")
    parser.add_argument("--scenarios", type=int, default=3, help="missions per n")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("-o", "--option", action="append", default=[])
    args = parser.parse_args()
    names = [p for p in args.planners.split(",") if p]
    options = planner_options(args.option, tuple(names))
    warm_up(names, options)
    seeds = range(args.first_seed, args.first_seed + args.scenarios)
    header = (
        f"{'planner':8} {'n':>2} {'decision ms mean':>16} {'p95':>7} {'max':>7} "
        f"{'capped':>7} {'expanded':>9} {'mission s':>9} {'max':>6} {'U':>7} "
        f"{'never':>7}"
    )
    print(f"{len(seeds)} missions per n (seeds {seeds.start}..{seeds.stop - 1}), 900 s each")
    print(header)
    for name in names:
        for n in (int(t) for t in args.targets.split(",")):
            r = measure(name, n, seeds, options.get(name, {}))
            print(
                f"{name:8} {n:>2} {r['mean_ms']:>16.1f} {r['p95_ms']:>7.1f} "
                f"{r['max_ms']:>7.1f} {r['capped']:>7.1%} {r['expanded']:>9.0f} "
                f"{r['mission_s']:>9.2f} {r['mission_max_s']:>6.2f} {r['u']:>7.2f} "
                f"{r['never']:>7.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
