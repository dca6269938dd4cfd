"""``hptrack fly`` with a fence against ``hptrack vehicle-sim``: the fence uploaded, read back
and flown with no setpoint outside the free space, the log replayed with its fence; a vehicle
that keeps another fence refused before arming; ``--fence-from-vehicle`` flying the vehicle's;
a breach of the vehicle's fence held by PX4's hold and left to the pilot by ``fly``."""

import importlib.util
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("mavsdk")
pytest.importorskip("pymavlink")

from hptrack.models.fence import point_free  # noqa: E402
from hptrack.runtime.log import read_log  # noqa: E402
from hptrack.scenario import load_scenario  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("stub-flights")]

FENCED = Path(__file__).resolve().parents[2] / "examples" / "fenced-flight.yaml"
BUDGET_S = 15.0


def _benchmark(name):
    path = Path(__file__).resolve().parents[2] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_FLOOD = _benchmark("flight_flood")
CLI = _FLOOD.CLI


def _fly(tmp_path, budget, stub_args=(), fly_args=()):
    """The fenced example with ``budget`` s flown on the stub; ``fly``'s result, the stub's
    statistics and the run."""
    run = _FLOOD.start_dry_run(tmp_path, FENCED, budget, list(stub_args))
    try:
        fly = subprocess.run(
            [*run["fly"], "--log", str(run["log"]), *fly_args],
            capture_output=True,
            text=True,
            timeout=240,
        )
    finally:
        _FLOOD.end_process(run["stub"])
    stats = json.loads(run["stats"].read_text()) if run["stats"].exists() else None
    return fly, stats, run


