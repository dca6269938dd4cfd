import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.baselines.stationary import StationaryPlanner
from hptrack.models.beliefs import position_logdet
from hptrack.models.vehicle import move_towards
from hptrack.scenario import AgentSpec, Scenario, TargetSpec, random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.record import EpisodeRecord

COV = (
    (900.0, 100.0, 0.0, 0.0),
    (100.0, 800.0, 0.0, 0.0),
    (0.0, 0.0, 0.3, 0.0),
    (0.0, 0.0, 0.0, 0.4),
)


def far_scenario(form="continuous"):
    targets = [
        TargetSpec(
            id=f"t{i}",
            mean=(5000.0 + 1000 * i, 0.0, 1.0, 0.5),
            covariance=COV,
            process_noise=2e-4 * (i + 1),
        )
        for i in range(3)
    ]
    return Scenario(seed=3, targets=targets, process_noise_form=form, budget=300.0)


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_unseen_targets_score_exactly_the_closed_form(form):
    scenario = far_scenario(form)
    record = run_episode(scenario, StationaryPlanner())
    assert not record.detections.any()
    motion = scenario.motion_model()
    mission = scenario.mission_spec()
    _, covs = motion.predict(
        scenario.means(),
        scenario.covariances(),
        scenario.process_noise(),
        mission.n_steps * mission.time_step,
    )
    np.testing.assert_allclose(record.per_target_logdet, position_logdet(covs), rtol=1e-10)
    assert record.uncertainty == pytest.approx(position_logdet(covs).sum(), rel=1e-10)


def test_detections_happen_exactly_within_half_the_footprint():
    scenario = random_scenario(4, seed=2)
    record = run_episode(scenario, GreedyPlanner())
    distance = np.linalg.norm(record.true_states[:, :, :2] - record.agent_path[:, None, :], axis=2)
    np.testing.assert_array_equal(record.detections, distance <= 50.0)
    assert record.detections.any()


def test_measured_targets_shrink_and_unmeasured_grow():
    record = run_episode(random_scenario(3, seed=4), GreedyPlanner())
    logdet = position_logdet(record.belief_covariances)
    grew = np.diff(logdet, axis=0) > 0
    measured = record.detections[1:]
    assert np.all(grew[~measured])
    first = np.argmax(measured, axis=0)
    for i, k in enumerate(first):
        if measured[k, i] and not record.detections[k, i]:
            assert not grew[k, i]


def test_same_seed_same_result_and_other_seed_differs():
    scenario = random_scenario(3, seed=8)
    a = run_episode(scenario, GreedyPlanner())
    b = run_episode(scenario, GreedyPlanner())
    c = run_episode(scenario, GreedyPlanner(), seed=9)
    np.testing.assert_array_equal(a.agent_path, b.agent_path)
    np.testing.assert_array_equal(a.true_states, b.true_states)
    assert a.uncertainty == b.uncertainty
    assert not np.array_equal(a.true_states, c.true_states)


def test_given_truth_is_used():
    scenario = far_scenario()
    record = run_episode(
        scenario.model_copy(
            update={
                "targets": [
                    t.model_copy(update={"truth": (1.0, 2.0, 0.0, 0.0)}) for t in scenario.targets
                ]
            }
        ),
        StationaryPlanner(),
    )
    np.testing.assert_array_equal(record.true_states[0, :, :2], [[1.0, 2.0]] * 3)


def test_agent_moves_at_most_speed_times_step():
    record = run_episode(random_scenario(2, seed=1), GreedyPlanner())
    steps = np.linalg.norm(np.diff(record.agent_path, axis=0), axis=1)
    assert steps.max() == pytest.approx(15.0, rel=1e-12)
    np.testing.assert_allclose(move_towards(np.zeros(2), np.array([3.0, 4.0]), 15.0), [3, 4])
    np.testing.assert_allclose(move_towards(np.zeros(2), np.array([30.0, 40.0]), 15.0), [9, 12])


def test_record_round_trip(tmp_path):
    record = run_episode(random_scenario(2, seed=6), GreedyPlanner(), belief_stride=50)
    assert record.belief_steps[-1] == 1800 and len(record.belief_steps) == 37
    record.save(tmp_path / "r.npz")
    loaded = EpisodeRecord.load(tmp_path / "r.npz")
    assert loaded.summary() == record.summary()
    np.testing.assert_array_equal(loaded.belief_covariances, record.belief_covariances)
    np.testing.assert_array_equal(loaded.detections, record.detections)
    assert loaded.agent_paths.shape == (1801, 1, 2) and loaded.n_vehicles == 1
    np.testing.assert_array_equal(loaded.agent_path, record.agent_paths[:, 0])


