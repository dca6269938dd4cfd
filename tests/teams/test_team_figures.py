"""A team's mission figure, animation and record: one colour per UAV, every UAV drawn."""

import numpy as np

from hptrack.registry import make_planner
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.record import EpisodeRecord
from hptrack.viz.animation import animate_mission, subtask_at
from hptrack.viz.mission import mission_figure, vehicle_color


def team_record():
    scenario = random_scenario(3, 1, homogeneous=True, team=2, budget=60.0)
    return run_episode(scenario, make_planner("team-mcts", {"iterations": 100}))


def test_the_figure_draws_every_uav_in_its_colour(tmp_path):
    record = team_record()
    fig = mission_figure(record)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"UAV 1 path (shade: time)", "UAV 2 path (shade: time)", "UAV 2 end"} <= set(labels)
    ax = fig.axes[0]
    starts = [line for line in ax.lines if line.get_marker() == "^"]
    assert [line.get_color() for line in starts] == [vehicle_color(0), vehicle_color(1)]
    assert vehicle_color(0) != vehicle_color(1)


def test_the_record_keeps_the_team(tmp_path):
    record = team_record()
    record.save(tmp_path / "team.npz")
    back = EpisodeRecord.load(tmp_path / "team.npz")
    assert back.n_vehicles == 2
    assert np.array_equal(back.agent_paths, record.agent_paths)


def test_the_animation_labels_every_uav(tmp_path):
    record = team_record()
    labels, _ = subtask_at(record.info, record.target_ids, np.array([1, 100]))
    assert labels[1].startswith("UAV 1: ") and "; UAV 2: " in labels[1]
    assert animate_mission(record, tmp_path / "team.gif", stride=40) > 1
