"""Static mission figures: ellipse geometry, colours that keep the agent apart from the targets,
the legend, and the side-by-side trajectory figure."""

import numpy as np
import pytest
from matplotlib.colors import rgb_to_hsv
from matplotlib.figure import Figure

from hptrack.viz.benchmark import plot_trajectories
from hptrack.viz.mission import (
    AGENT_TIME_CMAP,
    CONFIDENCE_SCALE_95,
    TARGET_COLORS,
    covariance_ellipse,
    ellipse_axes,
    plot_mission,
    save_mission_figure,
)


def test_95_percent_scale_holds_95_percent_of_a_gaussian():
    # P(chi^2_2 <= s^2) = 1 - exp(-s^2 / 2)
    assert 1.0 - np.exp(-(CONFIDENCE_SCALE_95**2) / 2.0) == pytest.approx(0.95)


def test_ellipse_axes_of_a_rotated_covariance():
    angle = np.radians(30.0)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cov = rot @ np.diag([9.0, 1.0]) @ rot.T
    width, height, degrees = ellipse_axes(np.stack([cov, np.diag([1.0, 4.0])]), scale=2.0)
    np.testing.assert_allclose(width, [12.0, 8.0])
    np.testing.assert_allclose(height, [4.0, 4.0])
    np.testing.assert_allclose(np.mod(degrees, 180.0), [30.0, 90.0], atol=1e-9)
    patch = covariance_ellipse(np.array([5.0, -2.0]), cov)
    assert patch.center == (5.0, -2.0)
    assert patch.width == pytest.approx(2.0 * CONFIDENCE_SCALE_95 * 3.0)


def test_agent_time_colours_cannot_be_taken_for_a_target():
    agent = AGENT_TIME_CMAP(np.linspace(0.0, 1.0, 50))[:, :3]
    targets = np.array(TARGET_COLORS)
    assert np.all(rgb_to_hsv(agent)[:, 1] < 1e-9)  # greys only
    assert np.all(rgb_to_hsv(targets)[:, 1] > 0.3)  # every target colour is saturated
    assert len(set(TARGET_COLORS)) == len(TARGET_COLORS) == 9


def test_mission_figure_says_what_it_shows(short_mission, tmp_path):
    _, record = short_mission
    fig = Figure()
    ax = fig.add_subplot()
    artists = plot_mission(ax, record)
    labels = [t.get_text() for t in artists["legend"].get_texts()]
    assert labels == [
        *record.target_ids,
        "95 % belief, t = 0 s",
        "95 % belief, t = 20 s",
        "95 % belief, t = 40 s",
        "95 % belief, t = 60 s",
        "agent path (shade: time)",
        "agent start",
        "agent end",
        "target start",
        "target end",
        "target measured",
    ]
    assert ax.get_title() == (
        "greedy, n = 2 targets, seed 1, 60 s\n"
        f"U = {record.uncertainty:.2f} (Σ log det Σxy, Σxy in m²)"
    )
    assert ax.get_aspect() == 1.0
    # one line style per time, the same for every target at that time
    styles = [e.get_linestyle() for e in artists["ellipses"]]
    assert styles == [s for s in (":", "-.", "--", "-") for _ in record.target_ids]
    measured = np.flatnonzero(record.detections.any(axis=0))
    assert len(artists["detections"]) == measured.size
    for scatter, i in zip(artists["detections"], measured, strict=True):
        np.testing.assert_allclose(
            scatter.get_offsets(), record.true_states[record.detections[:, i], i, :2]
        )
    # the targets are drawn over the agent's path; the agent's end diamond is hollow
    assert min(line.get_zorder() for line in artists["targets"]) > artists["agent"].get_zorder()
    end = [line for line in ax.lines if line.get_marker() == "D"]
    assert len(end) == 1 and end[0].get_markerfacecolor() == "none"
    path = tmp_path / "mission.png"
    save_mission_figure(record, str(path))
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_trajectories_share_limits_and_one_time_colour_bar(short_mission, tmp_path):
    _, record = short_mission
    later = type(record)(**{**record.__dict__, "agent_paths": record.agent_paths + 500.0})
    fig = Figure(figsize=(10, 5))
    plot_trajectories(fig, [record, later], ["first", "second"])
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["first", "second"]
    assert len(fig.axes) == 2  # two panels, and one colour bar beside the last
    assert [len(ax.child_axes) for ax in fig.axes] == [0, 1]
    assert panels[0].get_xlim() == panels[1].get_xlim()
    assert panels[0].get_ylim() == panels[1].get_ylim()
    assert all(ax.get_aspect() == 1.0 for ax in panels)
    assert panels[1].get_xlim()[1] >= later.agent_path[:, 0].max()
    assert len(fig.legends) == 1
    fig.savefig(tmp_path / "trajectories.png", dpi=60)
    with pytest.raises(ValueError, match="one title per record"):
        plot_trajectories(Figure(), [record], ["a", "b"])
