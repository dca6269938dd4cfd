"""What a fence costs: each planner on the same homogeneous random scenarios with and without
random no-fly circles (``hptrack benchmark --no-fly``: one to three circles covering 10-25 % of
the targets' square, margin 10 m).

Planners (``--planners``, default all): greedy, the default ``mcts`` and its paper preset
(``--iterations`` simulations per decision, so the rows are reproducible), the clairvoyant
reference, and the ARVI and A* baselines at their default (deterministic) settings. Episodes
are stored in ``--db`` as they finish (a re-run resumes); the report is per ``n`` and planner
the mean ``U`` open and fenced with standard errors, the paired cost fenced - open with its
standard error, and the targets never detected::

    python3 benchmarks/fence_cost.py --targets 6,12 --seeds 30 --workers 2 \\
        --planners greedy,mcts,"mcts paper",clairvoyant \\
        --db results/fence-cost.db --out docs/results/fence-cost
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_benchmark
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings

VARIANTS = {
    "greedy": ("greedy", None),
    "mcts": ("mcts", {"preset": "improved"}),
    "mcts paper": ("mcts", {"preset": "paper"}),
    "clairvoyant": ("clairvoyant", None),
    "arvi": ("arvi", None),
    "astar": ("astar", None),
}
"""The planners flown: their names in the table, registered names and options (``{}``: the
search with ``--iterations``)."""


def config(name: str, targets: tuple[int, ...], seeds: int, iterations: int, no_fly: bool):
    """The benchmark of one variant, open or fenced."""
    planner, options = VARIANTS[name]
    if options is not None:
        options = {**options, "iterations": iterations}
    return BenchmarkConfig(
        planners=(planner,),
        settings={planner: planner_settings(planner, options)},
        target_counts=targets,
        scenarios=seeds,
        homogeneous=True,
        no_fly=no_fly,
    )


def report(rows: dict, out: Path, iterations: int, names: list[str]) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{(variant, fenced): {(n, seed): row}}``."""
    searched = any(VARIANTS[name][0] == "mcts" for name in names)
    lines = [
        (f"mcts at {iterations:,} simulations per decision; " if searched else "")
        + "paired over the same scenarios.",
        "",
        "| n | planner | scenarios | mean U, open | std. error | mean U, fenced | std. error | "
        "cost, fenced - open | std. error | never detected, open | fenced |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    summary: dict = {"iterations": iterations, "rows": []}
    counts = sorted({n for by in rows.values() for n, _ in by})
    for n in counts:
        for name in names:
            open_, fenced = rows[name, False], rows[name, True]
            seeds = sorted(s for (m, s) in open_ if m == n and (m, s) in fenced)
            if not seeds:
                continue
            u_open = np.array([open_[n, s].uncertainty for s in seeds])
            u_fenced = np.array([fenced[n, s].uncertainty for s in seeds])
            never = [
                float(np.mean([by[n, s].info["targets_never_detected"] for s in seeds]))
                for by in (open_, fenced)
            ]
            (mo, so), (mf, sf), (mc, sc) = (
                mean_se(u_open),
                mean_se(u_fenced),
                mean_se(u_fenced - u_open),
            )
            lines.append(
                f"| {n} | {name} | {len(seeds)} | {mo:.2f} | {so:.2f} | {mf:.2f} | {sf:.2f} "
                f"| {mc:+.2f} | {sc:.2f} | {never[0]:.2f} | {never[1]:.2f} |"
            )
            summary["rows"].append(
                {
                    "n": n,
                    "planner": name,
                    "scenarios": len(seeds),
                    "mean_U_open": mo,
                    "se_U_open": so,
                    "mean_U_fenced": mf,
                    "se_U_fenced": sf,
                    "cost": mc,
                    "se_cost": sc,
                    "never_detected_open": never[0],
                    "never_detected_fenced": never[1],
                }
            )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--iterations", type=int, default=1000, help="mcts simulations")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/fence-cost.db"))
    parser.add_argument("--out", type=Path, default=Path("results/fence-cost"))
    parser.add_argument(
        "--planners", default=",".join(VARIANTS), help="the variants flown, comma-separated"
    )
    args = parser.parse_args()
    names = [name.strip() for name in args.planners.split(",")]
    unknown = sorted(set(names) - set(VARIANTS))
    if unknown:
        parser.error(f"unknown --planners {unknown}; choose from {list(VARIANTS)}")
    targets = tuple(int(t) for t in args.targets.split(","))
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        rows = {}
        for name in names:
            for no_fly in (False, True):
                c = config(name, targets, args.seeds, args.iterations, no_fly)
                run_benchmark(c, store, args.workers)
                wanted = set(c.keys())
                rows[name, no_fly] = {
                    (r.key.n_targets, r.key.seed): r for r in store.rows() if r.key in wanted
                }
    finally:
        store.close()
    report(rows, args.out, args.iterations, names)


if __name__ == "__main__":
    main()
