"""Coverage figures: the planned intercept and shifting spiral (paper Fig. 3, Fig. 5a) and the
estimated against empirical target-finding CDF (paper Fig. 5b), with ``t_cutoff`` marked and
``p_find`` in the titles. Functions take an Axes and return artists; `save_cdf_figure`
and `save_plan_figure` write whole figures in `hptrack.viz.style`'s style.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes

from hptrack.viz.mission import covariance_ellipse
from hptrack.viz.style import DPI, legend_below, new_figure, save_figure, style_axes


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
    """Estimated ``P_cdf`` (Sec. IV-B) against the simulated fraction found, over coverage time,
    with ``t_cutoff`` marked and ``p_find`` (the estimate's and the simulation's) annotated.

    Args:
        ax: target axes.
        estimated_cdf: ``P_cdf(k)`` for ``k = 0 .. t_cutoff``.
        detection_times: coverage time of detection per run, s (NaN if not found).
        time_step: ``tau``, s.
        title: axes title (``p_find`` of both is added on a second line).
    """
    n = len(estimated_cdf)
    t = np.arange(n) * time_step
    cutoff = t[-1]
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
    line = ax.axvline(cutoff, color="0.3", lw=1.0, ls=":", label="$t_{cutoff}$")
    ax.annotate(
        f"$t_{{cutoff}}$ = {cutoff:g} s",
        (cutoff, 0.04),
        xytext=(-4, 0),
        textcoords="offset points",
        ha="right",
        fontsize="small",
        color="0.3",
    )
    p_find = float(estimated_cdf[-1])
    ax.plot([cutoff], [p_find], marker="o", color="C3", ms=5, zorder=4)
    ax.set_xlabel("time since the coverage started (s)")
    ax.set_ylabel("probability of having found the target")
    ax.set_ylim(0.0, 1.02)
    ax.set_xlim(0.0, 1.04 * max(cutoff, time_step))
    heading = f"$p_{{find}}$ = {p_find:.3f} (simulated {empirical[-1]:.3f})"
    style_axes(ax, f"{title}\n{heading}" if title else heading)
    return {"simulation": sim, "estimate": est, "t_cutoff": line}


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
    belief ellipse when the coverage starts and, if given, at ``t_cutoff``. Returns the
    artists by role (``"handles"`` for a legend).

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
            label="95 % belief, coverage start",
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
                ls="--",
                label="95 % belief, $t_{cutoff}$",
            )
        )
    (departure,) = ax.plot(*path[0], marker="^", color="k", ms=7, ls="none", label="departure")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    style_axes(ax, "planned path")
    artists["handles"] = [a for a in artists.values() if a is not None] + [departure]
    return artists


def save_cdf_figure(
    panels: Mapping[str, Mapping], path: str, title: str = "", dpi: int = DPI
) -> None:
    """One CDF panel per delay (keys: delay in s as text; values with ``estimated_cdf``,
    ``detection_times`` and ``time_step``), side by side with one legend below, written to
    ``path``."""
    fig = new_figure(4.2 * len(panels), 4.3, dpi)
    axes = fig.subplots(1, len(panels), squeeze=False, sharey=True)[0]
    for ax, (delay, panel) in zip(axes, panels.items(), strict=True):
        drawn = plot_cdf_comparison(
            ax,
            panel["estimated_cdf"],
            panel["detection_times"],
            panel["time_step"],
            title=f"$t_d$ = {delay} s",
        )
        ax.label_outer()
    legend_below(fig, list(drawn.values()), ncol=3)
    if title:
        fig.suptitle(title)
    save_figure(fig, path, dpi)


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
    dpi: int = DPI,
    title: str = "",
) -> None:
    """Planned path (left) and estimated ``P_cdf`` (right, ``t_cutoff`` and ``p_find``
    marked) of one coverage sub-task, one legend below."""
    fig = new_figure(10.5, 5.0, dpi)
    left, right = fig.subplots(1, 2)
    drawn = plot_coverage_plan(
        left, plan_path, intercept_steps, start_mean, start_covariance, end_mean, end_covariance
    )
    t = np.arange(len(estimated_cdf)) * time_step
    (estimate,) = right.plot(t, estimated_cdf, color="C3", lw=1.6, label="estimate $P_{cdf}$")
    right.axvline(t[-1], color="0.3", lw=1.0, ls=":")
    right.plot([t[-1]], [estimated_cdf[-1]], marker="o", color="C3", ms=5)
    right.set_xlabel("time since the coverage started (s)")
    right.set_ylabel("estimated $P_{cdf}$")
    right.set_ylim(0.0, 1.02)
    right.set_xlim(0.0, 1.04 * max(t[-1], time_step))
    style_axes(
        right,
        f"$p_{{find}}$ = {estimated_cdf[-1]:.3f} at $t_{{cutoff}}$ = {t[-1]:g} s",
    )
    legend_below(fig, [*drawn["handles"], estimate], ncol=4)
    if title:
        fig.suptitle(title)
    save_figure(fig, path, dpi)
