"""What each UAV of a team knows of the others' claims: the team's communication link.

A *claim* is the target a UAV is pursuing, following or dwelling on (``-1``: none). With the
perfect link (``share_period = 0``, ``drop_rate = 0``) a claim is heard by every other UAV as
soon as it is made, so the UAVs that choose at the same step choose one at a time, each seeing
the choices before it. A limited link shares the claims only every ``share_period`` s (at the
steps that are whole multiples of it), and loses each message (one UAV's claim to one other
UAV, at one share) with probability ``drop_rate``, by an independent draw of the team
planner's random generator; a UAV then plans on what it last heard.
"""

from __future__ import annotations

import math

import numpy as np

NO_CLAIM = -1
"""A UAV that claims no target."""


class Link:
    """The claims each of ``n_vehicles`` UAVs knows of the others (module docstring).

    Args:
        n_vehicles: ``m``.
        time_step: ``tau``, s.
        share_period: s between shares (0: at once).
        drop_rate: the chance that one message is lost, in ``[0, 1)``.
        rng: the draws of the losses.
    """

    def __init__(
        self,
        n_vehicles: int,
        time_step: float,
        share_period: float,
        drop_rate: float,
        rng: np.random.Generator,
    ) -> None:
        self.known = np.full((n_vehicles, n_vehicles), NO_CLAIM, dtype=np.int64)
        """``known[j, k]``: the target UAV ``j`` last heard UAV ``k`` claim."""
        self.perfect = share_period == 0.0 and drop_rate == 0.0
        self._every = max(1, math.floor(share_period / time_step + 1e-9))
        self._drop_rate = drop_rate
        self._rng = rng
        self.messages = 0
        """Messages sent so far."""
        self.lost = 0
        """Messages lost so far."""

    def claimed(self, j: int, n_targets: int) -> np.ndarray:
        """``(n,)`` bool: the targets UAV ``j`` believes the others claim."""
        mask = np.zeros(n_targets, dtype=bool)
        others = np.delete(self.known[j], j)
        mask[others[others >= 0]] = True
        return mask

    def claim(self, k: int, target: int) -> None:
        """UAV ``k`` claims ``target`` (its own view at once; the others hear it at once on
        the perfect link, else at the next `share`)."""
        self.known[k, k] = target
        if self.perfect:
            self.known[:, k] = target

    def share(self, step: int) -> None:
        """At the end of step ``step``: a limited link's share, if one is due."""
        if self.perfect or step % self._every:
            return
        m = self.known.shape[0]
        for j in range(m):
            for k in range(m):
                if j == k:
                    continue
                self.messages += 1
                if self._drop_rate > 0.0 and self._rng.random() < self._drop_rate:
                    self.lost += 1
                    continue
                self.known[j, k] = self.known[k, k]

    def info(self) -> dict:
        """JSON-ready counts of the messages."""
        return {"messages": self.messages, "lost": self.lost}
