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

from hptrack.models.beliefs import TargetBeliefs
from hptrack.scenario.model import Scenario
from hptrack.interface import MissionSpec, Observation, Planner
from hptrack.sim.record import EpisodeRecord


def initial_true_states(scenario: Scenario, rng: np.random.Generator) -> np.ndarray:
    """True initial states ``(n, 4)``: given ones, or draws from each target's prior."""
    states = np.empty((len(scenario.targets), 4))
    for i, target in enumerate(scenario.targets):
        if target.truth is not None:
            states[i] = target.truth
        else:
            states[i] = rng.multivariate_normal(target.mean, target.covariance, method="cholesky")
    return states


def move_towards(position: np.ndarray, waypoint: np.ndarray, max_step: float) -> np.ndarray:
    """Holonomic move: straight towards ``waypoint`` by at most ``max_step`` metres."""
    delta = waypoint - position
    dist = float(np.hypot(delta[0], delta[1]))
    if dist <= max_step:
        return waypoint.astype(float)
    return position + delta * (max_step / dist)


def _observation(k: int, mission: MissionSpec, agent: np.ndarray, beliefs: TargetBeliefs,
                 detected: np.ndarray) -> Observation:
    arrays = [agent.copy(), beliefs.means.copy(), beliefs.covariances.copy(), detected.copy()]
    for a in arrays:
        a.flags.writeable = False
    time = k * mission.time_step
    return Observation(k, time, mission.budget - time, *arrays)


def run_episode(scenario: Scenario, planner: Planner, seed: int | None = None,
                belief_stride: int = 1,
                on_step: Callable[[int, int], None] | None = None) -> EpisodeRecord:
    """Simulate one mission of ``scenario`` flown by ``planner``.

    Args:
        scenario: the mission.
        planner: any :class:`~hptrack.interface.Planner`; it never sees the truth.
        seed: overrides ``scenario.seed``.
        belief_stride: store beliefs every this many steps (the last step is always stored).
        on_step: called as ``on_step(k, K)`` after each step (progress bars).
    """
    seed = scenario.seed if seed is None else seed
    truth_seq, motion_seq, sensor_seq, planner_seq = np.random.SeedSequence(seed).spawn(4)
    motion_rng = np.random.default_rng(motion_seq)
    sensor_rng = np.random.default_rng(sensor_seq)

    mission = scenario.mission_spec()
    motion, sensor, q = mission.motion, mission.sensor, mission.process_noise
    n, n_steps = mission.n_targets, mission.n_steps
    beliefs = TargetBeliefs(scenario.means(), scenario.covariances(), q, motion, sensor)

    truth = initial_true_states(scenario, np.random.default_rng(truth_seq))
    agent = np.asarray(scenario.agent.position, dtype=float)
    stored = sorted(set(range(0, n_steps + 1, belief_stride)) | {n_steps})
    store_at = {k: j for j, k in enumerate(stored)}

    agent_path = np.empty((n_steps + 1, 2))
    true_states = np.empty((n_steps + 1, n, 4))
    detections = np.zeros((n_steps + 1, n), dtype=bool)
    belief_means = np.empty((len(stored), n, 4))
    belief_covs = np.empty((len(stored), n, 4, 4))

    def sense(k: int) -> np.ndarray:
        seen = sensor.in_footprint(agent, truth[:, :2])
        idx = np.flatnonzero(seen)
        beliefs.update(idx, sensor.sample(truth[idx, :2], sensor_rng))
        agent_path[k], true_states[k], detections[k] = agent, truth, seen
        if k in store_at:
            belief_means[store_at[k]] = beliefs.means
            belief_covs[store_at[k]] = beliefs.covariances
        return seen

    seen = sense(0)
    observation = _observation(0, mission, agent, beliefs, seen)
    planner.reset(mission, observation, np.random.default_rng(planner_seq))
    for k in range(1, n_steps + 1):
        waypoint = np.asarray(planner.act(observation), dtype=float)
        if waypoint.shape != (2,) or not np.all(np.isfinite(waypoint)):
            raise ValueError(f"planner {planner.name!r} returned an invalid waypoint {waypoint!r}")
        agent = move_towards(agent, waypoint, mission.step_length)
        truth = motion.sample_motion(truth, q, motion_rng)
        beliefs.predict(mission.time_step)
        seen = sense(k)
        observation = _observation(k, mission, agent, beliefs, seen)
        if on_step is not None:
            on_step(k, n_steps)

    return EpisodeRecord(
        planner=planner.name, seed=seed, target_ids=mission.target_ids,
        time_step=mission.time_step, sensor_diameter=sensor.sensor_diameter,
        agent_path=agent_path, true_states=true_states, belief_steps=np.asarray(stored),
        belief_means=belief_means, belief_covariances=belief_covs, detections=detections,
        per_target_logdet=beliefs.position_logdets(), info=dict(planner.episode_info()),
    )


def record_bytes(n_targets: int, n_steps: int, belief_stride: int = 1) -> int:
    """Memory an :class:`EpisodeRecord` of a mission needs, bytes (to refuse one that does not
    fit before it starts)."""
    per_step = 8 * (2 + 4 * n_targets) + n_targets
    stored = n_steps // belief_stride + 2
    return (n_steps + 1) * per_step + stored * 8 * 20 * n_targets
