"""Position measurement and the Kalman update (paper Sec. III; ``docs/model.md``: ``R = 10 I`` by
default, any symmetric positive definite 2x2 ``R`` allowed).

A target inside the circular sensor footprint is measured as ``z = [x, y] + v``,
``v ~ N(0, R)``. The update is written out for ``H = [I 0]``: ``S = P_xy + R``,
``K = P H' S^-1``, ``P+ = P - K H P`` built symmetric entry by entry, ``m+ = m + K (z - H m)``.
`update_covariance` and `kalman_update` are the one implementation of the update in
the project (simulator, tree search, baselines and controller call them).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def within_footprint(diameter, agent_x, agent_y, x, y):
    """The footprint's rule: a target at ``(x, y)`` lies within ``w/2`` (``diameter`` ``w``, m)
    of the agent at ``(agent_x, agent_y)``, ``|p - agent|^2 <= (w/2)^2``."""
    dx = x - agent_x
    dy = y - agent_y
    r = 0.5 * diameter
    return dx * dx + dy * dy <= r * r


@numba.njit(cache=True, inline="always")
def table_probability(distances, probabilities, d):
    """``Pd(d)`` of a detection table: linear between its rows, the first value below the first
    distance (0) and the last beyond the last one."""
    last = distances.shape[0] - 1
    if d >= distances[last]:
        return probabilities[last]
    if d <= distances[0]:
        return probabilities[0]
    j = 1
    while distances[j] < d:
        j += 1
    lo, hi = distances[j - 1], distances[j]
    t = (d - lo) / (hi - lo)
    return probabilities[j - 1] + t * (probabilities[j] - probabilities[j - 1])


@numba.njit(cache=True)
def _within_all(diameter, agent, positions, out):
    for i in range(positions.shape[0]):
        out[i] = within_footprint(diameter, agent[0], agent[1], positions[i, 0], positions[i, 1])


@numba.njit(cache=True, inline="always")
def _gain(cov, noise):
    """Entries of ``K = P H' (H P H' + R)^-1`` (rows x, y, vx, vy) and of the symmetric ``P``."""
    p00, p01, p02, p03 = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[0, 2], cov[0, 3]
    p11, p12, p13 = cov[1, 1], cov[1, 2], cov[1, 3]
    p22, p23, p33 = cov[2, 2], 0.5 * (cov[2, 3] + cov[3, 2]), cov[3, 3]
    s00, s01, s11 = p00 + noise[0, 0], p01 + 0.5 * (noise[0, 1] + noise[1, 0]), p11 + noise[1, 1]
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    g00, g01 = p00 * i00 + p01 * i01, p00 * i01 + p01 * i11
    g10, g11 = p01 * i00 + p11 * i01, p01 * i01 + p11 * i11
    g20, g21 = p02 * i00 + p12 * i01, p02 * i01 + p12 * i11
    g30, g31 = p03 * i00 + p13 * i01, p03 * i01 + p13 * i11
    return (
        g00,
        g01,
        g10,
        g11,
        g20,
        g21,
        g30,
        g31,
        p00,
        p01,
        p02,
        p03,
        p11,
        p12,
        p13,
        p22,
        p23,
        p33,
    )


@numba.njit(cache=True)
def update_covariance(cov, noise, out):
    """Posterior covariance of a position measurement with noise ``R = noise`` (2x2):
    ``out = P - P H' (H P H' + R)^-1 H P`` (symmetric by construction; ``out`` may be ``cov``;
    written out for 4-D states, any other length takes `_update_any`)."""
    if cov.shape[0] != 4:
        _update_any(cov[0], cov, cov[0], noise, cov[0], out, False)
        return
    (g00, g01, g10, g11, g20, g21, g30, g31, p00, p01, p02, p03, p11, p12, p13, p22, p23, p33) = (
        _gain(cov, noise)
    )
    out[0, 0] = p00 - (g00 * p00 + g01 * p01)
    out[1, 1] = p11 - (g10 * p01 + g11 * p11)
    out[2, 2] = p22 - (g20 * p02 + g21 * p12)
    out[3, 3] = p33 - (g30 * p03 + g31 * p13)
    out[0, 1] = out[1, 0] = p01 - (g00 * p01 + g01 * p11)
    out[0, 2] = out[2, 0] = p02 - (g00 * p02 + g01 * p12)
    out[0, 3] = out[3, 0] = p03 - (g00 * p03 + g01 * p13)
    out[1, 2] = out[2, 1] = p12 - (g10 * p02 + g11 * p12)
    out[1, 3] = out[3, 1] = p13 - (g10 * p03 + g11 * p13)
    out[2, 3] = out[3, 2] = p23 - (g20 * p03 + g21 * p13)


@numba.njit(cache=True)
def _update_any(mean, cov, z, noise, mean_out, cov_out, with_mean):
    """The update of `kalman_update` for a state of any length ``d`` (``H = [I 0]``; the
    written-out 4-D update is `update_covariance`): ``K = P[:, :2] S^-1``, ``P+ = P - K P[:2]``
    symmetrised, ``m+ = m + K (z - m[:2])``."""
    d = cov.shape[0]
    s00 = cov[0, 0] + noise[0, 0]
    s01 = 0.5 * (cov[0, 1] + cov[1, 0]) + 0.5 * (noise[0, 1] + noise[1, 0])
    s11 = cov[1, 1] + noise[1, 1]
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    gain = np.empty((d, 2))
    for r in range(d):
        p0 = 0.5 * (cov[r, 0] + cov[0, r])
        p1 = 0.5 * (cov[r, 1] + cov[1, r])
        gain[r, 0] = p0 * i00 + p1 * i01
        gain[r, 1] = p0 * i01 + p1 * i11
    if with_mean:
        ex = z[0] - mean[0]
        ey = z[1] - mean[1]
        for r in range(d):
            mean_out[r] = mean[r] + gain[r, 0] * ex + gain[r, 1] * ey
    cross = np.empty((2, d))  # H P, symmetrised
    for c in range(d):
        cross[0, c] = 0.5 * (cov[0, c] + cov[c, 0])
        cross[1, c] = 0.5 * (cov[1, c] + cov[c, 1])
    for r in range(d):
        for c in range(r, d):
            pr = 0.5 * (cov[r, c] + cov[c, r])
            v = pr - 0.5 * (
                gain[r, 0] * cross[0, c]
                + gain[r, 1] * cross[1, c]
                + gain[c, 0] * cross[0, r]
                + gain[c, 1] * cross[1, r]
            )
            cov_out[r, c] = v
            cov_out[c, r] = v


@numba.njit(cache=True)
def kalman_update(mean, cov, z, noise, mean_out, cov_out):
    """Kalman update of one belief with a position measurement ``z`` (2,) of noise ``R``:
    ``mean_out = m + K (z - H m)``, ``cov_out`` as `update_covariance`. The outputs may be
    the inputs (in place). States of 6 entries (a motion with accelerations) take the update
    of any length."""
    if cov.shape[0] != 4:
        _update_any(mean, cov, z, noise, mean_out, cov_out, True)
        return
    g = _gain(cov, noise)
    ex = z[0] - mean[0]
    ey = z[1] - mean[1]
    m0 = mean[0] + g[0] * ex + g[1] * ey
    m1 = mean[1] + g[2] * ex + g[3] * ey
    m2 = mean[2] + g[4] * ex + g[5] * ey
    m3 = mean[3] + g[6] * ex + g[7] * ey
    update_covariance(cov, noise, cov_out)
    mean_out[0], mean_out[1], mean_out[2], mean_out[3] = m0, m1, m2, m3


@numba.njit(cache=True)
def _update_stacked(means, covariances, measurements, noise):
    for i in range(means.shape[0]):
        kalman_update(means[i], covariances[i], measurements[i], noise, means[i], covariances[i])


def check_noise_covariance(noise: np.ndarray) -> np.ndarray:
    """``noise`` as a finite symmetric positive definite 2x2 float array.

    Raises:
        ValueError: naming what is wrong.
    """
    r = np.array(noise, dtype=float)
    if r.shape != (2, 2) or not np.all(np.isfinite(r)):
        raise ValueError(f"measurement noise must be a finite 2x2 matrix, got {r.tolist()}")
    if abs(r[0, 1] - r[1, 0]) > 1e-9 * max(float(np.max(np.abs(r))), 1.0):
        raise ValueError(f"measurement noise is not symmetric: {r.tolist()}")
    if np.min(np.linalg.eigvalsh(r)) <= 0.0:
        raise ValueError(f"measurement noise is not positive definite: {r.tolist()}")
    return r


class PositionMeasurementModel:
    """Linear position sensor with a circular footprint.

    Args:
        noise_covariance: ``R``, the 2x2 covariance of the position error, m^2 (a full matrix
            is allowed); default ``10 I``.
        sensor_diameter: footprint diameter ``w``, m; targets within ``w/2`` are measured.
    """

    def __init__(
        self, noise_covariance: np.ndarray | None = None, sensor_diameter: float = 100.0
    ) -> None:
        r = check_noise_covariance(
            10.0 * np.eye(2) if noise_covariance is None else noise_covariance
        )
        r.flags.writeable = False
        self.noise_covariance = r
        self.sensor_diameter = float(sensor_diameter)
        self._factor = np.linalg.cholesky(r)

    @classmethod
    def isotropic(
        cls, noise_std: float, sensor_diameter: float = 100.0
    ) -> PositionMeasurementModel:
        """``R = noise_std^2 I`` (``noise_std`` in m per axis)."""
        return cls(noise_std**2 * np.eye(2), sensor_diameter)

    def __repr__(self) -> str:
        return (
            f"PositionMeasurementModel(noise_covariance={self.noise_covariance.tolist()}, "
            f"sensor_diameter={self.sensor_diameter})"
        )

    def in_footprint(self, agent_position: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """Boolean mask ``(n,)``: which positions ``(n, 2)`` lie within ``w/2`` of the agent
        (`within_footprint`)."""
        points = np.ascontiguousarray(np.asarray(positions, dtype=float).reshape(-1, 2))
        out = np.empty(points.shape[0], dtype=np.bool_)
        _within_all(self.sensor_diameter, np.asarray(agent_position, dtype=float), points, out)
        return out

    def sample(self, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy measurements ``(m, 2)`` of true positions ``(m, 2)``: ``z = p + L e``,
        ``L L' = R``, ``e ~ N(0, I)``."""
        e = rng.standard_normal(np.shape(positions))
        return positions + e @ self._factor.T

    def update(
        self, means: np.ndarray, covariances: np.ndarray, measurements: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Kalman update of stacked beliefs ``(m, d)``, ``(m, d, d)`` with ``z`` ``(m, 2)``."""
        new_means = np.array(means, dtype=float)
        new_covs = np.array(covariances, dtype=float)
        _update_stacked(
            new_means,
            new_covs,
            np.ascontiguousarray(measurements, dtype=float),
            self.noise_covariance,
        )
        return new_means, new_covs
