"""The planners at scale, side by side: the search with the revisit tour inside it, the tour
alone, the default search, the paper's search, greedy and the clairvoyant reference.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``), every search at
``--time-limit`` s per decision, or with ``--default-effort`` at its preset's default number of
simulations per search (no time limit). The variants (``--variants``, names of `VARIANTS`) run
in one process pool side by side; episodes are stored in the results database ``--db`` as they
finish (a re-run resumes; a run at another time limit is another identity). The report: mean
``U`` with its standard error, the share of the greedy-to-clairvoyant gap closed on the
scenarios all three flew, the targets never detected per episode, the paired difference of
the first variant and each other one (negative: the first is better), the searches' effort
(simulations and wall time per search), and, when the references ran, the gap closed by
planner and n as a table and a figure.

    python3 benchmarks/scale_benchmark.py --targets 6,12,20 --seeds 30 --time-limit 0.05 \\
        --workers 2 --db results/scale.db --out docs/results/scale-0.05s
    python3 benchmarks/scale_benchmark.py --targets 6,12,20 --seeds 30 --default-effort \\
        --variants revisit,improved --workers 2 --db results/scale.db --out results/effort
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

VARIANTS: dict[str, tuple[str, dict]] = {
    "revisit": ("mcts", {"preset": "revisit"}),
    "tour_plan+fortify": ("mcts", {"rollout": "tour_plan", "fortify": True}),
    "tour_plan": ("mcts", {"rollout": "tour_plan"}),
    "tour_plan+fortify+dwell": (
        "mcts",
        {"rollout": "tour_plan", "fortify": True, "dwell": 10.0, "miss": "keep"},
    ),
    "improved": ("mcts", {"preset": "improved"}),
    "paper": ("mcts", {"preset": "paper"}),
    "revisit+limit30+keep": ("mcts", {"preset": "revisit", "coverage_limit": 30.0, "miss": "keep"}),
    "revisit+limit60+keep": ("mcts", {"preset": "revisit", "coverage_limit": 60.0, "miss": "keep"}),
    "tour": ("tour", {}),
    "tour-find0.5": ("tour", {"min_find": 0.5}),
    "tour-find0": ("tour", {"min_find": 0.0}),
    "greedy": ("greedy", {}),
    "clairvoyant": ("clairvoyant", {}),
}
"""The planners compared, by their names in the tables: a planner and its options (the
searches' time limit added, if any); ``tour-findP`` is the tour that lets a target go only when
its chance of a find on arrival is below ``P`` (0.9 by default); ``revisit+limitS+keep`` the
default search whose pursuits' spirals end after ``S`` s at the latest and whose missed targets
stay in the action list."""

REFERENCES = ("greedy", "clairvoyant")
"""The two ends of the gap closed (``--references``: run by default)."""


def configs(
    names: tuple[str, ...], targets: tuple[int, ...], seeds: int, time_limit: float | None
) -> dict[str, BenchmarkConfig]:
    """The benchmark of each variant, by its name in the table; ``time_limit`` None: the
    searches at their presets' default effort."""
    out = {}
    for name in names:
        planner, options = VARIANTS[name]
        if planner == "mcts" and time_limit is not None:
            options = {**options, "time_limit": time_limit}
        out[name] = BenchmarkConfig(
            planners=(planner,),
            settings={planner: planner_settings(planner, options)},
            target_counts=targets,
            scenarios=seeds,
            homogeneous=True,
        )
    return out


def gap_closed(by_variant: dict[str, dict], variant: str, n: int) -> tuple[float, int]:
    """The share (%) of the greedy-to-clairvoyant gap that ``variant`` closes at ``n`` on the
    mean U of the scenarios all three flew, and their number."""
    if not all(ref in by_variant for ref in REFERENCES):
        return math.nan, 0
    rows = by_variant[variant]
    common = [s for m, s in rows if m == n and all((n, s) in by_variant[ref] for ref in REFERENCES)]
    if not common:
        return math.nan, 0
    greedy, clairvoyant, mine = (
        np.mean([by_variant[v][n, s].uncertainty for s in common]) for v in (*REFERENCES, variant)
    )
    return 100.0 * (greedy - mine) / (greedy - clairvoyant), len(common)


def effort_text(time_limit: float | None) -> str:
    """How long each search ran, in words."""
    if time_limit is None:
        return "at its preset's default effort (simulations per search)"
    return f"at {time_limit:g} s per decision"


def report(by_variant: dict[str, dict], out: Path, command: str, time_limit: float | None) -> None:
    """Write ``table.md``, ``summary.json`` and ``gap.png`` from ``{variant: {(n, seed):
    row}}``."""
    counts = sorted({n for rows in by_variant.values() for n, _ in rows})
    first = next(iter(by_variant))
    lines = [
        f"Homogeneous random scenarios (seeds from 0), every search {effort_text(time_limit)}.",
        "The variants: `tour_plan` is `mcts` with the revisit tour as its rollout policy and leaf",
        "value (`-o mcts.rollout=tour_plan`) and `revisit` the preset of that search (with its",
        "own default effort), `+fortify` keeps the tour's action unless the search beats it by",
        "more than the standard error of the difference, `+dwell` adds a 10 s dwell action and",
        "keeps missed targets in the action list; `improved` is the preset with the paper's",
        "random rollouts, `paper` the paper's search, `tour` the tour planner;",
        "`revisit+limitS+keep` is `revisit` whose pursuits' spirals end after S s at the latest",
        "(`-o mcts.coverage_limit=S`) and whose missed targets stay in the action list.",
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
    summary: dict = {"command": command, "time_limit_s": time_limit, "rows": [], "paired": []}
    for n in counts:
        for variant, rows in by_variant.items():
            seeds = sorted(s for m, s in rows if m == n)
            if not seeds:
                continue
            mean, se = mean_se(np.array([rows[n, s].uncertainty for s in seeds]))
            gap, common = gap_closed(by_variant, variant, n)
            never = float(np.mean([rows[n, s].info["targets_never_detected"] for s in seeds]))
            lines.append(
                f"| {n} | {variant} | {len(seeds)} | {mean:.2f} +- {se:.2f} | "
                f"{f'{gap:.0f} ({common})' if common else '-'} | {never:.2f} |"
            )
            summary["rows"].append(
                {
                    "n": n,
                    "planner": variant,
                    "episodes": len(seeds),
                    "mean_U": mean,
                    "se_U": se,
                    "gap_closed_percent": gap,
                    "gap_scenarios": common,
                    "never_detected": never,
                }
            )
    lines += [
        "",
        f"Paired differences of U, {first} - other, on the scenarios both flew, mean +- standard",
        f"error (negative: {first} is better).",
        "",
        f"| n | {first} - | scenarios | mean difference | in % of the other |",
        "|---|---|---|---|---|",
    ]
    paired, summary["paired"] = paired_differences(by_variant, counts, first, "first_minus_other")
    lines += paired
    lines += [
        "",
        "The searches' effort: searches per episode, simulations per search (median, and the",
        "least), wall time per search (median), s.",
        "",
        "| n | planner | searches per episode | simulations, median (least) | wall, median |",
        "|---|---|---|---|---|",
    ]
    summary["searches"] = []
    for n in counts:
        for variant, rows in by_variant.items():
            searches = [
                s for (m, _), r in rows.items() if m == n for s in r.info.get("searches", ())
            ]
            if not searches:
                continue
            episodes = sum(1 for m, _ in rows if m == n)
            sims = np.array([s["simulations"] for s in searches])
            wall = float(np.median([s["elapsed_s"] for s in searches]))
            lines.append(
                f"| {n} | {variant} | {len(searches) / episodes:.1f} | "
                f"{np.median(sims):.0f} ({sims.min()}) | {wall:.3f} |"
            )
            summary["searches"].append(
                {
                    "n": n,
                    "planner": variant,
                    "searches_per_episode": len(searches) / episodes,
                    "median_simulations": float(np.median(sims)),
                    "least_simulations": int(sims.min()),
                    "median_wall_s": wall,
                }
            )
    lines += gap_table(summary["rows"], counts)
    write_tables(out, lines, summary)
    if any(math.isfinite(r["gap_closed_percent"]) for r in summary["rows"]):
        figure(summary, out / "gap.png", time_limit)


def gap_table(rows: list[dict], counts: list[int]) -> list[str]:
    """The share of the gap closed, one row per planner but the references and one column per
    n (the scenarios in brackets); no lines when the references did not run."""
    gaps = {(r["planner"], r["n"]): r for r in rows if r["gap_scenarios"]}
    planners = [p for p in dict.fromkeys(r["planner"] for r in rows) if p not in REFERENCES]
    if not gaps:
        return []
    lines = [
        "",
        "The share of the greedy-to-clairvoyant gap closed, %, by n (the scenarios in brackets).",
        "",
        "| planner | " + " | ".join(f"n={n}" for n in counts) + " |",
        "|---|" + "---|" * len(counts),
    ]
    for planner in planners:
        cells = [
            f"{gaps[planner, n]['gap_closed_percent']:.0f} ({gaps[planner, n]['gap_scenarios']})"
            if (planner, n) in gaps
            else "-"
            for n in counts
        ]
        lines.append(f"| {planner} | " + " | ".join(cells) + " |")
    return lines


def figure(summary: dict, path: Path, time_limit: float | None) -> None:
    """The gap closed against n, one line per planner but the references."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    planners = dict.fromkeys(r["planner"] for r in summary["rows"])
    for planner in planners:
        if planner in REFERENCES:
            continue
        rows = [r for r in summary["rows"] if r["planner"] == planner]
        ax.plot(
            [r["n"] for r in rows], [r["gap_closed_percent"] for r in rows], "o-", label=planner
        )
    ax.set_xlabel("targets n")
    ax.set_ylabel("greedy-to-clairvoyant gap closed, %")
    ax.set_title(f"every search {effort_text(time_limit)}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12,20", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--time-limit", type=float, default=0.05, help="s per decision")
    parser.add_argument(
        "--default-effort",
        action="store_true",
        help="every search at its preset's default simulations per search, no time limit",
    )
    parser.add_argument(
        "--variants",
        default="tour_plan+fortify,improved,paper,tour",
        help=f"comma-separated, the first compared with the rest; of {', '.join(VARIANTS)}",
    )
    parser.add_argument(
        "--references",
        default=",".join(REFERENCES),
        help="the gap's ends run beside the variants (none: an empty string)",
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/scale.db"))
    parser.add_argument("--out", type=Path, default=Path("results/scale"))
    parser.add_argument(
        "--report-only", action="store_true", help="report what the database holds, run nothing"
    )
    args = parser.parse_args()
    names = tuple(v for v in args.variants.split(",") if v)
    references = tuple(v for v in args.references.split(",") if v)
    unknown = [v for v in (*names, *references) if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variants {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    names = (*names, *(r for r in references if r not in names))
    targets = tuple(int(t) for t in args.targets.split(",") if t)
    command = (
        f"python3 benchmarks/scale_benchmark.py --targets {args.targets} --seeds {args.seeds} "
        + ("--default-effort " if args.default_effort else f"--time-limit {args.time_limit:g} ")
        + f"--variants {args.variants} "
        + (f"--references '{args.references}' " if references != REFERENCES else "")
        + f"--workers {args.workers} --db {args.db} --out {args.out}"
    )
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        time_limit = None if args.default_effort else args.time_limit
        variants = configs(names, targets, args.seeds, time_limit)
        by_variant = run_variants(variants, store, args.workers, run=not args.report_only)
    finally:
        store.close()
    report(by_variant, args.out, command, time_limit)


if __name__ == "__main__":
    main()
