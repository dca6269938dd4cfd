"""The vehicle part of the mission record (`hptrack.models.mission.Mission`): how the agent moves
and how soon it can meet a moving point (paper Sec. III, IV-C "Node Expansion").

A vehicle model is a ``NamedTuple`` class (its fields are its parameters, SI units) registered
with `register_vehicle` and its compiled kernels (`VehicleKernels`). Compiled code calls them as
``vehicle_*(vehicle, ...)``, dispatched at compile time on the vehicle's class (as the MDPs of
`hptrack.planning.mdp`):

* ``move(vehicle, agent, waypoint)``: one step of ``tau`` towards ``waypoint`` (2,), ``agent``
  (2,) in place;
* ``intercept_time(vehicle, agent_x, agent_y, x, y, vx, vy) -> t``: the earliest time (s) at
  which the agent can be where a point from ``(x, y)`` moving at ``(vx, vy)`` is (``inf``:
  never);
* ``approach_step(vehicle, agent_x, agent_y, x, y, vx, vy, tau, steps) -> (dx, dy)``: the
  agent's displacement per step relative to that point on an intercept flight of ``steps``
  whole steps;
* ``open_space(vehicle) -> bool``: whether the vehicle may fly anywhere (a compile-time
  constant; ``True``, the default);
* ``sees(vehicle, x, y, radius) -> bool``: whether a footprint of ``radius`` m flown where the
  vehicle may fly can cover ``(x, y)`` (always, the default);
* ``flies_straight_between(vehicle, ax, ay, bx, by) -> bool``: whether the vehicle may fly the
  straight segment from ``(ax, ay)`` to ``(bx, by)`` (m) as it is (always, the default).

The models: `HolonomicVehicle` (the paper's): a point that flies straight at up to ``v_a``.
Interception, with ``d = mean - agent`` and the point's velocity ``v_hat``: the smallest
``t >= 0`` with ``|d + v_hat t| = v_a t``, i.e. ``(v_a^2 - |v_hat|^2) t^2 - 2 (d . v_hat) t -
|d|^2 = 0``, whose only non-negative root exists for every ``d`` when ``|v_hat| < v_a``.

`FencedHolonomicVehicle`: the same point kept inside a fence (`hptrack.models.fence`): it flies
the shortest free flight towards its waypoint (or towards the nearest free point when the
waypoint is not free), turning at the fence's corners within a step. Its intercept time is the
``t`` at which the shortest free flight to where the point will be (its nearest free point) is
``v_a t`` long, found by the fixed-point iteration ``t <- L(t) / v_a`` from the straight
intercept: ``L`` changes by at most ``|v_hat|`` per second, so the map contracts by
``|v_hat| / v_a < 1`` and the root is unique. Its ``approach_step`` is the straight one (the
relative motion of the flight's last leg is taken as that of a straight flight).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.models.fence import (
    Fence,
    fenced_route,
    nearest_free,
    point_free,
    sees,
    segment_free,
)


class HolonomicVehicle(NamedTuple):
    """A point that flies straight at up to its speed in any direction.

    Attributes:
        speed: ``v_a``, m/s.
        step_length: the largest displacement per step ``v_a tau``, m.
    """

    speed: float
    step_length: float


class FencedHolonomicVehicle(NamedTuple):
    """A point that flies at up to its speed in any direction the fence allows.

    Attributes:
        speed: ``v_a``, m/s.
        step_length: the largest displacement per step ``v_a tau``, m.
        fence: where it may fly (`hptrack.models.fence.Fence`).
    """

    speed: float
    step_length: float
    fence: Fence


VehiclePart = HolonomicVehicle | FencedHolonomicVehicle
"""The vehicle classes a mission record may hold (a union of the registered ones)."""


@numba.njit(cache=True, inline="always")
def anywhere(vehicle):
    """Default ``open_space``: the vehicle may fly anywhere."""
    return True


@numba.njit(cache=True, inline="always")
def sees_anything(vehicle, x, y, radius):
    """Default ``sees``: every point can be covered."""
    return True


@numba.njit(cache=True, inline="always")
def any_segment(vehicle, ax, ay, bx, by):
    """Default ``flies_straight_between``: every straight segment may be flown."""
    return True


class VehicleKernels(NamedTuple):
    """The compiled kernels of a vehicle model (module docstring); ``open_space``,
    ``sees`` and ``flies_straight_between`` default to open space."""

    move: Callable
    intercept_time: Callable
    approach_step: Callable
    open_space: Callable = anywhere
    sees: Callable = sees_anything
    flies_straight_between: Callable = any_segment


_VEHICLES: dict[type, VehicleKernels] = {}


def register_vehicle(vehicle_class: type, kernels: VehicleKernels) -> None:
    """Make ``kernels`` the motion of ``vehicle_class``."""
    _VEHICLES[vehicle_class] = kernels


def _kernel(vehicle, field: str):
    return getattr(registered(_VEHICLES, vehicle, "vehicle model"), field).py_func


def vehicle_move(vehicle, agent, waypoint):
    """The registered ``move`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


def vehicle_intercept_time(vehicle, agent_x, agent_y, x, y, vx, vy):
    """The registered ``intercept_time`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


