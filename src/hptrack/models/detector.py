"""The detector: what one look reports, the targets it detects and false alarms (issue 29).

A look from the agent detects each target the sensor part measures (`hptrack.models.sensor`:
inside the footprint and, with a `DetectingFootprintSensor`, a uniform below ``Pd(d)``, held
over consecutive looks when the sensor's draws hold, `hptrack.models.sensor.held_draws`) and
reports it as ``z = [x, y] + L e`` (``L L' = R``, ``e`` unit normals); it also reports a
Poisson number of false alarms of mean ``lambda pi (w/2)^2`` (``lambda`` the false-alarm
density, per m^2 per look), uniform over the footprint. The reports come in a random order, so
that their order says nothing of their source. Every draw comes from the detector's own
Generator (the simulator spawns it from the episode's seed, `hptrack.sim.step`), so a mission
of the paper's sensor draws exactly what it drew before. The simulator uses it for detections
without identity; flight's ``vehicle-sim`` and ``targets-sim`` are meant to draw from it too.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from hptrack.models.sensor import (
    SensorPart,
    detected_mask,
    detection_hold,
    draws_detection,
    held_draws,
    measured_mask,
)


class Detections(NamedTuple):
    """The reports of one look.

    Attributes:
        positions: ``(k, 2)`` reported positions, m.
        sources: ``(k,)`` the target index of each report, -1 a false alarm: the truth (a
            labelled sensor's ids; without identity only the episode record reads it).
    """

    positions: np.ndarray
    sources: np.ndarray


class Detector:
    """Draws the reports of a look (module docstring).

    Args:
        sensor: the mission record's sensor part (its ``diameter`` and detection rule).
        measurement_noise: ``R`` ``(2, 2)``, m^2.
        false_alarm_density: false alarms per m^2 per look inside the footprint.
        rng: the detector's Generator.
    """

    def __init__(
        self,
        sensor: SensorPart,
        measurement_noise: np.ndarray,
        false_alarm_density: float,
        rng: np.random.Generator,
    ) -> None:
        self.sensor = sensor
        self.factor = np.linalg.cholesky(np.asarray(measurement_noise, dtype=float))
        self.radius = 0.5 * float(sensor.diameter)
        self.false_alarm_density = float(false_alarm_density)
        self.mean_false_alarms = self.false_alarm_density * math.pi * self.radius**2
        self.rng = rng
        self._draws = bool(draws_detection(sensor))
        self._hold = int(detection_hold(sensor))
        self._held = np.zeros((0, 2))

    def look(self, agent: np.ndarray, positions: np.ndarray) -> Detections:
        """The reports of a look from ``agent`` ``(2,)`` over targets at ``positions``
        ``(n, 2)`` (m)."""
        rng = self.rng
        agent = np.asarray(agent, dtype=float)
        measured = measured_mask(self.sensor, agent, positions)
        inside = np.flatnonzero(measured)
        if self._draws:
            u = rng.random(inside.size)
            if self._hold > 1:  # each target's draw held over consecutive looks inside
                if self._held.shape[0] != measured.size:
                    self._held = np.zeros((measured.size, 2))
                u = held_draws(self._held, measured, u, self._hold)
            inside = inside[detected_mask(self.sensor, agent, positions[inside], u)]
        noise = rng.standard_normal((inside.size, 2)) @ self.factor.T
        measured = positions[inside] + noise
        count = int(rng.poisson(self.mean_false_alarms)) if self.mean_false_alarms > 0 else 0
        radius = self.radius * np.sqrt(rng.random(count))
        angle = 2.0 * math.pi * rng.random(count)
        clutter = agent + np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
        order = rng.permutation(inside.size + count)
        reports = np.concatenate([measured, clutter])[order]
        sources = np.concatenate([inside, np.full(count, -1)])[order]
        return Detections(reports, sources)
