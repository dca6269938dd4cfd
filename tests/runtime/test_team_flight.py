"""A team in flight: the separation rule on toy geometry, the team's controller on the
simulated runner (per-vehicle legs, the separation kept on a head-on course, every reference
kept inside a fence, the replay with 0 mismatches) and the command line's refusals."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from hptrack.interface import CurrentPlan, InputError
from hptrack.models.measurement import kalman_update
from hptrack.models.miss_update import miss_update
from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog
from hptrack.runtime.replay import replay_log
from hptrack.runtime.simulated import SimulatedFaults, run_simulated
from hptrack.runtime.team import TeamController, pairwise_minimum, separate
from hptrack.runtime.worker import InlineRunner
from hptrack.scenario import load_scenario
from hptrack.scenario.io import file_data, parse_scenario

EXAMPLE = Path(__file__).resolve().parents[2] / "src" / "hptrack" / "examples" / "team-flight.yaml"


def _team(**changes):
    data = file_data(load_scenario(EXAMPLE))
    data.update(changes)
    return parse_scenario(data, "team")


def test_a_later_vehicle_yields_on_its_own_side_and_the_first_never_does():
    refs = np.array([[0.0, 0.0], [4.0, 0.0], [50.0, 0.0]])
    vels = np.full((3, 2), 8.0)
    out, v, yields = separate(refs, vels, refs, 10.0)
    assert out.tolist() == [[0.0, 0.0], [10.0, 0.0], [50.0, 0.0]]
    assert v.tolist() == [[8.0, 8.0], [0.0, 0.0], [8.0, 8.0]] and yields == [None, 0, None]
    # a way through the first vehicle's circle stops 10 m short, on the side it comes from
    here = np.array([[0.0, 0.0], [-20.0, 0.0]])
    out, _, yields = separate(np.array([[0.0, 0.0], [20.0, 0.0]]), np.zeros((2, 2)), here, 10.0)
    assert out.tolist() == [[0.0, 0.0], [-10.0, 0.0]] and yields == [None, 0]
    # on top of each other: sent east; nothing to do when apart
    out, _, _ = separate(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), 10.0)
    assert out.tolist() == [[0.0, 0.0], [10.0, 0.0]]
    assert pairwise_minimum(np.array([[0.0, 0.0], [3.0, 4.0], [30.0, 0.0]])) == 5.0


HEAD_ON = [
    {"position": [-40.0, 0.0], "speed": 8.0, "sensor_diameter": 20.0},
    {"position": [40.0, 0.0], "speed": 8.0, "sensor_diameter": 20.0},
]
"""Two UAVs 80 m apart on the x axis."""


class _Swap:
    """Each UAV flies to the other's start: a head-on course (a planner for the test)."""

    name = "swap"

    class settings:  # noqa: N801 - the planner protocol's attribute
        @staticmethod
        def as_json():
            return {}

    def reset(self, mission, observation, rng):
        self.goal = observation.agent_positions[::-1].copy()

    def act(self, observation):
        return self.goal

    def current_plan(self):
        return CurrentPlan()

    def episode_info(self):
        return {}


def test_a_head_on_team_keeps_the_separation_and_the_first_flies_straight():
    scenario = _team(
        agents=HEAD_ON,
        budget=15.0,
    )
    run = run_simulated(scenario, _Swap(), seed=1, separation_m=12.0)
    controller = run.controller
    records = controller.log.records
    ticks = [r for r in records if r["kind"] == "tick" and "separation_m" in r]
    assert len(ticks) == 30
    assert min(r["separation_m"] for r in ticks) == pytest.approx(12.0, abs=1e-9)
    assert controller.end["min_reference_separation_m"] == pytest.approx(12.0, abs=1e-9)
    yields = [(r["vehicle"], r["to"]) for r in records if r["kind"] == "yield"]
    assert yields == [(1, 0), (1, None)] and controller.end["yields"] == 1
    # vehicle 0 flies straight to its goal; vehicle 1, on the same line, is pushed back ahead
    # of it and ends 12 m beyond it
    path = run.record.agent_paths
    assert path.shape == (31, 2, 2) and np.all(path[:, :, 1] == 0.0)
    assert np.allclose(path[-1], [[40.0, 0.0], [52.0, 0.0]], rtol=0.0, atol=1e-9)


