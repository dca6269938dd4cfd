"""The ``tour`` planner side by side with the default search, greedy and the clairvoyant reference.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``): ``tour`` (its
defaults), ``mcts`` (the default preset) at ``--time-limit`` s per decision, ``greedy`` and
``clairvoyant`` on every scenario, and ``mcts`` at ``--long-time-limit`` s on the first
``--long-seeds`` scenarios of each n in ``--long-targets``. Episodes are stored in the results
database ``--db`` as they finish (a re-run resumes). The report: mean ``U`` with its standard
error, the share of the greedy-to-clairvoyant gap closed, the targets never detected, the paired
difference tour - each other planner on the scenarios both flew (negative: tour is better), and
tour's wall and CPU time per decision.

    python3 benchmarks/tour_benchmark.py --targets 6,12,20 --seeds 30 --long-targets 12,20 \\
        --long-seeds 10 --workers 1 --db results/tour.db --out docs/results/tour
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_variants
from hptrack.experiments.report import mean_se, paired_differences, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings


def configs(
    targets: tuple[int, ...],
    seeds: int,
    time_limit: float,
    long_targets: tuple[int, ...],
    long_seeds: int,
    long_time_limit: float,
) -> dict[str, BenchmarkConfig]:
    """The benchmark of each variant, by its name in the table."""

    def one(planner: str, options: dict | None, counts: tuple[int, ...], scenarios: int):
        return BenchmarkConfig(
            planners=(planner,),
            settings={planner: planner_settings(planner, options)},
            target_counts=counts,
            scenarios=scenarios,
            homogeneous=True,
        )

    out = {
        "tour": one("tour", None, targets, seeds),
        f"mcts @ {time_limit:g} s": one(
            "mcts", {"preset": "improved", "time_limit": time_limit}, targets, seeds
        ),
        "greedy": one("greedy", None, targets, seeds),
    }
    if long_targets and long_seeds:
        out[f"mcts @ {long_time_limit:g} s"] = one(
            "mcts", {"preset": "improved", "time_limit": long_time_limit}, long_targets, long_seeds
        )
    out["clairvoyant"] = one("clairvoyant", None, targets, seeds)  # the slowest at n = 20
    return out


def report(by_variant: dict[str, dict], out: Path, command: str) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{variant: {(n, seed): row}}``."""
    counts = sorted({n for rows in by_variant.values() for n, _ in rows})
    lines = [
        "Homogeneous random scenarios (seeds from 0); `tour` at its defaults, `mcts` the improved",
        "preset at the planning time per decision given.",
        "",
        "```bash",
        command,
        "```",
        "",
        "Mean U +- standard error (episodes), share of the greedy-to-clairvoyant gap closed on the",
        "mean U of the scenarios the three flew (their number), targets never detected per",
        "episode.",
        "",
        "| n | planner | episodes | mean U | gap closed, % | never detected |",
        "|---|---|---|---|---|---|",
    ]
    summary: dict = {"command": command, "rows": [], "paired": [], "tour_decisions": []}
    for n in counts:
        for variant, rows in by_variant.items():
            seeds = sorted(s for m, s in rows if m == n)
            if not seeds:
                continue
            u = np.array([rows[n, s].uncertainty for s in seeds])
            common = [s for s in seeds if (n, s) in by_variant["clairvoyant"]]
            ends = [
                np.mean([by_variant[ref][n, s].uncertainty for s in common])
                for ref in ("greedy", "clairvoyant")
            ]
            mine = np.mean([rows[n, s].uncertainty for s in common])
            gap = 100.0 * (ends[0] - mine) / (ends[0] - ends[1]) if common else math.nan
            never = np.mean([rows[n, s].info["targets_never_detected"] for s in seeds])
            mean, se = mean_se(u)
            lines.append(
                f"| {n} | {variant} | {len(seeds)} | {mean:.2f} +- {se:.2f} | "
                f"{gap:.0f} ({len(common)}) | {never:.2f} |"
            )
            summary["rows"].append(
                {
                    "n": n,
                    "planner": variant,
                    "episodes": len(seeds),
                    "mean_U": mean,
                    "se_U": se,
                    "gap_closed_percent": gap,
                    "gap_scenarios": len(common),
                    "never_detected": float(never),
                }
            )
    lines += [
        "",
        "Paired differences of U, tour - other, on the scenarios both flew, mean +- standard",
        "error (negative: tour is better).",
        "",
        "| n | tour - | scenarios | mean difference | in % of the other |",
        "|---|---|---|---|---|",
    ]
    paired, summary["paired"] = paired_differences(by_variant, counts, "tour", "tour_minus_other")
    lines += paired
    tour = by_variant["tour"]
    lines += [
        "",
        "tour's planning time per decision, s (wall time on a shared machine, and CPU time).",
        "",
        "| n | decisions | mean wall | max wall | mean CPU | max CPU |",
        "|---|---|---|---|---|---|",
    ]
    for n in counts:
        decisions = [d for (m, _), r in tour.items() if m == n for d in r.info["tours"]]
        wall = np.array([d["elapsed_s"] for d in decisions])
        cpu = np.array([d["cpu_s"] for d in decisions])
        lines.append(
            f"| {n} | {len(decisions)} | {wall.mean():.4f} | {wall.max():.4f} | "
            f"{cpu.mean():.4f} | {cpu.max():.4f} |"
        )
        summary["tour_decisions"].append(
            {
                "n": n,
                "decisions": len(decisions),
                "mean_wall_s": float(wall.mean()),
                "max_wall_s": float(wall.max()),
                "mean_cpu_s": float(cpu.mean()),
                "max_cpu_s": float(cpu.max()),
            }
        )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12,20", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--time-limit", type=float, default=0.05, help="mcts, s per decision")
    parser.add_argument("--long-targets", default="", help="n of the longer mcts, comma-separated")
    parser.add_argument("--long-seeds", type=int, default=0, help="its scenarios per n")
    parser.add_argument("--long-time-limit", type=float, default=1.0, help="its s per decision")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/tour.db"))
    parser.add_argument("--out", type=Path, default=Path("results/tour"))
    parser.add_argument(
        "--report-only", action="store_true", help="report what the database holds, run nothing"
    )
    args = parser.parse_args()

    def counts(text: str) -> tuple[int, ...]:
        return tuple(int(t) for t in text.split(",") if t)

    command = (
        f"python3 benchmarks/tour_benchmark.py --targets {args.targets} --seeds {args.seeds} "
        f"--time-limit {args.time_limit:g}"
        + (
            f" --long-targets {args.long_targets} --long-seeds {args.long_seeds} "
            f"--long-time-limit {args.long_time_limit:g}"
            if args.long_targets and args.long_seeds
            else ""
        )
        + f" --workers {args.workers} --db {args.db} --out {args.out}"
    )
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        variants = configs(
            counts(args.targets),
            args.seeds,
            args.time_limit,
            counts(args.long_targets),
            args.long_seeds,
            args.long_time_limit,
        )
        by_variant = run_variants(variants, store, args.workers, run=not args.report_only)
    finally:
        store.close()
    report(by_variant, args.out, command)


if __name__ == "__main__":
    main()
