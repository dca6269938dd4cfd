"""Target beliefs on a clock: each target's belief as a short time-ordered history of its
measurements, so that a measurement that arrives late (within a tolerance) is filtered in its
time order and the belief at any recent time is exact.

Per target ``i`` the history keeps a *base* (the belief after every measurement older than the
horizon, at that measurement's time) and the measurements since, each with its posterior. A new
measurement at time ``t`` is inserted in time order; the posteriors from there on are recomputed
(predicted in closed form over each gap with the beliefs' motion, `BeliefMotion.predict`,
Eq. (1), and updated with `kalman_update`). The belief at time ``T`` is the
last posterior at or before ``T`` predicted to ``T``. The horizon is the newest measurement time
minus the tolerance: a measurement older than it is refused.

With negative information (a ``missed`` kernel, the scenario's ``sensor.negative_information``)
the history also holds misses: a look from the agent's position at a time that detected nothing
(`BeliefTimeline.add_miss`), filtered in their time order by the miss update
(`hptrack.models.miss_update`). A measurement of the same target taken within ``look_s`` before
a miss (during the look the miss stands for) arrives late: the miss is taken out.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hptrack.models.belief_motion import BeliefMotion
from hptrack.models.measurement import kalman_update


@dataclass
class _Entry:
    """One accepted measurement of one target (or, ``z`` ``None``, a miss of a look from the
    agent at ``noise``, m) and the belief after it."""

    t: float
    seq: int
    z: np.ndarray | None
    noise: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


class BeliefTimeline:
    """Beliefs over ``n`` targets with per-target measurement histories (module docstring).

    Args:
        means: ``(n, d)`` prior means at time ``start_s`` (``d`` the motion's state size).
        covariances: ``(n, d, d)`` prior covariances.
        process_noise: ``(n,)`` ``q``, m^2/s^3.
        motion: the motion model.
        tolerance_s: how far behind the newest measurement a measurement may be, s.
        start_s: time of the priors, s (the mission start).
        missed: ``missed(agent_x, agent_y, mean, cov)``, the miss update in place; ``None``
            (the paper's): no misses.
        look_s: how long before a miss a measurement of the target takes it out, s.
    """

    def __init__(
        self,
        means: np.ndarray,
        covariances: np.ndarray,
        process_noise: np.ndarray,
        motion: BeliefMotion,
        tolerance_s: float,
        start_s: float = 0.0,
        missed: Callable[[float, float, np.ndarray, np.ndarray], None] | None = None,
        look_s: float = 0.0,
    ) -> None:
        n = len(means)
        self._q = np.asarray(process_noise, dtype=float)
        self._motion = motion
        self.tolerance_s = float(tolerance_s)
        self._missed = missed
        self._look_s = float(look_s)
        self._base_t = np.full(n, float(start_s))
        self._base_mean = np.array(means, dtype=float)
        self._base_cov = np.array(covariances, dtype=float)
        self._entries: list[list[_Entry]] = [[] for _ in range(n)]
        self._keys: list[list[tuple[float, int]]] = [[] for _ in range(n)]
        self.newest_s = float(start_s)
        """Time of the newest accepted measurement (the priors' time before any), s."""

    @property
    def horizon_s(self) -> float:
        """The oldest time a new measurement may have, s."""
        return self.newest_s - self.tolerance_s

    def is_duplicate(self, i: int, t: float, z: np.ndarray) -> bool:
        """Whether target ``i`` already has a measurement ``z`` at time ``t``."""
        keys = self._keys[i]
        j = bisect.bisect_left(keys, (t - 1e-9, -1))
        while j < len(keys) and keys[j][0] <= t + 1e-9:
            found = self._entries[i][j].z
            if found is not None and np.array_equal(found, z):
                return True
            j += 1
        return False

    def add(self, i: int, t: float, z: np.ndarray, noise: np.ndarray, seq: int) -> None:
        """Filter measurement ``z`` (2,) m of target ``i`` taken at ``t`` s with noise ``R``
        (2, 2) m^2; ``seq`` orders measurements of the same time. The caller has checked that
        ``t >= horizon_s``."""
        key = (float(t), int(seq))
        first = self._drop_misses(i, float(t))
        pos = bisect.bisect_right(self._keys[i], key)
        entry = _Entry(
            float(t),
            int(seq),
            np.array(z, dtype=float),
            np.ascontiguousarray(noise, dtype=float),
            np.empty(self._motion.state_size),
            np.empty((self._motion.state_size,) * 2),
        )
        self._keys[i].insert(pos, key)
        self._entries[i].insert(pos, entry)
        self._refilter(i, min(pos, first))
        self.newest_s = max(self.newest_s, float(t))
        self._settle()

    def add_miss(self, i: int, t: float, agent: np.ndarray) -> None:
        """A look from ``agent`` (2,) m at ``t`` s did not detect target ``i`` (needs a
        ``missed`` kernel; ``t >= horizon_s``); after any measurement at the same time."""
        assert self._missed is not None, "a timeline without negative information has no misses"
        key = (float(t), np.iinfo(np.int64).max)
        pos = bisect.bisect_right(self._keys[i], key)
        d = self._motion.state_size
        entry = _Entry(
            float(t), key[1], None, np.array(agent, dtype=float), np.empty(d), np.empty((d, d))
        )
        self._keys[i].insert(pos, key)
        self._entries[i].insert(pos, entry)
        self._refilter(i, pos)

    def _drop_misses(self, i: int, t: float) -> int:
        """Take out target ``i``'s misses in ``[t, t + look_s)``; the first position changed
        (the history's length when none)."""
        entries = self._entries[i]
        first = len(entries)
        for j in range(len(entries) - 1, -1, -1):
            e = entries[j]
            if e.z is None and t - 1e-9 <= e.t < t + self._look_s - 1e-9:
                entries.pop(j)
                self._keys[i].pop(j)
                first = j
        return first

    def _state_before(self, i: int, pos: int) -> tuple[float, np.ndarray, np.ndarray]:
        if pos == 0:
            return self._base_t[i], self._base_mean[i], self._base_cov[i]
        e = self._entries[i][pos - 1]
        return e.t, e.mean, e.cov

    def _refilter(self, i: int, pos: int) -> None:
        t, mean, cov = self._state_before(i, pos)
        for e in self._entries[i][pos:]:
            m, c = self._motion.predict(mean[None], cov[None], self._q[i], max(e.t - t, 0.0))
            if e.z is None:
                assert self._missed is not None
                e.mean[:], e.cov[:] = m[0], c[0]
                self._missed(float(e.noise[0]), float(e.noise[1]), e.mean, e.cov)
            else:
                kalman_update(m[0], c[0], e.z, e.noise, e.mean, e.cov)
            t, mean, cov = e.t, e.mean, e.cov

    def _settle(self) -> None:
        """Fold measurements older than the horizon into the bases."""
        horizon = self.horizon_s
        for i, entries in enumerate(self._entries):
            while entries and entries[0].t < horizon:
                e = entries.pop(0)
                self._keys[i].pop(0)
                self._base_t[i], self._base_mean[i], self._base_cov[i] = e.t, e.mean, e.cov

    def at(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Beliefs ``(n, d)``, ``(n, d, d)`` at ``time_s`` from every measurement taken at or
        before it (a target whose base is newer is given at its base time)."""
        n = len(self._entries)
        src_t = np.empty(n)
        d = self._motion.state_size
        src_mean = np.empty((n, d))
        src_cov = np.empty((n, d, d))
        for i in range(n):
            pos = bisect.bisect_right(self._keys[i], (float(time_s), np.iinfo(np.int64).max))
            src_t[i], src_mean[i], src_cov[i] = self._state_before(i, pos)
        return self._motion.predict(
            src_mean, src_cov, self._q, np.maximum(float(time_s) - src_t, 0.0)
        )
