"""Compile (or load from the cache) before a flight every kernel the flight can need, so that
nothing compiles in the air: a fresh install's first ``mcts`` plan compiles about 100 kernels
(over a minute on a 2-core machine), and a compile in flight starves the setpoint stream and the
vehicle's callbacks of the interpreter.

`warm_up_flight` flies the planner through whole missions on the simulated clock
(`hptrack.runtime.simulated`): the flight's scenario and a random one with more targets
(`WARM_UP_EXTRA`: longer pursuits, plans after a miss), so the controller, the beliefs, every
kind of sub-task (pursuits, finds, misses, follows) and, through planner calls made slower than
the deadline, the greedy fallback all run. Kernels compile per argument type, not per value,
so these missions warm them for any scenario; in the same process they then stay in memory,
and the compile cache on disk, which every checkout of the same code shares, keeps them for
the next one.
"""

from __future__ import annotations

import time

from hptrack.registry import make_planner
from hptrack.runtime.simulated import SimulatedFaults, run_simulated
from hptrack.scenario.model import Scenario
from hptrack.scenario.random import random_scenario
from hptrack.settings import PlannerSettings

WARM_UP_SEEDS = 2
"""Missions flown per planner (each its own seed, so that finds and misses both happen)."""
WARM_UP_BUDGET_S = 60.0
"""The warm-up's missions are at most this long, s."""
WARM_UP_EXTRA = (4, 0)
"""Targets and seed of the random scenario (`random_scenario`) flown besides the flight's
own."""
WARM_UP_FAULTS = SimulatedFaults(planner_slow_probability=0.1, planner_slow_delay_s=1.5)
"""One call in ten slower than the default 1 s deadline: the greedy fallback flies too."""


def warm_up_flight(
    scenario: Scenario, planner: str, settings: PlannerSettings | None = None, seed: int = 0
) -> float:
    """Fly `WARM_UP_SEEDS` simulated missions of ``scenario`` (at most `WARM_UP_BUDGET_S`
    long) and one of `WARM_UP_EXTRA` with a fresh ``planner`` of ``settings`` each, seeds
    ``seed, seed + 1, ...``; returns the wall time it took, s."""
    started = time.perf_counter()
    short = scenario.model_copy(update={"budget": min(scenario.budget, WARM_UP_BUDGET_S)})
    missions = [short] * WARM_UP_SEEDS + [random_scenario(*WARM_UP_EXTRA)]
    for k, mission in enumerate(missions):
        run_simulated(mission, make_planner(planner, settings), seed + k, faults=WARM_UP_FAULTS)
    return time.perf_counter() - started
