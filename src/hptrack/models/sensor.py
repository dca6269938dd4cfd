"""The sensor part of the mission record (`hptrack.models.mission.Mission`): which targets a
look can measure, the measurement update, and what a look that measures nothing does (paper
Sec. III).

A sensor model is a ``NamedTuple`` class (its fields are its parameters, SI units) registered
with `register_sensor` and its compiled kernels (`SensorKernels`). Compiled code calls them as
``sensor_*(sensor, ...)``, dispatched at compile time on the sensor's class (as the MDPs of
`hptrack.planning.mdp`):

* ``measures(sensor, agent_x, agent_y, x, y) -> bool``: a look from the agent at
  ``(agent_x, agent_y)`` measures a target at ``(x, y)`` (m);
* ``reach(sensor) -> float``: the farthest from the agent a look can measure, m (bounds that
  prune a search use it);
* ``update(sensor, mean, cov, z, mean_out, cov_out)``: the belief after the measurement ``z``;
* ``update_covariance(sensor, cov, out)``: its covariance only (it does not depend on ``z``);
* ``missed(sensor, agent_x, agent_y, mean, cov)``: what a look from the agent at
  ``(agent_x, agent_y)`` that does not measure the target does to its belief in place (nothing
  for the footprint: the paper uses no negative information);
* ``draws(sensor) -> bool``: whether a look needs a uniform draw per target inside its reach to
  decide whether it detects it (a compile-time constant; ``False`` for the paper's sensor);
* ``detects(sensor, agent_x, agent_y, x, y, u) -> bool``: whether a look that ``measures`` the
  target detects it, given the uniform draw ``u`` in ``[0, 1)`` (always, for the paper's);
* ``find_factor(sensor) -> float``: the factor a coverage estimate's chance of a find takes for
  detections below certainty (1 for the paper's sensor; `pass_detection_factor`);
* ``informs(sensor) -> bool``: whether a miss changes a belief (a compile-time constant;
  ``False`` for the paper's sensor, which uses no negative information);
* ``search_missed(sensor, p_find, cov)``: what a coverage sub-task that found its target with
  the chance ``p_find`` and missed does to the covariance predicted to its end, in place
  (nothing for the paper's sensor; the sub-task MDP's miss branch);
* ``hold_looks(sensor) -> int``: the consecutive looks one draw serves while a target stays
  inside (1, independent looks, for every sensor but a `DetectingFootprintSensor` told
  otherwise; `held_draw`).

The last six have defaults, the paper's certain detection, no negative information and
independent looks (`SensorKernels`).

The models: `FootprintSensor` (the paper's): a target within ``w/2`` of the agent is measured as
``z = [x, y] + v``, ``v ~ N(0, R)`` (`hptrack.models.measurement`). `DetectingFootprintSensor`:
the same footprint with a detection probability below one, ``Pd(d)`` at the distance ``d`` from
the footprint's centre (a table, linearly interpolated, its last value held to the edge): a
target inside is detected, and then measured as above, with probability ``Pd(d)`` at each look,
independently or with each draw held over ``hold_looks`` looks (`detection_probability`,
`hold_looks_of`); a look that does not detect it leaves its belief as it is, as for a target
outside. The mission record holds it only when ``Pd`` is not 1 everywhere.
`NegativeInformationSensor` (the scenario's ``negative_information: true``): the same detector
(any ``Pd``, 1 included), whose look that detects nothing updates the belief by the miss
(`hptrack.models.miss_update.miss_update`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.models.measurement import (
    kalman_update,
    table_probability,
    update_covariance,
    within_footprint,
)
from hptrack.models.miss_update import miss_update, scale_position_covariance, search_miss_scale


class FootprintSensor(NamedTuple):
    """A circular footprint that measures every target inside it.

    Attributes:
        diameter: ``w``, m; a target within ``w/2`` of the agent is measured.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
    """

    diameter: float
    measurement_noise: np.ndarray


class DetectingFootprintSensor(NamedTuple):
    """A circular footprint whose looks detect a target inside with a probability ``Pd(d)``
    below one (``d`` the distance from the footprint's centre, m): a look detects a target
    when a uniform draw lies below ``Pd(d)``. The draw is fresh at every look
    (``hold_looks = 1``, independent looks) or held for ``hold_looks`` consecutive looks while
    the target stays inside (misses correlated in time: a target hidden or misclassified at one
    frame tends to stay so at the next).

    Attributes:
        diameter: ``w``, m; a look may detect a target within ``w/2`` of the agent.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        distances: ``(m,)`` the table's distances from the centre, m, strictly increasing from 0.
        probabilities: ``(m,)`` ``Pd`` at them, in ``[0, 1]`` (linear between rows, the last
            held to ``w/2``; one row: a constant ``Pd``).
        find_factor: the factor of a coverage estimate's chance of a find
            (`pass_detection_factor` of this table for the vehicle's step length).
        hold_looks: consecutive looks one draw holds for while a target stays inside (1:
            independent looks; `hold_looks_of` a correlation time).
    """

    diameter: float
    measurement_noise: np.ndarray
    distances: np.ndarray
    probabilities: np.ndarray
    find_factor: float
    hold_looks: int = 1


class NegativeInformationSensor(NamedTuple):
    """`DetectingFootprintSensor`'s detector (any ``Pd``, 1 included) whose look that detects
    nothing conditions the belief on the miss (`hptrack.models.miss_update.miss_update`).

    Attributes: as `DetectingFootprintSensor`'s (its looks independent: ``hold_looks`` 1).
    """

    diameter: float
    measurement_noise: np.ndarray
    distances: np.ndarray
    probabilities: np.ndarray
    find_factor: float
    hold_looks: int = 1


SensorPart = FootprintSensor | DetectingFootprintSensor | NegativeInformationSensor
"""The sensor classes a mission record may hold (a union of the registered ones)."""


@numba.njit(cache=True, inline="always")
def certain_draws(sensor):
    """Default ``draws``: no draw, every look that measures a target detects it."""
    return False


@numba.njit(cache=True, inline="always")
def certain_detects(sensor, agent_x, agent_y, x, y, u):
    """Default ``detects``: always (detection probability 1, the paper's)."""
    return True


@numba.njit(cache=True, inline="always")
def certain_find_factor(sensor):
    """Default ``find_factor``: 1 (a coverage estimate as the paper's)."""
    return 1.0


@numba.njit(cache=True, inline="always")
def uninformed(sensor):
    """Default ``informs``: a miss tells nothing (the paper's)."""
    return False


@numba.njit(cache=True, inline="always")
def search_unchanged(sensor, p_find, cov):
    """Default ``search_missed``: the covariance as predicted (the paper's)."""


@numba.njit(cache=True, inline="always")
def independent_looks(sensor):
    """Default ``hold_looks``: 1, every look draws afresh."""
    return 1


class SensorKernels(NamedTuple):
    """The compiled kernels of a sensor model (module docstring); ``draws``, ``detects`` and
    ``find_factor`` default to certain detection, ``informs`` and ``search_missed`` to no
    negative information, ``hold_looks`` to independent looks."""

    measures: Callable
    reach: Callable
    update: Callable
    update_covariance: Callable
    missed: Callable
    draws: Callable = certain_draws
    detects: Callable = certain_detects
    find_factor: Callable = certain_find_factor
    informs: Callable = uninformed
    search_missed: Callable = search_unchanged
    hold_looks: Callable = independent_looks


_SENSORS: dict[type, SensorKernels] = {}


def register_sensor(sensor_class: type, kernels: SensorKernels) -> None:
    """Make ``kernels`` the sensing of ``sensor_class``."""
    _SENSORS[sensor_class] = kernels


def _kernel(sensor, field: str):
    return getattr(registered(_SENSORS, sensor, "sensor model"), field).py_func


def sensor_measures(sensor, agent_x, agent_y, x, y):
    """The registered ``measures`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_reach(sensor):
    """The registered ``reach`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_update(sensor, mean, cov, z, mean_out, cov_out):
    """The registered ``update`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_update_covariance(sensor, cov, out):
    """The registered ``update_covariance`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_missed(sensor, agent_x, agent_y, mean, cov):
    """The registered ``missed`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_draws(sensor):
    """The registered ``draws`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_detects(sensor, agent_x, agent_y, x, y, u):
    """The registered ``detects`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_find_factor(sensor):
    """The registered ``find_factor`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_informs(sensor):
    """The registered ``informs`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_search_missed(sensor, p_find, cov):
    """The registered ``search_missed`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


def sensor_hold_looks(sensor):
    """The registered ``hold_looks`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


@overload(sensor_hold_looks, inline="always")
def _hold_looks(sensor):
    return _kernel(sensor, "hold_looks")


@overload(sensor_informs, inline="always")
def _informs(sensor):
    return _kernel(sensor, "informs")


@overload(sensor_search_missed, inline="always")
def _search_missed(sensor, p_find, cov):
    return _kernel(sensor, "search_missed")


@overload(sensor_draws, inline="always")
def _draws(sensor):
    return _kernel(sensor, "draws")


@overload(sensor_detects, inline="always")
def _detects(sensor, agent_x, agent_y, x, y, u):
    return _kernel(sensor, "detects")


@overload(sensor_find_factor, inline="always")
def _find_factor(sensor):
    return _kernel(sensor, "find_factor")


@overload(sensor_measures, inline="always")
def _measures(sensor, agent_x, agent_y, x, y):
    return _kernel(sensor, "measures")


@overload(sensor_reach, inline="always")
def _reach(sensor):
    return _kernel(sensor, "reach")


@overload(sensor_update, inline="always")
def _update(sensor, mean, cov, z, mean_out, cov_out):
    return _kernel(sensor, "update")


@overload(sensor_update_covariance, inline="always")
def _update_covariance(sensor, cov, out):
    return _kernel(sensor, "update_covariance")


@overload(sensor_missed, inline="always")
def _missed(sensor, agent_x, agent_y, mean, cov):
    return _kernel(sensor, "missed")


@numba.njit(cache=True, inline="always")
def footprint_radius(sensor):
    """``w / 2`` of a `FootprintSensor`, m."""
    return 0.5 * sensor.diameter


@numba.njit(cache=True, inline="always")
def footprint_measures(sensor, agent_x, agent_y, x, y):
    """`FootprintSensor`: ``|p - agent| <= w/2`` (`within_footprint`)."""
    return within_footprint(sensor.diameter, agent_x, agent_y, x, y)


@numba.njit(cache=True)
def footprint_update(sensor, mean, cov, z, mean_out, cov_out):
    """`FootprintSensor`: the Kalman update with ``R`` (`kalman_update`)."""
    kalman_update(mean, cov, z, sensor.measurement_noise, mean_out, cov_out)


@numba.njit(cache=True)
def footprint_update_covariance(sensor, cov, out):
    """`FootprintSensor`: the covariance of the Kalman update (`update_covariance`)."""
    update_covariance(cov, sensor.measurement_noise, out)


@numba.njit(cache=True, inline="always")
def footprint_missed(sensor, agent_x, agent_y, mean, cov):
    """`FootprintSensor`: a look that misses leaves the belief as it is."""


register_sensor(
    FootprintSensor,
    SensorKernels(
        footprint_measures,
        footprint_radius,
        footprint_update,
        footprint_update_covariance,
        footprint_missed,
    ),
)


@numba.njit(cache=True, inline="always")
def detecting_draws(sensor):
    """`DetectingFootprintSensor`: one uniform per target inside the footprint."""
    return True


@numba.njit(cache=True, inline="always")
def detecting_detects(sensor, agent_x, agent_y, x, y, u):
    """`DetectingFootprintSensor`: ``u < Pd(d)``, ``d = |p - agent|`` (the rule, once)."""
    d = math.hypot(x - agent_x, y - agent_y)
    return u < table_probability(sensor.distances, sensor.probabilities, d)


@numba.njit(cache=True, inline="always")
def detecting_find_factor(sensor):
    """`DetectingFootprintSensor`: its ``find_factor`` field."""
    return sensor.find_factor


@numba.njit(cache=True, inline="always")
def detecting_hold_looks(sensor):
    """`DetectingFootprintSensor`: its ``hold_looks`` field."""
    return sensor.hold_looks


register_sensor(
    DetectingFootprintSensor,
    SensorKernels(
        footprint_measures,
        footprint_radius,
        footprint_update,
        footprint_update_covariance,
        footprint_missed,
        detecting_draws,
        detecting_detects,
        detecting_find_factor,
        hold_looks=detecting_hold_looks,
    ),
)


@numba.njit(cache=True)
def negative_missed(sensor, agent_x, agent_y, mean, cov):
    """`NegativeInformationSensor`: the miss update over the footprint (`miss_update`)."""
    miss_update(
        mean, cov, agent_x, agent_y, 0.5 * sensor.diameter, sensor.distances, sensor.probabilities
    )


@numba.njit(cache=True, inline="always")
def negative_informs(sensor):
    """`NegativeInformationSensor`: a miss changes the belief."""
    return True


@numba.njit(cache=True)
def negative_search_missed(sensor, p_find, cov):
    """`NegativeInformationSensor`: the closed form of the spiral's miss
    (`search_miss_scale`, `scale_position_covariance`)."""
    scale_position_covariance(cov, search_miss_scale(p_find, sensor.find_factor))


register_sensor(
    NegativeInformationSensor,
    SensorKernels(
        footprint_measures,
        footprint_radius,
        footprint_update,
        footprint_update_covariance,
        negative_missed,
        detecting_draws,
        detecting_detects,
        detecting_find_factor,
        negative_informs,
        negative_search_missed,
    ),
)


def detection_table(detection_probability: float | Sequence) -> tuple[np.ndarray, np.ndarray]:
    """``(distances, probabilities)`` of a ``detection_probability``: a number in ``(0, 1]``
    (one row at distance 0) or rows ``[distance from the footprint's centre (m), Pd]``,
    distances strictly increasing from 0, ``Pd`` in ``[0, 1]``.

    Raises:
        ValueError: naming what is wrong, in one line.
    """
    if isinstance(detection_probability, bool | str | bytes | dict):
        raise ValueError(
            f"expected a number in (0, 1] or rows [distance_m, Pd], value {detection_probability!r}"
        )
    if isinstance(detection_probability, int | float | np.number):
        p = float(detection_probability)
        if not (math.isfinite(p) and 0.0 < p <= 1.0):
            raise ValueError(f"a detection probability must be in (0, 1], value {p!r}")
        return np.zeros(1), np.array([p])
    try:
        rows = [tuple(row) for row in detection_probability]
    except TypeError:
        raise ValueError(
            f"expected a number in (0, 1] or rows [distance_m, Pd], value {detection_probability!r}"
        ) from None
    if not rows:
        raise ValueError("the table has no rows; give rows [distance_m, Pd]")
    values = []
    for i, row in enumerate(rows):
        if len(row) != 2 or any(
            isinstance(v, bool) or not isinstance(v, int | float | np.number) for v in row
        ):
            raise ValueError(f"row {i} must be two numbers [distance_m, Pd], value {list(row)!r}")
        values.append((float(row[0]), float(row[1])))
    table = np.array(values)
    distances, probabilities = table[:, 0].copy(), table[:, 1].copy()
    if not np.all(np.isfinite(table)):
        raise ValueError(f"the table's entries must be finite, value {table.tolist()}")
    if distances[0] != 0.0:
        raise ValueError(f"the first distance must be 0 m, value {distances[0]:g}")
    if np.any(np.diff(distances) <= 0.0):
        raise ValueError(f"the distances must increase strictly, value {distances.tolist()}")
    if np.any((probabilities < 0.0) | (probabilities > 1.0)):
        raise ValueError(f"each Pd must be in [0, 1], value {probabilities.tolist()}")
    if not np.any(probabilities > 0.0):
        raise ValueError("every Pd is 0: such a sensor never detects anything")
    return distances, probabilities


def certain(detection_probability: float | Sequence) -> bool:
    """Whether a ``detection_probability`` is 1 everywhere (the paper's sensor)."""
    return bool(np.all(detection_table(detection_probability)[1] == 1.0))


PASS_OFFSETS = 400
"""Lateral offsets of the pass integral of `pass_detection_factor` (midpoints)."""
PASS_PHASES = 64
"""Phases of the steps along a pass averaged over (midpoints)."""
MAX_PASS_STEPS = 20_000
"""Steps across the footprint above which a pass is integrated as a continuum."""


def pass_probability(
    distances: np.ndarray,
    probabilities: np.ndarray,
    radius: float,
    step: float,
    offsets,
    hold_looks: int = 1,
) -> np.ndarray:
    """The chance that one straight pass of the footprint (radius ``radius`` m, a look every
    ``step`` m) detects a target at each lateral offset of ``offsets`` (m) from its line,
    averaged over the phase of the looks along the line. With independent looks
    (``hold_looks = 1``) it is ``1 - E_phase prod_j (1 - Pd(sqrt(s_j^2 + c^2)))`` over the looks
    ``s_j`` within the chord; with one draw held for ``hold_looks`` looks from the target's
    entry, the looks form blocks of that many and a block misses with ``1 - max Pd`` over its
    looks (its draw ``u`` detects at a look where ``u < Pd``).
    """

    def pd(d: np.ndarray) -> np.ndarray:  # `table_probability`, the same interpolation
        return np.interp(d, distances, probabilities)

    out = np.empty(len(offsets))
    for i, c in enumerate(np.asarray(offsets, dtype=float)):
        half = math.sqrt(max(radius * radius - c * c, 0.0))
        looks = 2.0 * half / step
        if looks > MAX_PASS_STEPS and hold_looks == 1:  # a continuum: exp(sum log(1 - Pd) ds)
            s = np.linspace(-half, half, 4001)
            with np.errstate(divide="ignore"):
                log_miss = np.log1p(-np.minimum(pd(np.hypot(s, c)), 1.0))
            total = np.trapezoid(log_miss, s) / step if np.all(np.isfinite(log_miss)) else -np.inf
            out[i] = -math.expm1(total)
            continue
        phases = (np.arange(PASS_PHASES) + 0.5) / PASS_PHASES
        first = -half + phases * step  # the first look inside the chord, per phase
        count = int(math.floor(looks)) + 1
        s = first[:, None] + step * np.arange(count)[None, :]
        inside = s <= half
        detect = np.where(inside, pd(np.hypot(s, c)), 0.0)
        if hold_looks > 1:  # each block of held looks detects with its largest Pd
            blocks = -(-count // hold_looks)
            padded = np.zeros((PASS_PHASES, blocks * hold_looks))
            padded[:, :count] = detect
            detect = padded.reshape(PASS_PHASES, blocks, hold_looks).max(axis=2)
        out[i] = 1.0 - float(np.mean(np.prod(1.0 - detect, axis=1)))
    return out


def hold_looks_of(correlation_time: float, time_step: float) -> int:
    """The looks one detection draw holds for: those within ``correlation_time`` s of the
    first, a look every ``time_step`` s (1 for a correlation time of 0: independent looks)."""
    return max(1, math.ceil(float(correlation_time) / float(time_step) - 1e-9))


def pass_detection_factor(
    distances: np.ndarray,
    probabilities: np.ndarray,
    diameter: float,
    step: float,
    hold_looks: int = 1,
) -> float:
    """``W_Pd / W_1``: the effective sweep width of one straight pass with ``Pd`` (the integral
    of `pass_probability` over the lateral offset in ``[-w/2, w/2]``) over the same with
    ``Pd = 1`` (less than ``w`` only where a chord is shorter than a step), for looks every
    ``step`` m (the vehicle's ``v_a tau``). A target that one pass of the spiral reaches is
    found with this probability: the coverage estimators' chance of a find is ``factor * F``
    (``docs/model.md``, "Sensor and measurement")."""
    radius = 0.5 * float(diameter)
    offsets = radius * ((np.arange(PASS_OFFSETS) + 0.5) / PASS_OFFSETS)  # symmetric in c
    with_pd = pass_probability(distances, probabilities, radius, float(step), offsets, hold_looks)
    certain_pass = pass_probability(np.zeros(1), np.ones(1), radius, float(step), offsets)
    return float(np.sum(with_pd) / np.sum(certain_pass))


def detecting_sensor(
    diameter: float,
    noise: np.ndarray,
    detection_probability: float | Sequence,
    step: float,
    hold_looks: int = 1,
) -> DetectingFootprintSensor:
    """The `DetectingFootprintSensor` of a ``detection_probability`` (`detection_table`), its
    ``find_factor`` for looks every ``step`` m, each draw held for ``hold_looks`` looks."""
    distances, probabilities = detection_table(detection_probability)
    factor = pass_detection_factor(distances, probabilities, diameter, step, hold_looks)
    distances.flags.writeable = False
    probabilities.flags.writeable = False
    return DetectingFootprintSensor(
        float(diameter), noise, distances, probabilities, factor, int(hold_looks)
    )


def negative_information_sensor(
    diameter: float, noise: np.ndarray, detection_probability: float | Sequence, step: float
) -> NegativeInformationSensor:
    """The `NegativeInformationSensor` of a ``detection_probability`` (as `detecting_sensor`)."""
    return NegativeInformationSensor(
        *detecting_sensor(diameter, noise, detection_probability, step)
    )


@numba.njit(cache=True)
def informs_misses(sensor):
    """Whether a miss changes a belief with ``sensor`` (`sensor_informs`, for Python
    callers)."""
    return sensor_informs(sensor)


@numba.njit(cache=True)
def look_missed(sensor, agent_x, agent_y, mean, cov):
    """``sensor``'s ``missed`` of a look from ``(agent_x, agent_y)`` m, in place (for Python
    callers)."""
    sensor_missed(sensor, agent_x, agent_y, mean, cov)


@numba.njit(cache=True)
def draws_detection(sensor):
    """Whether ``sensor`` draws a uniform per target inside its footprint (`sensor_draws`, for
    Python callers)."""
    return sensor_draws(sensor)


@numba.njit(cache=True)
def detection_hold(sensor):
    """The looks one detection draw of ``sensor`` holds for (`sensor_hold_looks`, for Python
    callers; 1: independent looks)."""
    return sensor_hold_looks(sensor)


@numba.njit(cache=True)
def held_draw(held, i, draw, hold_looks, inside):
    """The detection draw of target ``i`` at this look: ``draw`` (a fresh uniform) with
    independent looks, else the draw ``held[i, 0]`` taken at the first of at most
    ``hold_looks`` consecutive looks with the target inside (``held[i, 1]``: the looks it has
    served; a target outside starts afresh at its next look inside). ``NaN`` outside."""
    if hold_looks <= 1:
        return draw
    if not inside:
        held[i, 1] = 0.0
        return math.nan
    if held[i, 1] <= 0.0 or held[i, 1] >= hold_looks:
        held[i, 0] = draw
        held[i, 1] = 0.0
    held[i, 1] += 1.0
    return held[i, 0]


REPEAT_ANGLES = 32
"""Directions of the half turn `repeat_pass_share` averages over (midpoints)."""
REPEAT_RADII = 8
"""Radii of the whitened belief it averages over (midpoints of the Rayleigh quantiles)."""
REPEAT_DRIFTS = (-1.6506801238857844, -0.5246476232752904, 0.5246476232752904,
                 1.6506801238857844)  # fmt: skip
"""Gauss-Hermite nodes (probabilists') of the radial drift's own noise."""
REPEAT_DRIFT_WEIGHTS = (0.045875854768068, 0.454124145231932, 0.454124145231932,
                        0.045875854768068)  # fmt: skip
"""Their weights (sum 1)."""


@numba.njit(cache=True)
def repeat_pass_share(pass_find, cov, speed, diameter):
    """The chance that a target the elliptic spiral covers is detected when each pass of the
    footprint over it detects with ``pass_find`` on its own (a draw held within a pass), for
    the belief covariance ``cov`` (``d x d``, position then velocity) at the start of the
    coverage, the vehicle's ``speed`` (m/s) and the footprint's ``diameter`` (m).

    In the whitened position ``z = L^-1 (x - mean)`` (``L = [u1 u2] diag(A, B)``, the spiral's
    axes, `hptrack.coverage.spiral`) the belief is ``N(0, I)`` and the spiral ``|z| = b
    theta``, its loops ``w / A`` apart (``b = w / (2 pi A)``, Eq. (4)). The footprint spans
    ``m(theta) = sqrt(cos^2 theta + (A/B)^2 sin^2 theta)`` loop spacings across the track, so a
    still point lies under ``m`` passes. A target drifts: its velocity error, given its
    position, has the mean ``K (x - mean)`` (``K = P_vp P_pp^-1``) and the covariance ``P_vv -
    K P_pv``, so its radial speed in ``z`` is ``u`` while the loops advance at ``v_f = (w / A)
    v_a / (|z| P)`` (``P`` the perimeter of the ``A, B`` ellipse); it stays under the front
    ``v_f / (v_f - u)`` times as many loops (a target that outruns the front is not covered and
    not counted). ``N = m v_f / (v_f - u)`` passes detect it with ``1 - (1 - p)^floor(N) (1 -
    (N - floor(N)) p)``; the share is its mean over direction, radius and the drift's noise,
    over the covered targets."""
    sxx, sxy, syy = cov[0, 0], cov[0, 1], cov[1, 1]
    tr = 0.5 * (sxx + syy)
    gap = math.sqrt(max(tr * tr - (sxx * syy - sxy * sxy), 0.0))
    lam1 = tr + gap
    lam2 = max(tr - gap, 1e-12 * lam1)
    semi_a, semi_b = math.sqrt(lam1), math.sqrt(lam2)
    if gap > 0.0:  # the major axis u1
        ux, uy = sxy, lam1 - sxx
        if abs(ux) + abs(uy) == 0.0:
            ux, uy = lam1 - syy, sxy
        norm = math.hypot(ux, uy)
        ux, uy = ux / norm, uy / norm
    else:
        ux, uy = 1.0, 0.0
    # K = P_vp P_pp^-1 and the velocity's residual covariance (none without a velocity)
    k00 = k01 = k10 = k11 = r00 = r01 = r11 = 0.0
    if cov.shape[0] >= 4:
        det = sxx * syy - sxy * sxy
        ixx, ixy, iyy = syy / det, -sxy / det, sxx / det
        k00 = cov[2, 0] * ixx + cov[2, 1] * ixy
        k01 = cov[2, 0] * ixy + cov[2, 1] * iyy
        k10 = cov[3, 0] * ixx + cov[3, 1] * ixy
        k11 = cov[3, 0] * ixy + cov[3, 1] * iyy
        r00 = cov[2, 2] - (k00 * cov[0, 2] + k01 * cov[1, 2])
        r01 = cov[2, 3] - (k00 * cov[0, 3] + k01 * cov[1, 3])
        r11 = cov[3, 3] - (k10 * cov[0, 3] + k11 * cov[1, 3])
    ratio2 = lam1 / lam2
    perimeter = math.pi * (3.0 * (semi_a + semi_b) - math.sqrt(
        (3.0 * semi_a + semi_b) * (semi_a + 3.0 * semi_b)))  # fmt: skip
    front = (diameter / semi_a) * speed / perimeter  # v_f |z|, whitened units per s
    miss = 1.0 - pass_find
    total = 0.0
    weight = 0.0
    for j in range(REPEAT_ANGLES):
        theta = math.pi * (j + 0.5) / REPEAT_ANGLES
        c, s = math.cos(theta), math.sin(theta)
        m = math.sqrt(1.0 + (ratio2 - 1.0) * s * s)
        # the whitened direction e and the physical offset per unit radius x = L e
        px = semi_a * c * ux - semi_b * s * uy
        py = semi_a * c * uy + semi_b * s * ux
        # the radial speed per unit radius: e . L^-1 K L e; its noise: e . L^-1 R L^-T e
        vx = k00 * px + k01 * py
        vy = k10 * px + k11 * py
        # e . L^-1 v = (u1 . v) c / A + (u2 . v) s / B, u2 = (-uy, ux)
        drift = (ux * vx + uy * vy) * c / semi_a + (-uy * vx + ux * vy) * s / semi_b
        ax = ux * c / semi_a - uy * s / semi_b  # L^-T e, for the noise's variance
        ay = uy * c / semi_a + ux * s / semi_b
        noise = math.sqrt(max(ax * ax * r00 + 2.0 * ax * ay * r01 + ay * ay * r11, 0.0))
        for i in range(REPEAT_RADII):
            radius = math.sqrt(-2.0 * math.log(1.0 - (i + 0.5) / REPEAT_RADII))
            v_f = front / radius
            for h in range(4):
                u = drift * radius + noise * REPEAT_DRIFTS[h]
                if u >= v_f:
                    continue
                passes = m * v_f / (v_f - u)
                whole = math.floor(passes)
                w = REPEAT_DRIFT_WEIGHTS[h]
                total += w * (1.0 - miss**whole * (1.0 - (passes - whole) * pass_find))
                weight += w
    if weight == 0.0:
        return pass_find
    return total / weight


@numba.njit(cache=True, inline="always")
def held_find_share(sensor, cov, speed):
    """The factor of a coverage estimate's chance of a find when the sensor's draws hold over
    a pass (`repeat_pass_share` of its ``find_factor`` for the belief ``cov`` at the start of
    the coverage and the vehicle's ``speed``, m/s); 1 for independent looks, whose factor
    enters as a sweep width."""
    if sensor_hold_looks(sensor) <= 1:
        return 1.0
    return repeat_pass_share(sensor_find_factor(sensor), cov, speed, sensor.diameter)


@numba.njit(cache=True)
def held_draws(held, inside, fresh, hold_looks):
    """`held_draw` for every target of a look: ``inside`` ``(n,)`` which are in the footprint,
    ``fresh`` one uniform per target inside (target order); returns their draws."""
    out = np.empty(fresh.shape[0])
    k = 0
    for i in range(inside.shape[0]):
        if inside[i]:
            out[k] = held_draw(held, i, fresh[k], hold_looks, True)
            k += 1
        else:
            held_draw(held, i, 0.0, hold_looks, False)
    return out


@numba.njit(cache=True)
def _detected(sensor, agent, positions, u, out):
    for i in range(positions.shape[0]):
        ax, ay, x, y = agent[0], agent[1], positions[i, 0], positions[i, 1]
        out[i] = sensor_measures(sensor, ax, ay, x, y) and sensor_detects(
            sensor, ax, ay, x, y, u[i]
        )


def detected_mask(
    sensor: tuple, agent_position: np.ndarray, positions: np.ndarray, uniforms: np.ndarray
) -> np.ndarray:
    """Which positions ``(n, 2)`` (m) a look from ``agent_position`` detects, given one uniform
    in ``[0, 1)`` per position ``(n,)``: measured (`measured_mask`) and ``sensor_detects``."""
    points = np.ascontiguousarray(np.asarray(positions, dtype=float).reshape(-1, 2))
    out = np.empty(points.shape[0], dtype=np.bool_)
    u = np.ascontiguousarray(np.asarray(uniforms, dtype=float).reshape(-1))
    _detected(sensor, np.asarray(agent_position, dtype=float), points, u, out)
    return out


@numba.njit(cache=True)
def _measured(sensor, agent, positions, out):
    for i in range(positions.shape[0]):
        out[i] = sensor_measures(sensor, agent[0], agent[1], positions[i, 0], positions[i, 1])


def measured_mask(sensor: tuple, agent_position: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Which positions ``(n, 2)`` (m) a look from ``agent_position`` ``(2,)`` measures, ``(n,)``
    booleans (the numpy face of `sensor_measures`)."""
    points = np.ascontiguousarray(np.asarray(positions, dtype=float).reshape(-1, 2))
    out = np.empty(points.shape[0], dtype=np.bool_)
    _measured(sensor, np.asarray(agent_position, dtype=float), points, out)
    return out
