"""Textbook numpy references for the model kernels, written from the paper's formulas (Sec. III,
Eq. (1); Sec. V-A) and the standard Kalman filter, independently of :mod:`hptrack.models`.

State ``[x, y, vx, vy]``: ``F(T) = [[I, T I], [0, I]]``. Continuous white-noise acceleration of
intensity ``q`` accumulates ``q [[T^3/3 I, T^2/2 I], [T^2/2 I, T I]]`` over ``T`` seconds; the
paper's printed per-step noise is ``q [[tau^3/3 I, tau^2/2 I], [tau^2/2 I, I]]``.
"""

import numpy as np

H = np.hstack([np.eye(2), np.zeros((2, 2))])
"""Position measurement matrix ``z = H x + v``."""

I2 = np.eye(2)


def transition(duration):
    """``F`` over ``duration`` seconds."""
    return np.block([[I2, duration * I2], [np.zeros((2, 2)), I2]])


def continuous_noise(q, duration):
    """Noise of the continuous white-noise acceleration model accumulated over ``duration``."""
    t = duration
    return q * np.block([[t**3 / 3 * I2, t**2 / 2 * I2], [t**2 / 2 * I2, t * I2]])


def step_noise(q, tau, form):
    """One step's ``Q``: ``"continuous"`` (discretised) or ``"paper_text"`` (as printed)."""
    if form == "continuous":
        return continuous_noise(q, tau)
    return q * np.block([[tau**3 / 3 * I2, tau**2 / 2 * I2], [tau**2 / 2 * I2, I2]])


def predict_steps(cov, q, k, tau, form):
    """``k`` steps of ``P <- F P F' + Q`` (Eq. (1)), one at a time."""
    f, noise = transition(tau), step_noise(q, tau, form)
    for _ in range(k):
        cov = f @ cov @ f.T + noise
    return cov


def kalman_gain(cov, noise):
    """``K = P H' (H P H' + R)^-1``."""
    return cov @ H.T @ np.linalg.inv(H @ cov @ H.T + noise)


def joseph_update(cov, noise):
    """``P+ = (I - K H) P (I - K H)' + K R K'`` (equal to ``(I - K H) P`` for the optimal K)."""
    gain = kalman_gain(cov, noise)
    i_kh = np.eye(4) - gain @ H
    return i_kh @ cov @ i_kh.T + gain @ noise @ gain.T


def random_spd(rng, scales=(30.0, 30.0, 0.7, 0.7)):
    """A random dense symmetric positive definite 4x4 covariance (every entry non-zero), with
    standard deviations of the order of ``scales`` (m, m, m/s, m/s)."""
    a = rng.normal(size=(4, 4))
    d = np.diag(scales)
    return d @ (a @ a.T + 0.5 * np.eye(4)) @ d