def _replay(log, tmp_path):
    summary_path = tmp_path / "replay.json"
    replay = subprocess.run(
        [*CLI, "replay", str(log), "--json", str(summary_path), "--plot", str(tmp_path / "r.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert replay.returncode == 0, replay.stderr
    return json.loads(summary_path.read_text())


def test_a_fenced_flight_ends_by_its_budget_with_every_setpoint_inside_and_replays(tmp_path):
    fly, stats, run = _fly(tmp_path, BUDGET_S)
    assert fly.returncode == 0, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "ended by budget" in out
    assert (
        "fence: the scenario's, uploaded and read back (within 0.1 m), an inclusion polygon, "
        "1 exclusion polygon, 1 exclusion circle; GF_ACTION 2 (hold) on a breach"
    ) in out
    assert "fence margin 5 m; tracking lag at 8 m/s 2.1 m (PX4 flies 0.8 of its velocity" in out

    scenario = load_scenario(run["scenario"])
    free = scenario.fence.spec().compiled()  # the free space shrunk by the margin
    fence = scenario.fence.spec()._replace(margin=0.0).compiled()  # the fence itself
    setpoints = stats["setpoint_positions"]
    assert len(setpoints) > 10 * BUDGET_S
    outside = [(t, n, e) for t, n, e in setpoints if not point_free(free, e, n)]
    assert outside == []
    assert all(point_free(fence, e, n) for _, n, e, _, _ in stats["track"])
    assert stats["fence_breaches"] == [] and stats["final_mode"] == "hold"

    log = read_log(run["log"])
    geofence = [r for r in log.records if r["kind"] == "geofence"]
    assert geofence[0]["source"] == "scenario" and geofence[0]["action"] == 2
    assert geofence[1]["margin_m"] == 5.0
    assert geofence[1]["lag_m"] == pytest.approx(0.25 * 8.0 / 0.95, rel=1e-6)
    projections = [r for r in log.records if r["kind"] == "fence"]
    assert geofence[2]["projections"] == len(projections)
    for record in projections:
        assert point_free(free, *record["projected"])
    assert log.header["scenario"]["fence"] == json.loads(json.dumps(scenario.fence.model_dump()))
    end = next(r for r in log.records if r["kind"] == "end")
    assert end["reason"] == "budget" and end["time"] == BUDGET_S

    summary = _replay(run["log"], tmp_path)
    assert summary["mismatches"] == 0, summary["first_mismatches"]
    assert summary["U"] == end["U"]


def test_a_vehicle_that_keeps_another_fence_is_refused_before_arming(tmp_path):
    fly, stats, run = _fly(tmp_path, 8.0, ["--fence-shift", "0.5"])
    assert fly.returncode == 2, fly.stdout + fly.stderr
    lines = [line for line in fly.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and (
        "the vehicle's fence differs from the scenario's after the upload: inclusion corner 0: "
        "0.50 m apart (tolerance 0.1 m); nothing was flown"
    ) in " ".join(fly.stderr.split())
    assert stats["armed_at"] is None and "MAV_CMD_COMPONENT_ARM_DISARM" not in stats["commands"]
    assert not run["log"].exists()


def test_fence_from_vehicle_flies_the_vehicles_fence(tmp_path):
    fly, stats, run = _fly(
        tmp_path, 8.0, ["--hold-fence", "--fence-shift", "0.5"], ["--fence-from-vehicle"]
    )
    assert fly.returncode == 0, fly.stdout + fly.stderr
    assert "fence: the vehicle's, an inclusion polygon" in " ".join(fly.stdout.split())
    log = read_log(run["log"])
    flown = log.header["scenario"]["fence"]
    ours = load_scenario(run["scenario"]).fence
    np.testing.assert_allclose(
        np.array(flown["inclusion"]["polygon"]),
        np.array(ours.inclusion.polygon) + [0.0, 0.5],
        atol=0.012,
    )
    assert flown["margin"] == ours.margin
    free = (
        load_scenario(run["scenario"])
        .fence.spec()
        ._replace(
            inclusion=tuple(map(tuple, np.array(flown["inclusion"]["polygon"]))),
            polygons=(tuple(map(tuple, np.array(flown["exclusions"][0]["polygon"]))),),
            circles=(tuple(flown["exclusions"][1]["circle"]),),
        )
        .compiled()
    )
    assert all(point_free(free, e, n) for _, n, e in stats["setpoint_positions"])
    assert stats["fence_breaches"] == []
    summary = _replay(run["log"], tmp_path)
    assert summary["mismatches"] == 0, summary["first_mismatches"]


def _fly_past_the_vehicles_fence(tmp_path, budget, stub_args):
    """A dry run whose stub holds the example's fence (``stub_args``) while ``fly`` flies a
    copy of the example without it: ``(run, fly's completed process, the stub's stats)``."""
    run = _FLOOD.start_dry_run(tmp_path, FENCED, budget, stub_args)
    data = yaml.safe_load(run["scenario"].read_text())
    del data["fence"]
    open_space = tmp_path / "open.yaml"
    open_space.write_text(yaml.safe_dump(data))
    command = [str(open_space) if a == str(run["scenario"]) else a for a in run["fly"]]
    try:
        fly = subprocess.run(
            [*command, "--log", str(run["log"])], capture_output=True, text=True, timeout=240
        )
    finally:
        _FLOOD.end_process(run["stub"])
    return run, fly, json.loads(run["stats"].read_text())


def test_a_breach_with_gf_action_warning_is_said_and_the_mission_goes_on(tmp_path):
    """As below with ``GF_ACTION`` 1 on the stub: the vehicle's warning is said and logged,
    and the mission ends by its budget."""
    run, fly, stats = _fly_past_the_vehicles_fence(
        tmp_path, 8.0, ["--hold-fence", "--param", "GF_ACTION=1"]
    )
    assert fly.returncode == 0, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "vehicle says (CRITICAL): Geofence violation, action warning" in out
    assert "ended by budget" in out
    assert [b["action"] for b in stats["fence_breaches"]] == ["warning"]
    texts = [r for r in read_log(run["log"]).records if r["kind"] == "vehicle_text"]
    assert [(r["severity"], r["text"]) for r in texts] == [
        ("CRITICAL", "Geofence violation, action warning")
    ]


def test_a_breach_holds_the_vehicle_and_fly_leaves_it_to_the_pilot(tmp_path):
    """The stub holds the example's fence; ``fly`` flies a copy without it (so it leaves the
    vehicle's fence alone and flies straight at p1, through the no-fly square): the stub's
    GF_ACTION hold takes it out of OFFBOARD, and ``fly`` ends as when a pilot takes over."""
    run, fly, stats = _fly_past_the_vehicles_fence(tmp_path, BUDGET_S, ["--hold-fence"])
    assert fly.returncode == 4, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "the pilot took over: the vehicle left OFFBOARD for HOLD at mission time" in out
    assert "fence:" not in out  # no fence in the scenario: the vehicle's is left alone
    assert "vehicle says (CRITICAL): Geofence violation, action hold" in out
    assert [b["action"] for b in stats["fence_breaches"]] == ["hold"]
    assert stats["final_mode"] == "hold"
    scenario = load_scenario(run["scenario"])
    fence = scenario.fence.spec()._replace(margin=0.0).compiled()
    (breach,) = stats["fence_breaches"]
    assert not point_free(fence, *breach["position"])  # it crossed into the square
    assert all(point_free(fence, e, n) for _, n, e, _, _ in stats["track"])  # in OFFBOARD
    summary = _replay(run["log"], tmp_path)
    assert summary["ended_by"] == "pilot took over" and summary["mismatches"] == 0
