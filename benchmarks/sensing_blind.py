"""A planner that knows its sensor against one that does not, on a world whose detector misses.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``) whose sensor detects a
target inside its footprint with probability ``--detection-probability`` at each look. The
default ``mcts`` (preset ``improved``, ``--iterations`` simulations per decision, so the rows are
reproducible) flies each scenario twice: told the true ``Pd`` ("known") and told the paper's
certain sensor (``hptrack benchmark --blind``); ``greedy`` (which ignores ``Pd``) once. The
worlds are the same: the same truths, detector draws and noise. Episodes are stored in the
results database ``--db`` as they finish (a re-run resumes); the report is the mean ``U`` with
its standard error and the targets never detected per planner and ``n``, and the paired
difference known - blind (negative: knowing the sensor helps), with its standard error.

    python3 benchmarks/sensing_blind.py --targets 6,12 --seeds 30 --workers 2 \\
        --db results/sensing-blind.db --out docs/results/sensing-blind
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_benchmark
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings

VARIANTS = (("mcts", False), ("mcts", True), ("greedy", False))
"""The planners flown, and whether each is told the paper's certain sensor (blind)."""


def configs(
    targets: tuple[int, ...], seeds: int, pd: float, iterations: int
) -> dict[str, BenchmarkConfig]:
    """The benchmark of each variant, by its name in the table."""
    out = {}
    for planner, blind in VARIANTS:
        options = {"iterations": iterations} if planner == "mcts" else None
        out[f"{planner}{'_blind' if blind else ''}"] = BenchmarkConfig(
            planners=(planner,),
            settings={planner: planner_settings(planner, options)},
            target_counts=targets,
            scenarios=seeds,
            homogeneous=True,
            detection_probability=pd,
            blind=blind,
        )
    return out


def report(by_variant: dict[str, dict], out: Path, pd: float, iterations: int) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{variant: {(n, seed): row}}``."""
    lines = [
        f"Pd = {pd:g} at every look; mcts at {iterations:,} simulations per decision.",
        "",
        "| n | planner | episodes | mean U | std. error | targets never detected |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    summary: dict = {"detection_probability": pd, "iterations": iterations, "rows": []}
    counts = sorted({n for rows in by_variant.values() for n, _ in rows})
    for n in counts:
        for variant, rows in by_variant.items():
            mine = [r for (m, _), r in sorted(rows.items()) if m == n]
            u = np.array([r.uncertainty for r in mine])
            never = np.array([r.info["targets_never_detected"] for r in mine])
            mean, se = mean_se(u)
            lines.append(
                f"| {n} | {variant} | {len(mine)} | {mean:.2f} | {se:.2f} | {never.mean():.2f} |"
            )
            summary["rows"].append(
                {
                    "n": n,
                    "planner": variant,
                    "episodes": len(mine),
                    "mean_U": mean,
                    "se_U": se,
                    "never_detected": float(never.mean()),
                }
            )
    lines += [
        "",
        "| n | known - blind, paired mean U | std. error | scenarios | margin / std. error |",
        "| --- | --- | --- | --- | --- |",
    ]
    for n in counts:
        known, blind = by_variant["mcts"], by_variant["mcts_blind"]
        seeds = sorted(s for (m, s) in known if m == n and (m, s) in blind)
        diff = np.array([known[n, s].uncertainty - blind[n, s].uncertainty for s in seeds])
        mean, se = mean_se(diff)
        lines.append(f"| {n} | {mean:.2f} | {se:.2f} | {len(seeds)} | {-mean / se:.1f} |")
        summary.setdefault("paired", []).append(
            {"n": n, "known_minus_blind": mean, "se": se, "scenarios": len(seeds)}
        )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--detection-probability", type=float, default=0.7)
    parser.add_argument("--iterations", type=int, default=2000, help="mcts simulations")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/sensing-blind.db"))
    parser.add_argument("--out", type=Path, default=Path("results/sensing-blind"))
    args = parser.parse_args()
    targets = tuple(int(t) for t in args.targets.split(","))
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        by_variant = {}
        for variant, config in configs(
            targets, args.seeds, args.detection_probability, args.iterations
        ).items():
            run_benchmark(config, store, args.workers)
            wanted = set(config.keys())
            by_variant[variant] = {
                (r.key.n_targets, r.key.seed): r for r in store.rows() if r.key in wanted
            }
    finally:
        store.close()
    report(by_variant, args.out, args.detection_probability, args.iterations)


if __name__ == "__main__":
    main()
