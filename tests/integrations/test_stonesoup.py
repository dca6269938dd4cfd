"""The Stone Soup sensor manager: frame conversion, observation, actions, track identity, missions,
the plugin entry point, and a closed-loop Stone Soup simulation against a hovering platform."""

import datetime
import importlib
import importlib.metadata
import importlib.util
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from stonesoup.models.transition.linear import (  # noqa: E402
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
    RandomWalk,
)
from stonesoup.movable import FixedMovable  # noqa: E402
from stonesoup.movable.max_speed import MaxSpeedActionableMovable  # noqa: E402
from stonesoup.platform import MovingPlatform  # noqa: E402
from stonesoup.predictor.kalman import KalmanPredictor  # noqa: E402
from stonesoup.types.detection import Detection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState, State  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.updater.kalman import KalmanUpdater  # noqa: E402

import hptrack.integrations.stonesoup as ss  # noqa: E402
from hptrack.integrations.stonesoup import (  # noqa: E402
    STONESOUP_TO_HPTRACK,
    FootprintPositionSensor,
    HoverSensorManager,
    HptrackSensorManager,
    hptrack_beliefs,
    process_noise_of,
)
from hptrack.interface import InputError  # noqa: E402
from hptrack.models.motion import ConstantVelocityModel  # noqa: E402
from hptrack.registry import make_planner  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
T0 = datetime.datetime(2025, 1, 1)
TAU = 0.5


def at(seconds: float) -> datetime.datetime:
    return T0 + datetime.timedelta(seconds=seconds)


def make_platform(speed=30.0, diameter=100.0, noise=10.0, **movable_options) -> MovingPlatform:
    movable = MaxSpeedActionableMovable(
        states=[State([[0.0], [0.0]], timestamp=T0)],
        position_mapping=(0, 1),
        max_speed=speed,
        **movable_options,
    )
    sensor = FootprintPositionSensor(noise_covar=noise * np.eye(2), diameter=diameter)
    return MovingPlatform(movement_controller=movable, sensors=[sensor])


def track(track_id: str, ss_mean, var=400.0, time=T0) -> Track:
    cov = np.diag([var, 0.3, var, 0.3])
    return Track(
        [GaussianState(np.asarray(ss_mean, dtype=float), cov, timestamp=time)], id=track_id
    )


def manager(platform, planner="greedy", **options) -> HptrackSensorManager:
    return HptrackSensorManager(
        process_noise=3e-4, time_step=TAU, planner=planner, platforms={platform}, seed=1, **options
    )


def target_xy(configs, platform) -> np.ndarray:
    assert len(configs) == 1 and set(configs[0]) == {platform}
    (action,) = configs[0][platform]
    return np.asarray(action.target_value, dtype=float).ravel()


def step(platform, configs, time) -> None:
    for config in configs:
        for actionable, actions in config.items():
            actionable.add_actions(actions)
            actionable.act(time)


class Recorder:
    """Wraps a registry planner and keeps what the manager hands it."""

    def __init__(self, inner):
        self.inner, self.name, self.missions, self.observations = inner, inner.name, [], []

    def reset(self, mission, observation, rng):
        self.missions.append(mission)
        self.inner.reset(mission, observation, rng)

    def act(self, observation):
        self.observations.append(observation)
        return self.inner.act(observation)

    def episode_info(self):
        return self.inner.episode_info()


@pytest.fixture
def recorders(monkeypatch):
    made = []

    def make(name, settings=None):
        made.append(Recorder(make_planner(name, settings)))
        return made[-1]

    monkeypatch.setattr(ss, "make_planner", make)
    return made


# --- frame conversion -------------------------------------------------------------------------
def test_permutation_reorders_mean_and_covariance():
    a = np.arange(16.0).reshape(4, 4)
    cov = a + a.T + 40.0 * np.eye(4)
    means, covs = hptrack_beliefs([GaussianState([1.0, 2.0, 3.0, 4.0], cov)])
    np.testing.assert_array_equal(means[0], [1.0, 3.0, 2.0, 4.0])  # x, y, vx, vy
    # hptrack (x, y) is Stone Soup (x, y) = (0, 2); (vx, vy) is (1, 3); (y, vx) is (2, 1)
    assert covs[0, 0, 1] == cov[0, 2] and covs[0, 2, 3] == cov[1, 3]
    assert covs[0, 1, 2] == cov[2, 1] and covs[0, 1, 1] == cov[2, 2]
    np.testing.assert_array_equal(covs[0], cov[np.ix_(STONESOUP_TO_HPTRACK, STONESOUP_TO_HPTRACK)])
    # a 3-D [x, vx, y, vy, z, vz] track plans in the x, y plane
    means3, _ = hptrack_beliefs([GaussianState(np.arange(6.0), np.eye(6))])
    np.testing.assert_array_equal(means3[0], [0.0, 2.0, 1.0, 3.0])
    with pytest.raises(ValueError, match="state_mapping"):
        hptrack_beliefs([GaussianState(np.arange(4.0), np.eye(4))], (0, 1, 1, 3))


