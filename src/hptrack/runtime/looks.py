"""Beliefs kept from detections without identity in flight (issue 29; ``sensor.labelled:
false``): the reports that arrive are held until their tick, and each tick is one look of the
simulator's tracker (`hptrack.models.tracking.Tracker`, built by
`hptrack.sim.step.unlabelled_parts`: one tracker, two uses).

The look of tick ``k`` takes the reports stamped in ``((k-1) tau, k tau]``, the interval the
simulator's step ``k`` stands for. A detector sends one frame (one datagram, its lines sharing
a stamp) per look; when an interval holds several frames (a detector faster than ``1 / tau``),
the look takes the newest and lists the others as *superseded*, so that no target is reported
twice in one look. The beliefs are predicted to the frame's stamp (to ``k tau`` when the
interval holds none) and associated from the latest odometry, GNN or JPDA with the tentative
tracks and their confirmation as in the simulator; a look with no report still counts for the
tentative tracks (a miss). A report stamped at or before a tick already looked at is late: its
look is done, and it is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hptrack.models.mission import STEP_TOLERANCE
from hptrack.scenario.model import Scenario
from hptrack.sim.step import unlabelled_parts


@dataclass(frozen=True)
class Report:
    """One accepted detection without identity: its time ``t`` s, number ``seq`` (the
    controller's count of accepted detections), position ``z`` (2,) m and the ``vehicle`` of
    the team whose camera took it."""

    t: float
    seq: int
    z: np.ndarray
    vehicle: int = 0


@dataclass(frozen=True)
class Look:
    """What one look did: ``seen`` ``(n,)`` the beliefs a report went to (or that a tentative
    track claimed) and the look's log record (`TrackedBeliefs.look`)."""

    seen: np.ndarray
    record: dict[str, Any]


class TrackedBeliefs:
    """The mission's ``n`` beliefs kept by the tracker from reports without identity (module
    docstring).

    Args:
        scenario: the mission (priors, motion, sensor, association, confirmation).
        seed: the mission's seed (the tracker draws nothing; `unlabelled_parts` takes it).
    """

    def __init__(self, scenario: Scenario, seed: int) -> None:
        parts = unlabelled_parts(scenario, seed)
        assert parts is not None, "a labelled sensor names its targets: no tracker"
        self.tracker = parts[1]
        mission = scenario.mission_spec()
        self._motion = mission.motion
        self._q = np.asarray(mission.process_noise, dtype=float)
        self._tau = mission.time_step
        self.target_ids = mission.target_ids
        self.time_s = 0.0
        """Time of the beliefs (the last look), s."""
        self.means = np.array(scenario.means(), dtype=float)
        self.covariances = np.array(scenario.covariances(), dtype=float)
        self.pending: list[Report] = []
        """Accepted reports not yet looked at, in arrival order."""
        self._keys: set[tuple[float, float, float]] = set()
        self.looked_s = -np.inf
        """The end of the last look's interval (``k tau``), s: a report stamped at or before it
        is late."""
        self.newest_s = 0.0
        """Time of the newest accepted report (0 before any), s."""
        self.last_look: dict[str, Any] | None = None
        """The last look's record."""

    def at(self, time_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Beliefs ``(n, d)``, ``(n, d, d)`` at ``time_s`` (not before the last look)."""
        return self._motion.predict(
            self.means, self.covariances, self._q, max(float(time_s) - self.time_s, 0.0)
        )

    def late(self, t: float) -> bool:
        """Whether a report stamped ``t`` s falls in a look already done."""
        return t <= self.looked_s + STEP_TOLERANCE * self._tau

    def is_duplicate(self, t: float, z: np.ndarray) -> bool:
        """Whether the same report (time ``t`` s, position ``z``) is already waiting."""
        return (float(t), float(z[0]), float(z[1])) in self._keys

    def add(self, t: float, z: np.ndarray, seq: int, vehicle: int = 0) -> None:
        """Hold report ``z`` (2,) m stamped ``t`` s (checked: not `late`) by ``vehicle``'s
        camera for its look."""
        self.pending.append(Report(float(t), int(seq), np.array(z, dtype=float), int(vehicle)))
        self._keys.add((float(t), float(z[0]), float(z[1])))
        self.newest_s = max(self.newest_s, float(t))

    def look(self, k: int, agent: np.ndarray, vehicle: int = 0) -> Look:
        """The look of tick ``k`` from ``agent`` (2,) m by ``vehicle``'s camera (a team's
        vehicles look in turn, the first first): its reports associated, the beliefs updated
        (module docstring)."""
        end = k * self._tau
        due = end + STEP_TOLERANCE * self._tau
        mine = [r for r in self.pending if r.t <= due and r.vehicle == vehicle]
        self.pending = [r for r in self.pending if r.t > due or r.vehicle != vehicle]
        self._keys = {(r.t, float(r.z[0]), float(r.z[1])) for r in self.pending}
        self.looked_s = end
        stamp = max((r.t for r in mine), default=end)
        frame = [r for r in mine if abs(r.t - stamp) <= 1e-9]
        superseded = [r.seq for r in mine if abs(r.t - stamp) > 1e-9]
        stamp = max(stamp, self.time_s)  # a later vehicle's frame may be older than the first's
        means, covs = self.at(stamp)
        self.time_s = stamp
        reports = np.array([r.z for r in frame], dtype=float).reshape(-1, 2)
        result = self.tracker.look(
            np.asarray(agent, dtype=float), means, covs, reports, new_step=vehicle == 0
        )
        self.means, self.covariances = means, covs
        ids = self.target_ids
        record: dict[str, Any] = {
            "kind": "look",
            "k": k,
            "time": stamp,
            "agent": agent,
            "reports": [r.seq for r in frame],
            "belief": [None if b < 0 else ids[b] for b in result.belief_of.tolist()],
            "weight": result.weight,
            "claims": [[ids[c.belief], frame[c.detection].seq] for c in result.claims],
            "tentative": [[*t.mean[:2].tolist(), t.looks, t.hits] for t in self.tracker.tentative],
        }
        if superseded:
            record["superseded"] = superseded
        self.last_look = record
        return Look(result.seen.copy(), record)
