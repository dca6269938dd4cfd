"""Coverage figures: the planned intercept and shifting spiral (paper Fig. 3, Fig. 5a) and the
estimated against empirical target-finding CDF (paper Fig. 5b). Functions take an Axes and return
artists; :func:`save_cdf_figure` and :func:`save_plan_figure` write whole figures without pyplot.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from hptrack.viz.mission import covariance_ellipse


def empirical_cdf(detection_times: np.ndarray, time_step: float, n_steps: int) -> np.ndarray:
    """Fraction of runs detected by coverage time ``k tau``, ``k = 0 .. n_steps - 1``;
    ``detection_times`` holds one time per run in s, NaN for runs never detected."""
    times = np.asarray(detection_times, dtype=float)
    found = times[np.isfinite(times)]
    steps = np.rint(found / time_step).astype(np.int64)
    counts = np.bincount(np.clip(steps, 0, n_steps), minlength=n_steps + 1)[:n_steps]
    return np.cumsum(counts) / times.size


def plot_cdf_comparison(
    ax: Axes,
    estimated_cdf: np.ndarray,
    detection_times: np.ndarray,
    time_step: float,
    title: str | None = None,
) -> dict:
    """Estimated ``P_cdf`` (Sec. IV-B) against the simulated fraction found, over coverage time.

    Args:
        ax: target axes.
        estimated_cdf: ``P_cdf(k)`` for ``k = 0 .. t_cutoff``.
        detection_times: coverage time of detection per run, s (NaN if not found).
        time_step: ``tau``, s.
        title: axes title.
    """
    n = len(estimated_cdf)
    t = np.arange(n) * time_step
    empirical = empirical_cdf(detection_times, time_step, n)
    (sim,) = ax.step(
        t,
        empirical,
        where="post",
        color="C0",
        lw=1.6,
        label=f"simulation ({np.asarray(detection_times).size} runs)",
    )
    (est,) = ax.plot(t, estimated_cdf, color="C3", lw=1.6, ls="--", label="estimate $P_{cdf}$")
    ax.set_xlabel("time since the coverage started (s)")
    ax.set_ylabel("probability of having found the target")
    ax.set_ylim(0.0, 1.02)
    ax.set_xlim(0.0, max(t[-1], time_step))
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")
    if title:
        ax.set_title(title)
    return {"simulation": sim, "estimate": est}


def plot_coverage_plan(
    ax: Axes,
    path: np.ndarray,
    intercept_steps: int,
    start_mean: np.ndarray,
    start_covariance: np.ndarray,
    end_mean: np.ndarray | None = None,
    end_covariance: np.ndarray | None = None,
) -> dict:
    """The planned agent path: intercept flight (dashed) and spiral (solid), with the 95 %
    belief ellipse when the coverage starts and, if given, at ``t_cutoff``.

    Args:
        ax: target axes (equal aspect is set).
        path: ``(n + t_cutoff + 1, 2)`` planned positions from departure, m.
        intercept_steps: ``n``, the steps of the intercept flight.
        start_mean, start_covariance: belief position (2,) and 2x2 covariance at coverage start.
        end_mean, end_covariance: the same at ``t_cutoff``.
    """
    n = intercept_steps
    (flight,) = ax.plot(
        path[: n + 1, 0], path[: n + 1, 1], color="0.4", ls="--", lw=1.0, label="intercept"
    )
    (spiral,) = ax.plot(path[n:, 0], path[n:, 1], color="C0", lw=0.9, label="spiral")
    start = ax.add_patch(
        covariance_ellipse(
            start_mean,
            start_covariance,
            fill=False,
            edgecolor="C2",
            lw=1.2,
            label="95 % belief, start",
        )
    )
    artists = {"intercept": flight, "spiral": spiral, "start_ellipse": start}
    if end_mean is not None and end_covariance is not None:
        artists["end_ellipse"] = ax.add_patch(
            covariance_ellipse(
                end_mean,
                end_covariance,
                fill=False,
                edgecolor="C3",
                lw=1.2,
                label="95 % belief, $t_{cutoff}$",
            )
        )
    ax.plot(*path[0], marker="^", color="k", ms=7, label="departure")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize="small")
    return artists


def save_cdf_figure(
    panels: Mapping[str, Mapping], path: str, title: str = "", dpi: int = 130
) -> None:
    """One CDF panel per delay (keys: delay in s as text; values with ``estimated_cdf``,
    ``detection_times`` and ``time_step``), side by side, written to ``path``."""
    fig = Figure(figsize=(4.2 * len(panels), 3.8))
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (delay, panel) in zip(axes, panels.items(), strict=True):
        plot_cdf_comparison(
            ax,
            panel["estimated_cdf"],
            panel["detection_times"],
            panel["time_step"],
            title=f"$t_d$ = {delay} s",
        )
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")


def save_plan_figure(
    path: str,
    plan_path: np.ndarray,
    intercept_steps: int,
    start_mean: np.ndarray,
    start_covariance: np.ndarray,
    end_mean: np.ndarray,
    end_covariance: np.ndarray,
    estimated_cdf: np.ndarray,
    time_step: float,
    dpi: int = 130,
) -> None:
    """Planned path (left) and estimated ``P_cdf`` (right) of one coverage sub-task."""
    fig = Figure(figsize=(10.5, 4.5))
    left, right = fig.subplots(1, 2)
    plot_coverage_plan(
        left, plan_path, intercept_steps, start_mean, start_covariance, end_mean, end_covariance
    )
    t = np.arange(len(estimated_cdf)) * time_step
    right.plot(t, estimated_cdf, color="C3", lw=1.6)
    right.set_xlabel("time since the coverage started (s)")
    right.set_ylabel("estimated $P_{cdf}$")
    right.set_ylim(0.0, 1.02)
    right.grid(alpha=0.3)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
