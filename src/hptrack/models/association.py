"""Data association of detections without identity: gating, global nearest neighbour and JPDA
(issue 29; Bar-Shalom, Willett and Tian, *Tracking and Data Fusion*, 2011, ch. 6-7).

For a belief of position mean ``zhat`` and covariance ``P`` (m, m^2) and a detection ``z``
with noise ``R``, the innovation is ``nu = z - zhat``, ``S = H P H' + R`` (``H`` picks the
position). ``z`` is *gated* when ``nu' S^-1 nu <= chi2_2^-1(P_G)``. The association weights
are likelihood ratios against a false alarm: a gated pair weighs ``Pd N(z; zhat, S) / lambda``
(``lambda`` the false-alarm density, m^-2), a belief that none of the detections came from
weighs ``1 - Pd' P_G`` (``Pd'`` the chance that the look detects it at all), and a detection
that came from no belief 1. GNN takes the joint assignment of largest weight (an optimal 2-D
assignment); JPDA weighs every joint event of a cluster of beliefs that share gated
detections, exactly (the product of its weights), and gives each belief's marginals
``beta_0`` (no detection) and ``beta_j``, the combined (PDA) update's weights. Stone Soup's
``PDAHypothesiser`` with ``GNNWith2DAssignment`` and ``JPDA`` weigh the same (its tests).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

CLUTTER_FLOOR = float(np.finfo(float).tiny)
"""The false-alarm density taken for none, m^-2: every gated detection then comes from a
belief (its weight ratio is finite)."""
MAX_JOINT_EVENTS = 100_000
"""Joint events of a cluster above which JPDA weighs its beliefs one by one (PDA)."""


def gate_threshold(gate_probability: float) -> float:
    """``chi2_2^-1(P_G)``: the squared Mahalanobis distance of the 2-D gate."""
    return float(chi2.ppf(gate_probability, 2))


def innovations(
    positions: np.ndarray, covariances: np.ndarray, noise: np.ndarray, detections: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``nu`` ``(n, k, 2)`` and ``S = P + R`` ``(n, 2, 2)`` of beliefs of positions ``(n, 2)``
    and position covariances ``(n, 2, 2)`` against detections ``(k, 2)`` (m, m^2)."""
    nu = detections[None, :, :] - positions[:, None, :]
    return nu, covariances + noise


