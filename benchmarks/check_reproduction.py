"""Check that the published per-episode results still come out of the current code.

Re-runs the episodes of ``docs/results/benchmark/episodes.csv`` (by default mcts, arvi and astar
at n = 4 and 6, scenario seeds 0..9, homogeneous setting, each planner's default settings, which
are the published ones) and compares each episode's U and number of detection steps with the
published row. Prints one line per episode and a summary; exits 1 if any episode differs by more
than ``--tolerance`` in U (relative) or in its detections.

    python3 benchmarks/check_reproduction.py                 # 60 episodes, 2 workers
    python3 benchmarks/check_reproduction.py --tolerance 0   # bit-identical U required
"""

from __future__ import annotations

import argparse
import csv
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PUBLISHED = Path(__file__).resolve().parents[1] / "docs/results/benchmark/episodes.csv"


def run(planner: str, n: int, seed: int) -> tuple[float, int]:
    from hptrack.experiments.benchmark import run_one
    from hptrack.experiments.store import EpisodeKey
    from hptrack.registry import planner_settings

    options = {"preset": "paper"} if planner == "mcts" else None  # the published search
    key = EpisodeKey(planner, n, seed, "homogeneous",
                     planner_settings(planner, options).canonical())
    row = run_one(key)
    return row.uncertainty, row.detections


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--planners", default="mcts,arvi,astar")
    parser.add_argument("--targets", default="4,6")
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1")
    parser.add_argument("--tolerance", type=float, default=1e-9,
                        help="largest relative difference of U accepted (0: bit-identical)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    planners = args.planners.split(",")
    counts = [int(n) for n in args.targets.split(",")]
    with PUBLISHED.open(newline="") as fh:
        published = {(r["planner"], int(r["n_targets"]), int(r["seed"])): r
                     for r in csv.DictReader(fh)}
    jobs = [(p, n, s) for n in counts for s in range(args.seeds) for p in planners]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run, *zip(*jobs, strict=True)))
    worst, bad, identical = 0.0, 0, 0
    for (p, n, s), (u, detections) in zip(jobs, results, strict=True):
        ref = published[(p, n, s)]
        u_ref, d_ref = float(ref["U"]), int(ref["detections"])
        rel = abs(u - u_ref) / abs(u_ref)
        worst = max(worst, rel)
        identical += u == u_ref
        ok = rel <= args.tolerance and detections == d_ref
        bad += not ok
        print(f"{p:6s} n={n} seed={s}: U {u:.15g} published {u_ref:.15g} (rel diff {rel:.2e}), "
              f"detections {detections} / {d_ref} {'ok' if ok else 'DIFFERS'}")
    print(f"{len(jobs)} episodes: {identical} bit-identical U, largest relative difference "
          f"{worst:.2e}, {bad} beyond tolerance {args.tolerance:g} or with other detections")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
