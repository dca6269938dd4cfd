"""Every figure kind, drawn as the commands draw it: no legend and no colour bar overlaps a
plot (the pieces of its tight box in the renderer: the frame, each axis with its tick labels
and label, the titles), each lies inside the figure, and a colour bar is no taller than its
plot."""

import json

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from hptrack.experiments.store import EpisodeKey, EpisodeRow
from hptrack.learning.curves import plot_training_curve, save_training_curve
from hptrack.viz import benchmark, coverage
from hptrack.viz.benchmark import plot_trajectories
from hptrack.viz.mission import mission_figure


def _capture(monkeypatch, module, name="save_figure") -> list[Figure]:
    """Keep the figures that ``module`` saves (and still write them)."""
    figures = []
    original = getattr(module, name)

    def keep(fig, path, *args, **kwargs):
        figures.append(fig)
        return original(fig, path, *args, **kwargs)

    monkeypatch.setattr(module, name, keep)
    return figures


def _colorbars(fig: Figure) -> list:
    """Every colour bar's axes: figure-level ones and those inset beside a plot."""
    every = [c for ax in fig.axes for c in (ax, *ax.child_axes)]
    return [c for c in every if hasattr(c, "_colorbar")]


def _pieces(ax, renderer) -> list[Bbox]:
    """The boxes whose union is ``ax``'s own tight box: frame, axes with ticks, titles."""
    pieces = [ax.get_window_extent(renderer)]
    pieces += [axis.get_tightbbox(renderer) for axis in (ax.xaxis, ax.yaxis)]
    titles = (ax.title, ax._left_title, ax._right_title)
    pieces += [t.get_window_extent(renderer) for t in titles if t.get_text()]
    return [p for p in pieces if p is not None and p.width > 0 and p.height > 0]


