"""Every figure kind, drawn as the commands draw it: no legend and no colour bar overlaps a
plot (the pieces of its tight box in the renderer: the frame, each axis with its tick labels
and label, the titles), each lies inside the figure, so do the plots with their labels and
titles, and a colour bar is no taller than its plot. A mission figure's legend lists only what
it draws."""

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PathCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse, Patch
from matplotlib.transforms import Bbox

from hptrack.experiments.store import EpisodeKey, EpisodeRow
from hptrack.learning.curves import plot_training_curve, save_training_curve
from hptrack.registry import make_planner
from hptrack.runtime.simulated import run_simulated
from hptrack.scenario import load_scenario, random_scenario
from hptrack.sim.episode import run_episode
from hptrack.viz import benchmark, coverage, mission
from hptrack.viz.benchmark import plot_trajectories
from hptrack.viz.mission import mission_figure, save_mission_figure

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "paper-flight.yaml"


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


def _overlaps(fig: Figure, draw: bool = True) -> list[str]:
    """What collides in ``fig`` once drawn, in words (empty: nothing); ``draw=False``: as its
    last draw left it (a saved figure as written)."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    if draw:
        fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    colorbars = _colorbars(fig)
    plots = [ax for ax in fig.axes if ax not in colorbars]
    legends = list(fig.legends) + [ax.get_legend() for ax in plots if ax.get_legend()]
    boxes = {f"legend {k}": leg.get_window_extent(renderer) for k, leg in enumerate(legends)}
    for k, cax in enumerate(colorbars):
        boxes[f"colour bar {k}"] = cax.get_tightbbox(renderer)
    for k, ax in enumerate(plots):  # with its labels, titles and inset colour bar
        boxes[f"plot {k} ({ax.get_title()!r}) with its labels"] = ax.get_tightbbox(renderer)
    if fig._suptitle is not None:
        boxes["figure title"] = fig._suptitle.get_window_extent(renderer)
    whole = fig.bbox
    found = []
    for name, box in boxes.items():
        if not (box.x0 >= whole.x0 - 1 and box.x1 <= whole.x1 + 1):
            found.append(f"{name} is cut off left or right")
        if not (box.y0 >= whole.y0 - 1 and box.y1 <= whole.y1 + 1):
            found.append(f"{name} is cut off at the top or bottom")
        for k, ax in enumerate(plots):
            if name.startswith(("plot", "figure")):
                continue
            if any(Bbox.intersection(box, part.padded(-1)) for part in _pieces(ax, renderer)):
                found.append(f"{name} overlaps plot {k} ({ax.get_title()!r})")
    for k, cax in enumerate(colorbars):
        bar = cax.get_window_extent(renderer)
        plot = cax._colorbar.mappable.axes.get_window_extent(renderer)
        if bar.height > plot.height + 1:
            found.append(f"colour bar {k} is taller than its plot")
    return found


def _finite(artist) -> bool:
    """Whether ``artist`` shows something: a finite point, segment or patch."""
    if isinstance(artist, Line2D):
        return bool(np.isfinite(np.asarray(artist.get_xydata(), dtype=float)).all(axis=1).any())
    if isinstance(artist, LineCollection):
        return any(np.isfinite(s).all() for s in artist.get_segments())
    if isinstance(artist, PathCollection):
        return bool(np.isfinite(artist.get_offsets()).all(axis=1).any())
    return True


def _colours(artist) -> set[tuple]:
    """The colours ``artist`` is drawn in (rgb, rounded; not the transparent ones)."""
    if isinstance(artist, Line2D):
        found = [artist.get_color(), artist.get_markerfacecolor(), artist.get_markeredgecolor()]
    elif isinstance(artist, Patch):
        found = [artist.get_edgecolor(), artist.get_facecolor()]
    else:
        found = [*artist.get_edgecolors(), *artist.get_facecolors()]
    rgba = [to_rgba(c) for c in found if not (isinstance(c, str) and c == "none")]
    return {tuple(np.round(c[:3], 3)) for c in rgba if c[3] > 0}


def _shown_by(key, drawn: list) -> bool:
    """Whether a legend key (the legend's own artist) stands for something in ``drawn``."""
    if isinstance(key, Line2D) and key.get_marker() not in ("None", "", None, " "):
        if key.get_markerfacecolor() == "none":  # a hollow mark: a scatter of rings, or a line
            return any(
                (isinstance(a, PathCollection) and len(a.get_facecolors()) == 0)
                or (
                    isinstance(a, Line2D)
                    and a.get_marker() == key.get_marker()
                    and a.get_markerfacecolor() == "none"
                )
                for a in drawn
            )
        return any(
            isinstance(a, Line2D)
            and a.get_marker() == key.get_marker()
            and a.get_markerfacecolor() != "none"
            for a in drawn
        )
    if isinstance(key, Line2D):
        return any(
            isinstance(a, Line2D)
            and a.get_linestyle() == key.get_linestyle()
            and _colours(key) <= _colours(a)
            for a in drawn
        )
    if isinstance(key, Ellipse):  # a belief ellipse's key: ellipses in its line style
        return any(
            isinstance(a, Ellipse) and a.get_linestyle() == key.get_linestyle() for a in drawn
        )
    if isinstance(key, LineCollection):  # the agent's time-shaded path
        return any(isinstance(a, LineCollection) and a.get_array() is not None for a in drawn)
    if isinstance(key, Patch):  # a colour swatch: something drawn in that colour
        return any(_colours(key) & _colours(a) for a in drawn)
    return any(type(a) is type(key) for a in drawn)


def _undrawn(fig: Figure) -> list[str]:
    """The legend entries of ``fig`` that stand for nothing its plots draw."""
    colorbars = _colorbars(fig)
    drawn = [
        a
        for ax in fig.axes
        if ax not in colorbars
        for a in (*ax.lines, *ax.collections, *ax.patches)
        if a.get_visible() and _finite(a)
    ]
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    return [
        text.get_text()
        for legend in legends
        for key, text in zip(legend.legend_handles, legend.get_texts(), strict=True)
        if not _shown_by(key, drawn)
    ]


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
    clipped = Figure(figsize=(4, 3))
    ax = clipped.add_axes((0.0, 0.1, 0.9, 0.8))
    ax.plot([0, 1], [0, 1000])
    ax.set_ylabel("y (m)")
    assert "plot 0 ('') with its labels is cut off left or right" in _overlaps(clipped)


def test_the_checker_sees_legend_entries_for_what_is_not_drawn():
    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1], color="C0", label="a line")
    ax.plot([np.nan], [np.nan], marker="s", ls="none", label="a square at NaN")
    proxies = [
        Line2D([], [], marker="o", ls="none", label="a start"),
        Ellipse((0, 0), 1, 1, fill=False, ls="--", label="an ellipse"),
        Patch(color="C2", label="a green swatch"),
    ]
    fig.legend(handles=[*ax.lines, *proxies])
    assert _undrawn(fig) == ["a square at NaN", "a start", "an ellipse", "a green swatch"]
    ax.plot([0.5], [0.5], marker="o", color="C2")
    assert _undrawn(fig) == ["a square at NaN", "an ellipse"]


