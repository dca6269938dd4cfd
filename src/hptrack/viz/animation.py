"""Animated mission: the agent and its recent trail, the true targets, each belief's 95 %
ellipse, a fading ring on every detection, the current sub-task and the mission time.

Frames are drawn with `matplotlib.animation.FuncAnimation` on a
`matplotlib.figure.Figure` (no pyplot state) and written as a GIF with Pillow, or as an
MP4 when ffmpeg is installed. One frame every ``stride`` steps, plus the last step.
"""

from __future__ import annotations

import bisect
import logging
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter, writers
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Ellipse

from hptrack.interface import InputError
from hptrack.models.beliefs import position_logdet
from hptrack.sim.record import EpisodeRecord
from hptrack.subtasks import read_subtasks
from hptrack.viz.fence import draw_fence
from hptrack.viz.mission import ellipse_axes, target_color, vehicle_color

log = logging.getLogger(__name__)

FLASH_FRAMES = 4
"""Frames over which a detection ring fades out."""

RING_POINTS = 12.0
"""Diameter of a fresh detection ring, points (it widens as it fades)."""

TARGET_COLUMNS = 8
FORMATS = (".gif", ".mp4")


_LEFT_IN, _RIGHT_IN, _TOP_IN = 0.75, 0.3, 0.3  # map margins, inches
_XLABEL_IN, _ELEMENTS_IN, _TARGETS_TITLE_IN, _TARGET_ROW_IN = 0.5, 0.45, 0.25, 0.2