def test_a_fenced_team_sends_every_vehicle_s_reference_inside_the_fence():
    # a no-fly circle on the head-on course: neither vehicle's reference enters it (margin kept)
    scenario = _team(
        agents=HEAD_ON,
        budget=15.0,
        fence={"exclusions": [{"circle": [0.0, 3.0, 6.0]}], "margin": 2.0},
    )
    run = run_simulated(scenario, _Swap(), seed=1)
    records = run.controller.log.records
    fences = [r for r in records if r["kind"] == "fence"]
    assert {r["vehicle"] for r in fences} == {0, 1}
    outer = 8.0 / np.cos(np.pi / 32)  # the circle of radius 6 + 2 m is flown as a 32-gon
    for r in fences:  # projected onto it
        assert np.hypot(*(np.asarray(r["reference"]) - [0.0, 3.0])) < outer
        assert 8.0 - 1e-9 <= np.hypot(*(np.asarray(r["projected"]) - [0.0, 3.0])) <= outer
    assert run.controller.fence_projections == len(fences)
    assert run.controller.status()["fence"]["vehicle_free"] is True
    # the vehicles lag their references round the circle, inside the margin, never in the zone
    paths = run.record.agent_paths.reshape(-1, 2)
    assert 6.0 < np.hypot(*(paths - [0.0, 3.0]).T).min() < 8.0


class _Recorder(_Swap):
    """Holds every UAV where it is and keeps the observations (a planner for the test)."""

    name = "recorder"

    def reset(self, mission, observation, rng):
        self.observations = []

    def act(self, observation):
        self.observations.append(observation)
        return observation.agent_positions.copy()


def test_with_negative_information_a_tick_is_every_vehicle_s_look_in_turn():
    """Tick 0 from (20, 15) and (20, -15) m detects nothing: every target gets vehicle 0's miss
    update, then vehicle 1's. p2 is detected at 0.3 s, so at tick 1 it gets neither."""
    data = file_data(load_scenario(EXAMPLE))
    for agent in data["agents"]:
        agent.pop("sensor_diameter")
        agent.pop("measurement_noise_std")
    data["sensor"] = {
        "diameter": 20.0,
        "measurement_noise_std": 1.0,
        "detection_probability": 0.8,
        "negative_information": True,
    }
    scenario = parse_scenario(data, "team")
    planner = _Recorder()
    controller = TeamController(scenario, planner, runner=InlineRunner())
    here = np.array([[20.0, 15.0], [20.0, -15.0]])
    controller.prepare(here)
    controller.detection(0.3, "p2", [31.0, 15.0])
    for j in (0, 1):
        controller.odometry(0.5, here[j] + [1.0, 0.0], vehicle=j)
    controller.setpoint(0.5)
    first, second = planner.observations
    table = (np.zeros(1), np.array([0.8]))
    means, covs = scenario.means(), scenario.covariances()
    for i in range(4):
        for x, y in here:
            miss_update(means[i], covs[i], x, y, 10.0, *table)
    np.testing.assert_allclose(first.means, means, rtol=1e-12)
    np.testing.assert_allclose(first.covariances, covs, rtol=1e-12)
    # p2 on vehicle 0's rim, p3 on vehicle 1's: each miss pushed its belief away east
    assert np.all(means[1:3, 0] > scenario.means()[1:3, 0] + 0.5)
    motion, q = scenario.mission_spec().motion, scenario.process_noise()
    m, c = motion.predict(means, covs, q, np.array([0.5, 0.3, 0.5, 0.5]))
    kalman_update(m[1].copy(), c[1].copy(), np.array([31.0, 15.0]), np.eye(2), m[1], c[1])
    m[1], c[1] = (x[0] for x in motion.predict(m[1:2], c[1:2], q[1:2], 0.2))
    for i in (0, 2, 3):
        for x, y in here + [1.0, 0.0]:
            miss_update(m[i], c[i], x, y, 10.0, *table)
    np.testing.assert_allclose(second.means, m, rtol=1e-10)
    np.testing.assert_allclose(second.covariances, c, rtol=1e-10, atol=1e-12)
    controller.close()


