"""The sub-task MDP of the global planner (paper Sec. IV-C-1 "Markov Decision Process" and
Sec. IV-C-2 "Node Expansion") as compiled kernels.

Time is counted in whole simulator steps of ``tau`` seconds from the root of the search (step 0);
the budget ends at step ``N = floor(remaining_budget / tau)``.

**State** (paper: history, action list, remaining budget, agent pose, every target's belief). The
belief means never change in this MDP: a "find" is a measurement at the predicted mean, so in
expectation the mean stays on its open-loop prediction ``mean + v t``. A state is therefore fully
described by

* ``step`` ``t`` (remaining budget ``N - t`` steps),
* ``mask``: the action list as a bitmask of the targets not yet missed,
* ``last``: the target found by the previous sub-task (``-1`` if none); choosing it again means
  following it to the end of the budget,
* the agent position (m): the estimated position of the last pursued target at step ``t``,
* per target the covariance right after its last "find" and the step of that find
  (``base_cov``, ``base_step``; never found: the root covariance and step 0). Its covariance at
  any later step follows in closed form (Eq. (1), :func:`grow_covariance`).

The kernels keep the integer part ``(t, mask, last)`` in an ``int64`` array ``si``, the agent
position in a ``float64`` array ``sf`` and mutate all four arrays in place.

**Action** "pursue target a" (node expansion). The agent flies to the belief mean in
``n_i = ceil(t_intercept / tau)`` steps (:func:`hptrack.coverage.intercept.intercept_steps`, the
shared whole-step convention; ``0`` when the mean is already in the footprint) and starts the
spiral coverage from the covariance predicted to step ``t + n_i``. The coverage estimator
(:func:`hptrack.coverage.estimator.coverage_outcome`, Sec. IV-B) gives ``t_cutoff``, ``p_max``
and ``E[T_find]``, truncated to the ``N - t - n_i`` steps left (budget truncation). The action
is available only when ``n_i < N - t``. Outcomes:

* find, probability ``p_find = p_max``: the sub-task lasts ``n_i + round(E[T_find])`` steps
  (nearest step, halves up); the target's belief becomes the posterior of a position measurement
  (noise ``R``) at that step;
* miss, probability ``1 - p_max``: it lasts ``n_i + t_cutoff`` steps and the target leaves the
  action list.

Either way the agent ends at the target's estimated position and every other belief grows by the
time spent. A sub-task lasts at least one step (so a history always advances in time). Choosing
the target found by the previous sub-task again follows it to the end of the budget with its
detection guaranteed: it is measured at every step, its covariance follows the Riccati recursion
(:func:`follow_covariance`). At the end of the budget, or when no action is available, the value
of the state is ``-U`` with ``U = sum_i log det Sigma^xy_i`` at step ``N`` (Sec. III).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba
import numpy as np

from hptrack.coverage.estimator import coverage_outcome
from hptrack.coverage.intercept import intercept_steps
from hptrack.models.motion import noise_blocks, position_covariance_after

if TYPE_CHECKING:
    from hptrack.sim.interface import MissionSpec, Observation

I_STEP, I_MASK, I_LAST = 0, 1, 2
"""Indices of ``t``, the action bitmask and the last found target in the state array ``si``."""

MAX_TARGETS = 62
"""The action list is an ``int64`` bitmask."""

WORK_SLOTS = 5
"""Number of 4x4 scratch matrices the kernels need (:func:`new_work`)."""

FOLLOW_TOLERANCE = 1e-13
"""Relative size below which the initial covariance no longer affects a followed covariance."""


class Model(NamedTuple):
    """Everything the kernels need that does not change during a search (arrays are float64).

    Attributes:
        means: ``(n, 4)`` belief means at the root, m and m/s.
        q: ``(n,)`` process noise intensities, m^2/s^3.
        noise: ``(2, 2)`` measurement noise covariance ``R``, m^2.
        tau: time step, s.
        c_per_step: lower-right per-step ``Q`` block over ``q`` (``tau`` or ``1``).
        speed: agent speed ``v_a``, m/s.
        diameter: sensor footprint diameter ``w``, m.
        n_steps: ``N``, the steps left in the budget at the root.
        follow_a, follow_g, follow_h: ``(n, L, 4, 4)`` follow maps (:func:`follow_table`).
        follow_len: ``(n,)`` number of valid entries of each target's follow maps.
    """

    means: np.ndarray
    q: np.ndarray
    noise: np.ndarray
    tau: float
    c_per_step: float
    speed: float
    diameter: float
    n_steps: int
    follow_a: np.ndarray
    follow_g: np.ndarray
    follow_h: np.ndarray
    follow_len: np.ndarray


class Memo(NamedTuple):
    """Estimator results for coverages of targets never found since the root, by start step.

    Such a coverage depends only on the target and its start step ``s`` (the covariance is the
    root's grown ``s`` steps, the truncation is ``N - s``), so each ``(target, s)`` is estimated
    once per search. ``cutoff[a, s] < 0``: not computed yet.
    """

    cutoff: np.ndarray
    p_find: np.ndarray
    expected: np.ndarray


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """The root state of a search (paper Sec. IV-C-2) and the model it is planned with.

    Attributes:
        agent_position: ``(2,)`` agent position, m.
        means: ``(n, 4)`` belief means ``[x, y, vx, vy]``, m and m/s.
        covariances: ``(n, 4, 4)`` belief covariances.
        process_noise: ``(n,)`` noise intensities ``q``, m^2/s^3.
        remaining_budget: time left, s (the search plans ``floor(remaining / tau)`` steps).
        time_step: ``tau``, s.
        c_per_step: lower-right per-step ``Q`` block over ``q``: ``tau`` (continuous form) or
            ``1`` (the paper's printed form), see :mod:`hptrack.models.motion`.
        agent_speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        available: ``(n,)`` targets still in the action list (not missed); default all.
        last_found: the target found by the sub-task that just ended, if any (choosing it again
            follows it to the end of the budget).
        current_action: re-planning mode (Sec. IV-C-4): the target being pursued, fixed as the
            root's only action; ``None`` for a first plan.
    """

    agent_position: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    process_noise: np.ndarray
    remaining_budget: float
    time_step: float
    c_per_step: float
    agent_speed: float
    sensor_diameter: float
    measurement_noise: np.ndarray
    available: np.ndarray | None = None
    last_found: int | None = None
    current_action: int | None = None

    def __post_init__(self) -> None:
        means = _frozen(self.means, "means")
        n = means.shape[0] if means.ndim == 2 else 0
        if means.shape != (n, 4) or not 1 <= n <= MAX_TARGETS:
            raise ValueError(f"means must have shape (n, 4) with 1 <= n <= {MAX_TARGETS}, "
                             f"got {means.shape}")
        checks = {
            "agent_position": (2,), "covariances": (n, 4, 4), "process_noise": (n,),
            "measurement_noise": (2, 2),
        }
        arrays = {name: _frozen(getattr(self, name), name) for name in checks}
        for name, shape in checks.items():
            if arrays[name].shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arrays[name].shape}")
        available = (np.ones(n, dtype=bool) if self.available is None
                     else np.array(self.available, dtype=bool))
        if available.shape != (n,):
            raise ValueError(f"available must have shape ({n},), got {available.shape}")
        available.flags.writeable = False
        for name in ("remaining_budget", "time_step", "agent_speed", "sensor_diameter",
                     "c_per_step"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
            object.__setattr__(self, name, value)
        noise = arrays["measurement_noise"]
        if not (np.allclose(noise, noise.T) and np.all(np.linalg.eigvalsh(noise) > 0.0)):
            raise ValueError("measurement_noise must be symmetric positive definite")
        for name in ("last_found", "current_action"):
            value = getattr(self, name)
            if value is not None and not (0 <= value < n and available[value]):
                raise ValueError(f"{name}={value} is not an available target")
        object.__setattr__(self, "means", means)
        object.__setattr__(self, "available", available)
        for name, array in arrays.items():
            object.__setattr__(self, name, array)

    @classmethod
    def from_mission(cls, mission: MissionSpec, observation: Observation,
                     available: np.ndarray | None = None,
                     last_found: int | None = None,
                     current_action: int | None = None) -> PlanningProblem:
        """The problem seen from an :class:`~hptrack.sim.interface.Observation` of a mission
        described by a :class:`~hptrack.sim.interface.MissionSpec`."""
        return cls(
            agent_position=observation.agent_position, means=observation.means,
            covariances=observation.covariances, process_noise=mission.process_noise,
            remaining_budget=observation.remaining_budget, time_step=mission.time_step,
            c_per_step=mission.motion.c_per_step, agent_speed=mission.agent_speed,
            sensor_diameter=mission.sensor.sensor_diameter,
            measurement_noise=mission.sensor.noise_covariance, available=available,
            last_found=last_found, current_action=current_action)

    @property
    def n_targets(self) -> int:
        return self.means.shape[0]

    @property
    def n_steps(self) -> int:
        """``N``: whole steps left in the budget."""
        return int(math.floor(self.remaining_budget / self.time_step + 1e-9))

    @property
    def mask(self) -> int:
        """The root's action list as a bitmask."""
        return int(sum(1 << i for i in np.flatnonzero(self.available)))

    def model(self) -> Model:
        """The compiled kernels' view of the problem (builds the follow maps of every target)."""
        n_steps = self.n_steps
        tables = [follow_table(float(q), self.time_step, self.c_per_step,
                               self.measurement_noise, n_steps) for q in self.process_noise]
        lengths = np.array([t[3] for t in tables], dtype=np.int64)
        stacked = [np.stack([t[k][:lengths.max()] for t in tables]) for k in range(3)]
        return Model(np.ascontiguousarray(self.means), np.ascontiguousarray(self.process_noise),
                     np.ascontiguousarray(self.measurement_noise), self.time_step,
                     self.c_per_step, self.agent_speed, self.sensor_diameter, n_steps,
                     stacked[0], stacked[1], stacked[2], lengths)

    def root_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fresh state arrays ``(si, sf, base_cov, base_step)`` of the root."""
        last = -1 if self.last_found is None else self.last_found
        si = np.array([0, self.mask, last], dtype=np.int64)
        return (si, np.array(self.agent_position, dtype=np.float64),
                np.array(self.covariances, dtype=np.float64),
                np.zeros(self.n_targets, dtype=np.int64))


def _frozen(value, name: str) -> np.ndarray:
    array = np.array(value, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    array.flags.writeable = False
    return array


def new_work() -> np.ndarray:
    """Scratch space for the kernels' 4x4 temporaries."""
    return np.empty((WORK_SLOTS, 4, 4))


def new_memo(n_targets: int, n_steps: int) -> Memo:
    """An empty :class:`Memo` for ``n_targets`` targets and ``n_steps`` budget steps."""
    return Memo(np.full((n_targets, n_steps + 1), -1, dtype=np.int64),
                np.zeros((n_targets, n_steps + 1)), np.zeros((n_targets, n_steps + 1)))


@numba.njit(cache=True)
def grow_covariance(cov, q, steps, tau, c_per_step, out):
    """``out = F^k cov F^k' + sum_{j<k} F^j Q F^j'`` for ``k = steps`` (Eq. (1) in closed form,
    O(1) in ``k``; the noise sums are :func:`hptrack.models.motion.noise_blocks`)."""
    t = steps * tau
    qpp, qpv, qvv = noise_blocks(q, float(steps), tau, c_per_step)
    for i in range(2):
        for j in range(2):
            vv = cov[2 + i, 2 + j]
            out[i, j] = cov[i, j] + t * (cov[i, 2 + j] + cov[2 + i, j]) + t * t * vv
            out[i, 2 + j] = cov[i, 2 + j] + t * vv
            out[2 + i, j] = cov[2 + i, j] + t * vv
            out[2 + i, 2 + j] = vv
    for i in range(2):
        out[i, i] += qpp
        out[i, 2 + i] += qpv
        out[2 + i, i] += qpv
        out[2 + i, 2 + i] += qvv


@numba.njit(cache=True)
def measurement_update(cov, noise, out):
    """Posterior covariance of a position measurement with noise ``R = noise``:
    ``out = P - P H' (H P H' + R)^-1 H P`` (symmetric by construction; ``out`` may be ``cov``)."""
    p00, p01, p02, p03 = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[0, 2], cov[0, 3]
    p11, p12, p13 = cov[1, 1], cov[1, 2], cov[1, 3]
    p22, p23, p33 = cov[2, 2], 0.5 * (cov[2, 3] + cov[3, 2]), cov[3, 3]
    s00, s01, s11 = p00 + noise[0, 0], p01 + 0.5 * (noise[0, 1] + noise[1, 0]), p11 + noise[1, 1]
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    # rows of the gain (P H')_i S^-1 and of P H', for i = x, y, vx, vy
    g00, g01 = p00 * i00 + p01 * i01, p00 * i01 + p01 * i11
    g10, g11 = p01 * i00 + p11 * i01, p01 * i01 + p11 * i11
    g20, g21 = p02 * i00 + p12 * i01, p02 * i01 + p12 * i11
    g30, g31 = p03 * i00 + p13 * i01, p03 * i01 + p13 * i11
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
def _matmul4(a, b, out, transpose_b):
    """``out = a b`` (or ``a b'``) for 4x4 arrays; ``out`` must not alias ``a`` or ``b``."""
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += a[i, k] * (b[j, k] if transpose_b else b[k, j])
            out[i, j] = acc


@numba.njit(cache=True)
def _solve4(m, x, out):
    """``out = m^-1 x`` for a 4x4 ``m`` and a 4-row ``x`` (Gaussian elimination with partial
    pivoting); ``m`` and ``x`` are overwritten."""
    cols = x.shape[1]
    for col in range(4):
        piv = col
        for r in range(col + 1, 4):
            if abs(m[r, col]) > abs(m[piv, col]):
                piv = r
        if piv != col:
            for c in range(4):
                m[col, c], m[piv, c] = m[piv, c], m[col, c]
            for c in range(cols):
                x[col, c], x[piv, c] = x[piv, c], x[col, c]
        for r in range(col + 1, 4):
            f = m[r, col] / m[col, col]
            for c in range(col, 4):
                m[r, c] -= f * m[col, c]
            for c in range(cols):
                x[r, c] -= f * x[col, c]
    for col in range(3, -1, -1):
        for c in range(cols):
            acc = x[col, c]
            for k in range(col + 1, 4):
                acc -= m[col, k] * out[k, c]
            out[col, c] = acc / m[col, col]


@numba.njit(cache=True)
def _lft_apply(a, g, h, x, out, work):
    """``out = h + a x (I + g x)^-1 a'`` (a linear fractional map of covariances); ``work`` is
    ``(>= 3, 4, 4)`` scratch, ``out`` must not alias ``x``."""
    m, w, aw = work[0], work[1], work[2]
    _matmul4(x, g, m, True)  # m = x g' = (I + g x)' - I, as g and x are symmetric
    for i in range(4):
        m[i, i] += 1.0
        for j in range(4):
            aw[i, j] = x[i, j]
    _solve4(m, aw, w)  # w = (I + g x)'^-1 x = (x (I + g x)^-1)'
    _matmul4(a, w, aw, True)  # a x (I + g x)^-1
    _matmul4(aw, a, m, True)
    for i in range(4):
        for j in range(4):
            out[i, j] = h[i, j] + 0.5 * (m[i, j] + m[j, i])


@numba.njit(cache=True)
def follow_table(q, tau, c_per_step, noise, max_steps):
    """Maps ``X_{j+1} = T^j(X_1)`` of the predicted covariance of a target measured every step.

    One step of the Riccati recursion on predicted covariances is the linear fractional map
    ``T(X) = Q + F X (I + S X)^-1 F'`` with ``S = H' R^-1 H``; ``j`` steps compose into
    ``T^j(X) = H_j + A_j X (I + G_j X)^-1 A_j'`` (the composition rule of the structure-preserving
    doubling algorithm; here one step at a time):
    ``A_{j+1} = F M^-1 A_j``, ``G_{j+1} = G_j + A_j' S M^-1 A_j``, ``H_{j+1} = Q + F M^-1 H_j F'``
    with ``M = I + H_j S``. Entry ``j`` holds ``(A_j, G_j, H_j)``, ``j = 0 .. L-1``. The table
    stops when the initial covariance no longer matters, ``|A G^-1 A'| <= 1e-13 |H|`` (then
    ``T^j(X) = H_{L-1}`` for every ``j >= L-1``), or at ``j = max_steps``. Built once per search
    and target; a follow then costs O(1) in its duration.

    Returns:
        ``(A, G, H, L)``: ``(max_steps + 1, 4, 4)`` arrays, of which the first ``L`` are valid.
    """
    f = np.eye(4)
    f[0, 2] = tau
    f[1, 3] = tau
    qq = np.zeros((4, 4))
    qpp, qpv, qvv = noise_blocks(q, 1.0, tau, c_per_step)
    for i in range(2):
        qq[i, i] = qpp
        qq[i, 2 + i] = qpv
        qq[2 + i, i] = qpv
        qq[2 + i, 2 + i] = qvv
    det = noise[0, 0] * noise[1, 1] - noise[0, 1] * noise[1, 0]
    s = np.zeros((4, 4))
    s[0, 0] = noise[1, 1] / det
    s[1, 1] = noise[0, 0] / det
    s[0, 1] = s[1, 0] = -0.5 * (noise[0, 1] + noise[1, 0]) / det
    cap = max_steps + 1
    ta = np.zeros((cap, 4, 4))
    tg = np.zeros((cap, 4, 4))
    th = np.zeros((cap, 4, 4))
    for i in range(4):
        ta[0, i, i] = 1.0
    m = np.empty((4, 4))
    rhs = np.empty((4, 8))
    sol = np.empty((4, 8))
    ma = np.empty((4, 4))
    mh = np.empty((4, 4))
    t1 = np.empty((4, 4))
    t2 = np.empty((4, 4))
    length = cap
    for j in range(1, cap):
        a1, g1, h1 = ta[j - 1], tg[j - 1], th[j - 1]
        _matmul4(h1, s, m, False)
        for r in range(4):
            m[r, r] += 1.0
            for c in range(4):
                rhs[r, c] = a1[r, c]
                rhs[r, 4 + c] = h1[r, c]
        _solve4(m, rhs, sol)  # [M^-1 A_j, M^-1 H_j]
        for r in range(4):
            for c in range(4):
                ma[r, c] = sol[r, c]
                mh[r, c] = sol[r, 4 + c]
        _matmul4(f, ma, ta[j], False)
        _matmul4(s, ma, t1, False)
        for r in range(4):  # G_{j+1} = G_j + A_j' (S M^-1 A_j), symmetrised
            for c in range(4):
                acc = 0.0
                for k in range(4):
                    acc += a1[k, r] * t1[k, c]
                t2[r, c] = acc
        for r in range(4):
            for c in range(4):
                tg[j, r, c] = g1[r, c] + 0.5 * (t2[r, c] + t2[c, r])
        _matmul4(f, mh, t1, False)
        _matmul4(t1, f, t2, True)
        for r in range(4):
            for c in range(4):
                th[j, r, c] = qq[r, c] + 0.5 * (t2[r, c] + t2[c, r])
        if j >= 2:
            for r in range(4):
                for c in range(4):
                    m[r, c] = tg[j, r, c]
                    t2[r, c] = ta[j, c, r]
            _solve4(m, t2, t1)  # G^-1 A'
            _matmul4(ta[j], t1, t2, False)
            bound = 0.0
            scale = 0.0
            for r in range(4):
                for c in range(4):
                    bound = max(bound, abs(t2[r, c]))
                    scale = max(scale, abs(th[j, r, c]))
            if bound <= FOLLOW_TOLERANCE * scale:
                length = j + 1
                break
    return ta, tg, th, length


@numba.njit(cache=True)
def follow_covariance(model, a, cov, steps, out, work):
    """Covariance of target ``a`` after ``steps >= 1`` steps of being measured at every step,
    starting from the posterior ``cov`` (predict, then update with ``R``, ``steps`` times).

    Uses the composed Riccati maps of :func:`follow_table`: O(1) in ``steps``. ``work`` is
    ``(>= 4, 4, 4)`` scratch.
    """
    x1 = work[3]
    grow_covariance(cov, model.q[a], 1, model.tau, model.c_per_step, x1)
    j = min(steps - 1, model.follow_len[a] - 1)
    _lft_apply(model.follow_a[a, j], model.follow_g[a, j], model.follow_h[a, j], x1, out, work)
    measurement_update(out, model.noise, out)


@numba.njit(cache=True)
def intercept_of(model, sf, a, t):
    """Whole intercept steps from the agent position ``sf`` at step ``t`` to target ``a``'s
    belief mean (``-1``: the target is faster than the agent)."""
    m = model.means[a]
    time = t * model.tau
    return intercept_steps(sf[0], sf[1], m[0] + m[2] * time, m[1] + m[3] * time, m[2], m[3],
                           model.speed, model.tau, 0.5 * model.diameter)


@numba.njit(cache=True)
def is_available(model, si, sf, a):
    """Whether target ``a`` is an action of the state: in the action list and either followed
    (``a`` was just found) or interceptable strictly before the end of the budget."""
    t = si[I_STEP]
    if t >= model.n_steps or not (si[I_MASK] >> a) & 1:
        return False
    if a == si[I_LAST]:
        return True
    ic = intercept_of(model, sf, a, t)
    return 0 <= ic < model.n_steps - t


@numba.njit(cache=True)
def expand_action(model, memo, si, sf, base_cov, base_step, a, work):
    """Node expansion of "pursue ``a``", an available action of the state (Sec. IV-C-2).

    Returns ``(intercept_steps, p_find, find_steps, miss_steps)``: the sub-task's durations for
    each outcome, in steps. Following (``a`` was just found) has ``p_find = 1`` and lasts to the
    end of the budget. ``work`` is ``(>= 1, 4, 4)`` scratch.
    """
    t = si[I_STEP]
    left = model.n_steps - t
    if a == si[I_LAST]:
        return 0, 1.0, left, left
    ic = intercept_of(model, sf, a, t)
    start = t + ic
    if base_step[a] == 0 and memo.cutoff[a, start] >= 0:
        cutoff, p, expected = memo.cutoff[a, start], memo.p_find[a, start], memo.expected[a, start]
    else:
        cov = work[0]
        grow_covariance(base_cov[a], model.q[a], start - base_step[a], model.tau,
                        model.c_per_step, cov)
        k, p, expected = coverage_outcome(cov, model.q[a], model.tau, model.c_per_step,
                                          model.speed, model.diameter, left - ic)
        cutoff = int(k)
        if base_step[a] == 0:
            memo.cutoff[a, start] = cutoff
            memo.p_find[a, start] = p
            memo.expected[a, start] = expected
    find_steps = max(1, ic + int(math.floor(expected + 0.5)))
    miss_steps = max(1, ic + cutoff)
    return ic, p, find_steps, miss_steps


@numba.njit(cache=True)
def apply_outcome(model, si, sf, base_cov, base_step, a, found, duration, work):
    """Move the state through the sub-task "pursue ``a``" lasting ``duration`` steps.

    Found: ``a``'s covariance becomes the posterior of a measurement at the end step (or, when
    following, the followed covariance at the end of the budget). Missed: ``a`` leaves the action
    list. The agent ends at ``a``'s estimated position; other beliefs are implicit (they grow
    from their base). ``work`` is ``(>= 5, 4, 4)`` scratch.
    """
    t = si[I_STEP]
    end = t + duration
    if found:
        prior = work[4]
        if a == si[I_LAST]:
            follow_covariance(model, a, base_cov[a], duration, prior, work)
            for i in range(4):
                for j in range(4):
                    base_cov[a, i, j] = prior[i, j]
        else:
            grow_covariance(base_cov[a], model.q[a], end - base_step[a], model.tau,
                            model.c_per_step, prior)
            measurement_update(prior, model.noise, base_cov[a])
        base_step[a] = end
        si[I_LAST] = a
    else:
        si[I_MASK] &= ~(np.int64(1) << a)
        si[I_LAST] = -1
    si[I_STEP] = end
    m = model.means[a]
    sf[0] = m[0] + m[2] * end * model.tau
    sf[1] = m[1] + m[3] * end * model.tau


@numba.njit(cache=True)
def terminal_value(model, base_cov, base_step):
    """``-U``: minus the sum of the position log-determinants at the end of the budget
    (Sec. III), every belief grown in closed form from its base (Algorithm 1, line 17)."""
    total = 0.0
    for i in range(base_cov.shape[0]):
        sxx, sxy, syy = position_covariance_after(base_cov[i], model.q[i],
                                                  float(model.n_steps - base_step[i]), model.tau,
                                                  model.c_per_step)
        total += math.log(sxx * syy - sxy * sxy)
    return -total
