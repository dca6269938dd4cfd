"""Teams of UAVs side by side: the team search, the CBBA allocation baseline, greedy and the
clairvoyant team, for teams of ``--teams`` UAVs on the same scenarios.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``), every UAV of a
team starting at the scenario's start (`hptrack.scenario.random.random_scenario`'s ``team``),
so that a scenario's targets are the same for every team size. Planners: ``team-mcts`` and
``team-cbba`` at ``--time-limit`` s per UAV and decision, ``team-greedy`` and
``team-clairvoyant`` (a team of one of each is its planner of one UAV); with ``--links``, also
``team-mcts`` over a limited link (claims shared every 60 s; half of the messages lost); with
``--revisit``, also ``team-mcts`` at the revisit preset (the revisit tour inside every UAV's
search) beside the team planners' own (improved); ``--no-references`` leaves out the greedy
and clairvoyant teams (no gap closed then).
Episodes are stored in ``--db`` as they finish (a re-run resumes). The report: mean ``U`` with
its standard error, the share of the gap from the greedy team to the clairvoyant team closed,
the targets never detected, the paired differences team-mcts - team-cbba and team-mcts -
team-clairvoyant.

    python3 benchmarks/team_benchmark.py --targets 12,20 --seeds 30 --teams 1,2,3 \\
        --time-limit 0.05 --db results/teams.db --out docs/results/teams
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_variants
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings

LINKS = {
    "team-mcts, shared every 60 s": {"share_period": 60.0},
    "team-mcts, half the messages lost": {"drop_rate": 0.5},
}
"""The limited links of ``--links`` (`hptrack.teams.link`)."""


REVISIT = "team-mcts, revisit"
"""The name of ``team-mcts`` at the revisit preset (``--revisit``)."""


def configs(
    targets: tuple[int, ...],
    seeds: int,
    team: int,
    time_limit: float,
    links: bool,
    revisit: bool = False,
    references: bool = True,
) -> dict[str, BenchmarkConfig]:
    """The benchmark of each variant of a team of ``team``, by its name in the table."""

    def one(planner: str, options: dict | None) -> BenchmarkConfig:
        return BenchmarkConfig(
            planners=(planner,),
            settings={planner: planner_settings(planner, options)},
            target_counts=targets,
            scenarios=seeds,
            homogeneous=True,
            team=team,
        )

    effort = {"time_limit": time_limit}
    out = {"team-greedy": one("team-greedy", None)} if references else {}
    out |= {"team-mcts": one("team-mcts", effort), "team-cbba": one("team-cbba", effort)}
    if revisit:
        out[REVISIT] = one("team-mcts", {**effort, "preset": "revisit"})
    if links and team > 1:
        out |= {name: one("team-mcts", {**effort, **link}) for name, link in LINKS.items()}
    if references:
        out["team-clairvoyant"] = one("team-clairvoyant", None)
    return out


def paired(a: dict, b: dict, n: int) -> tuple[int, float, float]:
    """``(scenarios, mean, se)`` of ``U_a - U_b`` on the scenarios of ``n`` both flew."""
    seeds = sorted(s for m, s in a if m == n and (m, s) in b)
    diff = np.array([a[n, s].uncertainty - b[n, s].uncertainty for s in seeds])
    mean, se = mean_se(diff) if seeds else (float("nan"), float("nan"))
    return len(seeds), mean, se


def report(by_team: dict[int, dict[str, dict]], out: Path, command: str) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{m: {variant: {(n, seed): row}}}``."""
    counts = sorted({n for variants in by_team.values() for r in variants.values() for n, _ in r})
    lines = [
        "Homogeneous random scenarios (seeds from 0), every UAV of a team from the start;",
        "`team-mcts` and `team-cbba` at the planning time per UAV and decision given.",
        "",
        "```bash",
        command,
        "```",
        "",
        "Mean U +- standard error (episodes), share of the gap from the greedy team to the",
        "clairvoyant team of the same size closed, on the mean U of the scenarios all three flew",
        "(their number), and targets never detected per episode.",
        "",
        "| n | UAVs | planner | episodes | mean U | gap closed, % | never detected |",
        "|---|---|---|---|---|---|---|",
    ]
    summary: dict = {"command": command, "rows": [], "paired": []}
    for n in counts:
        for m, variants in sorted(by_team.items()):
            greedy, clair = variants.get("team-greedy", {}), variants.get("team-clairvoyant", {})
            for variant, rows in variants.items():
                seeds = sorted(s for k, s in rows if k == n)
                if not seeds:
                    continue
                u = np.array([rows[n, s].uncertainty for s in seeds])
                common = [s for s in seeds if (n, s) in greedy and (n, s) in clair]
                gap = math.nan
                if common:
                    ends = [
                        np.mean([ref[n, s].uncertainty for s in common]) for ref in (greedy, clair)
                    ]
                    mine = np.mean([rows[n, s].uncertainty for s in common])
                    gap = 100.0 * (ends[0] - mine) / (ends[0] - ends[1])
                never = np.mean([rows[n, s].info["targets_never_detected"] for s in seeds])
                mean, se = mean_se(u)
                lines.append(
                    f"| {n} | {m} | {variant} | {len(seeds)} | {mean:.2f} +- {se:.2f} | "
                    f"{f'{gap:.0f} ({len(common)})' if common else '-'} | {never:.2f} |"
                )
                summary["rows"].append(
                    {
                        "n": n,
                        "team": m,
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
        "Paired differences of U on the scenarios both flew, mean +- standard error (negative:",
        "the first is better); `team-mcts - team-clairvoyant` is the team search's distance",
        "from the clairvoyant team of its size.",
        "",
        "| n | UAVs | difference | scenarios | mean difference |",
        "|---|---|---|---|---|",
    ]
    for n in counts:
        for m, variants in sorted(by_team.items()):
            for other in ("team-cbba", REVISIT, "team-clairvoyant", *LINKS):
                if other not in variants:
                    continue
                count, mean, se = paired(variants["team-mcts"], variants[other], n)
                if not count:
                    continue
                lines.append(
                    f"| {n} | {m} | team-mcts - {other} | {count} | {mean:+.2f} +- {se:.2f} |"
                )
                summary["paired"].append(
                    {"n": n, "team": m, "other": other, "scenarios": count, "mean": mean, "se": se}
                )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="12,20", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--teams", default="1,2,3", help="team sizes, comma-separated")
    parser.add_argument("--time-limit", type=float, default=0.05, help="s per UAV and decision")
    parser.add_argument("--links", action="store_true", help="also team-mcts over limited links")
    parser.add_argument(
        "--revisit", action="store_true", help="also team-mcts at the revisit preset"
    )
    parser.add_argument(
        "--no-references",
        action="store_true",
        help="leave out the greedy and clairvoyant teams (no gap closed)",
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/teams.db"))
    parser.add_argument("--out", type=Path, default=Path("results/teams"))
    parser.add_argument(
        "--report-only", action="store_true", help="report what the database holds, run nothing"
    )
    args = parser.parse_args()

    def counts(text: str) -> tuple[int, ...]:
        return tuple(int(t) for t in text.split(",") if t)

    command = (
        f"python3 benchmarks/team_benchmark.py --targets {args.targets} --seeds {args.seeds} "
        f"--teams {args.teams} --time-limit {args.time_limit:g}"
        + (" --links" if args.links else "")
        + (" --revisit" if args.revisit else "")
        + (" --no-references" if args.no_references else "")
        + f" --workers {args.workers} --db {args.db} --out {args.out}"
    )
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        by_team = {
            m: run_variants(
                configs(
                    counts(args.targets),
                    args.seeds,
                    m,
                    args.time_limit,
                    args.links,
                    args.revisit,
                    not args.no_references,
                ),
                store,
                args.workers,
                run=not args.report_only,
            )
            for m in counts(args.teams)
        }
    finally:
        store.close()
    report(by_team, args.out, command)


if __name__ == "__main__":
    main()