def test_without_identity_each_vehicle_looks_at_its_own_reports_in_turn():
    """Reports of one tick from each vehicle's camera: each vehicle's look takes its own (two
    ``look`` records, vehicle 0 first), the report over the target under it goes to that
    belief, and the one far from every belief starts a tentative track that the tick's later
    look does not move. A team's report without its vehicle is refused."""
    scenario = _team(sensor={"labelled": False})
    planner = _Recorder()
    controller = TeamController(scenario, planner, runner=InlineRunner())
    here = np.array([[30.0, 15.0], [30.0, -15.0]])
    controller.prepare(here)
    assert controller.detection(0.4, None, [38.0, 15.0], vehicle=0) is True
    assert controller.detection(0.4, None, [30.1, -15.1], vehicle=1) is True
    assert controller.detection(0.4, None, [29.9, 15.2], vehicle=0) is True
    assert controller.detection(0.4, None, [29.0, 15.0]) is False
    assert controller.detection(0.4, None, [29.0, 15.0], vehicle=2) is False
    for j in (0, 1):
        controller.odometry(0.5, here[j], vehicle=j)
    controller.setpoint(0.5)
    looks = [r for r in controller.log.records if r["kind"] == "look" and r["k"] == 1]
    assert [r["vehicle"] for r in looks] == [0, 1]
    assert [(r["reports"], r["belief"]) for r in looks] == [([1, 3], [None, "p2"]), ([2], ["p3"])]
    rejected = {"detection: no vehicle": 1, "detection: unknown vehicle": 1}
    assert dict(controller.rejected) == rejected
    assert looks[0]["tentative"] == looks[1]["tentative"] == [[38.0, 15.0, 1, 1]]
    assert planner.observations[1].detected.tolist() == [False, True, True, False]
    controller.close()


@pytest.mark.parametrize("misses", [False, True])
def test_a_simulated_team_flight_replays_with_no_mismatch(tmp_path, misses):
    scenario = load_scenario(EXAMPLE).model_copy(update={"budget": 20.0})
    if misses:  # each vehicle's miss updates, made again on replay
        scenario = _team(budget=20.0, sensor={"negative_information": True})
    path = tmp_path / "team.jsonl"
    with MissionLog(path) as log:
        run = run_simulated(scenario, make_planner("team-greedy"), seed=2, log=log)
    end = run.controller.end
    assert end["reason"] == "budget" and end["separation_m"] == 10.0
    header = json.loads(path.read_text().splitlines()[0])
    assert header["separation_m"] == 10.0
    ticks = [r for r in run.controller.log.records if r["kind"] == "tick"]
    assert all(len(r["agent"]) == 2 for r in ticks if r["agent"] is not None)
    replayed = replay_log(path)
    assert replayed.summary["mismatches"] == 0, replayed.summary["first_mismatches"]
    assert replayed.summary["U"] == end["U"]
    assert replayed.summary["min_separation_m"] == end["min_separation_m"]
    assert replayed.record.agent_paths.shape == (41, 2, 2)
    assert np.array_equal(replayed.record.agent_paths, run.controller.episode_record().agent_paths)


def test_the_team_controller_refuses_what_it_cannot_fly_and_unknown_vehicles():
    team = load_scenario(EXAMPLE)
    planner = make_planner("team-greedy")
    data = file_data(team)
    data["agents"][1]["sensor_diameter"] = 30.0
    data["sensor"] = {"negative_information": True, "detection_probability": 0.8}
    with pytest.raises(InputError, match="negative_information with one footprint"):
        TeamController(parse_scenario(data, "team"), planner)
    with pytest.raises(InputError, match="--separation"):
        TeamController(team, planner, separation_m=-1.0)
    controller = TeamController(team, planner)
    assert not controller.odometry(0.0, [0.0, 0.0], vehicle=2)
    assert not controller.odometry(0.0, [0.0, 0.0], vehicle="0")
    assert controller.odometry(0.0, [0.0, 15.0], vehicle=0)
    assert controller.last_odometry is None  # every vehicle must report first
    assert controller.odometry(0.0, [0.0, -15.0], vehicle=1)
    assert controller.last_odometry[1].tolist() == [[0.0, 15.0], [0.0, -15.0]]
    assert not controller.odometry(0.1, [100.0, 15.0], vehicle=0)  # a jump of its own
    assert dict(controller.rejected) == {"odometry: unknown vehicle": 2, "odometry: jump": 1}
    controller.close()