def test_hptrack_prediction_equals_stonesoup_kalman_prediction():
    rng = np.random.default_rng(3)
    q = 0.7
    predictor = KalmanPredictor(
        CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    )
    a = rng.normal(size=(4, 4))
    prior = GaussianState(rng.normal(size=4) * 100.0, a @ a.T + np.eye(4), timestamp=T0)
    predicted = predictor.predict(prior, timestamp=at(7.3))
    mean, cov = hptrack_beliefs([prior])
    mean, cov = ConstantVelocityModel(TAU).predict(mean, cov, q, 7.3)
    expected_mean, expected_cov = hptrack_beliefs([predicted])
    np.testing.assert_allclose(mean, expected_mean, rtol=1e-12)
    np.testing.assert_allclose(cov, expected_cov, rtol=1e-12)


def test_process_noise_of_reads_one_q():
    assert (
        process_noise_of(
            CombinedLinearGaussianTransitionModel([ConstantVelocity(2e-4), ConstantVelocity(2e-4)])
        )
        == 2e-4
    )
    with pytest.raises(ValueError, match="one process noise"):
        process_noise_of(
            CombinedLinearGaussianTransitionModel([ConstantVelocity(1e-4), ConstantVelocity(2e-4)])
        )
    with pytest.raises(ValueError, match="ConstantVelocity"):
        process_noise_of(CombinedLinearGaussianTransitionModel([RandomWalk(1.0), RandomWalk(1.0)]))


def test_footprint_sensor_measures_within_half_the_diameter():
    platform = make_platform(diameter=100.0)
    (sensor,) = platform.sensors
    near = State(np.array([49.0, 0.0, 0.0, 0.0]))
    far = State(np.array([35.5, 0.0, 35.5, 0.0]))  # 50.2 m away
    assert sensor.is_detectable(near) and not sensor.is_detectable(far)
    assert sensor.is_clutter_detectable(Detection(np.array([[0.0], [-50.0]])))
    np.testing.assert_array_equal(sensor.measurement_model.matrix(), [[1, 0, 0, 0], [0, 0, 1, 0]])


# --- observation and mission ------------------------------------------------------------------
def test_observation_and_mission_come_from_tracks_and_platform(recorders):
    platform = make_platform(speed=20.0, diameter=80.0, noise=4.0)
    old = track("old", [300.0, 1.0, -50.0, 2.0], time=at(-2.0))
    fresh = track("fresh", [0.0, 0.0, 10.0, 0.0])
    measured = track("measured", [5.0, 0.0, 5.0, 0.0])
    detection = Detection(
        np.array([[5.0], [5.0]]),
        timestamp=T0,
        measurement_model=platform.sensors[0].measurement_model,
    )
    measured.append(KalmanUpdater(None).update(SingleHypothesis(measured.state, detection)))
    sm = HptrackSensorManager(
        process_noise={"old": 1e-3, "fresh": 2e-4, "measured": 3e-4},
        time_step=TAU,
        planner="greedy",
        budget=30.0,
        platforms={platform},
        seed=0,
    )
    sm.choose_actions({old, fresh, measured}, at(TAU))
    (planner,) = recorders
    (mission,) = planner.missions
    assert mission.target_ids == ("fresh", "measured", "old")  # first seen together: by id
    assert (mission.agent_speed, mission.sensor_diameter, mission.budget) == (20.0, 80.0, 30.0)
    np.testing.assert_array_equal(mission.measurement_noise, 4.0 * np.eye(2))
    np.testing.assert_array_equal(mission.process_noise, [2e-4, 3e-4, 1e-3])
    assert mission.process_noise_form == "continuous" and mission.time_step == TAU
    (obs,) = planner.observations
    assert (obs.step, obs.time, obs.remaining_budget) == (0, 0.0, 30.0)
    np.testing.assert_array_equal(obs.detected, [False, True, False])
    np.testing.assert_array_equal(obs.agent_position, [0.0, 0.0])
    # the stale track is predicted 2 s to the platform's time by Stone Soup's own model
    stone_soup = KalmanPredictor(
        CombinedLinearGaussianTransitionModel([ConstantVelocity(1e-3), ConstantVelocity(1e-3)])
    ).predict(old.state, timestamp=T0)
    mean, cov = hptrack_beliefs([stone_soup])
    np.testing.assert_allclose(obs.means[2], mean[0], rtol=1e-12)
    np.testing.assert_allclose(obs.covariances[2], cov[0], rtol=1e-12)
    np.testing.assert_allclose(obs.means[0], [0.0, 10.0, 0.0, 0.0])


