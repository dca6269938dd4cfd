"""The one place where the planner's local frame meets the vehicle's (all in metres).

hptrack plans in an east-north-up local frame: ``x`` east, ``y`` north, altitude up. PX4 and
MAVLink use north-east-down: ``n`` north, ``e`` east, ``d`` down. Both share the origin of the
vehicle's local position (PX4's EKF origin), so the conversion is a swap and a sign:
``n = y``, ``e = x``, ``d = -altitude``.
"""

from __future__ import annotations


def enu_to_ned(east_m: float, north_m: float, altitude_m: float) -> tuple[float, float, float]:
    """``(north, east, down)`` of a point given east, north and altitude (up), m."""
    return float(north_m), float(east_m), -float(altitude_m)


def ned_to_enu(north_m: float, east_m: float, down_m: float) -> tuple[float, float, float]:
    """``(east, north, altitude)`` of a point given north, east and down, m."""
    return float(east_m), float(north_m), -float(down_m)