def vehicle_approach_step(vehicle, agent_x, agent_y, x, y, vx, vy, tau, steps):
    """The registered ``approach_step`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


def vehicle_open_space(vehicle):
    """The registered ``open_space`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


def vehicle_sees(vehicle, x, y, radius):
    """The registered ``sees`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


def vehicle_flies_straight_between(vehicle, ax, ay, bx, by):
    """The registered ``flies_straight_between`` of ``vehicle``'s class (compiled code only)."""
    raise NotImplementedError


@overload(vehicle_flies_straight_between, inline="always")
def _flies_straight_between(vehicle, ax, ay, bx, by):
    return _kernel(vehicle, "flies_straight_between")


@overload(vehicle_open_space, inline="always")
def _open_space(vehicle):
    return _kernel(vehicle, "open_space")


@overload(vehicle_sees, inline="always")
def _sees(vehicle, x, y, radius):
    return _kernel(vehicle, "sees")


@overload(vehicle_move, inline="always")
def _move(vehicle, agent, waypoint):
    return _kernel(vehicle, "move")


@overload(vehicle_intercept_time, inline="always")
def _intercept_time(vehicle, agent_x, agent_y, x, y, vx, vy):
    return _kernel(vehicle, "intercept_time")


@overload(vehicle_approach_step, inline="always")
def _approach_step(vehicle, agent_x, agent_y, x, y, vx, vy, tau, steps):
    return _kernel(vehicle, "approach_step")


@numba.njit(cache=True)
def move_agent(agent, waypoint, max_step):
    """Holonomic move in place: straight towards ``waypoint`` by at most ``max_step`` m."""
    dx = waypoint[0] - agent[0]
    dy = waypoint[1] - agent[1]
    dist = math.hypot(dx, dy)
    if dist <= max_step:
        agent[0] = waypoint[0]
        agent[1] = waypoint[1]
    else:
        scale = max_step / dist
        agent[0] = agent[0] + dx * scale
        agent[1] = agent[1] + dy * scale


def move_towards(position: np.ndarray, waypoint: np.ndarray, max_step: float) -> np.ndarray:
    """Holonomic move: a new position straight towards ``waypoint`` by at most ``max_step`` m
    (`move_agent` on a copy)."""
    agent = np.array(position, dtype=float)
    move_agent(agent, np.asarray(waypoint, dtype=float), float(max_step))
    return agent


@numba.njit(cache=True)
def intercept_time(
    agent_x: float,
    agent_y: float,
    mean_x: float,
    mean_y: float,
    vel_x: float,
    vel_y: float,
    speed: float,
) -> float:
    """Smallest ``t >= 0`` (s) with ``|mean + vel t - agent| = speed t`` (closed form, module
    docstring).

    Positions in m, velocities in m/s. Returns ``inf`` when ``|vel| >= speed`` (the target cannot
    be caught for sure) and ``0`` when the agent is on the mean.
    """
    dx = mean_x - agent_x
    dy = mean_y - agent_y
    closing = speed * speed - (vel_x * vel_x + vel_y * vel_y)
    if closing <= 0.0:
        return math.inf
    dd = dx * dx + dy * dy
    if dd == 0.0:
        return 0.0
    dv = dx * vel_x + dy * vel_y
    root = math.sqrt(dv * dv + closing * dd)
    # Two algebraically equal forms of the positive root; each avoids cancellation on its side.
    if dv >= 0.0:
        return (dv + root) / closing
    return dd / (root - dv)


