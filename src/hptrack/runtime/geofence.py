"""A scenario's fence on the vehicle: its zones in latitude and longitude (what MAVLink's
fence protocol and MAVSDK's geofence plugin carry), converted from and to the local frame
around the local frame's origin (`hptrack.runtime.frames`), and the comparison of the fence
the vehicle holds with the scenario's.

PX4's geofence is a pass/fail backstop: on a breach it does ``GF_ACTION`` (`FENCE_ACTIONS`), and
its breach predictor (``GF_PREDICT``) is off by default; there is no virtual wall. So the planner
keeps its own setpoints inside the free space shrunk by the fence's margin, and the margin must
cover the vehicle's tracking lag (`hptrack.runtime.legs.tracking_lag_m`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from hptrack.models.fence import FenceSpec
from hptrack.runtime.frames import geodetic_to_local, local_to_geodetic

FENCE_ACTIONS = {0: "none", 1: "warning", 2: "hold", 3: "return", 4: "terminate", 5: "land"}
"""PX4's ``GF_ACTION`` values: what the vehicle does on a breach."""
DEFAULT_FENCE_ACTION = 2
"""``fly`` sets ``GF_ACTION`` to hold unless told otherwise."""
FENCE_TOLERANCE_M = 0.1
"""The vehicle's fence agrees with the scenario's when every corner and centre is within this
and every radius too, m (MAVLink carries degrees times 1e7, about 1 cm, and float radii)."""


class GeoZone(NamedTuple):
    """One zone of a fence on the vehicle.

    Attributes:
        inclusion: an operating area (``True``) or a no-fly zone.
        points: a polygon's corners ``(latitude, longitude)``, degrees; a circle's centre alone.
        radius_m: a circle's radius, m; ``None`` for a polygon.
    """

    inclusion: bool
    points: tuple[tuple[float, float], ...]
    radius_m: float | None = None


def to_geodetic(spec: FenceSpec, origin: tuple[float, float]) -> list[GeoZone]:
    """The zones of ``spec`` (local east-north metres) in latitude and longitude around the
    local frame's ``origin`` ``(latitude, longitude)``, degrees: the inclusion first, then the
    polygons and the circles in the scenario's order. The margin stays with the planner."""

    def geodetic(x: float, y: float) -> tuple[float, float]:
        return local_to_geodetic(*origin, y, x)

    zones = []
    if spec.inclusion is not None:
        zones.append(GeoZone(True, tuple(geodetic(x, y) for x, y in spec.inclusion)))
    zones += [GeoZone(False, tuple(geodetic(x, y) for x, y in ring)) for ring in spec.polygons]
    zones += [GeoZone(False, (geodetic(x, y),), float(r)) for x, y, r in spec.circles]
    return zones


def from_geodetic(zones: list[GeoZone], origin: tuple[float, float], margin: float) -> FenceSpec:
    """The `FenceSpec` (local east-north metres, ``margin`` m) of the vehicle's ``zones``.

    Raises:
        ValueError: more than one inclusion, or an inclusion circle (the planner's operating
            area is one polygon).
    """

    def local(lat: float, lon: float) -> tuple[float, float]:
        north, east = geodetic_to_local(*origin, lat, lon)
        return east, north

    inclusions = [z for z in zones if z.inclusion]
    if len(inclusions) > 1 or any(z.radius_m is not None for z in inclusions):
        raise ValueError(
            f"the vehicle's fence has {len(inclusions)} inclusion zones "
            f"({sum(z.radius_m is not None for z in inclusions)} circles); hptrack flies one "
            "inclusion polygon"
        )
    return FenceSpec(
        inclusion=tuple(local(*p) for p in inclusions[0].points) if inclusions else None,
        polygons=tuple(
            tuple(local(*p) for p in z.points)
            for z in zones
            if not z.inclusion and z.radius_m is None
        ),
        circles=tuple(
            (*local(*z.points[0]), z.radius_m)
            for z in zones
            if not z.inclusion and z.radius_m is not None
        ),
        margin=float(margin),
    )


def fence_difference(
    scenario: FenceSpec, vehicle: FenceSpec, tolerance_m: float = FENCE_TOLERANCE_M
) -> str | None:
    """``None`` when the vehicle's fence is the scenario's within ``tolerance_m`` (corners,
    centres and radii, in order; margins are not compared), else one line on the first
    difference."""
    if (scenario.inclusion is None) != (vehicle.inclusion is None):
        if vehicle.inclusion is None:
            return "the vehicle's fence has no inclusion polygon, the scenario's has one"
        return "the vehicle's fence has an inclusion polygon, the scenario's has none"
    rings = [("inclusion", scenario.inclusion or (), vehicle.inclusion or ())]
    if len(scenario.polygons) != len(vehicle.polygons):
        return (
            f"the vehicle holds {len(vehicle.polygons)} exclusion polygons, the scenario "
            f"{len(scenario.polygons)}"
        )
    if len(scenario.circles) != len(vehicle.circles):
        return (
            f"the vehicle holds {len(vehicle.circles)} exclusion circles, the scenario "
            f"{len(scenario.circles)}"
        )
    rings += [
        (f"exclusion polygon {i}", a, b)
        for i, (a, b) in enumerate(zip(scenario.polygons, vehicle.polygons, strict=True))
    ]
    for name, a, b in rings:
        if len(a) != len(b):
            return f"{name}: the vehicle's has {len(b)} corners, the scenario's {len(a)}"
        for k, (p, q) in enumerate(zip(a, b, strict=True)):
            gap = math.dist(p, q)
            if gap > tolerance_m:
                return f"{name} corner {k}: {gap:.2f} m apart (tolerance {tolerance_m:g} m)"
    for i, (c, d) in enumerate(zip(scenario.circles, vehicle.circles, strict=True)):
        gap = max(math.dist(c[:2], d[:2]), abs(c[2] - d[2]))
        if gap > tolerance_m:
            return f"exclusion circle {i}: {gap:.2f} m apart (tolerance {tolerance_m:g} m)"
    return None


def fence_block(spec: FenceSpec) -> dict:
    """``spec`` as a scenario's ``fence:`` block (JSON data)."""
    block: dict = {
        "exclusions": [{"polygon": [list(p) for p in ring]} for ring in spec.polygons]
        + [{"circle": list(circle)} for circle in spec.circles],
        "margin": spec.margin,
    }
    if spec.inclusion is not None:
        block["inclusion"] = {"polygon": [list(p) for p in spec.inclusion]}
    return block


def fence_summary(spec: FenceSpec) -> str:
    """The zones of ``spec`` in a few words."""
    parts = ["an inclusion polygon"] if spec.inclusion is not None else []
    for count, kind in ((len(spec.polygons), "polygon"), (len(spec.circles), "circle")):
        if count:
            parts.append(f"{count} exclusion {kind}{'s' if count > 1 else ''}")
    return ", ".join(parts) or "no zones"