def test_flight_commands_refuse_a_team_they_cannot_fly_in_one_line(flight_cli, tmp_path):
    path = tmp_path / "team.yaml"
    path.write_text(EXAMPLE.read_text())
    one = str(Path(__file__).resolve().parents[2] / "examples" / "paper-flight.yaml")
    flight_cli("fly", str(path), "--connection", "udpin://127.0.0.1:14540").refused(
        "--connection given 1 times", "2 UAVs"
    )
    flight_cli(
        "fly", str(path), "--connection", "udpin://127.0.0.1:14540", "--connection",
        "udpin://127.0.0.1:14540",
    ).refused("given twice")  # fmt: skip
    flight_cli("fly", str(path), "--planner", "mcts").refused("planner 'mcts' flies one UAV")
    flight_cli("fly", one, "--separation", "5").refused("--separation 5", "one UAV")
    flight_cli("vehicle-sim", str(path), "--instances", "3").refused("--instances 3", "2 UAVs")
    data = yaml.safe_load(EXAMPLE.read_text())
    data["agents"][1]["sensor_diameter"] = 30.0
    data["sensor"] = {"labelled": False}
    unlabelled = tmp_path / "unlabelled.yaml"
    unlabelled.write_text(yaml.safe_dump(data))
    flight_cli("targets-sim", str(unlabelled)).refused("labelled false", "same sensor_diameter")
    data = yaml.safe_load(EXAMPLE.read_text())
    data["agents"][1]["sensor_diameter"] = 30.0
    data["sensor"] = {"detection_probability": 0.8}
    misses = tmp_path / "misses.yaml"
    misses.write_text(yaml.safe_dump(data))
    flight_cli("vehicle-sim", str(misses)).refused("one footprint", "sensor_diameter")


def test_a_late_team_planner_is_replaced_by_team_greedy_and_replays(tmp_path):
    scenario = load_scenario(EXAMPLE).model_copy(update={"budget": 10.0})
    path = tmp_path / "late.jsonl"
    faults = SimulatedFaults(planner_slow_probability=0.5, planner_slow_delay_s=1.5)
    with MissionLog(path) as log:
        run = run_simulated(scenario, make_planner("team-greedy"), seed=3, faults=faults, log=log)
    fallbacks = [r for r in run.controller.log.records if r["kind"] == "fallback"]
    assert fallbacks and {r["planner"] for r in fallbacks} == {"team-greedy"}
    assert all(np.shape(r["waypoint"]) == (2, 2) for r in fallbacks)
    replayed = replay_log(path)
    assert replayed.summary["mismatches"] == 0, replayed.summary["first_mismatches"]
    assert replayed.summary["U"] == run.controller.end["U"]


def test_fly_searches_every_uav_as_it_searches_one():
    from hptrack.cli.flight import FLY_ITERATIONS, flight_planner_settings

    for planner in ("team-mcts", "team-cbba"):
        settings = flight_planner_settings(planner, None, None, None)
        assert settings.iterations == FLY_ITERATIONS and settings.readmit is True
    given = flight_planner_settings("team-mcts", ["readmit=false"], 50, None)
    assert given.iterations == 50 and given.readmit is False


def test_targets_sim_puts_another_vehicle_in_the_first_ones_frame_by_their_gps():
    from hptrack.runtime.frames import local_to_geodetic
    from hptrack.runtime.targets import _Telemetry, team_position

    origin = (47.397742, 8.545594)
    first = _Telemetry(np.array([5.0, 10.0, -20.0]), geodetic=local_to_geodetic(*origin, 5, 10))
    other = _Telemetry(geodetic=local_to_geodetic(*first.geodetic, 20.0, -30.0))
    assert np.allclose(team_position(first, other), [-20.0, 25.0], rtol=0.0, atol=1e-6)
    assert team_position(first, _Telemetry()) is None


def test_a_team_flies_one_fence_and_refuses_vehicles_whose_fences_differ(monkeypatch):
    pytest.importorskip("mavsdk")
    import asyncio

    from hptrack.runtime import team_flight

    spec = _team(fence={"exclusions": [{"circle": [0.0, 3.0, 6.0]}], "margin": 2.0}).fence.spec()
    shifted = spec._replace(circles=((0.0, 3.5, 6.0),))
    origins = []

    async def sync(member, system, fence, origin):  # what each vehicle holds
        origins.append(origin)
        return system

    class Member:
        def __init__(self, index):
            self.index = index

    monkeypatch.setattr(team_flight, "sync_fence", sync)
    members, origin = [Member(0), Member(1)], (47.0, 8.0)
    same = asyncio.run(team_flight._sync_fences(members, [spec, spec], spec, origin))
    assert same == spec and origins == [origin, origin]  # the first vehicle's origin for both
    assert asyncio.run(team_flight._sync_fences(members, [None, None], None, origin)) is None
    with pytest.raises(InputError, match=r"vehicle 1's fence differs from vehicle 0's: exclusion"):
        asyncio.run(team_flight._sync_fences(members, [spec, shifted], spec, origin))