@pytest.mark.parametrize("size", [None, (6.4, 6.4)])
def test_mission_figure(short_mission, size):
    _, record = short_mission
    width, height = size or (7.5, None)
    fig = mission_figure(record, width, height, dpi=100)
    assert _overlaps(fig) == []
    assert _undrawn(fig) == []
    (bar,) = _colorbars(fig)
    (plot,) = fig.axes
    renderer = fig.canvas.get_renderer()
    assert bar.get_window_extent(renderer).height == pytest.approx(
        plot.get_window_extent(renderer).height, abs=1.0
    )


def test_a_tall_mission_keeps_its_axis_and_colour_bar_labels(monkeypatch, tmp_path):
    # a map taller than wide: a first layout pass would push the y label and the colour
    # bar's label off the figure
    scenario = random_scenario(2, seed=2)
    record = run_episode(scenario, make_planner("stationary"), belief_stride=60)
    figures = _capture(monkeypatch, mission)
    save_mission_figure(record, str(tmp_path / "tall.png"))
    (fig,) = figures
    (ax,) = [a for a in fig.axes if a not in _colorbars(fig)]
    (y0, y1), (x0, x1) = ax.get_ylim(), ax.get_xlim()
    assert (y1 - y0) > 1.25 * (x1 - x0)
    assert fig.get_size_inches()[1] > 1.2 * fig.get_size_inches()[0]
    assert _overlaps(fig, draw=False) == []  # as written


def _flight_record():
    """What ``hptrack replay`` draws after a flight: the controller's mission without truth."""
    run = run_simulated(load_scenario(EXAMPLE), make_planner("greedy"))
    return run.controller.episode_record()


def test_the_flight_figure_shows_the_detections_and_lists_only_what_it_draws(monkeypatch, tmp_path):
    record = _flight_record()
    assert np.isnan(record.true_states).all() and record.detections.sum() > 20
    figures = _capture(monkeypatch, mission)
    save_mission_figure(record, str(tmp_path / "flight.png"))
    (fig,) = figures
    assert _overlaps(fig, draw=False) == []
    assert _undrawn(fig) == []
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "target start" not in labels and "target end" not in labels
    assert "target measured (belief mean)" in labels and "agent path (shade: time)" in labels
    (ax,) = [a for a in fig.axes if a not in _colorbars(fig)]
    rings = [c for c in ax.collections if isinstance(c, PathCollection)]
    assert len(rings) == len(record.target_ids)  # one scatter of measurements per target
    stored = {int(k): j for j, k in enumerate(record.belief_steps)}
    for i, ring in enumerate(rings):
        ticks = [k for k in np.flatnonzero(record.detections[:, i]) if k in stored]
        assert len(ticks) > 5
        # each measurement at the belief's mean of its tick
        np.testing.assert_allclose(
            ring.get_offsets(), [record.belief_means[stored[k], i, :2] for k in ticks]
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
    later = type(record)(**{**record.__dict__, "agent_paths": record.agent_paths + 300.0})
    fig = Figure(figsize=(13, 7))
    plot_trajectories(fig, [record, later])
    assert _overlaps(fig) == []
    assert _undrawn(fig) == []


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
        assert _overlaps(fig, draw=False) == []
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
    assert _overlaps(fig, draw=False) == []
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
    assert _overlaps(fig, draw=False) == []
    assert fig.axes[0].get_title() == (
        "PPO (stable-baselines3), n = 3 targets, heterogeneous setting, 4 validation scenarios"
    )
    assert len(fig.legends) == 1 and fig.axes[0].get_legend() is None
    artists = plot_training_curve(Figure().add_subplot(), curve)
    assert set(artists) == {"zero", "episodes", "running", "validation"}