@numba.njit(cache=True)
def approach_step(
    agent_x: float,
    agent_y: float,
    mean_x: float,
    mean_y: float,
    vel_x: float,
    vel_y: float,
    speed: float,
    tau: float,
    steps: int,
) -> tuple:
    """The agent's displacement per step relative to the belief mean during an intercept flight
    of ``steps`` whole steps, m: ``v_a tau u - v_hat tau`` with ``u`` the unit vector towards the
    mean at step ``steps``. ``(0, 0)`` when ``steps <= 0``."""
    if steps <= 0:
        return 0.0, 0.0
    dx = mean_x + vel_x * steps * tau - agent_x
    dy = mean_y + vel_y * steps * tau - agent_y
    length = math.hypot(dx, dy)
    return speed * tau * dx / length - vel_x * tau, speed * tau * dy / length - vel_y * tau


@numba.njit(cache=True, inline="always")
def holonomic_move(vehicle, agent, waypoint):
    """`HolonomicVehicle`: `move_agent` by at most ``v_a tau``."""
    move_agent(agent, waypoint, vehicle.step_length)


@numba.njit(cache=True, inline="always")
def holonomic_intercept_time(vehicle, agent_x, agent_y, x, y, vx, vy):
    """`HolonomicVehicle`: the closed-form `intercept_time` at ``v_a``."""
    return intercept_time(agent_x, agent_y, x, y, vx, vy, vehicle.speed)


@numba.njit(cache=True, inline="always")
def holonomic_approach_step(vehicle, agent_x, agent_y, x, y, vx, vy, tau, steps):
    """`HolonomicVehicle`: `approach_step` at ``v_a``."""
    return approach_step(agent_x, agent_y, x, y, vx, vy, vehicle.speed, tau, steps)


register_vehicle(
    HolonomicVehicle,
    VehicleKernels(holonomic_move, holonomic_intercept_time, holonomic_approach_step),
)


FIXED_POINT_ROUNDS = 200
"""Most rounds of the fenced intercept's fixed-point iteration (it converges geometrically)."""


@numba.njit(cache=True)
def move_fenced(fence, step_length, agent, waypoint):
    """In place: by at most ``step_length`` m along the shortest free flight of ``fence``
    towards ``waypoint`` (its nearest free point), through as many corners as the step
    reaches; from a point that is not free, straight towards the nearest free one."""
    left = step_length
    if not point_free(fence, agent[0], agent[1]):
        gx, gy = nearest_free(fence, agent[0], agent[1])
        move_agent(agent, np.array([gx, gy]), left)
        return
    gx, gy = nearest_free(fence, waypoint[0], waypoint[1])
    for _ in range(fence.nodes.shape[0] + 1):
        length, wx, wy = fenced_route(fence, agent[0], agent[1], gx, gy)
        if not math.isfinite(length):
            return
        d = math.hypot(wx - agent[0], wy - agent[1])
        if d > left:
            agent[0] += (wx - agent[0]) * left / d
            agent[1] += (wy - agent[1]) * left / d
            return
        agent[0], agent[1] = wx, wy
        left -= d
        if wx == gx and wy == gy:
            return


@numba.njit(cache=True)
def fenced_intercept(fence, speed, agent_x, agent_y, x, y, vx, vy):
    """The intercept time (s) at ``speed`` (m/s) inside ``fence`` by the fixed point of the
    shortest free flight (module docstring); ``inf`` when the point cannot be caught."""
    t = intercept_time(agent_x, agent_y, x, y, vx, vy, speed)
    if math.isinf(t):
        return t
    ax, ay = nearest_free(fence, agent_x, agent_y)  # the agent itself when it is free
    for _ in range(FIXED_POINT_ROUNDS):
        gx, gy = nearest_free(fence, x + vx * t, y + vy * t)
        length = fenced_route(fence, ax, ay, gx, gy)[0]
        if not math.isfinite(length):
            return math.inf
        after = length / speed
        if abs(after - t) <= 1e-12 * (1.0 + t):
            return after
        t = after
    return t


@numba.njit(cache=True, inline="always")
def fenced_move(vehicle, agent, waypoint):
    """`FencedHolonomicVehicle`: `move_fenced` by at most ``v_a tau``."""
    move_fenced(vehicle.fence, vehicle.step_length, agent, waypoint)


