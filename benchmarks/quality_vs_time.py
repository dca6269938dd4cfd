"""Quality against planning time: the tree search's variants side by side on the same scenarios.

Every variant of ``mcts`` (the paper's search and the improvements, :data:`VARIANTS`) flies the
same homogeneous random scenarios with a wall-clock limit per decision (``--levels``, s), and
``greedy`` flies them once as the reference without look-ahead. Episodes are interleaved (for each
scenario every variant and level in turn), so a change of machine load hits all of them alike;
they are stored as they finish in a resumable database (``--db``), and a re-run with other
``--targets`` or ``--scenarios`` adds to it. ``--report`` writes, from everything in the database,
the mean ``U`` per variant, level and ``n`` with its standard error, paired differences
(same scenarios) with their standard errors, and a figure of ``U`` against time per ``n``.

    python3 benchmarks/quality_vs_time.py --targets 2,3,4,5,6 --scenarios 100 --workers 2
    python3 benchmarks/quality_vs_time.py --targets 8,10,12 --scenarios 30 --workers 2
    python3 benchmarks/quality_vs_time.py --report --out docs/results/quality-vs-time
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

VARIANTS = {
    "paper": {"preset": "paper"},
    "improved": {"preset": "improved"},
    "max": {"preset": "improved", "backup": "max"},
    "expected": {"preset": "improved", "backup": "expected"},
    "most_uncertain": {"preset": "improved", "rollout": "most_uncertain"},
}
"""``mcts`` options of each variant (the single-option rows are the ablation)."""

SETTING = "homogeneous"


def settings(variant: str, level: float) -> str:
    from hptrack.planning.hierarchical import MctsSettings

    return MctsSettings.from_options("mcts", {**VARIANTS[variant], "time_limit": level}).canonical()


BASELINES = ("greedy", "clairvoyant")
"""Planners flown once per scenario, without a planning time: no look-ahead, and the reference
that reads the truth (the report gives the share of the gap between them that a variant closes)."""


def keys(targets, scenarios, first_seed, levels, variants, greedy, only=None, clairvoyant=False):
    """The episodes to run; ``only``: a set of ``(variant, level)`` pairs to keep (all if
    ``None``)."""
    from hptrack.experiments.store import EpisodeKey
    from hptrack.settings import NoSettings

    out = []  # seeds outermost: a run stopped early leaves every n and level alike
    for seed in range(first_seed, first_seed + scenarios):
        for n in targets:
            for level in levels:
                out += [
                    EpisodeKey("mcts", n, seed, SETTING, settings(v, level))
                    for v in variants
                    if only is None or (v, level) in only
                ]
            for baseline, wanted in zip(BASELINES, (greedy, clairvoyant), strict=True):
                if wanted:
                    out.append(EpisodeKey(baseline, n, seed, SETTING, NoSettings().canonical()))
    return out


def label(key, levels, variants) -> tuple[str, float] | None:
    """``(variant, level)`` of a stored episode (``("greedy", 0)``), ``None`` if not ours."""
    if key.planner in BASELINES:
        return (key.planner, 0.0)
    for level in levels:
        for v in variants:
            if key.planner_settings == settings(v, level):
                return (v, level)
    return None


def chosen_variants(parser: argparse.ArgumentParser, args, table: dict) -> list[str]:
    """Add ``--define NAME=JSON`` variants to ``table`` and return ``--variants`` (an unknown
    name is a usage error)."""
    for text in args.define:
        name, _, options = text.partition("=")
        table[name] = json.loads(options)
    variants = args.variants.split(",")
    unknown = [v for v in variants if v not in table]
    if unknown:
        parser.error(f"--variants: unknown {unknown} (known: {', '.join(table)})")
    return variants


def header(text: str, first: str, ns) -> list[str]:
    """The lines that open a table of one column per ``n``, after a blank line and ``text``."""
    columns = " | ".join(f"n={n}" for n in ns)
    return [
        "",
        text,
        "",
        f"| {first} | {columns} |",
        "|---" * (first.count("|") + 1) + "|" + "---|" * len(ns),
    ]


def mean_se(values) -> tuple[float, float]:
    a = np.asarray(values, dtype=float)
    return float(a.mean()), float(a.std(ddof=1) / math.sqrt(a.size)) if a.size > 1 else math.nan


def report(db: Path, out: Path, levels, variants, reference: str = "paper") -> None:
    from matplotlib.figure import Figure

    from hptrack.experiments.report import write_csv
    from hptrack.experiments.store import ResultStore

    store = ResultStore(db)
    rows = store.rows()
    store.close()
    by = defaultdict(dict)  # (variant, level, n) -> {seed: U}
    lost = defaultdict(list)  # (variant, level, n) -> targets never detected, per episode
    mine = []
    for r in rows:
        tag = label(r.key, levels, variants) if r.key.setting == SETTING else None
        if tag is not None:
            by[(*tag, r.key.n_targets)][r.key.seed] = r.uncertainty
            if "targets_never_detected" in r.info:
                lost[(*tag, r.key.n_targets)].append(r.info["targets_never_detected"])
            mine.append(r)
    ns = sorted({n for (_, _, n) in by})
    out.mkdir(parents=True, exist_ok=True)
    write_csv(mine, out / "episodes.csv")
    lines = [
        "Mean U +- standard error (episodes), homogeneous scenarios; time limit per decision in s.",
        "",
        "| variant | time, s | " + " | ".join(f"n={n}" for n in ns) + " |",
        "|---|---|" + "---|" * len(ns),
    ]
    cells = sorted(
        {(v, lv) for (v, lv, _) in by},
        key=lambda c: (
            c[0] not in BASELINES,
            list(VARIANTS).index(c[0]) if c[0] in VARIANTS else BASELINES.index(c[0]),
            c[1],
        ),
    )
    for v, lv in cells:
        row = []
        for n in ns:
            seeds = by.get((v, lv, n), {})
            if seeds:
                m, se = mean_se(list(seeds.values()))
                row.append(f"{m:.2f} +- {se:.2f} ({len(seeds)})")
            else:
                row.append("")
        lines.append(f"| {v} | {'-' if v in BASELINES else f'{lv:g}'} | " + " | ".join(row) + " |")
    if any(lost.values()):
        text = "Targets never detected per episode, mean (episodes that record it)."
        lines += header(text, "variant | time, s", ns)
        for v, lv in cells:
            row = [f"{np.mean(lost[(v, lv, n)]):.2f}" if lost[(v, lv, n)] else "" for n in ns]
            if any(row):
                time = "-" if v in BASELINES else f"{lv:g}"
                lines.append(f"| {v} | {time} | " + " | ".join(row) + " |")

    def gap_closed(cell):
        """Share of the greedy-to-clairvoyant gap that ``cell`` closes, % (shared scenarios)."""
        out_cells = []
        for n in ns:
            a, g, c = (by.get((*x, n), {}) for x in (cell, ("greedy", 0.0), ("clairvoyant", 0.0)))
            shared = sorted(set(a) & set(g) & set(c))
            if not shared:
                out_cells.append("")
                continue
            mg, mc = np.mean([g[s] for s in shared]), np.mean([c[s] for s in shared])
            closed = 100.0 * (mg - np.mean([a[s] for s in shared])) / (mg - mc)
            out_cells.append(f"{closed:.0f} ({len(shared)})")
        return out_cells

    gap_rows = [(f"{v} @ {lv:g} s", gap_closed((v, lv))) for v, lv in cells if v not in BASELINES]
    if any(any(c) for _, c in gap_rows):
        text = (
            "Share of the gap from greedy (no look-ahead) to clairvoyant (reads the true target "
            "states) closed, % (scenarios)."
        )
        lines += header(text, "variant", ns)
        lines += [f"| {name} | " + " | ".join(c) + " |" for name, c in gap_rows if any(c)]

    def paired(a, b, relative=False):
        """Mean of ``U_a - U_b`` over the shared scenarios (percent of mean ``U_b``)."""
        out_cells = []
        for n in ns:
            sa, sb = by.get((*a, n), {}), by.get((*b, n), {})
            shared = sorted(set(sa) & set(sb))
            if len(shared) < 2:
                out_cells.append("")
                continue
            d = np.array([sa[s] - sb[s] for s in shared])
            scale = 100.0 / np.mean([sb[s] for s in shared]) if relative else 1.0
            m, se = mean_se(d * scale)
            out_cells.append(f"{m:+.2f} +- {se:.2f} ({len(shared)})")
        return out_cells

    comparisons = []
    top = max(levels)
    for v in variants:
        if v == "paper":
            continue
        comparisons.append(
            (
                f"{v} @ {min(levels):g} s - paper @ {top:g} s",
                (v, min(levels)),
                ("paper", top),
                False,
            )
        )
        for lv in levels:
            comparisons.append(
                (f"{v} @ {lv:g} s - paper @ {lv:g} s, % of paper", (v, lv), ("paper", lv), True)
            )
    if reference != "paper":
        for v in variants:
            if v in ("paper", reference):
                continue
            for lv in levels:
                comparisons.append(
                    (
                        f"{v} @ {lv:g} s - {reference} @ {lv:g} s, % of {reference}",
                        (v, lv),
                        (reference, lv),
                        True,
                    )
                )
    for v in variants:
        for lv in sorted(levels)[:-1]:
            comparisons.append((f"{v} @ {top:g} s - {v} @ {lv:g} s", (v, top), (v, lv), False))
    for v in variants:
        comparisons.append(
            (f"{v} @ {top:g} s - greedy, % of greedy", (v, top), ("greedy", 0.0), True)
        )
    text = (
        "Paired differences of U on the same scenarios, mean +- standard error "
        "(scenarios); negative: the first is better."
    )
    lines += header(text, "comparison", ns)
    for name, a, b, rel in comparisons:
        cells_ = paired(a, b, rel)
        if any(cells_):
            lines.append(f"| {name} | " + " | ".join(cells_) + " |")
    text = "\n".join(lines) + "\n"
    (out / "table.md").write_text(text)
    print(text)
    cols = min(4, len(ns))
    fig = Figure(figsize=(3.6 * cols, 3.2 * math.ceil(len(ns) / cols)))
    for i, n in enumerate(ns):
        ax = fig.add_subplot(math.ceil(len(ns) / cols), cols, i + 1)
        for v in variants:
            pts = [
                (lv, *mean_se(list(by[(v, lv, n)].values()))) for lv in levels if by.get((v, lv, n))
            ]
            if pts:
                x, m, se = map(np.array, zip(*pts, strict=True))
                ax.errorbar(x, m, yerr=se, marker="o", capsize=3, label=v)
        if by.get(("greedy", 0.0, n)):
            ax.axhline(
                mean_se(list(by[("greedy", 0.0, n)].values()))[0],
                color="grey",
                ls="--",
                label="greedy",
            )
        ax.set_xscale("log")
        ax.set_title(f"n = {n}")
        ax.set_xlabel("planning time per decision, s")
        ax.set_ylabel("mean U")
        if i == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "quality_vs_time.png", dpi=120)
    print(f"written to {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", default="2,3,4,5,6")
    parser.add_argument("--scenarios", type=int, default=100)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--levels", default="0.05,0.2,1", help="seconds per decision")
    parser.add_argument("--variants", default="paper,improved")
    parser.add_argument(
        "--define",
        action="append",
        default=[],
        metavar="NAME=JSON",
        help='another variant, e.g. max_c1=\'{"backup": "max", "exploration": 1.0}\'',
    )
    parser.add_argument(
        "--only",
        default=None,
        metavar="VARIANT@LEVEL,...",
        help="run only these pairs of variant and level (e.g. paper@1)",
    )
    parser.add_argument("--no-greedy", action="store_true")
    parser.add_argument(
        "--clairvoyant", action="store_true", help="also fly the reference that reads the truth"
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--db", type=Path, default=Path("results/quality_vs_time.db"))
    parser.add_argument("--report", action="store_true", help="only write the report")
    parser.add_argument(
        "--reference", default="paper", help="the report also compares every variant with this one"
    )
    parser.add_argument("--out", type=Path, default=Path("results/quality-vs-time"))
    args = parser.parse_args()
    levels = [float(x) for x in args.levels.split(",")]
    variants = chosen_variants(parser, args, VARIANTS)
    only = None
    if args.only:
        only = set()
        for pair in args.only.split(","):
            v, _, level = pair.partition("@")
            if v not in variants or not level or float(level) not in levels:
                parser.error(f"--only: {pair!r} is not a variant@level of --variants and --levels")
            only.add((v, float(level)))
    if args.report:
        report(args.db, args.out, levels, variants, args.reference)
        return
    from hptrack.experiments.benchmark import run_keys
    from hptrack.experiments.store import ResultStore

    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    todo = keys(
        [int(n) for n in args.targets.split(",")],
        args.scenarios,
        args.first_seed,
        levels,
        variants,
        not args.no_greedy,
        only,
        args.clairvoyant,
    )

    def on_done(row, finished, total):
        s = json.loads(row.key.planner_settings)
        print(
            f"[{finished}/{total}] {row.key.planner} n={row.key.n_targets} "
            f"seed={row.key.seed} {s.get('time_limit', '')} {s.get('backup', '')} "
            f"U={row.uncertainty:.2f} wall={row.wall_time_s:.1f}s",
            flush=True,
        )

    try:
        run_keys(todo, store, workers=args.workers, on_done=on_done)
    finally:
        store.close()


if __name__ == "__main__":
    main()
