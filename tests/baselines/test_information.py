"""The deterministic covariance rollout and the Riccati bound shared by ARVI and A*."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.baselines.controls import HOVER, step_directions
from hptrack.baselines.information import (
    RiccatiBound,
    child_covariances,
    expand,
    expand_uncertainty,
    mean_positions,
    step_costs,
)
from hptrack.models.beliefs import position_logdet

EAST = 1
K = 10
FULL_R = np.array([[12.0, 5.0], [5.0, 7.0]])
"""A measurement noise with correlated axes, m^2 (the rollouts take any 2x2 ``R``)."""
NOISES = {"R=10I": None, "full R": FULL_R}


def setup(make_mission, make_observation, means, horizon=1, form="continuous", noise=None):
    mission = make_mission(len(means), form=form, noise=noise)
    obs = make_observation(means)
    steps = mission.step_length * step_directions(8)
    return mission, obs, steps, mean_positions(obs.means, mission.motion, horizon * K)


def reference_rollout(mission, obs, agent_path):
    """Sub-step by sub-step with the library's one-step predict and Kalman update."""
    means, covs = obs.means.copy(), obs.covariances.copy()
    measured = []
    for position in agent_path:
        means, covs = mission.motion.predict(means, covs, mission.process_noise, mission.time_step)
        seen = np.flatnonzero(mission.sensor.in_footprint(position, means[:, :2]))
        if len(seen):
            _, covs[seen] = mission.sensor.update(means[seen], covs[seen], means[seen, :2])
        measured.append(seen.tolist())
    return covs, measured


def test_mean_positions_are_open_loop_constant_velocity(make_mission):
    means = np.array([[100.0, -50.0, -3.0, 2.0]])
    got = mean_positions(means, make_mission(1).motion, 4)
    np.testing.assert_array_equal(
        got[:, 0], [[100.0, -50.0], [98.5, -49.0], [97.0, -48.0], [95.5, -47.0], [94.0, -46.0]]
    )


@pytest.mark.parametrize("noise", list(NOISES))
@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_primitive_measures_exactly_the_sub_steps_in_the_footprint(
    make_mission, make_observation, form, noise
):
    # Agent flies east at 15 m per step; target 0 drifts west at 1.5 m per step from x = 100 m:
    # distance |100 - 16.5 s| <= 50 m for s = 4..9. Target 1 is never within reach.
    means = [[100.0, 0.0, -3.0, 0.0], [2000.0, 0.0, 1.0, 1.0]]
    mission, obs, steps, mp = setup(
        make_mission, make_observation, means, form=form, noise=NOISES[noise]
    )
    path = [np.array([15.0 * s, 0.0]) for s in range(1, K + 1)]
    expected, measured = reference_rollout(mission, obs, path)
    assert measured == [[], [], [], [0], [0], [0], [0], [0], [0], []]
    pos, covs, unc = expand(mission, steps, mp, obs.agent_position[None], obs.covariances[None])
    assert pos.shape == (9, 2) and covs.shape == (9, 2, 4, 4)
    np.testing.assert_array_equal(pos[EAST], [150.0, 0.0])
    np.testing.assert_allclose(covs[EAST], expected, rtol=1e-9, atol=1e-12)
    assert unc[EAST] == pytest.approx(position_logdet(expected).sum(), rel=1e-12)


def test_unreached_targets_get_exactly_the_closed_form_prediction(make_mission, make_observation):
    means = [[1000.0, 0.0, 0.0, 0.0], [-400.0, 300.0, 2.0, -1.0]]
    mission, obs, steps, mp = setup(make_mission, make_observation, means)
    _, covs, unc = expand(mission, steps, mp, obs.agent_position[None], obs.covariances[None])
    _, predicted = mission.motion.predict(
        obs.means, obs.covariances, mission.process_noise, K * mission.time_step
    )
    for c in range(9):
        np.testing.assert_allclose(covs[c], predicted, rtol=1e-12)
    np.testing.assert_allclose(unc, position_logdet(predicted).sum(), rtol=1e-12)