@numba.njit(cache=True, inline="always")
def fenced_intercept_time(vehicle, agent_x, agent_y, x, y, vx, vy):
    """`FencedHolonomicVehicle`: `fenced_intercept` at ``v_a``."""
    return fenced_intercept(vehicle.fence, vehicle.speed, agent_x, agent_y, x, y, vx, vy)


@numba.njit(cache=True, inline="always")
def fenced(vehicle):
    """`FencedHolonomicVehicle`'s ``open_space``: no."""
    return False


@numba.njit(cache=True, inline="always")
def fenced_sees(vehicle, x, y, radius):
    """`FencedHolonomicVehicle`: `hptrack.models.fence.sees` of its fence."""
    return sees(vehicle.fence, x, y, radius)


@numba.njit(cache=True, inline="always")
def fenced_segment(vehicle, ax, ay, bx, by):
    """`FencedHolonomicVehicle`: the segment stays in the free space
    (`hptrack.models.fence.segment_free`; a segment of no length, where the vehicle is)."""
    if ax == bx and ay == by:
        return True
    return segment_free(vehicle.fence, ax, ay, bx, by)


register_vehicle(
    FencedHolonomicVehicle,
    VehicleKernels(
        fenced_move,
        fenced_intercept_time,
        holonomic_approach_step,
        fenced,
        fenced_sees,
        fenced_segment,
    ),
)


@numba.njit(cache=True)
def flown_path(vehicle, start, waypoints, out):
    """The positions ``out`` ``(k, 2)`` the vehicle reaches from ``start`` ``(2,)`` sent to
    ``waypoints[1:]`` ``(k, 2)`` one per step (``out[0]`` is ``start``), m."""
    agent = start.copy()
    out[0] = agent
    for j in range(1, waypoints.shape[0]):
        vehicle_move(vehicle, agent, waypoints[j])
        out[j] = agent


def flies_straight(vehicle: VehiclePart) -> bool:
    """Whether ``vehicle`` flies straight to any point (open space): an intercept's waypoints
    can then be laid on the straight line; a fenced one is sent to the meeting point and finds
    its own way."""
    return not isinstance(vehicle, FencedHolonomicVehicle)


@numba.njit(cache=True)
def _fenced_reach_times(vehicle, agent, positions, velocities, radius, out):
    for k in range(positions.shape[0]):
        dx, dy = positions[k, 0] - agent[k, 0], positions[k, 1] - agent[k, 1]
        if dx * dx + dy * dy <= radius * radius:
            out[k] = 0.0
        else:
            out[k] = fenced_intercept(
                vehicle.fence,
                vehicle.speed,
                agent[k, 0],
                agent[k, 1],
                positions[k, 0],
                positions[k, 1],
                velocities[k, 0],
                velocities[k, 1],
            )


def reach_times(
    vehicle: VehiclePart,
    agent: np.ndarray,
    positions: np.ndarray,
    velocities: np.ndarray,
    radius: float,
) -> np.ndarray:
    """Earliest time, s, at which the ``vehicle`` flying straight at full speed from ``agent``
    ``(2,)`` or ``(k, 2)`` comes within ``radius`` (m) of each point moving at constant
    ``velocities`` ``(k, 2)`` (m/s) from ``positions`` ``(k, 2)`` (m); ``inf`` if it never does
    (a point faster than the agent). A fenced vehicle flies the shortest free flight to the
    point (`fenced_intercept_time`) and is within ``radius`` only once there or at the start."""
    if isinstance(vehicle, FencedHolonomicVehicle):
        points = np.asarray(positions, dtype=float)
        starts = np.broadcast_to(np.asarray(agent, dtype=float), points.shape)
        out = np.empty(points.shape[0])
        _fenced_reach_times(
            vehicle,
            np.ascontiguousarray(starts),
            points,
            np.asarray(velocities, float),
            radius,
            out,
        )
        return out
    speed = vehicle.speed
    d = positions - agent
    v = velocities
    a = np.einsum("ij,ij->i", v, v) - speed * speed
    b = 2.0 * (np.einsum("ij,ij->i", d, v) - radius * speed)
    c = np.einsum("ij,ij->i", d, d) - radius * radius
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.where(
            np.abs(a) > 1e-12, (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a), -c / b
        )
    root = np.where((disc < 0.0) | ~np.isfinite(root) | (root < 0.0), math.inf, root)
    return np.where(c <= 0.0, 0.0, root)
