"""Check that the published per-episode results still come out of the current code.

Re-runs the episodes of ``docs/results/benchmark/episodes.csv`` (by default mcts, arvi and astar
at n = 4 and 6, scenario seeds 0..9, homogeneous setting, each planner's default settings, which
are the published ones) and compares each episode's U and number of detection steps with the
published row. Prints one line per episode and a summary; exits 1 if any episode differs by more
than ``--tolerance`` in U (relative) or in its detections.

    python3 benchmarks/check_reproduction.py                 # 60 episodes, 2 workers
    python3 benchmarks/check_reproduction.py --tolerance 0   # bit-identical U required

With ``--db``, the episodes stored in a results database are re-run instead (those of
``--planners``, ``--targets`` and the first ``--seeds`` seeds, each with its stored settings;
time-limited ones are skipped, their results depend on the machine), e.g. the improved preset:

    python3 benchmarks/check_reproduction.py --db results/default-effort.db --planners mcts \
        --seeds 2 --tolerance 0
"""

from __future__ import annotations

import argparse
import csv
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PUBLISHED = Path(__file__).resolve().parents[1] / "docs/results/benchmark/episodes.csv"


def published_key(planner: str, n: int, seed: int):
    from hptrack.experiments.store import EpisodeKey
    from hptrack.registry import planner_settings

    options = {"preset": "paper"} if planner == "mcts" else None  # the published search
    return EpisodeKey(
        planner, n, seed, "homogeneous", planner_settings(planner, options).canonical()
    )


def run(key) -> tuple[float, int]:
    from hptrack.experiments.benchmark import run_one

    row = run_one(key)
    return row.uncertainty, row.detections


def stored(db: Path, planners: list[str], counts: list[int], seeds: int) -> dict:
    """``{key: (U, detections)}`` of the database's episodes that a re-run must reproduce."""
    import json

    from hptrack.experiments.store import ResultStore

    store = ResultStore(db)
    try:
        return {
            r.key: (r.uncertainty, r.detections)
            for r in store.rows()
            if r.key.planner in planners
            and r.key.n_targets in counts
            and r.key.seed < seeds
            and json.loads(r.key.planner_settings).get("time_limit") is None
        }
    finally:
        store.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--planners", default="mcts,arvi,astar")
    parser.add_argument("--targets", default="4,6")
    parser.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1")
    parser.add_argument(
        "--tolerance",
        type=float,
        default=1e-9,
        help="largest relative difference of U accepted (0: bit-identical)",
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--db", type=Path, default=None, help="re-run this results database's episodes instead"
    )
    args = parser.parse_args()
    planners = args.planners.split(",")
    counts = [int(n) for n in args.targets.split(",")]
    if args.db is None:
        with PUBLISHED.open(newline="") as fh:
            published = {
                (r["planner"], int(r["n_targets"]), int(r["seed"])): r for r in csv.DictReader(fh)
            }
        expected = {}
        for n in counts:
            for s in range(args.seeds):
                for p in planners:
                    row = published[(p, n, s)]
                    expected[published_key(p, n, s)] = (float(row["U"]), int(row["detections"]))
    else:
        expected = stored(args.db, planners, counts, args.seeds)
    jobs = list(expected)
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run, jobs))
    worst, bad, identical = 0.0, 0, 0
    for key, (u, detections) in zip(jobs, results, strict=True):
        p, n, s = key.planner, key.n_targets, key.seed
        u_ref, d_ref = expected[key]
        rel = abs(u - u_ref) / abs(u_ref)
        worst = max(worst, rel)
        identical += u == u_ref
        ok = rel <= args.tolerance and detections == d_ref
        bad += not ok
        print(
            f"{p:6s} {key.setting} n={n} seed={s}: U {u:.15g} stored {u_ref:.15g} "
            f"(rel diff {rel:.2e}), "
            f"detections {detections} / {d_ref} {'ok' if ok else 'DIFFERS'}"
        )
    print(
        f"{len(jobs)} episodes: {identical} bit-identical U, largest relative difference "
        f"{worst:.2e}, {bad} beyond tolerance {args.tolerance:g} or with other detections"
    )
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
