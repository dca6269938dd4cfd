"""Whole dry runs of the example without identity (``examples/unlabelled-flight.yaml``: no ids,
``Pd`` 0.8, false alarms) on the PX4-like stub (``hptrack vehicle-sim``, 0.8 of its velocity
setpoint) with ``hptrack fly --takeoff --altitude 20``, one seed after another (the stub's
targets and detector and the planner take the seed). For each flight it prints, from the
mission log and the stub's statistics: how the mission ended, ``U``, the stub's reports (from
targets, by their true source, and false alarms), the reports ``fly`` accepted and refused, its
tracker's looks, the reports a belief took, the claims by tentative tracks and the superseded
reports, and the replay's mismatches. With ``--simulator`` it runs the same seeds on the
simulator instead (`hptrack.sim.episode.run_episode`, the planner with ``fly``'s settings), which
knows each report's source: the reports from targets and false alarms, those a belief took,
the wrong associations and the tracks lost.

    python3 benchmarks/unlabelled_flight.py --seeds 1,2,3 \
        --json docs/results/unlabelled-flight/stub.json
    python3 benchmarks/unlabelled_flight.py --seeds 1,2,3 --simulator \
        --json docs/results/unlabelled-flight/simulator.json

writes the rows as JSON and, beside it, as a CSV and a Markdown table (``stub.csv``,
``stub.md``...) for the docs' quotes; ``--tables`` writes the CSV and the table again from the
JSON, without running anything.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import subprocess
import tempfile
from pathlib import Path

from hptrack.runtime.log import read_log
from hptrack.scenario import load_scenario

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "unlabelled-flight.yaml"


def _flood():
    path = Path(__file__).resolve().parent / "flight_flood.py"
    spec = importlib.util.spec_from_file_location("flight_flood", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def fly_once(work: Path, seed: int, budget: float) -> dict:
    """One dry run with ``seed``; its figures."""
    flood = _flood()
    run = flood.start_dry_run(work, EXAMPLE, budget, ["--seed", str(seed)])
    command = [*run["fly"], "--log", str(run["log"]), "--seed", str(seed)]
    command[command.index("--altitude") + 1] = "20"
    try:
        fly = subprocess.run(command, capture_output=True, text=True, timeout=budget + 600)
    finally:
        flood.end_process(run["stub"])
    stats = json.loads(run["stats"].read_text())
    records = read_log(run["log"]).records
    replay = subprocess.run(
        [*flood.CLI, "replay", str(run["log"]), "--json", str(work / "r.json")],
        capture_output=True,
        text=True,
        timeout=900,
    )
    mismatches = json.loads((work / "r.json").read_text())["mismatches"]
    end = next(r for r in records if r["kind"] == "end")
    tracking = end.get("tracking", {})
    sent = stats["detections_sent"]
    return {
        "command": "python3 benchmarks/unlabelled_flight.py",
        "seed": seed,
        "fly_exit_code": fly.returncode,
        "ended_by": end["reason"],
        "mission_time_s": end["time"],
        "U": end["U"],
        "target_reports_sent": sum(sent.values()),
        **{f"sent_{tid}": count for tid, count in sorted(sent.items())},
        "false_alarms_sent": stats["false_alarms_sent"],
        "reports_accepted": end["accepted"].get("detection", 0),
        "reports_refused": sum(v for k, v in end["rejected"].items() if k.startswith("detection")),
        "refused_late": end["rejected"].get("detection: late", 0),
        "looks": tracking.get("looks", 0),
        "reports_looked_at": tracking.get("reports", 0),
        "taken_by_a_belief": tracking.get("taken by a belief", 0),
        "claims": tracking.get("claims", 0),
        "superseded": tracking.get("superseded", 0),
        "replay_mismatches": mismatches if replay.returncode == 0 else None,
    }


def simulate_once(seed: int) -> dict:
    """The example on the simulator with ``seed`` and ``fly``'s planner settings; its
    figures."""
    from hptrack.cli.flight import flight_planner_settings
    from hptrack.registry import make_planner
    from hptrack.sim.episode import run_episode

    settings = flight_planner_settings("mcts", None, None, None)
    record = run_episode(load_scenario(EXAMPLE), make_planner("mcts", settings), seed=seed)
    rows = record.associations
    tracking = record.tracking_summary()["tracking"]
    return {
        "command": "python3 benchmarks/unlabelled_flight.py --simulator",
        "seed": seed,
        "U": record.uncertainty,
        "target_reports": int(sum(rows[:, 3] >= 0)),
        "false_alarms": tracking["false_alarms"],
        "taken_by_a_belief": int(sum(rows[:, 4] >= 0)),
        "false_alarms_taken": tracking["false_alarms_taken"],
        "wrong_associations": tracking["wrong_associations"],
        "claims": tracking["claims"],
        "tracks_lost": tracking["tracks_lost"],
    }


STUB_COLUMNS = {
    "seed": "seed",
    "ended_by": "ended by",
    "U": "`U`",
    "target_reports_sent": "reports of targets sent",
    "false_alarms_sent": "false alarms sent",
    "reports_accepted": "reports accepted",
    "refused_late": "refused as late",
    "taken_by_a_belief": "taken by a belief",
    "claims": "claims",
    "replay_mismatches": "replay mismatches",
}
SIMULATOR_COLUMNS = {
    "seed": "seed",
    "U": "`U`",
    "target_reports": "reports of targets",
    "false_alarms": "false alarms",
    "taken_by_a_belief": "taken by a belief",
    "false_alarms_taken": "false alarms taken",
    "wrong_associations": "wrong associations",
    "claims": "claims",
    "tracks_lost": "tracks lost",
}
"""The Markdown tables' columns and headings."""


def write_results(rows: list[dict], path: Path) -> None:
    """``rows`` as JSON at ``path`` and, beside it, as a CSV and a Markdown table."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rows, indent=2) + "\n")
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with path.with_suffix(".csv").open("w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    columns = SIMULATOR_COLUMNS if "tracks_lost" in fields else STUB_COLUMNS
    cell = lambda v: f"{v:.2f}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(columns.values()) + " |", "|" + " --- |" * len(columns)]
    lines += ["| " + " | ".join(cell(row[key]) for key in columns) + " |" for row in rows]
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="1", help="comma-separated seeds")
    parser.add_argument("--budget", type=float, default=None, help="s (default the example's)")
    parser.add_argument("--simulator", action="store_true", help="the simulator, not the stub")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--tables", action="store_true", help="only rewrite --json's tables")
    args = parser.parse_args()
    if args.tables:
        write_results(json.loads(args.json.read_text()), args.json)
        return
    budget = args.budget or load_scenario(EXAMPLE).budget
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        if args.simulator:
            row = simulate_once(seed)
        else:
            with tempfile.TemporaryDirectory() as tmp:
                row = fly_once(Path(tmp), seed, budget)
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json is not None:
        write_results(rows, args.json)


if __name__ == "__main__":
    main()
