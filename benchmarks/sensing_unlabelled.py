"""Detections without identity against named ones, on the same worlds.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``) whose sensor detects
a target inside its footprint with probability ``--detection-probability`` at each look, flown
by ``greedy`` and the default ``mcts`` (``--time-limit`` s per decision, or ``--iterations``
simulations for reproducible rows) under four sensors: labelled (every detection names its
target, today's), and without identity (``labelled: false``) with GNN at no clutter, GNN at
``--clutter`` false alarms per m^2 per look, and JPDA at that clutter. The worlds are the same
(the same truths and motion noise; the detector's draws come from its own stream). Per episode:
``U``, the wrong associations (reports that went to a belief not of their source, and claims of
a belief by another target's track), the tracks lost at the end (the truth outside its
belief's 99 % ellipse, or the belief's last report from another source), reports and false
alarms (and those a belief took). Episodes are appended to ``OUT/episodes.jsonl`` as they
finish (a re-run resumes); the report is ``OUT/table.md``, ``OUT/summary.json`` and
``OUT/summary.csv``: per planner and sensor the mean ``U`` with its standard error, and the
paired difference against labelled.

    python3 benchmarks/sensing_unlabelled.py --targets 6 --seeds 16 --workers 1 \\
        --out docs/results/sensing-unlabelled
"""

from __future__ import annotations

import argparse
import csv
import json
from multiprocessing import Pool
from pathlib import Path

import numpy as np

from hptrack.experiments.report import mean_se
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.scenario.model import FootprintSensorSpec
from hptrack.sim.episode import run_episode

PLANNERS = ("greedy", "mcts")


def sensors(pd: float, clutter: float) -> dict[str, dict]:
    """The sensors flown, by their name in the table (``sensor:`` fields)."""
    base = {"detection_probability": pd}
    return {
        "labelled": base,
        "gnn": base | {"labelled": False},
        f"gnn, clutter {clutter:g}": base | {"labelled": False, "false_alarm_density": clutter},
        f"jpda, clutter {clutter:g}": base
        | {"labelled": False, "false_alarm_density": clutter, "association": "jpda"},
    }


def episode(job: tuple) -> dict:
    """One episode's row: ``(n, seed, planner, sensor name, sensor fields, effort)``."""
    n, seed, planner, name, fields, effort = job
    scenario = random_scenario(n, seed=seed, homogeneous=True, sensor=FootprintSensorSpec(**fields))
    options = {"preset": "improved", **effort} if planner == "mcts" else None
    record = run_episode(scenario, make_planner(planner, options), seed=seed)
    tracking = record.tracking_summary().get("tracking", {})
    return {
        "n": n,
        "seed": seed,
        "planner": planner,
        "sensor": name,
        "U": record.uncertainty,
        "wrong_associations": record.wrong_associations(),
        "tracks_lost": int(np.sum(record.tracks_lost())),
        "reports": tracking.get("reports", int(record.detections.sum())),
        "false_alarms": tracking.get("false_alarms", 0),
        "false_alarms_taken": tracking.get("false_alarms_taken", 0),
        "claims": tracking.get("claims", 0),
    }


def report(rows: list[dict], out: Path, header: str, names: list[str]) -> None:
    """Write ``table.md`` and ``summary.json`` from the episode rows."""
    lines = [
        header,
        "",
        "| n | planner | sensor | episodes | mean U | std. error | unlabelled - labelled, "
        "paired U | std. error | wrong associations / episode | tracks lost / episode | "
        "false alarms / episode | taken by a belief / episode |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    summary: dict = {"setting": header, "rows": []}
    by = {(r["n"], r["planner"], r["sensor"], r["seed"]): r for r in rows}
    for n in sorted({r["n"] for r in rows}):
        for planner in PLANNERS:
            for name in names:
                mine = sorted(
                    (r for r in rows if (r["n"], r["planner"], r["sensor"]) == (n, planner, name)),
                    key=lambda r: r["seed"],
                )
                if not mine:
                    continue
                u, u_se = mean_se([r["U"] for r in mine])
                paired = [
                    r["U"] - by[n, planner, "labelled", r["seed"]]["U"]
                    for r in mine
                    if (n, planner, "labelled", r["seed"]) in by
                ]
                d, d_se = mean_se(paired) if name != "labelled" else (0.0, 0.0)
                wrong = float(np.mean([r["wrong_associations"] for r in mine]))
                lost = float(np.mean([r["tracks_lost"] for r in mine]))
                alarms = float(np.mean([r["false_alarms"] for r in mine]))
                taken = float(np.mean([r["false_alarms_taken"] for r in mine]))
                pair_text = f"{d:+.2f} | {d_se:.2f}" if name != "labelled" else "- | -"
                lines.append(
                    f"| {n} | {planner} | {name} | {len(mine)} | {u:.2f} | {u_se:.2f} | "
                    f"{pair_text} | {wrong:.2f} | {lost:.2f} | {alarms:.2f} | {taken:.2f} |"
                )
                summary["rows"].append(
                    {
                        "n": n,
                        "planner": planner,
                        "sensor": name,
                        "episodes": len(mine),
                        "mean_U": u,
                        "se_U": u_se,
                        "paired_minus_labelled": d if name != "labelled" else None,
                        "se_paired": d_se if name != "labelled" else None,
                        "wrong_associations": wrong,
                        "tracks_lost": lost,
                        "false_alarms": alarms,
                        "false_alarms_taken": taken,
                    }
                )
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    with (out / "summary.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(summary["rows"][0]))
        writer.writeheader()
        writer.writerows(summary["rows"])
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=16, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--detection-probability", type=float, default=0.9)
    parser.add_argument("--clutter", type=float, default=1e-6, help="per m^2 per look")
    parser.add_argument("--time-limit", type=float, default=0.05, help="mcts s per decision")
    parser.add_argument("--iterations", type=int, default=None, help="mcts simulations instead")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/sensing-unlabelled"))
    args = parser.parse_args()
    targets = [int(t) for t in args.targets.split(",")]
    effort = (
        {"iterations": args.iterations}
        if args.iterations is not None
        else {"time_limit": args.time_limit}
    )
    flown = sensors(args.detection_probability, args.clutter)
    args.out.mkdir(parents=True, exist_ok=True)
    log = args.out / "episodes.jsonl"
    rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    done = {(r["n"], r["seed"], r["planner"], r["sensor"]) for r in rows}
    jobs = [
        (n, seed, planner, name, fields, effort)
        for n in targets
        for seed in range(args.seeds)
        for planner in PLANNERS
        for name, fields in flown.items()
        if (n, seed, planner, name) not in done
    ]
    with Pool(args.workers) as pool, log.open("a") as fh:
        for row in pool.imap_unordered(episode, jobs):
            rows.append(row)
            fh.write(json.dumps(row) + "\n")
            fh.flush()
    mcts = (
        f"{effort.get('iterations', 0):,} simulations"
        if args.iterations
        else (f"{args.time_limit:g} s")
    )
    header = (
        f"Homogeneous random scenarios, Pd = {args.detection_probability:g} at every look; "
        f"mcts (improved preset) at {mcts} per decision; clutter in false alarms per m^2 per look."
    )
    report(rows, args.out, header, list(flown))


if __name__ == "__main__":
    main()
