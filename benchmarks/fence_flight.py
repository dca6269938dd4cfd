"""A whole dry run of the fenced example (``examples/fenced-flight.yaml``) on the PX4-like stub
(``hptrack vehicle-sim``, 0.8 of its velocity setpoint) with ``hptrack fly --takeoff --altitude
20``: the fence uploaded and read back, then the mission to its budget. It prints, from the
stub's statistics and the mission log: the setpoints the stub received and how many lie outside
the free space (the fence shrunk by its margin), the setpoints ``fly`` projected into it, the
breaches the stub saw, and the vehicle's closest approach to a no-fly zone or the operating
area's edge (its flown track, 10 Hz) against the margin; then the replay's mismatches.

    python3 benchmarks/fence_flight.py --json docs/results/fence-flight/stub.json

writes the figures as JSON and, beside it, as a one-row CSV (``stub.csv``, the breaches
counted) for the docs' quotes.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import subprocess
import tempfile
from pathlib import Path

from shapely.geometry import LineString, Point, Polygon

from hptrack.models.fence import circle_polygon, point_free
from hptrack.runtime.log import read_log
from hptrack.scenario import load_scenario

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "fenced-flight.yaml"


def _flood():
    path = Path(__file__).resolve().parent / "flight_flood.py"
    spec = importlib.util.spec_from_file_location("flight_flood", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def closest_approach_m(scenario, track: list) -> float:
    """The smallest distance (m) from the flown ``track`` (rows ``t, n, e, ...``) to the
    fence itself: a no-fly zone (a circle as its outer 32-gon) or the operating area's edge."""
    spec = scenario.fence.spec()
    zones = [Polygon(ring) for ring in spec.polygons]
    zones += [circle_polygon(x, y, r) for x, y, r in spec.circles]
    edges = [LineString([*spec.inclusion, spec.inclusion[0]])] if spec.inclusion else []
    return min(Point(row[2], row[1]).distance(shape) for row in track for shape in zones + edges)


def write_csv(figures: dict, path: Path) -> None:
    """``figures`` as a one-row CSV at ``path`` (the breaches counted)."""
    row = {**figures, "breaches": len(figures["breaches"])}
    with path.open("w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=list(row))
        writer.writeheader()
        writer.writerow(row)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=float, default=None, help="s (default the example's)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    flood = _flood()
    budget = args.budget or load_scenario(EXAMPLE).budget
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        run = flood.start_dry_run(work, EXAMPLE, budget)
        command = [*run["fly"], "--log", str(run["log"])]
        command[command.index("--altitude") + 1] = "20"
        try:
            fly = subprocess.run(command, capture_output=True, text=True, timeout=budget + 600)
        finally:
            flood.end_process(run["stub"])
        stats = json.loads(run["stats"].read_text())
        scenario = load_scenario(run["scenario"])
        free = scenario.fence.spec().compiled()
        records = read_log(run["log"]).records
        replay = subprocess.run(
            [*flood.CLI, "replay", str(run["log"]), "--json", str(work / "r.json")],
            capture_output=True,
            text=True,
            timeout=300,
        )
        mismatches = json.loads((work / "r.json").read_text())["mismatches"]
    setpoints = stats["setpoint_positions"]
    end = next(r for r in records if r["kind"] == "end")
    figures = {
        "command": "python3 benchmarks/fence_flight.py",
        "fly_exit_code": fly.returncode,
        "ended_by": end["reason"],
        "mission_time_s": end["time"],
        "U": end["U"],
        "setpoints_received": len(setpoints),
        "setpoints_outside_free_space": sum(not point_free(free, e, n) for _, n, e in setpoints),
        "setpoints_projected": sum(r["kind"] == "fence" for r in records),
        "breaches": stats["fence_breaches"],
        "margin_m": scenario.fence.margin,
        "closest_approach_m": closest_approach_m(scenario, stats["track"]),
        "replay_mismatches": mismatches if replay.returncode == 0 else None,
    }
    for key, value in figures.items():
        print(f"{key}: {value}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
        write_csv(figures, args.json.with_suffix(".csv"))


if __name__ == "__main__":
    main()