def _overlaps(fig: Figure) -> list[str]:
    """What collides in ``fig`` once drawn, in words (empty: nothing)."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    colorbars = _colorbars(fig)
    plots = [ax for ax in fig.axes if ax not in colorbars]
    legends = list(fig.legends) + [ax.get_legend() for ax in plots if ax.get_legend()]
    boxes = {f"legend {k}": leg.get_window_extent(renderer) for k, leg in enumerate(legends)}
    for k, cax in enumerate(colorbars):
        boxes[f"colour bar {k}"] = cax.get_tightbbox(renderer)
    whole = fig.bbox
    found = []
    for name, box in boxes.items():
        if not (box.x0 >= whole.x0 - 1 and box.x1 <= whole.x1 + 1):
            found.append(f"{name} is cut off left or right")
        if not (box.y0 >= whole.y0 - 1 and box.y1 <= whole.y1 + 1):
            found.append(f"{name} is cut off at the top or bottom")
        for k, ax in enumerate(plots):
            if any(Bbox.intersection(box, part.padded(-1)) for part in _pieces(ax, renderer)):
                found.append(f"{name} overlaps plot {k} ({ax.get_title()!r})")
    for k, cax in enumerate(colorbars):
        bar = cax.get_window_extent(renderer)
        plot = cax._colorbar.mappable.axes.get_window_extent(renderer)
        if bar.height > plot.height + 1:
            found.append(f"colour bar {k} is taller than its plot")
    return found


def test_the_checker_sees_a_legend_over_an_axis_label_and_a_tall_colour_bar():
    fig = Figure(figsize=(4, 3))
    ax = fig.add_subplot()
    (line,) = ax.plot([0, 1], [0, 1], label="a line")
    ax.set_xlabel("x (m)")
    ax.legend(handles=[line], loc="upper center", bbox_to_anchor=(0.5, -0.02))
    assert any("legend 0 overlaps plot 0" in f for f in _overlaps(fig))
    wide = Figure(figsize=(5, 5))
    ax = wide.add_subplot()
    ax.set_aspect("equal")
    points = ax.scatter([0, 4], [0, 1], c=[0, 1])
    wide.colorbar(points, ax=ax, shrink=0.8)
    assert "colour bar 0 is taller than its plot" in _overlaps(wide)


@pytest.mark.parametrize("size", [None, (6.4, 6.4)])
def test_mission_figure(short_mission, size):
    _, record = short_mission
    width, height = size or (7.5, None)
    fig = mission_figure(record, width, height, dpi=100)
    assert _overlaps(fig) == []
    (bar,) = _colorbars(fig)
    (plot,) = fig.axes
    renderer = fig.canvas.get_renderer()
    assert bar.get_window_extent(renderer).height == pytest.approx(
        plot.get_window_extent(renderer).height, abs=1.0
    )


def test_env_render_and_flight_figure_use_the_mission_figure(short_mission, tmp_path):
    import gymnasium as gym

    import hptrack.envs  # noqa: F401 (registers the envs)

    env = gym.make("hptrack/Tracking-v0", n_targets=2, render_mode="rgb_array")
    env.reset(seed=4)
    for _ in range(30):
        env.step(0)
    frame = env.render()
    assert frame.shape == (640, 640, 3)
    fig = mission_figure(env.unwrapped.episode_record(), 6.4, 6.4, dpi=100)
    assert _overlaps(fig) == []


def test_trajectories(short_mission):
    _, record = short_mission
    later = type(record)(**{**record.__dict__, "agent_path": record.agent_path + 300.0})
    fig = Figure(figsize=(13, 7))
    plot_trajectories(fig, [record, later])
    assert _overlaps(fig) == []


def test_coverage_figures(monkeypatch, tmp_path):
    figures = _capture(monkeypatch, coverage)
    rng = np.random.default_rng(0)
    cdf = 1.0 - np.exp(-np.arange(60) / 15.0)
    times = np.where(rng.random(200) < 0.9, rng.exponential(8.0, 200), np.nan)
    panel = {"estimated_cdf": cdf, "detection_times": times, "time_step": 0.5}
    coverage.save_cdf_figure({"0": panel, "100": panel}, str(tmp_path / "c.png"), title="case 0")
    path = np.column_stack([np.linspace(0, 300, 80), np.linspace(0, -200, 80)])
    cov = np.diag([900.0, 400.0])
    coverage.save_plan_figure(
        str(tmp_path / "p.png"), path, 20, path[20], cov, path[-1], 4 * cov, cdf, 0.5, title="t"
    )
    assert len(figures) == 2
    for fig in figures:
        assert _overlaps(fig) == []
    cdf_axes = figures[0].axes
    # p_find is the estimate at t_cutoff (29.5 s); the simulation's share found by then
    found = np.mean(times <= 59 * 0.5)
    assert cdf_axes[0].get_title() == (
        f"$t_d$ = 0 s\n$p_{{find}}$ = {cdf[-1]:.3f} (simulated {found:.3f})"
    )
    labels = [t.get_text() for t in figures[0].legends[0].get_texts()]
    assert labels == ["simulation (200 runs)", "estimate $P_{cdf}$", "$t_{cutoff}$"]
    cutoff = [line for line in cdf_axes[0].lines if line.get_linestyle() == ":"]
    assert cutoff[0].get_xdata()[0] == pytest.approx(59 * 0.5)


def _rows() -> list[EpisodeRow]:
    return [
        EpisodeRow(EpisodeKey(p, n, s, "homogeneous", "{}"), u + s, 51.0, 0, 1.0, {})
        for p, u in (("stationary", 50.0), ("mcts", 10.0), ("arvi", 30.0))
        for n in (2, 3)
        for s in range(5)
    ]


def test_benchmark_boxes_keep_the_planner_order(monkeypatch, tmp_path):
    figures = _capture(monkeypatch, benchmark)
    benchmark.save_uncertainty_boxes(_rows(), tmp_path / "b.png", ("mcts", "arvi"), "title")
    (fig,) = figures
    assert _overlaps(fig) == []
    for ax in fig.axes:
        # the order asked, then the others in the order of the rows
        assert [t.get_text() for t in ax.get_xticklabels()] == ["mcts", "arvi", "stationary"]
    assert [ax.get_title() for ax in fig.axes] == [
        "n = 2 targets, 5 scenarios",
        "n = 3 targets, 5 scenarios",
    ]


def test_learning_curve(monkeypatch, tmp_path):
    from hptrack.learning import curves

    figures = _capture(monkeypatch, curves)
    curve = [
        {"kind": "episode", "step": 100 * (k + 1), "U": 50.0 - k, "never_observed_U": 51.0}
        for k in range(12)
    ] + [{"kind": "validation", "step": 0, "mean_delta_U": 0.5, "sem_delta_U": 0.1}]
    (tmp_path / "curve.json").write_text(json.dumps(curve))
    config = {"task": {"n_targets": 3, "setting": "heterogeneous", "validation_scenarios": 4}}
    (tmp_path / "config.json").write_text(json.dumps({**config, "train": {"algorithm": "PPO"}}))
    save_training_curve(tmp_path, tmp_path / "c.png")
    (fig,) = figures
    assert _overlaps(fig) == []
    assert fig.axes[0].get_title() == (
        "PPO (stable-baselines3), n = 3 targets, heterogeneous setting, 4 validation scenarios"
    )
    assert len(fig.legends) == 1 and fig.axes[0].get_legend() is None
    artists = plot_training_curve(Figure().add_subplot(), curve)
    assert set(artists) == {"zero", "episodes", "running", "validation"}
