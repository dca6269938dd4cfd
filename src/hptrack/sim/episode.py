"""The episode loop (paper Fig. 2 closed around a simulated world).

Each step ``k -> k+1`` (``tau`` seconds): the planner gives a waypoint, the agent moves straight
towards it by at most ``v_a tau``, the true targets move with ``F`` and ``Q`` noise, every belief
is predicted (Eq. (1)), and every target whose true position lies within ``w/2`` of the agent is
measured (``z = [x, y] + v``) and updated. Sensing also happens at step 0. ``U`` is taken after
the last step, ``K = B / tau``.

Randomness: ``SeedSequence(seed)`` spawns independent streams for the true initial states, the
target motion, the measurement noise and the planner.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hptrack.interface import MissionSpec, Planner, TruthReader, vehicle_waypoints
from hptrack.models.state import positions
from hptrack.scenario.model import Scenario
from hptrack.sim.record import EpisodeRecord
from hptrack.sim.step import World


def run_episode(
    scenario: Scenario,
    planner: Planner,
    seed: int | None = None,
    belief_stride: int = 1,
    on_step: Callable[[int, int], None] | None = None,
    planner_mission: MissionSpec | None = None,
) -> EpisodeRecord:
    """Simulate one mission of ``scenario`` flown by ``planner``.

    Args:
        scenario: the mission.
        planner: any `Planner`; it never sees the truth unless it
            is a `TruthReader` (a reference).
        seed: overrides ``scenario.seed``.
        belief_stride: store beliefs every this many steps (the last step is always stored).
        on_step: called as ``on_step(k, K)`` after each step (progress bars).
        planner_mission: the mission the planner is told, when it is not the world's (the same
            targets, vehicles, time step and budget; e.g. the paper's certain sensor on a world
            whose detector misses: the "blind" planner of a sensing comparison).

    Raises:
        ValueError: ``planner_mission`` is not a mission of the same targets, vehicles and
            steps.
    """
    world = World(scenario, seed)
    mission = world.mission
    told = mission if planner_mission is None else planner_mission
    if (told.target_ids, told.n_vehicles, told.time_step, told.n_steps) != (
        mission.target_ids,
        mission.n_vehicles,
        mission.time_step,
        mission.n_steps,
    ):
        raise ValueError("planner_mission must have the world's targets, vehicles and steps")
    n, n_steps = mission.n_targets, mission.n_steps
    stored = sorted(set(range(0, n_steps + 1, belief_stride)) | {n_steps})
    store_at = {k: j for j, k in enumerate(stored)}
    agent_paths = np.empty((n_steps + 1, mission.n_vehicles, 2))
    d_true, d = world.truth.shape[1], world.means.shape[1]
    true_states = np.empty((n_steps + 1, n, d_true))
    detections = np.zeros((n_steps + 1, n), dtype=bool)
    belief_means = np.empty((len(stored), n, d))
    belief_covs = np.empty((len(stored), n, d, d))
    mean_positions = np.empty((n_steps + 1, n, 2))

    def store(k: int) -> None:
        agent_paths[k], true_states[k], detections[k] = world.agents, world.truth, world.seen
        mean_positions[k] = positions(world.means)
        if k in store_at:
            belief_means[store_at[k]] = world.means
            belief_covs[store_at[k]] = world.covariances

    store(0)
    observation = world.observation()
    planner.reset(told, observation, np.random.default_rng(world.planner_seed))
    reader = planner if isinstance(planner, TruthReader) else None
    for k in range(1, n_steps + 1):
        if reader is not None:
            reader.see_truth(world.truth.copy())
        waypoint = vehicle_waypoints(planner.act(observation), mission.n_vehicles, planner.name)
        world.step_team(waypoint)
        store(k)
        observation = world.observation()
        if on_step is not None:
            on_step(k, n_steps)
    return EpisodeRecord(
        planner=planner.name,
        seed=world.seed,
        target_ids=mission.target_ids,
        time_step=mission.time_step,
        sensor_diameter=mission.sensor_diameter,
        agent_paths=agent_paths,
        true_states=true_states,
        belief_steps=np.asarray(stored),
        belief_means=belief_means,
        belief_covariances=belief_covs,
        detections=detections,
        per_target_logdet=world.logdets.copy(),
        info=dict(planner.episode_info()),
        fence=mission.fence,
        mean_positions=mean_positions,
        associations=world.associations,
        claims=world.claims,
    )


def record_bytes(n_targets: int, n_steps: int, belief_stride: int = 1) -> int:
    """Memory an `EpisodeRecord` of a mission needs, bytes (to refuse one that does not
    fit before it starts; sized for 4-D states: per step the vehicle, the truths, the
    belief means' positions and the detections)."""
    per_step = 8 * (2 + 6 * n_targets) + n_targets
    stored = n_steps // belief_stride + 2
    return (n_steps + 1) * per_step + stored * 8 * 20 * n_targets