def frame_size_in(width_in: float, n_targets: int) -> tuple[float, float]:
    """Frame width and height, inches: a square map of ``width_in`` less its side margins,
    above it the title, below it the axis label and the legends (one target row per eight)."""
    legends = _ELEMENTS_IN + _TARGETS_TITLE_IN + _TARGET_ROW_IN * -(-n_targets // TARGET_COLUMNS)
    height = _TOP_IN + (width_in - _LEFT_IN - _RIGHT_IN) + _XLABEL_IN + legends
    return width_in, round(height, 2)


def frame_steps(n_steps: int, stride: int) -> np.ndarray:
    """Steps drawn: ``0, stride, 2 stride, ...`` and the last step ``n_steps``."""
    return np.unique(np.append(np.arange(0, n_steps + 1, stride), n_steps))


def stored_belief_index(belief_steps: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Index of the stored belief at or before each step (beliefs are stored from step 0)."""
    return np.maximum(np.searchsorted(belief_steps, steps, side="right") - 1, 0)


def detection_flash(
    detections: np.ndarray, steps: np.ndarray, flash_frames: int = FLASH_FRAMES
) -> np.ndarray:
    """Ring strength ``(frames, n)`` in ``[0, 1]``: 1 in a frame whose steps (after the previous
    frame's step, up to its own) hold a detection of the target, then fading linearly to 0 over
    ``flash_frames`` frames."""
    seen = np.cumsum(detections, axis=0)
    upto = seen[steps]
    before = np.vstack([np.zeros((1, detections.shape[1]), dtype=seen.dtype), upto[:-1]])
    frames = np.arange(len(steps))[:, None]
    last = np.maximum.accumulate(np.where(upto > before, frames, -flash_frames), axis=0)
    return np.clip(1.0 - (frames - last) / flash_frames, 0.0, 1.0)


def subtask_at(
    info: dict, target_ids: Sequence[str], steps: np.ndarray
) -> tuple[list[str], np.ndarray]:
    """What the planner was doing at each step, from its sub-task log (``info["subtasks"]``;
    a team's, from every UAV's, ``info["members"]``, labelled ``UAV 1: ...; UAV 2: ...``).

    Returns a label per step (``"pursuing t2"``, ``"following t1"``, ``"dwelling on t1"``,
    ``"hover"``, or ``""`` without a log) and the index of the target in focus (``-1`` for
    none; a team's: the first UAV's).
    """
    if "members" in info:
        each = [subtask_at(member, target_ids, steps) for member in info["members"]]
        labels = [
            "; ".join(f"UAV {v + 1}: {m[0][f]}" for v, m in enumerate(each) if m[0][f])
            for f in range(len(steps))
        ]
        return labels, each[0][1]
    entries = read_subtasks(info.get("subtasks") or [], target_ids)
    starts = [e.start_step for e in entries]
    labels, focus = [], np.full(len(steps), -1, dtype=np.int64)
    for f, step in enumerate(steps):
        j = bisect.bisect_right(starts, int(step)) - 1
        if j < 0:
            labels.append("")
            continue
        entry = entries[j]
        if entry.target is None:
            labels.append("hover")
            continue
        focus[f] = entry.target
        tid = target_ids[entry.target]
        if entry.kind == "pursue":
            ended = entry.end_step is not None and step >= entry.end_step
            labels.append(
                f"pursued {tid}: {entry.outcome or 'ended'}" if ended else f"pursuing {tid}"
            )
        elif entry.kind == "follow":
            labels.append(f"following {tid}")
        else:
            labels.append(f"dwelling on {tid}")
    return labels, focus


def _view_limits(record: EpisodeRecord) -> tuple[tuple[float, float], tuple[float, float]]:
    """Square view around the agent, the truth and the belief means, with a footprint margin."""
    points = np.concatenate(
        [
            record.agent_paths.reshape(-1, 2),
            record.true_states[..., :2].reshape(-1, 2),
            record.belief_means[..., :2].reshape(-1, 2),
        ]
    )
    low, high = points.min(axis=0), points.max(axis=0)
    half = 0.5 * float(np.max(high - low)) + record.sensor_diameter
    center = 0.5 * (low + high)
    return (center[0] - half, center[0] + half), (center[1] - half, center[1] + half)


def check_format(path: Path, option: str = "output") -> None:
    """Refuse an output whose suffix is not a known format, or an MP4 without ffmpeg."""
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise InputError(
            f"{option} {str(path)!r}: unknown animation format "
            f"{path.suffix or '(none)'!r}; use one of {', '.join(FORMATS)}"
        )
    if suffix == ".mp4" and not writers.is_available("ffmpeg"):
        raise InputError(
            f"{option} {str(path)!r}: ffmpeg is not installed, so MP4 cannot be "
            f"written; use a .gif file"
        )


class GifWriter(PillowWriter):
    """matplotlib's Pillow GIF writer that reports ``encoding(done, total)`` as Pillow converts
    each frame to a palette image (most of the encoding's time; the file is written after
    the last). An MP4 needs no such report: ffmpeg encodes each frame as it is grabbed."""

    def __init__(self, fps: int, encoding: Callable[[int, int], None] | None = None) -> None:
        super().__init__(fps=fps)
        self.encoding = encoding

    def finish(self) -> None:
        frames = self._frames  # matplotlib's grabbed frames (PillowWriter.setup)
        report = self.encoding or (lambda _done, _total: None)

        def counted():
            for done, frame in enumerate(frames[1:], start=1):
                report(done, len(frames))
                yield frame
            report(len(frames), len(frames))

        frames[0].save(
            self.outfile,
            save_all=True,
            append_images=counted(),
            duration=int(1000 / self.fps),
            loop=0,
        )


def _writer(path: Path, fps: int, encoding: Callable[[int, int], None] | None):
    check_format(path)
    if path.suffix.lower() == ".gif":
        return GifWriter(fps, encoding)
    return FFMpegWriter(fps=fps)


def animate_mission(
    record: EpisodeRecord,
    path: str | Path,
    stride: int = 5,
    fps: int = 20,
    trail_s: float = 30.0,
    progress: Callable[[int, int], None] | None = None,
    *,
    encoding: Callable[[int, int], None] | None = None,
    dpi: int = 80,
    size_in: float = 6.0,
) -> int:
    """Animate ``record`` into ``path`` (``.gif``, or ``.mp4`` with ffmpeg); returns the
    number of frames written.

    Args:
        record: the episode (beliefs stored with a stride are shown at the stored step at or
            before each frame).
        path: output file; its suffix picks the format.
        stride: steps between frames (the last step is always drawn).
        fps: frames per second of the output.
        trail_s: length of the agent's and the targets' trails, s.
        progress: called as ``progress(done, total)`` per frame drawn.
        encoding: called as ``encoding(done, total)`` per frame encoded, after the last frame
            is drawn (a GIF is encoded at the end; an MP4 as it goes, and reports nothing).
        dpi: dots per inch.
        size_in: figure width, inches; the height fits the square map, the title and the
            legends (`frame_size_in`). The frame is ``size * dpi`` pixels.
    """
    path = Path(path)
    if stride < 1:
        raise InputError(f"stride must be a positive number of steps, got {stride}")
    if fps < 1:
        raise InputError(f"fps must be a positive number of frames per second, got {fps}")
    if trail_s < 0:
        raise InputError(f"trail_s must be a non-negative duration in s, got {trail_s}")
    writer = _writer(path, fps, encoding)

    n_steps = record.agent_path.shape[0] - 1
    steps = frame_steps(n_steps, stride)
    belief_at = stored_belief_index(record.belief_steps, steps)
    flash = detection_flash(record.detections, steps)
    labels, focus = subtask_at(record.info, record.target_ids, steps)
    widths, heights, angles = ellipse_axes(record.belief_covariances[..., :2, :2])
    total_u = position_logdet(record.belief_covariances).sum(axis=1)
    trail_steps = int(round(trail_s / record.time_step))
    radius = 0.5 * record.sensor_diameter
    n = len(record.target_ids)
    colors = [target_color(i) for i in range(n)]
    duration = n_steps * record.time_step

    width, height = frame_size_in(size_in, n)
    # The figure keeps matplotlib's base canvas, whose draw() does nothing: FuncAnimation's
    # redraw after each frame costs nothing and only the writer's grab renders (with Agg).
    fig = Figure(figsize=(width, height), dpi=dpi)
    map_in = width - _LEFT_IN - _RIGHT_IN
    bottom_in = height - _TOP_IN - map_in
    ax = fig.add_axes((_LEFT_IN / width, bottom_in / height, map_in / width, map_in / height))
    xlim, ylim = _view_limits(record)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.tick_params(labelsize="small")
    fence_keys = draw_fence(ax, record.fence) if record.fence is not None else []

    paths = record.agent_paths  # (K+1, m, 2): one trail, footprint and marker per UAV
    histories, trails, footprints, agents = [], [], [], []
    for v in range(paths.shape[1]):
        color = vehicle_color(v)
        histories.append(ax.plot([], [], color="0.82", lw=0.6, zorder=1)[0])
        trails.append(ax.plot([], [], color=color, lw=1.4, zorder=4)[0])
        footprints.append(
            ax.add_patch(
                Circle(
                    (0.0, 0.0), radius, facecolor=(0, 0, 0, 0.06), edgecolor=color, lw=0.6, zorder=4
                )
            )
        )
        agents.append(ax.plot([], [], marker="^", color=color, ms=7, ls="none", zorder=6)[0])
    truth_trails, truths, means, ellipses, rings = [], [], [], [], []
    for color in colors:
        truth_trails.append(ax.plot([], [], color=color, lw=0.8, alpha=0.6, zorder=2)[0])
        truths.append(
            ax.plot([], [], marker="o", color=color, mec="k", mew=0.5, ms=6, ls="none", zorder=5)[0]
        )
        means.append(ax.plot([], [], marker="+", color=color, ms=7, ls="none", zorder=3)[0])
        ellipses.append(
            ax.add_patch(
                Ellipse((0.0, 0.0), 0.0, 0.0, fill=False, edgecolor=color, ls="--", zorder=3)
            )
        )
        rings.append(ax.plot([], [], marker="o", mfc="none", ls="none", zorder=5)[0])
    header = ax.set_title("", fontsize="medium", loc="left")
    status = ax.set_title("", fontsize="medium", loc="right", fontweight="bold")
    targets = [
        Line2D([], [], color=c, marker="o", mec="k", mew=0.5, ms=6, ls="none", label=tid)
        for tid, c in zip(record.target_ids, colors, strict=True)
    ]
    team = paths.shape[1] > 1
    elements = [
        *(
            Line2D(
                [],
                [],
                color=vehicle_color(v),
                marker="^",
                ms=7,
                lw=1.4,
                label=f"{f'UAV {v + 1}' if team else 'agent'}, last {trail_s:g} s",
            )
            for v in range(paths.shape[1])
        ),
        Line2D([], [], color="0.35", ls="--", lw=1.0, label="95 % belief ellipse"),
        Line2D(
            [],
            [],
            color="0.35",
            marker="o",
            mfc="none",
            ms=RING_POINTS,
            mew=2.0,
            ls="none",
            label="detection",
        ),
        Line2D(
            [],
            [],
            color="k",
            marker="o",
            mfc=(0, 0, 0, 0.06),
            ms=11,
            ls="none",
            mew=0.6,
            label="sensor footprint",
        ),
        Line2D([], [], color="0.35", marker="+", ms=7, ls="none", label="belief mean"),
        Line2D([], [], color="0.82", lw=0.8, label="agent path so far"),
        *fence_keys,
    ]
    legend_style = {
        "fontsize": "small",
        "frameon": False,
        "columnspacing": 1.0,
        "handletextpad": 0.4,
    }
    fig.legend(handles=elements, loc="lower center", ncol=3, **legend_style)
    fig.legend(
        handles=targets,
        loc="lower center",
        bbox_to_anchor=(0.5, _ELEMENTS_IN / height),
        ncol=min(n, TARGET_COLUMNS),
        title="true targets",
        title_fontsize="small",
        **legend_style,
    )

    def draw(f: int) -> list:
        k = int(steps[f])
        j = int(belief_at[f])
        first = max(0, k - trail_steps)
        for v in range(paths.shape[1]):
            histories[v].set_data(paths[: k + 1, v, 0], paths[: k + 1, v, 1])
            trails[v].set_data(paths[first : k + 1, v, 0], paths[first : k + 1, v, 1])
            agents[v].set_data([paths[k, v, 0]], [paths[k, v, 1]])
            footprints[v].center = tuple(paths[k, v])
        for i in range(n):
            truth = record.true_states[first : k + 1, i, :2]
            truth_trails[i].set_data(truth[:, 0], truth[:, 1])
            truths[i].set_data([truth[-1, 0]], [truth[-1, 1]])
            means[i].set_data([record.belief_means[j, i, 0]], [record.belief_means[j, i, 1]])
            ellipse = ellipses[i]
            ellipse.set_center(tuple(record.belief_means[j, i, :2]))
            ellipse.set_width(widths[j, i])
            ellipse.set_height(heights[j, i])
            ellipse.set_angle(angles[j, i])
            ellipse.set_linewidth(2.2 if focus[f] == i else 1.1)
            strength = flash[f, i]
            ring = rings[i]
            ring.set_data([truth[-1, 0]], [truth[-1, 1]])
            ring.set_visible(strength > 0.0)
            ring.set_markersize(RING_POINTS * (1.8 - 0.8 * strength))
            ring.set_markeredgewidth(1.0 + 1.5 * strength)
            ring.set_markeredgecolor((*colors[i], strength))
        header.set_text(
            f"{record.planner}   t = {k * record.time_step:.0f} s / {duration:g} s"
            f"   U = {total_u[j]:.1f}"
        )
        status.set_text(labels[f])
        return []

    def report(frame: int, _total: int | None) -> None:
        if progress is not None:
            progress(frame + 1, len(steps))

    animation = FuncAnimation(
        fig,
        draw,
        frames=len(steps),
        init_func=lambda: draw(0),
        blit=False,
        repeat=False,
        cache_frame_data=False,
    )
    animation.save(str(path), writer=writer, dpi=dpi, progress_callback=report)
    log.info("animation of %d frames written to %s", len(steps), path)
    return len(steps)
