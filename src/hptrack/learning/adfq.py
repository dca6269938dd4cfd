"""The ADFQ posterior update of a Gaussian Q-value (Jeong & Lee, "Assumed Density Filtering
Q-learning", IJCAI 2019), vectorised over a batch of transitions and the next state's actions.

Each Q-value is a Gaussian belief. For a transition ``(s, a, r, s')`` with prior
``Q(s, a) ~ N(mu, var)`` and next-state beliefs ``Q(s', b) ~ N(mu_b, var_b)``, each next action
gives a Bellman target ``T_b ~ N(r + gamma mu_b, gamma^2 var_b + noise)`` and the likelihood of
``Q(s, a) = x`` is the density of ``max_b T_b`` at ``x``::

    p(x) ~ N(x; mu, var) sum_b N(x; m_b, v_b) prod_{c != b} Phi((x - m_c) / sqrt(v_c)).

Term ``b`` is the prior merged with ``T_b`` (mean ``mu_bar_b``, variance ``var_bar_b``, evidence
``c_b = N(mu; m_b, var + v_b)``) times the other targets' CDFs. ADFQ approximates each CDF
factor: a target above the term's peak pulls like a Gaussian, ``Phi(z) ~ exp(-z^2 / 2)`` for
``z < 0``; one below it counts as 1. The pulling set is found by scanning the other targets in
decreasing mean; it gives the term's peak ``mu*_b``, width ``var*_b`` and log-weight (the
Gaussian integral of the approximated term). The posterior, a mixture of the terms, is projected
back onto one Gaussian by moment matching (assumed density filtering), with a variance floor.

As the variances shrink the update becomes a Q-learning step towards ``r + gamma max_b mu_b``
with the adaptive step size ``var / (var + gamma^2 var_b*)``.
"""

from __future__ import annotations

import numpy as np

VARIANCE_FLOOR = 1e-10
"""Smallest posterior variance (the update never returns a degenerate belief)."""

_LOG_2PI = float(np.log(2.0 * np.pi))


def _others_index(n_actions: int) -> np.ndarray:
    """``(A, A - 1)``: row ``p`` lists the positions ``0..A-1`` without ``p``, in order."""
    grid = np.tile(np.arange(n_actions), (n_actions, 1))
    return grid[~np.eye(n_actions, dtype=bool)].reshape(n_actions, n_actions - 1)


def adfq_posterior(
    prior_mean: np.ndarray,
    prior_var: np.ndarray,
    next_means: np.ndarray,
    next_vars: np.ndarray,
    reward: np.ndarray,
    discount: float,
    terminal: np.ndarray | None = None,
    noise: float = 0.0,
    var_floor: float = VARIANCE_FLOOR,
) -> tuple[np.ndarray, np.ndarray]:
    """ADFQ posterior mean and variance of ``Q(s, a)`` for a batch of transitions.

    Args:
        prior_mean, prior_var: ``(B,)`` belief of ``Q(s, a)``.
        next_means, next_vars: ``(B, A)`` beliefs of ``Q(s', b)``.
        reward: ``(B,)`` rewards.
        discount: ``gamma``.
        terminal: ``(B,)`` bool; a terminal transition's target is ``r`` alone (variance
            ``noise``). ``None``: none is terminal.
        noise: observation noise variance added to every Bellman target (``epsilon``).
        var_floor: smallest returned variance.

    Returns:
        ``(mean, var)``, each ``(B,)`` float64.
    """
    mu = np.asarray(prior_mean, dtype=np.float64)[:, None]
    var = np.asarray(prior_var, dtype=np.float64)[:, None]
    reward = np.asarray(reward, dtype=np.float64)
    batch, n_actions = np.shape(next_means)

    target_mean = reward[:, None] + discount * np.asarray(next_means, dtype=np.float64)
    target_var = discount**2 * np.asarray(next_vars, dtype=np.float64) + noise

    # each term: the prior merged with one target (a Gaussian product) and its evidence c_b
    order = np.argsort(-target_mean, axis=1, kind="stable")
    target_mean = np.take_along_axis(target_mean, order, axis=1)
    target_var = np.take_along_axis(target_var, order, axis=1)
    target_prec = 1.0 / target_var
    bar_var = 1.0 / (1.0 / var + target_prec)
    bar_mean = bar_var * (mu / var + target_mean * target_prec)
    sum_var = var + target_var
    log_evidence = -0.5 * (_LOG_2PI + np.log(sum_var) + (mu - target_mean) ** 2 / sum_var)

    if n_actions == 1:
        peak, peak_var, log_weight = bar_mean, bar_var, log_evidence
    else:
        # the other targets of each term, in decreasing mean: (B, A, A - 1)
        others = _others_index(n_actions)
        other_mean = target_mean[:, others]
        other_prec = target_prec[:, others]
        # peak and precision when the first k others pull, k = 0..A-1: (B, A, A)
        zero = np.zeros((batch, n_actions, 1))
        prec_k = 1.0 / bar_var[:, :, None] + np.concatenate(
            [zero, np.cumsum(other_prec, axis=2)], axis=2
        )
        info_k = (bar_mean / bar_var)[:, :, None] + np.concatenate(
            [zero, np.cumsum(other_mean * other_prec, axis=2)], axis=2
        )
        peak_k = info_k / prec_k
        # the j-th other pulls if its target lies above the peak with the first j pulling;
        # the scan stops at the first that does not
        pulls = np.cumprod(other_mean > peak_k[:, :, :-1], axis=2, dtype=bool)
        n_pull = pulls.sum(axis=2)
        peak = np.take_along_axis(peak_k, n_pull[:, :, None], axis=2)[:, :, 0]
        peak_var = 1.0 / np.take_along_axis(prec_k, n_pull[:, :, None], axis=2)[:, :, 0]
        mismatch = (
            np.where(pulls, (peak[:, :, None] - other_mean) ** 2 * other_prec, 0.0).sum(axis=2)
            + (peak - bar_mean) ** 2 / bar_var
        )
        log_weight = log_evidence + 0.5 * np.log(peak_var / bar_var) - 0.5 * mismatch

    # moment matching of the mixture (softmax weights)
    weight = np.exp(log_weight - log_weight.max(axis=1, keepdims=True))
    weight /= weight.sum(axis=1, keepdims=True)
    mean = (weight * peak).sum(axis=1)
    second = (weight * (peak_var + (peak - mean[:, None]) ** 2)).sum(axis=1)

    if terminal is not None:
        terminal = np.asarray(terminal, dtype=bool)
        if terminal.any():
            mu_t, var_t = mu[terminal, 0], var[terminal, 0]
            if noise > 0.0:
                post_var = 1.0 / (1.0 / var_t + 1.0 / noise)
                mean[terminal] = post_var * (mu_t / var_t + reward[terminal] / noise)
                second[terminal] = post_var
            else:
                mean[terminal] = reward[terminal]
                second[terminal] = 0.0
    return mean, np.maximum(second, var_floor)