def test_greedy_flies_at_the_track_at_full_speed_in_the_right_axis():
    # Stone Soup [x, vx, y, vy] = [0, 3, 300, 0]: the target is due north (+y), moving east;
    # read as [x, y, vx, vy] it would sit 3 m from the platform.
    platform = make_platform()
    sm = manager(platform)
    configs = sm.choose_actions({track("a", [0.0, 3.0, 300.0, 0.0])}, at(TAU))
    np.testing.assert_allclose(target_xy(configs, platform), [0.0, 15.0], atol=1e-12)
    step(platform, configs, at(TAU))
    np.testing.assert_allclose(np.ravel(platform.position), [0.0, 15.0], atol=1e-12)
    assert platform.movement_controller.state.timestamp == at(TAU)
    assert sm.target_ids == ("a",) and sm.planner_info()["settings"] == {}


def test_discrete_actions_take_the_generators_closest_action():
    platform = make_platform(resolution=5.0, angle_resolution=np.pi / 2)
    tracks = {track("a", [300.0, 0.0, 100.0, 0.0])}
    continuous = target_xy(manager(platform).choose_actions(tracks, at(TAU)), platform)
    np.testing.assert_allclose(continuous, 15.0 * np.array([3.0, 1.0]) / np.sqrt(10.0))
    discrete = target_xy(
        manager(platform, discrete_actions=True).choose_actions(tracks, at(TAU)), platform
    )
    np.testing.assert_allclose(discrete, [15.0, 0.0], atol=1e-9)


def test_moves_stay_inside_the_action_space():
    platform = make_platform(action_space=np.array([[-5.0, 5.0], [-100.0, 100.0]]))
    configs = manager(platform).choose_actions({track("a", [300.0, 0.0, 0.0, 0.0])}, at(TAU))
    np.testing.assert_allclose(target_xy(configs, platform), [5.0, 0.0])


def test_without_tracks_the_platform_stays():
    platform = make_platform()
    sm = manager(platform)
    np.testing.assert_array_equal(target_xy(sm.choose_actions(set(), at(TAU)), platform), [0, 0])
    assert sm.mission is None and sm.target_ids == () and sm.planner_info() == {}


# --- track identity and missions --------------------------------------------------------------
def test_track_ids_keep_first_seen_order_and_changes_restart_the_mission(recorders):
    platform = make_platform()
    sm = manager(platform)
    b, a, c = (track(i, [200.0 * (k + 1), 0.0, 0.0, 0.0]) for k, i in enumerate("bac"))
    calls = [
        ({b}, ("b",)),
        ({a, b}, ("b", "a")),
        ({a, b, c}, ("b", "a", "c")),
        ({a, b, c}, ("b", "a", "c")),
        ({c, a}, ("a", "c")),
    ]
    for k, (tracks, expected) in enumerate(calls):
        sm.choose_actions(tracks, at((k + 1) * TAU))
        assert sm.target_ids == expected
        platform.movement_controller.move(at((k + 1) * TAU))  # hover; stale tracks are predicted
    assert [r.missions[0].target_ids for r in recorders] == [e for _, e in calls[:3]] + [("a", "c")]
    assert [len(r.missions) for r in recorders] == [1, 1, 1, 1]
    # the unchanged call kept its mission and counted one more step
    assert [o.step for o in recorders[2].observations] == [0, 1]


def test_missions_roll_over_when_the_budget_ends(recorders):
    platform = make_platform()
    sm = manager(platform, budget=2.0)  # 4 steps
    tr = track("a", [300.0, 0.0, 0.0, 0.0])
    for k in range(6):
        configs = sm.choose_actions({tr}, at((k + 1) * TAU))
        step(platform, configs, at((k + 1) * TAU))
        tr.append(GaussianState(tr.state.state_vector, tr.state.covar, timestamp=at((k + 1) * TAU)))
    assert len(recorders) == 2
    assert [o.step for o in recorders[0].observations] == [0, 1, 2, 3]
    assert [o.step for o in recorders[1].observations] == [0, 1]
    np.testing.assert_allclose(recorders[1].observations[0].agent_position, [60.0, 0.0])


