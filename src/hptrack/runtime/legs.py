"""What the controller tells the vehicle: each decision is flown as a straight `Leg` from
the odometry of the moment it arrives, at the planned speed (shifted by the vehicle's lag behind
the previous leg, `Leg.lag`), and every ``setpoint`` call returns a `Setpoint` with the leg's
reference point for now and its velocity (the feed-forward of the vehicle's position
controller), or a hold."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PX4_VELOCITY_TRACKING = 0.8
"""The share of its velocity setpoint that PX4's SIH quadrotor flies in steady flight: about
6.3-6.5 m/s on straight legs while PX4's own velocity setpoint was 8.1-8.5 m/s (PX4 main of
early 2025); 1 is an ideal velocity loop."""


@dataclass(frozen=True)
class Setpoint:
    """Where the vehicle should be now.

    Attributes:
        position: ``(2,)`` m (``x`` east, ``y`` north): the decision's waypoint, or the hold.
        hold: the position is a hold, not the planner's waypoint.
        reason: ``"tracking"``, ``"no odometry yet"``, ``"waiting for the first plan"``,
            ``"odometry stale"``, ``"planner error"`` or ``"mission over"``.
        detail: one line with the figures behind ``reason``.
        reference: ``(2,)`` m, where the vehicle should be now on its way to ``position``: it
            leaves the odometry of the moment the decision arrived (plus the vehicle's lag
            behind the previous leg) at the planned speed.
        velocity: ``(2,)`` m/s, the planned velocity at ``reference`` (0 once it reaches
            ``position``, and in a hold): the feed-forward of a position controller.
    """

    position: np.ndarray
    hold: bool
    reason: str
    detail: str
    reference: np.ndarray
    velocity: np.ndarray


@dataclass(frozen=True)
class Leg:
    """The straight flight to a decision's waypoint: from ``start`` (m) at ``start_s`` (mission
    s) at ``speed`` m/s towards ``end`` (m)."""

    start: np.ndarray
    start_s: float
    end: np.ndarray
    speed: float

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference position (m) and velocity (m/s) at mission time ``t`` s."""
        step = self.end - self.start
        length = float(np.hypot(*step))
        along = self.speed * max(t - self.start_s, 0.0)
        if length <= 0.0 or along >= length:
            return self.end.copy(), np.zeros(2)
        unit = step / length
        return self.start + along * unit, self.speed * unit

    def lag(self, t: float, position: np.ndarray, limit_m: float) -> np.ndarray:
        """How far the reference at mission time ``t`` s is ahead of the vehicle at
        ``position`` (m), at most ``limit_m`` long, m: a position loop ``v = v_ff + P (p_ref -
        p)`` that flies a share ``s`` of its command needs `tracking_lag_m` of it to fly ``v``,
        so the next leg starts that far ahead too."""
        ahead = self.at(t)[0] - position
        norm = float(np.hypot(*ahead))
        return ahead if norm <= limit_m else ahead * (limit_m / norm)


def tracking_lag_m(speed_m_s: float, tracking: float, gain_per_s: float) -> float:
    """How far behind its reference a position loop ``v = v_ff + P (p_ref - p)`` that flies a
    share ``tracking`` of its command flies at ``speed_m_s`` in steady flight, m:
    ``(1 / s - 1) v / P`` (2.1 m for PX4's 0.8 at 8 m/s with ``MPC_XY_P`` 0.95 1/s)."""
    return (1.0 / tracking - 1.0) * speed_m_s / gain_per_s
