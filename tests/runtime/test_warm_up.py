"""``hptrack warm-up`` compiles every kernel a flight can need: after it, a new process flies
simulated missions with faults (other scenarios and seeds, late plans and the fallback, delayed
and reordered detections, bad input) without compiling anything."""

import os
import subprocess
import sys

import pytest

FLIGHT = """
import numpy as np
from numba.core import event
from hptrack.cli.flight import flight_planner_settings
from hptrack.registry import make_planner
from hptrack.runtime import SimulatedFaults, run_simulated
from hptrack.scenario import load_scenario, random_scenario

compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(str(ev.data["dispatcher"]))
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
faults = SimulatedFaults(
    odometry_drop_probability=0.1, detection_rate_hz=10, detection_latency_s=0.3,
    detection_jitter_s=0.5, planner_slow_probability=0.2, planner_slow_delay_s=1.5,
    bad_input_rate_hz=2.0,
)
settings = flight_planner_settings("mcts", None, None, None)
missions = (
    (load_scenario({example!r}), 7),
    (random_scenario(3, seed=4), 8),
    (random_scenario(6, seed=9, homogeneous=True), 3),
    (random_scenario(2, seed=1), 2),
)
for scenario, seed in missions:
    run_simulated(scenario, make_planner("mcts", settings), seed, faults=faults)
print(len(compiled), sorted(set(compiled))[:5])
"""


@pytest.mark.slow
def test_after_the_warm_up_a_new_process_flies_without_compiling(tmp_path, example_path):
    env = {**os.environ, "HPTRACK_CACHE_DIR": str(tmp_path / "cache")}  # a fresh install's
    warm = subprocess.run(
        [sys.executable, "-m", "hptrack", "warm-up"], env=env, capture_output=True, text=True
    )
    assert warm.returncode == 0, warm.stderr
    assert "mcts: kernels ready in" in warm.stdout and str(tmp_path / "cache") in warm.stdout
    flight = subprocess.run(
        [sys.executable, "-c", FLIGHT.format(example=str(example_path))],
        env=env,
        capture_output=True,
        text=True,
    )
    assert flight.returncode == 0, flight.stderr
    assert flight.stdout.split()[0] == "0", flight.stdout
