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
* ``missed(sensor, mean, cov)``: what a look that does not measure the target does to its belief
  in place (nothing for the footprint: the paper uses no negative information).

The model: `FootprintSensor` (the paper's): a target within ``w/2`` of the agent is measured as
``z = [x, y] + v``, ``v ~ N(0, R)`` (`hptrack.models.measurement`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.models.measurement import kalman_update, update_covariance, within_footprint


class FootprintSensor(NamedTuple):
    """A circular footprint that measures every target inside it.

    Attributes:
        diameter: ``w``, m; a target within ``w/2`` of the agent is measured.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
    """

    diameter: float
    measurement_noise: np.ndarray


SensorPart = FootprintSensor
"""The sensor classes a mission record may hold (a union of the registered ones)."""


class SensorKernels(NamedTuple):
    """The compiled kernels of a sensor model (module docstring)."""

    measures: Callable
    reach: Callable
    update: Callable
    update_covariance: Callable
    missed: Callable


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


def sensor_missed(sensor, mean, cov):
    """The registered ``missed`` of ``sensor``'s class (compiled code only)."""
    raise NotImplementedError


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
def _missed(sensor, mean, cov):
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
def footprint_missed(sensor, mean, cov):
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
