"""Fly the real-time mission controller on a simulated clock, with faults injected.

The controller is the one ``hptrack fly`` runs on a vehicle; here the simulator's world stands in
for the drone and the detector (late, jittered and dropped detections, an odometry outage, slow
plans). For a dry run through MAVSDK with the vehicle stub, see ``paper-flight.yaml``.

    python3 fly_simulated.py [--planner greedy] [--seed 3]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import hptrack
from hptrack.runtime import SimulatedFaults, run_simulated

HERE = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planner", default="greedy")
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args()

    faults = SimulatedFaults(
        detection_rate_hz=10,
        detection_latency_s=0.3,
        detection_jitter_s=0.6,
        detection_drop_probability=0.3,
        odometry_outages=((12.0, 2.5),),
        planner_slow_probability=0.2,
        planner_slow_delay_s=1.5,
    )
    scenario = hptrack.load_scenario(HERE / "paper-flight.yaml")
    run = run_simulated(scenario, hptrack.make_planner(args.planner), seed=args.seed, faults=faults)
    print(f"U = {run.uncertainty:.3f}; inputs rejected: {dict(run.controller.rejected)}")


if __name__ == "__main__":
    main()
