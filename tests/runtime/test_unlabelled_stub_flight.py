"""``hptrack fly`` on detections without identity: the unlabelled-flight example (no ids,
``Pd`` 0.8, false alarms) flown on the vehicle stub ends by its budget with the tracker's
associations in its log, and the log replays with 0 mismatches (issue 29's flight)."""

import importlib.util
import json
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("mavsdk")
pytest.importorskip("pymavlink")

from hptrack.runtime.log import read_log  # noqa: E402

# one stub flight at a time on one test worker, as the other stub flights
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("stub-flights")]

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "unlabelled-flight.yaml"
BUDGET_S = 15.0


def _flood():
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "flight_flood.py"
    spec = importlib.util.spec_from_file_location("flight_flood", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_stub_flight_without_identity_ends_by_its_budget_and_replays(tmp_path):
    flood = _flood()
    run = flood.start_dry_run(tmp_path, EXAMPLE, BUDGET_S)
    try:
        fly = subprocess.run(
            [*run["fly"], "--log", str(run["log"])], capture_output=True, text=True, timeout=240
        )
    finally:
        flood.end_process(run["stub"])
    assert fly.returncode == 0, fly.stdout + fly.stderr
    assert "ended by budget" in fly.stdout
    assert f"reports in {round(BUDGET_S / 0.5) + 1} looks" in " ".join(fly.stdout.split())
    records = read_log(run["log"]).records
    reports = [r for r in records if r["kind"] == "detection" and r["accepted"]]
    assert reports and all(r["target"] is None for r in reports)
    looks = [r for r in records if r["kind"] == "look"]
    assert len(looks) == BUDGET_S / 0.5 + 1
    taken = [b for look in looks for b in look["belief"] if b is not None]
    assert len(taken) > 0
    end = next(r for r in records if r["kind"] == "end")
    assert end["reason"] == "budget" and end["tracking"]["taken by a belief"] == len(taken)

    summary = tmp_path / "replay.json"
    replay = subprocess.run(
        [*flood.CLI, "replay", str(run["log"]), "--json", str(summary), "--plot",
         str(tmp_path / "r.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    replayed = json.loads(summary.read_text())
    assert replayed["mismatches"] == 0, replayed["first_mismatches"]
    assert replayed["ended_by"] == "budget" and replayed["tracking"] == end["tracking"]