def test_a_record_an_older_hptrack_saved_still_loads(tmp_path):
    """Older files hold one vehicle's ``agent_path`` (K+1, 2) and sub-tasks in older shapes."""
    record = run_episode(random_scenario(2, seed=6), GreedyPlanner(), belief_stride=600)
    record.info = {"subtasks": [{"target_index": 1, "start_step": 0, "plan_after_find": 0}]}
    record.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        arrays = {k: data[k] for k in data.files}
    arrays["agent_path"] = arrays.pop("agent_paths")[:, 0]
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    old = EpisodeRecord.load(tmp_path / "old.npz")
    np.testing.assert_array_equal(old.agent_paths, record.agent_paths)
    assert old.summary()["info"]["subtasks"] == [
        {
            "kind": "pursue",
            "target": "t2",
            "start_step": 0,
            "plan_after_find": {"kind": "pursue", "target": "t1"},
        }
    ]


def test_greedy_beats_stationary_on_average():
    u = {p: [] for p in ("greedy", "stationary")}
    for seed in range(6):
        scenario = random_scenario(3, seed=seed, budget=300.0)
        u["greedy"].append(run_episode(scenario, GreedyPlanner()).uncertainty)
        u["stationary"].append(run_episode(scenario, StationaryPlanner()).uncertainty)
    assert np.mean(u["greedy"]) < np.mean(u["stationary"]) - 5.0


def test_invalid_waypoint_is_reported():
    class Broken(StationaryPlanner):
        name = "broken"

        def act(self, observation):
            return np.array([np.nan, 0.0])

    with pytest.raises(ValueError, match="broken"):
        run_episode(far_scenario(), Broken())


def test_observation_is_read_only_and_has_no_truth():
    seen = []

    class Spy(StationaryPlanner):
        def act(self, observation):
            seen.append(observation)
            return super().act(observation)

    run_episode(
        Scenario(budget=2.0, targets=far_scenario().targets, agent=AgentSpec(position=(1.0, 1.0))),
        Spy(),
    )
    obs = seen[0]
    assert not hasattr(obs, "true_states")
    with pytest.raises(ValueError):
        obs.means[0, 0] = 1.0
    assert obs.remaining_budget == 2.0 and obs.time == 0.0


def test_the_planners_episode_info_is_stored_with_the_record():
    class Counting(StationaryPlanner):
        name = "counting"

        def reset(self, mission, observation, rng):
            super().reset(mission, observation, rng)
            self.calls = 0

        def act(self, observation):
            self.calls += 1
            return super().act(observation)

        def episode_info(self):
            return {"acts": self.calls, **super().episode_info()}

    record = run_episode(Scenario(budget=5.0, targets=far_scenario().targets), Counting())
    assert record.planner == "counting"
    assert record.info["acts"] == 10  # one waypoint per step of the 5 s budget
    assert record.info["settings"] == {}


def test_the_json_summary_names_targets_by_id_in_the_subtask_log():
    """The summary writes the one sub-task shape with targets by id, from the records
    planners write and from the shapes older hptrack wrote (a planned index ``n``: a dwell)."""
    from hptrack.sim.record import subtasks_with_ids
    from hptrack.subtasks import Subtask, SubtaskAction

    older = [
        {"target_index": 1, "start_step": 0, "plan_after_find": 2, "plan_after_miss": None},
        {"dwell": 1, "start_step": 9, "dwell_steps": 4, "plan_after_dwell": 0, "end_step": 13},
        {"follow": 0, "start_step": 20},
        {"follow": None, "start_step": 30},
    ]
    named = [
        {
            "kind": "pursue",
            "target": "b",
            "start_step": 0,
            "plan_after_find": {"kind": "dwell", "target": "b"},
        },
        {
            "kind": "dwell",
            "target": "b",
            "start_step": 9,
            "parameter": 4,
            "end_step": 13,
            "plan_after_find": {"kind": "pursue", "target": "a"},
        },
        {"kind": "follow", "target": "a", "start_step": 20},
        {"kind": "hover", "target": None, "start_step": 30},
    ]
    assert subtasks_with_ids(older, ("a", "b")) == named
    records = [
        Subtask("pursue", 1, 0, p_find=0.5, after_find=SubtaskAction("dwell", 1, 4)),
        Subtask("dwell", 1, 9, 4, end_step=13, after_find=SubtaskAction("pursue", 0)),
    ]
    as_json = [r.to_json() for r in records]
    assert as_json[0]["target"] == 1 and as_json[0]["plan_after_find"]["parameter"] == 4
    assert subtasks_with_ids(as_json, ("a", "b"))[1] == named[1]
    assert [Subtask.from_json(e, ("a", "b")) for e in subtasks_with_ids(as_json, ("a", "b"))] == (
        records
    )