def mahalanobis2(nu: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``nu' S^-1 nu`` ``(n, k)``."""
    return np.einsum("nki,nij,nkj->nk", nu, np.linalg.inv(s), nu)


def log_likelihoods(nu: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``log N(z; zhat, S)`` ``(n, k)``, m^-2."""
    _, logdet = np.linalg.slogdet(s)
    return -0.5 * mahalanobis2(nu, s) - math.log(2.0 * math.pi) - 0.5 * logdet[:, None]


def log_weights(
    log_likelihood: np.ndarray,
    gated: np.ndarray,
    detect: np.ndarray,
    miss: np.ndarray,
    false_alarm_density: float,
) -> np.ndarray:
    """The association's log weights ``(n, k + 1)``: column 0 ``log miss_i`` (``miss`` the
    weight ``1 - Pd' P_G`` of no detection from belief ``i``), column ``j + 1``
    ``log(Pd_i N_ij / lambda)`` where gated and ``-inf`` elsewhere (``detect`` the ``Pd_i``;
    ``lambda`` at least `CLUTTER_FLOOR`)."""
    density = max(float(false_alarm_density), CLUTTER_FLOOR)
    with np.errstate(divide="ignore"):
        pair = np.log(detect)[:, None] + log_likelihood - math.log(density)
        return np.column_stack([np.log(miss), np.where(gated, pair, -np.inf)])


def gnn(weights: np.ndarray) -> np.ndarray:
    """Global nearest neighbour: the detection of each belief ``(n,)`` (-1: none) of the joint
    assignment of largest total log weight (`log_weights`), by a 2-D assignment over the
    detections and one "no detection" column per belief."""
    n, k = weights.shape[0], weights.shape[1] - 1
    assigned = np.full(n, -1)
    rows = np.flatnonzero(np.any(np.isfinite(weights[:, 1:]), axis=1))
    if rows.size == 0:
        return assigned
    matrix = np.full((rows.size, k + rows.size), -np.inf)
    matrix[:, :k] = weights[rows, 1:]
    matrix[np.arange(rows.size), k + np.arange(rows.size)] = weights[rows, 0]
    r, c = linear_sum_assignment(matrix, maximize=True)
    assigned[rows[r]] = np.where(c < k, c, -1)
    return assigned


def clusters(gated: np.ndarray) -> list[np.ndarray]:
    """The beliefs ``(n, k)``-gated to some detection, grouped into clusters that share gated
    detections (connected components), each sorted."""
    n = gated.shape[0]
    label = np.arange(n)

    def root(i: int) -> int:
        while label[i] != i:
            i = label[i]
        return i

    for j in range(gated.shape[1]):
        rows = np.flatnonzero(gated[:, j])
        for i in rows[1:]:
            label[root(int(i))] = root(int(rows[0]))
    active = np.flatnonzero(gated.any(axis=1))
    groups: dict[int, list[int]] = {}
    for i in active:
        groups.setdefault(root(int(i)), []).append(int(i))
    return [np.array(sorted(g)) for g in groups.values()]


def _events(options: list[list[int]]):
    """Every joint event: one choice per belief (0 none, ``j + 1`` detection ``j``), no
    detection twice."""
    for event in itertools.product(*options):
        used = [c for c in event if c > 0]
        if len(used) == len(set(used)):
            yield event


def jpda(weights: np.ndarray) -> np.ndarray:
    """JPDA's marginal association probabilities ``beta`` ``(n, k + 1)`` (column 0: no
    detection) from the log weights of `log_weights`, by exact enumeration of each cluster's
    joint events (a cluster of more than `MAX_JOINT_EVENTS` choices: per belief, PDA)."""
    n, k = weights.shape[0], weights.shape[1] - 1
    beta = np.zeros((n, k + 1))
    beta[:, 0] = 1.0
    gated = np.isfinite(weights[:, 1:])
    for cluster in clusters(gated):
        options = [[0, *(np.flatnonzero(gated[i]) + 1).tolist()] for i in cluster]
        if math.prod(map(len, options)) > MAX_JOINT_EVENTS:
            for i in cluster:
                w = np.exp(weights[i] - np.max(weights[i]))
                beta[i] = w / np.sum(w)
            continue
        events = np.array(list(_events(options)))
        logw = np.sum(weights[cluster[None, :], events], axis=1)
        w = np.exp(logw - np.max(logw))
        w /= np.sum(w)
        for row, i in enumerate(cluster):
            beta[i] = np.bincount(events[:, row], weights=w, minlength=k + 1)
    return beta


def pda_update(
    mean: np.ndarray,
    covariance: np.ndarray,
    noise: np.ndarray,
    detections: np.ndarray,
    beta: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The combined (PDA) update of one belief ``(d,)``, ``(d, d)`` by detections ``(k, 2)``
    with weights ``beta`` ``(k + 1,)`` (``beta[0]``: none of them):
    ``x + K nu``, ``nu = sum_j beta_j nu_j``, and
    ``beta_0 P + (1 - beta_0) (I - K H) P + K (sum_j beta_j nu_j nu_j' - nu nu') K'``
    (``K = P H' S^-1``, ``S = H P H' + R``)."""
    s = covariance[:2, :2] + noise
    gain = np.linalg.solve(s, covariance[:2, :]).T
    nu_j = detections - mean[:2]
    nu = beta[1:] @ nu_j
    spread = (nu_j * beta[1:, None]).T @ nu_j - np.outer(nu, nu)
    updated = covariance - gain @ covariance[:2, :]
    cov = beta[0] * covariance + (1.0 - beta[0]) * updated + gain @ spread @ gain.T
    return mean + gain @ nu, 0.5 * (cov + cov.T)
