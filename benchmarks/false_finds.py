"""What modelling false finds buys: the revisit search with and without `false_finds="model"`
on the same cluttered worlds.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``), detections without
identity (GNN) with ``--clutter`` false alarms per m^2 per look at each detection probability of
``--pds``. Two searches fly every world at their preset's default simulations per decision
(reproducible rows): ``revisit`` (the default search, a pursuit ends in a find or a miss) and
``false-finds`` (the same search whose sub-task MDP also has the false find,
``-o mcts.false_finds=model``). Episodes are stored in ``--db`` as they finish (a re-run
resumes).

The report (``OUT/table.md``, ``OUT/summary.json``): per n, sensor and search the mean ``U``,
GOSPA over the mission and at its end (m), tracks lost, targets never detected and the false
alarms a belief took per episode (the tracking summary of each episode's ``info``; "-" where a
stored row predates it); and the paired differences, ``false-finds`` minus ``revisit``, of
``U``, the end GOSPA and the tracks lost.

    python3 benchmarks/false_finds.py --targets 6,12 --seeds 30 --workers 2 \\
        --db results/false-finds.db --out docs/results/false-finds
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_variants
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings

SEARCHES = {
    "revisit": {"preset": "revisit"},
    "false-finds": {"preset": "revisit", "false_finds": "model"},
}
"""The two searches, by their names in the tables, and their mcts options."""

PAIRED = ("U", "gospa_end", "track_loss")
"""The metrics whose paired differences the report gives."""


def sensor_of(pd: float, clutter: float) -> tuple[str, dict]:
    """A cluttered sensor's name in the table and its `BenchmarkConfig` fields."""
    fields = {"detection_probability": pd, "labelled": False, "false_alarm_density": clutter}
    return f"Pd {pd:g}, unlabelled, clutter {clutter:g}", fields


def configs(
    targets: tuple[int, ...], seeds: int, pds: tuple[float, ...], clutter: float
) -> dict[tuple[str, str], BenchmarkConfig]:
    """The benchmark of each (sensor, search), by their names in the table."""
    out = {}
    for pd in pds:
        sensor, fields = sensor_of(pd, clutter)
        for name, options in SEARCHES.items():
            out[sensor, name] = BenchmarkConfig(
                planners=("mcts",),
                settings={"mcts": planner_settings("mcts", options)},
                target_counts=targets,
                scenarios=seeds,
                homogeneous=True,
                **fields,
            )
    return out


def false_alarms_taken(rows: list) -> float | None:
    """The false alarms a belief took per episode over ``rows`` (``None``: a row does not hold
    its tracking summary)."""
    taken = [r.info.get("tracking", {}).get("false_alarms_taken") for r in rows]
    return None if any(t is None for t in taken) else float(np.mean(taken))


def report(by: dict[tuple[str, str], dict], out: Path, command: str) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{(sensor, search): {(n, seed): row}}``."""
    counts = sorted({n for rows in by.values() for n, _ in rows})
    lines = [
        "Homogeneous random scenarios of the paper (seeds from 0), detections without identity",
        "(GNN), clutter in false alarms per m^2 per look; both searches at the revisit preset's",
        "default simulations per decision, `false-finds` with `-o mcts.false_finds=model`.",
        "",
        "```bash",
        command,
        "```",
        "",
        "Mean U +- standard error; GOSPA (p = 2, alpha = 2, c = the footprint radius, m) over the",
        "mission and at its end; tracks lost, targets never detected and false alarms a belief",
        "took per episode.",
        "",
        "| n | sensor | search | episodes | mean U | GOSPA, mean | GOSPA, end | tracks lost | "
        "never detected | false alarms taken |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    summary: dict = {"command": command, "rows": [], "paired": []}
    for n in counts:
        for (sensor, search), rows in by.items():
            mine = [rows[key] for key in sorted(rows) if key[0] == n]
            if not mine:
                continue
            mean, se = mean_se([r.uncertainty for r in mine])
            record = {
                "n": n,
                "sensor": sensor,
                "search": search,
                "episodes": len(mine),
                "mean_U": mean,
                "se_U": se,
                **{m: float(np.mean([r.metric(m) for r in mine])) for m in PAIRED[1:]},
                "gospa_mean": float(np.mean([r.metric("gospa_mean") for r in mine])),
                "never_detected": float(np.mean([r.metric("never_detected") for r in mine])),
                "false_alarms_taken": false_alarms_taken(mine),
            }
            taken = record["false_alarms_taken"]
            lines.append(
                f"| {n} | {sensor} | {search} | {len(mine)} | {mean:.2f} +- {se:.2f} | "
                f"{record['gospa_mean']:.1f} | {record['gospa_end']:.1f} | "
                f"{record['track_loss']:.2f} | {record['never_detected']:.2f} | "
                f"{'-' if taken is None else f'{taken:.2f}'} |"
            )
            summary["rows"].append(record)
    lines += [
        "",
        "Paired differences, `false-finds` minus `revisit`, on the scenarios both flew, mean +-",
        "standard error (negative: modelling false finds is better).",
        "",
        "| n | sensor | scenarios | U | GOSPA, end | tracks lost |",
        "|---|---|---|---|---|---|",
    ]
    for n in counts:
        for sensor in dict.fromkeys(s for s, _ in by):
            mine, base = by.get((sensor, "false-finds"), {}), by.get((sensor, "revisit"), {})
            seeds = sorted(s for m, s in base if m == n and (m, s) in mine)
            if len(seeds) < 2:
                continue
            diffs = {
                m: mean_se([mine[n, s].metric(m) - base[n, s].metric(m) for s in seeds])
                for m in PAIRED
            }
            lines.append(
                f"| {n} | {sensor} | {len(seeds)} | "
                + " | ".join(f"{d:+.2f} +- {se:.2f}" for d, se in diffs.values())
                + " |"
            )
            summary["paired"].append(
                {"n": n, "sensor": sensor, "scenarios": len(seeds)}
                | {f"{m}_diff": d for m, (d, _) in diffs.items()}
                | {f"{m}_se": se for m, (_, se) in diffs.items()}
            )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--pds", default="1", help="detection probabilities per look")
    parser.add_argument("--clutter", type=float, default=1e-6, help="per m^2 per look")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/false-finds.db"))
    parser.add_argument("--out", type=Path, default=Path("results/false-finds"))
    parser.add_argument(
        "--report-only", action="store_true", help="report what the database holds, run nothing"
    )
    args = parser.parse_args()
    if not args.clutter > 0.0:
        parser.error(f"--clutter {args.clutter:g}: false finds need clutter above 0")
    targets = tuple(int(t) for t in args.targets.split(",") if t)
    pds = tuple(float(p) for p in args.pds.split(",") if p)
    command = (
        f"python3 benchmarks/false_finds.py --targets {args.targets} --seeds {args.seeds} "
        f"--pds {args.pds} --clutter {args.clutter:g} --workers {args.workers} "
        f"--db {args.db} --out {args.out}"
    )
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        by = run_variants(
            configs(targets, args.seeds, pds, args.clutter),
            store,
            args.workers,
            not args.report_only,
        )
    finally:
        store.close()
    report(by, args.out, command)


if __name__ == "__main__":
    main()
