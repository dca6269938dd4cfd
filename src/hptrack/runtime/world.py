"""The simulated targets shared by the simulated runner and the vehicle stub: the simulator's
true initial states and one step of true motion per ``tau`` (the scenario's truth motion),
linearly interpolated between steps so that a sensor may look at any time; and the scenario's
detector (`synthetic_detector`), which they and ``targets-sim`` look with."""

from __future__ import annotations

import numpy as np

from hptrack.models.detector import Detector
from hptrack.models.sensor import detected_mask, draws_detection, measured_mask
from hptrack.models.truth_motion import sample_truth
from hptrack.scenario.model import Scenario
from hptrack.sim.step import DETECTOR_STREAM, initial_true_states, unlabelled_parts


def synthetic_detector(scenario: Scenario, seed: int) -> Detector | None:
    """The simulator's detector of ``scenario`` for synthetic detections
    (`hptrack.models.detector.Detector`: misses by ``detection_probability``, false alarms by
    ``false_alarm_density``), its Generator the simulator's detector stream of ``seed``
    (`hptrack.sim.step.DETECTOR_STREAM`); ``None`` for the paper's sensor, which measures every
    target inside the footprint from the simulator's sensor stream as before. Its kernels load
    (or compile) here, before any flight, without a draw."""
    parts = unlabelled_parts(scenario, seed)
    sensor = scenario.mission_spec().record.sensor
    if parts is not None:
        detector = parts[0]
    elif draws_detection(sensor):
        spec = scenario.sensor_spec()
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(DETECTOR_STREAM,)))
        detector = Detector(sensor, spec.noise_covariance(), spec.false_alarm_density, rng)
    else:
        return None
    here, nowhere = np.zeros(2), np.zeros((1, 2))
    measured_mask(sensor, here, nowhere)
    if draws_detection(sensor):
        detected_mask(sensor, here, nowhere, np.zeros(1))
    return detector


class TrueTargets:
    """True target states at whole steps, drawn lazily as time advances.

    Args:
        scenario: the mission (priors or given truths, ``q``, ``tau``).
        truth_rng: draws the initial states (when the scenario gives none).
        motion_rng: draws the motion noise, one call per step in order (as the simulator).
    """

    def __init__(
        self, scenario: Scenario, truth_rng: np.random.Generator, motion_rng: np.random.Generator
    ) -> None:
        mission = scenario.mission_spec()
        self._record, self._q, self.time_step = (
            mission.record,
            mission.process_noise,
            mission.time_step,
        )
        self._rng = motion_rng
        self.states: list[np.ndarray] = [initial_true_states(scenario, truth_rng)]
        self._truth_motion = scenario.truth_motion_model(truth_rng)
        self.state(1)  # the first step now: its kernel loads (or compiles) before any flight
        """True states ``(n, 4)`` at steps ``0, 1, ...`` drawn so far."""

    def state(self, k: int) -> np.ndarray:
        """True states at step ``k`` (drawing the steps up to it)."""
        while len(self.states) <= k:
            self.states.append(
                sample_truth(self._truth_motion, self._record, self.states[-1], self._q, self._rng)
            )
        return self.states[k]

    def positions(self, k: int, fraction: float) -> np.ndarray:
        """True positions ``(n, 2)`` at ``fraction`` (0..1) of the way from step ``k`` to
        ``k + 1``, m."""
        here = self.state(k)[:, :2]
        if fraction <= 0.0:
            return here.copy()
        return here + fraction * (self.state(k + 1)[:, :2] - here)

    def positions_at(self, time_s: float) -> np.ndarray:
        """True positions ``(n, 2)`` at ``time_s`` s from the start, m."""
        k, rest = divmod(max(float(time_s), 0.0), self.time_step)
        return self.positions(int(k), rest / self.time_step)
