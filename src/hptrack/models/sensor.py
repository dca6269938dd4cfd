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
  (nothing for the paper's sensor; the sub-task MDP's miss branch).

The last five have defaults, the paper's certain detection and no negative information
(`SensorKernels`).

The models: `FootprintSensor` (the paper's): a target within ``w/2`` of the agent is measured as
``z = [x, y] + v``, ``v ~ N(0, R)`` (`hptrack.models.measurement`). `DetectingFootprintSensor`:
the same footprint with a detection probability below one, ``Pd(d)`` at the distance ``d`` from
the footprint's centre (a table, linearly interpolated, its last value held to the edge): a
target inside is detected, and then measured as above, with probability ``Pd(d)`` at each look,
independently (`detection_probability`); a look that does not detect it leaves its belief as it
is, as for a target outside. The mission record holds it only when ``Pd`` is not 1 everywhere.
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
    below one (``d`` the distance from the footprint's centre, m), independently at each look.

    Attributes:
        diameter: ``w``, m; a look may detect a target within ``w/2`` of the agent.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        distances: ``(m,)`` the table's distances from the centre, m, strictly increasing from 0.
        probabilities: ``(m,)`` ``Pd`` at them, in ``[0, 1]`` (linear between rows, the last
            held to ``w/2``; one row: a constant ``Pd``).
        find_factor: the factor of a coverage estimate's chance of a find
            (`pass_detection_factor` of this table for the vehicle's step length).
    """

    diameter: float
    measurement_noise: np.ndarray
    distances: np.ndarray
    probabilities: np.ndarray
    find_factor: float


class NegativeInformationSensor(NamedTuple):
    """`DetectingFootprintSensor`'s detector (any ``Pd``, 1 included) whose look that detects
    nothing conditions the belief on the miss (`hptrack.models.miss_update.miss_update`).

    Attributes: as `DetectingFootprintSensor`'s.
    """

    diameter: float
    measurement_noise: np.ndarray
    distances: np.ndarray
    probabilities: np.ndarray
    find_factor: float


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


class SensorKernels(NamedTuple):
    """The compiled kernels of a sensor model (module docstring); ``draws``, ``detects`` and
    ``find_factor`` default to certain detection, ``informs`` and ``search_missed`` to no
    negative information."""

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
    distances: np.ndarray, probabilities: np.ndarray, radius: float, step: float, offsets
) -> np.ndarray:
    """The chance that one straight pass of the footprint (radius ``radius`` m, a look every
    ``step`` m) detects a target at each lateral offset of ``offsets`` (m) from its line, with
    ``Pd(d)`` at each look independently, averaged over the phase of the looks along the line:
    ``1 - E_phase prod_j (1 - Pd(sqrt(s_j^2 + c^2)))`` over the looks ``s_j`` within the chord.
    """

    def pd(d: np.ndarray) -> np.ndarray:  # `table_probability`, the same interpolation
        return np.interp(d, distances, probabilities)

    out = np.empty(len(offsets))
    for i, c in enumerate(np.asarray(offsets, dtype=float)):
        half = math.sqrt(max(radius * radius - c * c, 0.0))
        looks = 2.0 * half / step
        if looks > MAX_PASS_STEPS:  # a continuum of looks: exp(sum log(1 - Pd) ds / step)
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
        miss = np.where(inside, 1.0 - pd(np.hypot(s, c)), 1.0)
        out[i] = 1.0 - float(np.mean(np.prod(miss, axis=1)))
    return out


def pass_detection_factor(
    distances: np.ndarray, probabilities: np.ndarray, diameter: float, step: float
) -> float:
    """``W_Pd / W_1``: the effective sweep width of one straight pass with ``Pd`` (the integral
    of `pass_probability` over the lateral offset in ``[-w/2, w/2]``) over the same with
    ``Pd = 1`` (less than ``w`` only where a chord is shorter than a step), for looks every
    ``step`` m (the vehicle's ``v_a tau``). A target that one pass of the spiral reaches is
    found with this probability: the coverage estimators' chance of a find is ``factor * F``
    (``docs/model.md``, "Sensor and measurement")."""
    radius = 0.5 * float(diameter)
    offsets = radius * ((np.arange(PASS_OFFSETS) + 0.5) / PASS_OFFSETS)  # symmetric in c
    with_pd = pass_probability(distances, probabilities, radius, float(step), offsets)
    certain_pass = pass_probability(np.zeros(1), np.ones(1), radius, float(step), offsets)
    return float(np.sum(with_pd) / np.sum(certain_pass))


def detecting_sensor(
    diameter: float, noise: np.ndarray, detection_probability: float | Sequence, step: float
) -> DetectingFootprintSensor:
    """The `DetectingFootprintSensor` of a ``detection_probability`` (`detection_table`), its
    ``find_factor`` for looks every ``step`` m."""
    distances, probabilities = detection_table(detection_probability)
    factor = pass_detection_factor(distances, probabilities, diameter, step)
    distances.flags.writeable = False
    probabilities.flags.writeable = False
    return DetectingFootprintSensor(float(diameter), noise, distances, probabilities, factor)


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
