"""The planners under a detector that misses, reports false alarms and names no target.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``). For every
detection probability of ``--pds`` the sensor is flown three ways: labelled (every detection
names its target), unlabelled (positions only, associated by the tracker's GNN) without
clutter, and unlabelled with ``--clutter`` false alarms per m^2 per look. Under each sensor
the variants (``--variants``, names of `VARIANTS`) fly the same worlds: greedy, the paper's
search, the default search, the clairvoyant reference, and below ``Pd = 1`` the default search
told the paper's certain sensor (``blind``). Every search runs at ``--time-limit`` s per
decision. Episodes are stored in the results database ``--db`` as they finish (a re-run
resumes; every sensor is its own setting of the episodes' identity, as ``hptrack benchmark
--detection-probability P --unlabelled --false-alarm-density L`` writes it).

The report (``OUT/table.md``, ``OUT/summary.json``, ``OUT/rows.csv``, ``OUT/paired.csv``): per
n, sensor and variant the mean ``U``, mean and end-of-mission GOSPA (m), tracks lost and targets
never detected per episode; and the paired difference of ``U`` of the search told its sensor and
the blind one.

    python3 benchmarks/sensing_table.py --targets 6,12 --seeds 30 --time-limit 0.05 \\
        --workers 2 --db results/sensing.db --out docs/results/sensing

``--iterations N`` runs every search at ``N`` simulations per decision instead (reproducible rows;
``--default-effort``: at its preset's default number, also reproducible),
``--correlation-time T`` holds each detection draw ``T`` s (misses in runs) and ``--sensors``
picks some of labelled, unlabelled and clutter.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from hptrack.experiments.benchmark import BenchmarkConfig, run_variants
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import ResultStore
from hptrack.registry import planner_settings

VARIANTS: dict[str, tuple[str, dict, bool]] = {
    "greedy": ("greedy", {}, False),
    "paper": ("mcts", {"preset": "paper"}, False),
    "default": ("mcts", {"preset": "improved"}, False),
    "clairvoyant": ("clairvoyant", {}, False),
    "blind": ("mcts", {"preset": "improved"}, True),
    "revisit": ("mcts", {"preset": "revisit"}, False),
    "blind-revisit": ("mcts", {"preset": "revisit"}, True),
}
"""The planners compared, by their names in the tables: a planner, its options (the searches'
time limit added) and whether it is told the paper's certain sensor (run only below
``Pd = 1``)."""

PAIRS = (("default", "blind"), ("revisit", "blind-revisit"))
"""The searches told their sensor and the same searches told the paper's, paired in the
report."""


SENSOR_KINDS = ("labelled", "unlabelled", "clutter")
"""The sensors flown at each detection probability (``--sensors``)."""


def sensors(
    pd: float, clutter: float, correlation: float = 0.0, kinds: tuple[str, ...] = SENSOR_KINDS
) -> dict[str, dict]:
    """The sensors flown at one detection probability, by their name in the table
    (`BenchmarkConfig` fields): of ``kinds``, labelled, unlabelled without clutter and
    unlabelled with ``clutter``, each draw held ``correlation`` s (below ``Pd = 1``)."""
    base: dict = {"detection_probability": pd}
    held = ""
    if correlation > 0.0 and pd < 1.0:
        base["detection_correlation_time"] = correlation
        held = f", held {correlation:g} s"
    every = {
        "labelled": (f"Pd {pd:g}{held}, labelled", base),
        "unlabelled": (f"Pd {pd:g}{held}, unlabelled", base | {"labelled": False}),
        "clutter": (
            f"Pd {pd:g}{held}, unlabelled, clutter {clutter:g}",
            base | {"labelled": False, "false_alarm_density": clutter},
        ),
    }
    return dict(every[kind] for kind in kinds)


def configs(
    variants: tuple[str, ...],
    targets: tuple[int, ...],
    seeds: int,
    effort: dict,
    pds: tuple[float, ...],
    clutter: float,
    correlation: float = 0.0,
    kinds: tuple[str, ...] = SENSOR_KINDS,
) -> dict[tuple[str, str], BenchmarkConfig]:
    """The benchmark of each (sensor, variant), by their names in the table (``effort``: the
    searches' ``time_limit`` or ``iterations``)."""
    out = {}
    for pd in pds:
        for sensor, fields in sensors(pd, clutter, correlation, kinds).items():
            for name in variants:
                planner, options, blind = VARIANTS[name]
                if blind and pd == 1.0:
                    continue
                if planner == "mcts":
                    options = {**options, **effort}
                out[sensor, name] = BenchmarkConfig(
                    planners=(planner,),
                    settings={planner: planner_settings(planner, options)},
                    target_counts=targets,
                    scenarios=seeds,
                    homogeneous=True,
                    blind=blind,
                    **fields,
                )
    return out


def _mean(rows: list, metric: str) -> float:
    values = [r.metric(metric) for r in rows]
    return float(np.mean(values)) if values and None not in values else float("nan")


def report(by: dict[tuple[str, str], dict], out: Path, command: str, effort: str) -> None:
    """Write ``table.md`` and ``summary.json`` from ``{(sensor, variant): {(n, seed): row}}``
    (``effort``: the searches', as the table says it)."""
    counts = sorted({n for rows in by.values() for n, _ in rows})
    lines = [
        f"Homogeneous random scenarios of the paper (seeds from 0); every search at {effort}.",
        *(
            [
                "`paper` is the paper's search, `default` the improved search, `blind` it told",
                "`Pd = 1` on the same worlds (`revisit`, `blind-revisit`: the same for the revisit",
                "search); clutter in false alarms per m^2 per look; unlabelled detections are",
                "associated by GNN.",
            ]
            if any(v in ("revisit", "blind-revisit") for _, v in by)
            else [
                "`paper` is the paper's search, `default` the improved search, `blind` it told",
                "`Pd = 1` on the same worlds; clutter in false alarms per m^2 per look; unlabelled",
                "detections are associated by GNN.",
            ]
        ),
        "",
        "```bash",
        command,
        "```",
        "",
        "Mean U +- standard error; GOSPA (p = 2, alpha = 2, c = the footprint radius, m) over the",
        "mission and at its end; tracks lost and targets never detected per episode.",
        "",
        "| n | sensor | planner | episodes | mean U | GOSPA, mean | GOSPA, end | tracks lost | "
        "never detected |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    summary: dict = {"command": command, "effort": effort, "rows": [], "paired": []}
    for n in counts:
        for (sensor, variant), rows in by.items():
            mine = [rows[key] for key in sorted(rows) if key[0] == n]
            if not mine:
                continue
            mean, se = mean_se([r.uncertainty for r in mine])
            record = {
                "n": n,
                "sensor": sensor,
                "planner": variant,
                "episodes": len(mine),
                "mean_U": mean,
                "se_U": se,
                **{m: _mean(mine, m) for m in ("gospa_mean", "gospa_end", "track_loss")},
                "never_detected": _mean(mine, "never_detected"),
            }
            lines.append(
                f"| {n} | {sensor} | {variant} | {len(mine)} | {mean:.2f} +- {se:.2f} | "
                f"{record['gospa_mean']:.1f} | {record['gospa_end']:.1f} | "
                f"{record['track_loss']:.2f} | {record['never_detected']:.2f} |"
            )
            summary["rows"].append(record)
    searches = [pair for pair in PAIRS if any(v == pair[1] for _, v in by)]
    named = len(searches) > 1 or searches != [PAIRS[0]]
    said = (
        [
            "Paired differences of U, the search told its sensor minus the same search told the",
            "paper's (blind), on the scenarios both flew (negative: knowing the sensor is better).",
        ]
        if named
        else [
            "Paired differences of U, the default search told its sensor minus the blind one, on "
            "the",
            "scenarios both flew (negative: knowing the sensor is better).",
        ]
    )
    lines += [
        "",
        *said,
        "",
        f"| n | sensor |{' search |' if named else ''} scenarios | known - blind | std. error "
        "| margin / std. error |",
        f"|---|---|{'---|' if named else ''}---|---|---|---|",
    ]
    for n in counts:
        for sensor in dict.fromkeys(s for s, _ in by):
            for known_name, blind_name in searches:
                known, blind = by.get((sensor, known_name), {}), by.get((sensor, blind_name), {})
                seeds = sorted(s for m, s in blind if m == n and (m, s) in known)
                if len(seeds) < 2:
                    continue
                diff = [known[n, s].uncertainty - blind[n, s].uncertainty for s in seeds]
                d, d_se = mean_se(diff)
                lines.append(
                    f"| {n} | {sensor} |{f' {known_name} |' if named else ''} {len(seeds)} "
                    f"| {d:+.2f} | {d_se:.2f} | {abs(d) / d_se:.1f} |"
                )
                summary["paired"].append(
                    {
                        "n": n,
                        "sensor": sensor,
                        **({"search": known_name} if named else {}),
                        "scenarios": len(seeds),
                        "known_minus_blind": d,
                        "se": d_se,
                    }
                )
    write_tables(out, lines, summary)
    for name in ("rows", "paired"):
        if summary[name]:
            with (out / f"{name}.csv").open("w", newline="") as fh:
                writer = csv.DictWriter(fh, fieldnames=list(summary[name][0]))
                writer.writeheader()
                writer.writerows(summary[name])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=30, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--pds", default="1,0.9,0.7", help="detection probabilities per look")
    parser.add_argument("--clutter", type=float, default=1e-6, help="per m^2 per look")
    parser.add_argument("--time-limit", type=float, default=0.05, help="s per decision")
    parser.add_argument("--iterations", type=int, help="simulations per decision instead")
    parser.add_argument(
        "--default-effort",
        action="store_true",
        help="every search at its preset's default simulations per search instead",
    )
    parser.add_argument(
        "--correlation-time", type=float, default=0.0, help="s a detection draw holds (below 1)"
    )
    parser.add_argument(
        "--sensors", default=",".join(SENSOR_KINDS), help=f"of {', '.join(SENSOR_KINDS)}"
    )
    parser.add_argument(
        "--variants", default=",".join(VARIANTS), help=f"comma-separated, of {', '.join(VARIANTS)}"
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--db", type=Path, default=Path("results/sensing.db"))
    parser.add_argument("--out", type=Path, default=Path("results/sensing"))
    parser.add_argument(
        "--report-only", action="store_true", help="report what the database holds, run nothing"
    )
    args = parser.parse_args()
    variants = tuple(v for v in args.variants.split(",") if v)
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variants {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    targets = tuple(int(t) for t in args.targets.split(",") if t)
    pds = tuple(float(p) for p in args.pds.split(",") if p)
    kinds = tuple(k for k in args.sensors.split(",") if k)
    if any(k not in SENSOR_KINDS for k in kinds):
        parser.error(f"--sensors {args.sensors}: of {', '.join(SENSOR_KINDS)}")
    if args.default_effort:
        effort, said = {}, "its preset's default simulations"
        given = "--default-effort "
    elif args.iterations is not None:
        effort, said = {"iterations": args.iterations}, f"{args.iterations:,} simulations"
        given = f"--iterations {args.iterations} "
    else:
        effort, said = {"time_limit": args.time_limit}, f"{args.time_limit:g} s"
        given = f"--time-limit {args.time_limit:g} "
    command = (
        f"python3 benchmarks/sensing_table.py --targets {args.targets} --seeds {args.seeds} "
        f"--pds {args.pds} --clutter {args.clutter:g} {given}"
        + (f"--correlation-time {args.correlation_time:g} " if args.correlation_time else "")
        + (f"--sensors {args.sensors} " if kinds != SENSOR_KINDS else "")
        + (f"--variants {args.variants} " if variants != tuple(VARIANTS) else "")
        + f"--workers {args.workers} --db {args.db} --out {args.out}"
    )
    args.db.parent.mkdir(parents=True, exist_ok=True)
    store = ResultStore(args.db)
    try:
        wanted = configs(
            variants, targets, args.seeds, effort, pds, args.clutter, args.correlation_time, kinds
        )
        by = run_variants(wanted, store, args.workers, run=not args.report_only)
    finally:
        store.close()
    report(by, args.out, command, f"{said} per decision")


if __name__ == "__main__":
    main()