# --- errors -----------------------------------------------------------------------------------
def test_refuses_what_it_cannot_plan():
    platform = make_platform()
    tracks = {track("a", [300.0, 0.0, 0.0, 0.0])}
    with pytest.raises(ValueError, match="time_step = 0.5 s"):
        manager(platform).choose_actions(tracks, at(1.0))
    with pytest.raises(ValueError, match="nchoose"):
        manager(platform).choose_actions(tracks, at(TAU), nchoose=2)
    with pytest.raises(ValueError, match="ahead of the platform"):
        manager(platform).choose_actions({track("a", [0, 0, 0, 0], time=at(0.1))}, at(TAU))
    with pytest.raises(ValueError, match="no entry for track 'a'"):
        HptrackSensorManager(
            process_noise={"b": 1e-4}, time_step=TAU, planner="greedy", platforms={platform}
        ).choose_actions(tracks, at(TAU))
    with pytest.raises(InputError, match="unknown planner 'nope'"):
        manager(platform, planner="nope")
    with pytest.raises(InputError, match="iterations"):
        manager(platform, planner="mcts", planner_options={"iterations": 0})
    with pytest.raises(ValueError, match="exactly one platform"):
        HptrackSensorManager(
            process_noise=1e-4, time_step=TAU, platforms={make_platform(), make_platform()}
        )
    fixed = MovingPlatform(
        movement_controller=FixedMovable(
            states=[State([[0.0], [0.0]], timestamp=T0)], position_mapping=(0, 1)
        )
    )
    with pytest.raises(ValueError, match="MaxSpeedActionableMovable"):
        HptrackSensorManager(process_noise=1e-4, time_step=TAU, platforms={fixed})
    bare = MovingPlatform(
        movement_controller=MaxSpeedActionableMovable(
            states=[State([[0.0], [0.0]], timestamp=T0)], position_mapping=(0, 1)
        )
    )
    with pytest.raises(ValueError, match="FootprintPositionSensor"):
        HptrackSensorManager(process_noise=1e-4, time_step=TAU, platforms={bare})
    HptrackSensorManager(
        process_noise=1e-4,
        time_step=TAU,
        platforms={bare},
        sensor_diameter=100.0,
        measurement_noise=10.0 * np.eye(2),
    )


# --- plugin -----------------------------------------------------------------------------------
def test_pyproject_registers_the_stone_soup_plugin(monkeypatch):
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"][
        "stonesoup.plugins"
    ]
    points = [
        importlib.metadata.EntryPoint(name, value, "stonesoup.plugins")
        for name, value in declared.items()
    ]
    monkeypatch.setattr(
        importlib.metadata,
        "entry_points",
        lambda group=None: [p for p in points if p.group == group],
    )
    names = ("stonesoup.plugins", "stonesoup.plugins.hptrack")
    saved = {name: sys.modules.pop(name) for name in names if name in sys.modules}
    try:
        plugin = importlib.import_module("stonesoup.plugins.hptrack")
        assert plugin.HptrackSensorManager is HptrackSensorManager
    finally:
        for name in names:
            sys.modules.pop(name, None)
        sys.modules.update(saved)


# --- closed loop ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location(
        "stonesoup_tracking", ROOT / "examples" / "stonesoup_tracking.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    del sys.modules[spec.name]


def test_hptrack_manager_keeps_tracks_tighter_than_hovering(example):
    setup = example.Setup(n_targets=4, steps=80, seed=0)
    flown, hover = example.compare(setup, "greedy", None)
    # measured: greedy 6.29, hover 14.41 log m^4; a manager that flies the wrong way measures
    # nothing and scores like the hover one
    assert flown.mean_logdet < hover.mean_logdet - 5.0
    assert flown.detections > 20 and hover.detections == 0
    assert 0.9 * 80 * 15.0 < flown.distance_m <= 80 * 15.0 + 1e-6  # at most v_a tau per step


def test_stationary_planner_scores_exactly_like_hovering(example):
    setup = example.Setup(n_targets=3, steps=30, seed=2, range_m=(0.0, 40.0))
    flown, hover = example.compare(setup, "stationary", None)
    assert hover.detections > 0
    np.testing.assert_array_equal(flown.logdets, hover.logdets)


def test_example_prints_the_comparison(example, capsys):
    example.main(["--planner", "mcts", "-o", "iterations=50", "--targets", "2", "--steps", "12"])
    out = capsys.readouterr().out
    assert "hptrack mcts" in out and "hover" in out and "hptrack - hover" in out


def test_hover_manager_returns_the_stay_action():
    platform = make_platform()
    configs = HoverSensorManager(platforms={platform}).choose_actions(set(), at(TAU))
    np.testing.assert_array_equal(target_xy(configs, platform), [0.0, 0.0])
