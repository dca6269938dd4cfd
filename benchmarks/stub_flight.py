"""Full dry runs of the paper-flight example on the PX4-like stub: ``hptrack vehicle-sim`` (which
flies 0.8 of its velocity setpoint, as PX4's SIH quadrotor does) and ``hptrack fly --takeoff
--altitude 20`` on loopback, one variant after another. For each flight it prints, from the
mission log and the stub's statistics: how long after reaching the take-off altitude offboard
started (and how long the take-off and the warm-up before it took), the first plan's compute
time, the flown speed on straight legs (median, lowest,
highest; from the odometry), the sub-tasks flown and how often the pursued target changed, the
detections accepted per target, late plans and fallbacks, and ``U``.

    python3 benchmarks/stub_flight.py                           # the defaults, seed 1
    python3 benchmarks/stub_flight.py --variants default,no-keep-lag --seeds 1,2
    python3 benchmarks/stub_flight.py --variants default --cold  # a fresh compile cache

``--cold`` gives every flight an empty cache directory (``HPTRACK_CACHE_DIR``), as a fresh
install has. The end-to-end tests (``tests/runtime/test_flight_integration.py``) use
`straight_leg_speeds` from here.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from hptrack.runtime.log import read_log

VARIANTS: dict[str, tuple[list[str], list[str]]] = {
    "default": ([], []),
    "no-keep-lag": (["--no-keep-lag"], []),
    "ideal-stub": (["--no-keep-lag"], ["--velocity-tracking", "1"]),
    "sharp": (["-o", "mcts.estimator=sharp", "-o", "mcts.miss=keep"], []),
    "sharp-no-keep-lag": (
        ["-o", "mcts.estimator=sharp", "-o", "mcts.miss=keep", "--no-keep-lag"],
        [],
    ),
    "sharp-commit": (["-o", "mcts.estimator=sharp", "-o", "mcts.miss=keep", "-o", "commit=5"], []),
    "sharp-no-keep-lag-commit": (
        ["-o", "mcts.estimator=sharp", "-o", "mcts.miss=keep", "-o", "commit=5", "--no-keep-lag"],
        [],
    ),
}
"""``fly`` and ``vehicle-sim`` arguments of each variant."""


def _sibling(name: str):
    """Another script of ``benchmarks/``, as a module."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def straight_leg_speeds(
    records: list[dict], min_run_s: float = 3.0, heading_tolerance_deg: float = 3.0
) -> list[tuple[float, float]]:
    """``(planned, flown)`` speeds (m/s) between consecutive plans that continue a straight run
    of at least ``min_run_s`` at full planned speed (the leg at least one step long, its heading
    within the tolerance of the run's), flown speed from the odometry."""
    odometry = np.array(
        [[r["t"], *r["position"]] for r in records if r["kind"] == "odometry" and r["accepted"]]
    )
    ticks = {r["k"]: r for r in records if r["kind"] == "tick"}
    plans = [r for r in records if r["kind"] == "plan" and r["status"] == "ok"]
    out = []
    run_start, run_heading = None, None
    for plan, following in zip(plans, plans[1:], strict=False):
        leg = np.asarray(plan["waypoint"]) - np.asarray(ticks[plan["k"]]["agent"])
        heading = np.degrees(np.arctan2(leg[1], leg[0]))
        full = np.hypot(*leg) >= plan["speed_m_s"] * 0.5
        if not full or run_heading is None or abs(heading - run_heading) > heading_tolerance_deg:
            run_start, run_heading = (plan["t"], heading) if full else (None, None)
            continue
        if plan["t"] - run_start < min_run_s:
            continue
        inside = odometry[(odometry[:, 0] >= plan["t"]) & (odometry[:, 0] <= following["t"])]
        if len(inside) >= 2:
            flown = np.hypot(*(inside[-1, 1:] - inside[0, 1:])) / (inside[-1, 0] - inside[0, 0])
            out.append((plan["speed_m_s"], float(flown)))
    return out


def subtasks(records: list[dict]) -> list[str]:
    """The sub-tasks flown, in order (``"pursue p1"``, ``"follow p1"``...), from the flown
    plans: a new one at each change of kind, target or start step. A plan's sub-task is
    `hptrack.subtasks.Subtask.to_json`'s ``{"kind", "target", "start_step", ...}``, or in older
    logs ``{"target" | "follow" | "dwell": id, "since_step", ...}``."""
    out: list[str] = []
    last = None
    for r in records:
        if r["kind"] == "plan" and r["status"] == "ok" and not r.get("after_end"):
            sub = r["subtask"] or {}
            if "kind" in sub:
                kind, target, start = sub["kind"], sub.get("target"), sub.get("start_step")
            else:
                kind = next((k for k in ("target", "follow", "dwell") if k in sub), None)
                target, start = sub.get(kind), sub.get("since_step")
                kind = "pursue" if kind == "target" else kind
            key = (kind, target, start)
            if key != last:
                out.append(" ".join(str(x) for x in (kind, target) if x is not None) or "none")
                last = key
    return out


