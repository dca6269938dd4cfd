"""The tracker of detections without identity (issue 29): the mission's ``n`` beliefs (the
mission names its targets, so their number is known) kept from a look's positions alone.

At each look (after the beliefs' prediction) the tracker gates the reports against every
belief and associates them (`hptrack.models.association`: GNN, or JPDA and its combined
update) with the proper likelihood ratios: a pair weighs ``Pd N(z; zhat, S) / lambda``, and a
belief none of them came from ``1 - Pd P_in P_G``, with ``P_in`` the belief's chance of being
inside the footprint (`footprint_probability`). So a belief far outside the footprint claims
no report, and a very wide one (unseen for long) takes a false alarm only when its density at
the report beats the clutter's. A report that no belief takes (GNN: unassigned; JPDA: less
than half of its weight on the beliefs) starts or extends a *tentative track* (gated to the
reports left by the same GNN, a Kalman filter of the beliefs' motion); once it is detected at
``M`` of its first ``N`` looks it is confirmed and re-initialises the belief that explains it
best among those no report was associated with at this look (the largest
``N(m_t; m_i, P_i + P_t)`` over the positions), and is dropped; one that can no longer reach
``M`` is dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import ndtr

from hptrack.models.association import (
    gate_threshold,
    gnn,
    innovations,
    jpda,
    log_likelihoods,
    log_weights,
    mahalanobis2,
    pda_update,
)
from hptrack.models.belief_motion import BeliefMotion
from hptrack.models.measurement import kalman_update
from hptrack.models.sensor import DetectingFootprintSensor, SensorPart

GATE_PROBABILITY = 0.9999
"""``P_G``: the chance that the gate holds a detected target's report (``d^2 <= 18.4``). The
gate only prunes; the likelihood ratios decide. At 0.99 about one report in a hundred of a
followed target fell outside its own belief's gate and, with no clutter, went to a wide one
(``docs/results/sensing-unlabelled/gate-0.99``)."""
QUADRATURE_NODES = 128
"""Gauss-Legendre nodes of `footprint_probability` across the footprint."""

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(QUADRATURE_NODES)


def footprint_probability(
    agent: np.ndarray, radius: float, positions: np.ndarray, covariances: np.ndarray
) -> np.ndarray:
    """``P_in`` ``(n,)``: the chance that a target of position belief ``N(positions[i],
    covariances[i])`` (m, m^2) lies within ``radius`` m of ``agent``. In the belief's
    principal axes (standard deviations ``s1``, ``s2``; the footprint's centre at ``c``) it is
    ``int phi(x / s1) / s1 [Phi((c_y + h) / s2) - Phi((c_y - h) / s2)] dx`` over the chord
    ``x = c_x + r sin t``, ``h = r cos t``, by Gauss-Legendre in ``t``."""
    values, vectors = np.linalg.eigh(covariances)
    s = np.sqrt(values)  # (n, 2)
    centre = np.einsum("nji,nj->ni", vectors, np.asarray(agent) - positions)
    t = 0.5 * math.pi * _NODES
    x = centre[:, :1] + radius * np.sin(t)[None, :]
    h = radius * np.cos(t)[None, :]
    cy, s1, s2 = centre[:, 1:], s[:, :1], s[:, 1:]
    density = np.exp(-0.5 * (x / s1) ** 2) / (math.sqrt(2.0 * math.pi) * s1)
    band = ndtr((cy + h) / s2) - ndtr((cy - h) / s2)
    return 0.5 * math.pi * (density * band * h) @ _WEIGHTS


def detection_probability_at(
    sensor: SensorPart, agent: np.ndarray, positions: np.ndarray
) -> np.ndarray:
    """``Pd`` ``(n,)`` of the sensor part at ``positions`` ``(n, 2)`` (m) from ``agent``,
    as if inside the footprint (`hptrack.models.sensor.table_probability`'s interpolation)."""
    if not isinstance(sensor, DetectingFootprintSensor):
        return np.ones(positions.shape[0])
    d = np.hypot(*(positions - agent).T)
    return np.interp(d, sensor.distances, sensor.probabilities)


@dataclass
class TentativeTrack:
    """A report's track before it claims a target: its state, looks and hits since it began."""

    mean: np.ndarray
    covariance: np.ndarray
    looks: int = 1
    hits: int = 1


class Claim(NamedTuple):
    """A confirmed tentative track's claim: the belief it re-initialised and the report of this
    look that confirmed it."""

    belief: int
    detection: int


class TrackerLook(NamedTuple):
    """What one look did.

    Attributes:
        seen: ``(n,)`` the beliefs a report was associated with.
        belief_of: ``(k,)`` the belief each report went to (-1: none; JPDA: the belief of its
            largest weight, when at least half of its weight is on the beliefs).
        weight: ``(k,)`` that association's weight (GNN: 1).
        claims: the confirmations of this look.
    """

    seen: np.ndarray
    belief_of: np.ndarray
    weight: np.ndarray
    claims: list[Claim]


class Tracker:
    """The beliefs' tracker of detections without identity (module docstring).

    Args:
        motion: the beliefs' motion (predicts the tentative tracks one step).
        sensor: the mission record's sensor part (footprint and ``Pd``).
        noise: ``R`` ``(2, 2)``, m^2.
        false_alarm_density: ``lambda``, per m^2 per look.
        association: ``"gnn"`` or ``"jpda"``.
        confirmation: ``(M, N)``.
        process_noise: ``q`` of the tentative tracks, m^2/s^3.
        new_covariance: ``(d, d)`` a new tentative track's covariance (its position block
            ``R``).
    """

    def __init__(
        self,
        motion: BeliefMotion,
        sensor: SensorPart,
        noise: np.ndarray,
        false_alarm_density: float,
        association: str,
        confirmation: tuple[int, int],
        process_noise: float,
        new_covariance: np.ndarray,
    ) -> None:
        self.motion = motion
        self.sensor = sensor
        self.noise = np.asarray(noise, dtype=float)
        self.radius = 0.5 * float(sensor.diameter)
        self.false_alarm_density = float(false_alarm_density)
        self.association = association
        self.confirm, self.window = confirmation
        self.process_noise = float(process_noise)
        self.new_covariance = np.asarray(new_covariance, dtype=float)
        self.gate = gate_threshold(GATE_PROBABILITY)
        self.tentative: list[TentativeTrack] = []

    def _weights(self, agent, means, covariances, reports) -> np.ndarray:
        positions, cov_xy = means[:, :2], covariances[:, :2, :2]
        nu, s = innovations(positions, cov_xy, self.noise, reports)
        gated = mahalanobis2(nu, s) <= self.gate
        pd = detection_probability_at(self.sensor, agent, positions)
        inside = footprint_probability(agent, self.radius, positions, cov_xy)
        miss = 1.0 - pd * np.minimum(inside, 1.0) * GATE_PROBABILITY
        return log_weights(log_likelihoods(nu, s), gated, pd, miss, self.false_alarm_density)

    def look(
        self,
        agent: np.ndarray,
        means: np.ndarray,
        covariances: np.ndarray,
        reports: np.ndarray,
        new_step: bool = True,
    ) -> TrackerLook:
        """Associate a look's ``reports`` ``(k, 2)`` from ``agent`` with the beliefs ``(n, d)``,
        ``(n, d, d)`` (predicted to this look) and update them in place. ``new_step``: the
        look's step is new, so the tentative tracks are first predicted one step and count
        one more look; a team's later UAVs look in the same step (``False``)."""
        n, k = means.shape[0], reports.shape[0]
        if new_step:
            self._predict_tentative()
        belief_of, weight = np.full(k, -1), np.zeros(k)
        seen = np.zeros(n, dtype=bool)
        if k:
            weights = self._weights(agent, means, covariances, reports)
            if self.association == "jpda":
                beta = jpda(weights)
                for i in np.flatnonzero(beta[:, 0] < 1.0):
                    means[i], covariances[i] = pda_update(
                        means[i], covariances[i], self.noise, reports, beta[i]
                    )
                seen = beta[:, 0] < 0.5
                on_beliefs = beta[:, 1:].sum(axis=0) >= 0.5
                best = np.argmax(beta[:, 1:], axis=0)
                belief_of = np.where(on_beliefs, best, -1)
                weight = np.where(on_beliefs, beta[best, np.arange(k) + 1], 0.0)
            else:
                assigned = gnn(weights)
                for i in np.flatnonzero(assigned >= 0):
                    z = reports[assigned[i]]
                    kalman_update(means[i], covariances[i], z, self.noise, means[i], covariances[i])
                    belief_of[assigned[i]] = i
                    weight[assigned[i]] = 1.0
                seen = assigned >= 0
        claims = self._tentative(agent, means, covariances, reports, belief_of < 0, seen)
        for claim in claims:
            seen[claim.belief] = True
        return TrackerLook(seen, belief_of, weight, claims)

    def _predict_tentative(self) -> None:
        if not self.tentative:
            return
        means = np.array([t.mean for t in self.tentative])
        covs = np.array([t.covariance for t in self.tentative])
        means, covs = self.motion.predict(means, covs, self.process_noise, self.motion.time_step)
        for track, m, c in zip(self.tentative, means, covs, strict=True):
            track.mean, track.covariance = m, c
            track.looks += 1

    def _tentative(self, agent, means, covariances, reports, free, seen) -> list[Claim]:
        """Extend the tentative tracks by the ``free`` reports (GNN), start new ones from the
        rest, confirm and drop (module docstring)."""
        left = np.flatnonzero(free)
        hit_by = np.full(len(self.tentative), -1)
        if self.tentative and left.size:
            t_means = np.array([t.mean for t in self.tentative])
            t_covs = np.array([t.covariance for t in self.tentative])
            hit = gnn(self._weights(agent, t_means, t_covs, reports[left]))
            for t, j in enumerate(hit):
                if j >= 0:
                    track = self.tentative[t]
                    kalman_update(
                        track.mean, track.covariance, reports[left[j]], self.noise,
                        track.mean, track.covariance,
                    )  # fmt: skip
                    track.hits += 1
                    hit_by[t] = left[j]
            left = np.setdiff1d(left, hit_by[hit_by >= 0])
        d = means.shape[1]
        for j in left:
            mean = np.zeros(d)
            mean[:2] = reports[j]
            self.tentative.append(TentativeTrack(mean, self.new_covariance.copy()))
        hit_by = np.concatenate([hit_by, left])
        claims, kept = [], []
        free_beliefs = ~seen.copy()
        for track, j in zip(self.tentative, hit_by, strict=True):
            if track.hits >= self.confirm and j >= 0:
                belief = self._claimant(track, means, covariances, free_beliefs)
                if belief >= 0:
                    means[belief], covariances[belief] = track.mean, track.covariance
                    free_beliefs[belief] = False
                    claims.append(Claim(belief, int(j)))
            elif track.looks - track.hits <= self.window - self.confirm:
                kept.append(track)
        self.tentative = kept
        return claims

    @staticmethod
    def _claimant(track, means, covariances, free) -> int:
        """The free belief whose density at the track's position is largest (-1: none)."""
        candidates = np.flatnonzero(free)
        if candidates.size == 0:
            return -1
        nu, s = innovations(
            means[candidates, :2], covariances[candidates, :2, :2], track.covariance[:2, :2],
            track.mean[None, :2],
        )  # fmt: skip
        return int(candidates[np.argmax(log_likelihoods(nu, s)[:, 0])])


def new_track_covariance(noise: np.ndarray, priors: np.ndarray) -> np.ndarray:
    """A new tentative track's covariance ``(d, d)``: ``R`` on the position and, on every other
    entry of the state, the largest variance of the targets' priors ``(n, d, d)``."""
    d = priors.shape[1]
    cov = np.diag(
        np.concatenate([[0.0, 0.0], np.max(priors[:, np.arange(2, d), np.arange(2, d)], axis=0)])
    )
    cov[:2, :2] = noise
    return cov
