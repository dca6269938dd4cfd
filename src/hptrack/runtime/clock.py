"""The controller's clock: mission time from the events (the newest odometry, ``setpoint`` or
detection time), the ``setpoint`` calls' own order, and the planner's step ticks at ``k tau``
(paper Fig. 2: one decision per step)."""

from __future__ import annotations

import math

from hptrack.models.mission import STEP_TOLERANCE


def step_of(time_s: float, time_step: float) -> int:
    """The step a mission time falls in (``floor(t / tau)``, exact at whole steps)."""
    return math.floor(time_s / time_step + STEP_TOLERANCE)


class MissionClock:
    """Mission time as the events tell it.

    Args:
        time_step: ``tau``, s.
        n_steps: steps in the budget; the last tick is the budget's end.

    Attributes:
        now: the newest time of a clock source (odometry, ``setpoint``, detection), s.
        last_call: the time of the last ``setpoint`` call, s.
        tick: the last tick processed (``-1`` before the first).
    """

    def __init__(self, time_step: float, n_steps: int) -> None:
        self.time_step, self.n_steps = time_step, n_steps
        self.now = 0.0
        self.last_call = 0.0
        self.tick = -1

    def observe(self, t: float) -> None:
        """An accepted event at ``t`` s moves the clock on (never back)."""
        self.now = max(self.now, t)

    def ahead(self, t: float) -> float:
        """How far ``t`` s is ahead of the clock, s."""
        return t - self.now

    def call(self, t: float) -> tuple[float, str | None]:
        """A ``setpoint`` call at ``t`` s: the time it runs at (the last call's if ``t`` is
        not finite or goes back) and the problem with ``t``, or ``None``."""
        problem = None
        if not math.isfinite(t) or t < self.last_call:
            problem = f"time {t} is not finite or before the last call ({self.last_call:.3f} s)"
            t = self.last_call
        self.last_call = t
        self.observe(t)
        return t, problem

    def due(self, t: float) -> tuple[int, int] | None:
        """The tick due at ``t`` s and how many were skipped since the last, or ``None`` if
        none is due; ticks stop at the budget's end (``n_steps``)."""
        k = min(step_of(t, self.time_step), self.n_steps)
        if k <= self.tick:
            return None
        missed = k - self.tick - 1
        self.tick = k
        return k, missed