def summary(records: list[dict], header: dict) -> dict:
    """The figures of one flight (module docstring), from its mission log."""
    status = [r for r in records if r["kind"] == "status"]
    walls = {}
    for r in status:
        message = r.get("message", "")
        if message.startswith("taking off to "):
            walls["takeoff"] = r["wall"]
        if message.startswith("take-off done: "):  # PX4's TAKEOFF -> HOLD at the altitude
            walls["altitude"] = r["wall"]
        if message.startswith("offboard started"):
            walls["offboard"] = r["wall"]
    plans = [r for r in records if r["kind"] == "plan"]
    first = next((r for r in plans if r["k"] == 0), None)
    speeds = [flown for _, flown in straight_leg_speeds(records)]
    accepted: dict[str, int] = {}
    for r in records:
        if r["kind"] == "detection" and r["accepted"]:
            accepted[r["target"]] = accepted.get(r["target"], 0) + 1
    end = next((r for r in records if r["kind"] == "end"), {})
    flown = subtasks(records)
    targets = [s.split()[1] for s in flown if len(s.split()) == 2]

    def between(start: str, end: str) -> float | None:
        return walls[end] - walls[start] if start in walls and end in walls else None

    return {
        "warm_up_s": header.get("warm_up_s"),
        "takeoff_s": between("takeoff", "altitude"),
        "offboard_after_altitude_s": between("altitude", "offboard"),
        "first_plan_s": None if first is None else first["compute_s"],
        "straight_legs": len(speeds),
        "straight_speed_median_m_s": float(np.median(speeds)) if speeds else None,
        "straight_speed_range_m_s": [min(speeds), max(speeds)] if speeds else None,
        "subtasks": len(flown),
        "target_changes": sum(a != b for a, b in zip(targets, targets[1:], strict=False)),
        "subtask_sequence": flown,
        "detections": accepted,
        "late": sum(r["kind"] == "late" for r in records),
        "fallbacks": sum(r["kind"] == "fallback" for r in records),
        "U": end.get("U"),
        "ended_by": end.get("reason"),
    }


def fly_once(
    workdir: Path, variant: str, seed: int, budget: float | None, altitude: float, cold: bool
) -> dict:
    """One dry run of ``variant`` (`VARIANTS`); its `summary`."""
    flood = _sibling("flight_flood")
    fly_args, stub_args = VARIANTS[variant]
    example = flood.SCENARIO
    if budget is None:
        import yaml

        budget = float(yaml.safe_load(example.read_text())["budget"])
    env = dict(os.environ)
    if cold:
        env["HPTRACK_CACHE_DIR"] = tempfile.mkdtemp(prefix="cold-cache-", dir=workdir)
    run = flood.start_dry_run(workdir, example, budget, ["--seed", str(seed), *stub_args], env=env)
    command = [*run["fly"], "--log", str(run["log"]), "--seed", str(seed), *fly_args]
    command[command.index("--altitude") + 1] = f"{altitude:g}"
    try:
        fly = subprocess.run(command, capture_output=True, text=True, timeout=budget + 900, env=env)
    finally:
        flood.end_process(run["stub"])
    log = read_log(run["log"])
    out = summary(log.records, log.header)
    out.update(variant=variant, seed=seed, cold=cold, exit_code=fly.returncode)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", default="default", help=f"of {', '.join(VARIANTS)}")
    parser.add_argument("--seeds", default="1", help="comma-separated seeds")
    parser.add_argument("--budget", type=float, default=None, help="s (default the example's)")
    parser.add_argument("--altitude", type=float, default=20.0, help="take-off altitude, m")
    parser.add_argument("--cold", action="store_true", help="a fresh compile cache per flight")
    parser.add_argument("--workdir", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args()
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="stub-flight-"))
    rows = []
    for variant in args.variants.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            place = workdir / f"{variant}-{seed}"
            place.mkdir(parents=True, exist_ok=True)
            row = fly_once(place, variant, seed, args.budget, args.altitude, args.cold)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
