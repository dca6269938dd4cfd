"""The one place where the planner's local frame meets the vehicle's (all in metres).

hptrack plans in an east-north-up local frame: ``x`` east, ``y`` north, altitude up. PX4 and
MAVLink use north-east-down: ``n`` north, ``e`` east, ``d`` down. Both share the origin of the
vehicle's local position (PX4's EKF origin), so the conversion is a swap and a sign:
``n = y``, ``e = x``, ``d = -altitude``. The local frame's origin has a latitude and longitude
(PX4's ``GPS_GLOBAL_ORIGIN``); `local_to_geodetic` and `geodetic_to_local` convert around it.
"""

from __future__ import annotations

import math


def enu_to_ned(east_m: float, north_m: float, altitude_m: float) -> tuple[float, float, float]:
    """``(north, east, down)`` of a point given east, north and altitude (up), m."""
    return float(north_m), float(east_m), -float(altitude_m)


def ned_to_enu(north_m: float, east_m: float, down_m: float) -> tuple[float, float, float]:
    """``(east, north, altitude)`` of a point given north, east and down, m."""
    return float(east_m), float(north_m), -float(down_m)


EARTH_RADIUS_M = 6_378_137.0
"""WGS-84's equatorial radius, m: the sphere of the local tangent-plane conversion."""


def local_to_geodetic(
    origin_lat_deg: float, origin_lon_deg: float, north_m: float, east_m: float
) -> tuple[float, float]:
    """``(latitude, longitude)`` (degrees) of a point ``north_m``, ``east_m`` from the local
    frame's origin at ``origin_lat_deg``, ``origin_lon_deg``: the equirectangular tangent
    plane (under 1 cm off over 2 km from the origin)."""
    lat = origin_lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    lon = origin_lon_deg + math.degrees(
        east_m / (EARTH_RADIUS_M * math.cos(math.radians(origin_lat_deg)))
    )
    return lat, lon


def geodetic_to_local(
    origin_lat_deg: float, origin_lon_deg: float, lat_deg: float, lon_deg: float
) -> tuple[float, float]:
    """``(north, east)`` (m) of a point at ``lat_deg``, ``lon_deg`` in the local frame of the
    origin (the inverse of `local_to_geodetic`)."""
    north = math.radians(lat_deg - origin_lat_deg) * EARTH_RADIUS_M
    east = (
        math.radians(lon_deg - origin_lon_deg)
        * EARTH_RADIUS_M
        * math.cos(math.radians(origin_lat_deg))
    )
    return north, east