def test_two_phase_expansion_matches_the_full_one(make_mission, make_observation):
    means = [[100.0, 0.0, -3.0, 0.0], [-120.0, 60.0, 1.0, 0.0], [900.0, 900.0, 0.0, 0.0]]
    mission, obs, steps, mp = setup(make_mission, make_observation, means, horizon=2)
    pos1, covs1, _ = expand(
        mission, steps, mp[: K + 1], obs.agent_position[None], obs.covariances[None]
    )
    pos2, covs2, unc2 = expand(mission, steps, mp[K:], pos1, covs1)
    pos_u, unc_u = expand_uncertainty(mission, steps, mp[K:], pos1, covs1)
    np.testing.assert_array_equal(pos_u, pos2)
    np.testing.assert_array_equal(unc_u, unc2)
    chosen = np.array([80, 3, 40, 41])
    np.testing.assert_array_equal(
        child_covariances(mission, steps, mp[K:], pos1, covs1, chosen), covs2[chosen]
    )
    # Child a C + c is node a after control c: node 5 (west) then east is back at the origin.
    np.testing.assert_array_equal(pos2[5 * 9 + EAST], [0.0, 0.0])


def test_difference_costs_telescope_and_sum_costs_add_the_levels():
    levels = np.array([10.0, 12.5, 11.0, 13.0])
    diff = step_costs(levels[:-1], levels[1:], "difference")
    assert diff.sum() == pytest.approx(levels[-1] - levels[0])
    np.testing.assert_array_equal(step_costs(levels[:-1], levels[1:], "sum"), levels[1:])
    with pytest.raises(ValueError, match="unknown cost kind"):
        step_costs(levels[:-1], levels[1:], "mean")


def plan_uncertainty(mission, steps, mp, obs, plan):
    pos, covs = obs.agent_position[None], obs.covariances[None]
    for level, control in enumerate(plan):
        pos, covs, unc = expand(mission, steps, mp[level * K : (level + 1) * K + 1], pos, covs)
        pos, covs, unc = pos[control : control + 1], covs[control : control + 1], unc[control]
    return unc


@pytest.mark.parametrize("noise", list(NOISES))
@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_bound_is_attained_by_flying_to_a_static_target_and_hovering(
    make_mission, make_observation, form, noise
):
    # Target mean at (200, 0), static: reachable first at sub-step 10 (150 m flown, 50 m left),
    # when the plan [east, hover, hover] reaches it; it then measures it at every sub-step.
    mission, obs, steps, mp = setup(
        make_mission,
        make_observation,
        [[200.0, 0.0, 0.0, 0.0]],
        horizon=3,
        form=form,
        noise=NOISES[noise],
    )
    bound = RiccatiBound(mission, 3 * K)
    got = bound.lower_bounds(
        obs.agent_position[None], obs.covariances[None], 0, np.array([K, 2 * K, 3 * K]), mp
    )
    for length in (1, 2, 3):
        actual = plan_uncertainty(mission, steps, mp, obs, [EAST] + [HOVER] * (length - 1))
        assert got[0, length - 1] == pytest.approx(actual, rel=1e-9)
    # One sub-step later, from the hover at (150, 0): measured at once and every sub-step after.
    pos1, covs1, _ = expand(
        mission, steps, mp[: K + 1], obs.agent_position[None], obs.covariances[None]
    )
    later = bound.lower_bounds(
        pos1[EAST : EAST + 1], covs1[EAST : EAST + 1], K, np.array([3 * K]), mp
    )
    assert later[0, 0] == pytest.approx(got[0, 2], rel=1e-9)


def test_bound_of_an_unreachable_target_is_its_prediction(make_mission, make_observation):
    mission, obs, steps, mp = setup(
        make_mission, make_observation, [[1500.0, 0.0, 1.0, 0.0]], horizon=6
    )
    got = RiccatiBound(mission, 6 * K).lower_bounds(
        obs.agent_position[None], obs.covariances[None], 0, np.array([60]), mp
    )
    _, predicted = mission.motion.predict(
        obs.means, obs.covariances, mission.process_noise, 60 * mission.time_step
    )
    assert got[0, 0] == pytest.approx(position_logdet(predicted).sum(), rel=1e-12)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_bound_is_below_every_plan(make_mission, make_observation, seed):
    rng = np.random.default_rng(seed)
    means = np.column_stack([rng.uniform(-250, 250, (3, 2)), rng.uniform(-3, 3, (3, 2))])
    mission, obs, steps, mp = setup(make_mission, make_observation, means, horizon=3)
    bound = RiccatiBound(mission, 3 * K).lower_bounds(
        obs.agent_position[None], obs.covariances[None], 0, np.array([K, 2 * K, 3 * K]), mp
    )[0]
    pos, covs = obs.agent_position[None], obs.covariances[None]
    for level in range(3):
        pos, covs, unc = expand(mission, steps, mp[level * K : (level + 1) * K + 1], pos, covs)
        assert np.all(unc >= bound[level] - 1e-9)
