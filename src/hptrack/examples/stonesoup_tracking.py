"""Stone Soup closed loop: an hptrack planner flies the sensor platform, against one that hovers.

A Stone Soup simulation end to end: constant-velocity ground truths, a footprint position sensor
on a ``MaxSpeedActionableMovable`` platform, one Kalman track per target (``KalmanPredictor`` +
``KalmanUpdater``; detections are associated by ground-truth id, as in the paper where targets
are known by identity), and a sensor manager choosing the platform's moves every step. The same
truths are flown twice: by `HptrackSensorManager` and by
`HoverSensorManager`. The score is the mean over tracks of
``log det`` of the final position covariance (log m^4, lower is tighter).

    python3 stonesoup_tracking.py                      # mcts, 300 simulations/search
    python3 stonesoup_tracking.py --planner greedy
    python3 stonesoup_tracking.py --planner mcts -o iterations=2000 --steps 240
"""

from __future__ import annotations

import argparse
import datetime
from dataclasses import dataclass

import numpy as np
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.movable.max_speed import MaxSpeedActionableMovable
from stonesoup.platform import MovingPlatform
from stonesoup.predictor.kalman import KalmanPredictor
from stonesoup.sensormanager.base import SensorManager
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import GaussianState, State
from stonesoup.types.track import Track
from stonesoup.updater.kalman import KalmanUpdater

from hptrack.integrations.stonesoup import (
    FootprintPositionSensor,
    HoverSensorManager,
    HptrackSensorManager,
    hptrack_beliefs,
    process_noise_of,
)
from hptrack.models.beliefs import position_logdet

START = datetime.datetime(2025, 1, 1)
DEFAULT_MCTS_OPTIONS = {"iterations": 300}


@dataclass(frozen=True)
class Setup:
    """The simulated mission (SI units; the paper's speed, footprint, ``R`` and ``q``)."""

    n_targets: int = 4
    steps: int = 120
    time_step: float = 0.5
    agent_speed: float = 30.0
    sensor_diameter: float = 100.0
    noise_variance: float = 10.0
    process_noise: float = 3e-4
    range_m: tuple[float, float] = (150.0, 450.0)
    seed: int = 0


@dataclass(frozen=True)
class Run:
    """One flown mission: final ``log det Sigma_xy`` per track, detections, distance flown."""

    manager: str
    logdets: np.ndarray
    detections: int
    distance_m: float

    @property
    def mean_logdet(self) -> float:
        return float(np.mean(self.logdets))


def scenario(setup: Setup) -> tuple[list[GaussianState], np.ndarray]:
    """Priors (Stone Soup order ``[x, vx, y, vy]``) and true states ``(steps + 1, n, 4)``.

    Targets start ``range_m`` from the platform; prior position variances 500-1000 m^2 per axis,
    velocity variances 0.25-0.5 (m/s)^2; truths are drawn from the priors and moved by the
    constant-velocity model with ``q``.
    """
    rng = np.random.default_rng(np.random.SeedSequence(setup.seed).spawn(1)[0])
    model = transition_model(setup)
    dt = datetime.timedelta(seconds=setup.time_step)
    noise = model.covar(time_interval=dt)
    priors, states = [], np.empty((setup.steps + 1, setup.n_targets, 4))
    for i in range(setup.n_targets):
        r, bearing = rng.uniform(*setup.range_m), rng.uniform(0.0, 2.0 * np.pi)
        vx, vy = rng.uniform(-3.0, 3.0, size=2)
        mean = np.array([r * np.cos(bearing), vx, r * np.sin(bearing), vy])
        cov = np.diag(
            [
                rng.uniform(500.0, 1000.0),
                rng.uniform(0.25, 0.5),
                rng.uniform(500.0, 1000.0),
                rng.uniform(0.25, 0.5),
            ]
        )
        priors.append(GaussianState(mean, cov, timestamp=START))
        states[0, i] = rng.multivariate_normal(mean, cov)
        for k in range(1, setup.steps + 1):
            step_noise = rng.multivariate_normal(np.zeros(4), noise).reshape(4, 1)
            states[k, i] = model.function(
                State(states[k - 1, i].reshape(4, 1)), noise=step_noise, time_interval=dt
            ).ravel()
    return priors, states


def transition_model(setup: Setup) -> CombinedLinearGaussianTransitionModel:
    return CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(setup.process_noise), ConstantVelocity(setup.process_noise)]
    )


def make_platform(setup: Setup, sensor_seed: int) -> MovingPlatform:
    sensor = FootprintPositionSensor(
        noise_covar=setup.noise_variance * np.eye(2),
        diameter=setup.sensor_diameter,
        seed=sensor_seed,
    )
    movable = MaxSpeedActionableMovable(
        states=[State([[0.0], [0.0]], timestamp=START)],
        position_mapping=(0, 1),
        action_mapping=(0, 1),
        max_speed=setup.agent_speed,
    )
    return MovingPlatform(movement_controller=movable, sensors=[sensor])


def fly(setup: Setup, make_manager, name: str) -> Run:
    """Fly the mission with the manager ``make_manager(platform)``; returns the score."""
    priors, states = scenario(setup)
    sensor_seed = int(np.random.SeedSequence(setup.seed).spawn(2)[1].generate_state(1)[0])
    platform = make_platform(setup, sensor_seed)
    (sensor,) = platform.sensors
    manager: SensorManager = make_manager(platform)
    model = transition_model(setup)
    predictor, updater = KalmanPredictor(model), KalmanUpdater(measurement_model=None)
    truths = [GroundTruthPath(id=f"target-{i}") for i in range(setup.n_targets)]
    tracks = [Track([prior], id=truth.id) for prior, truth in zip(priors, truths, strict=True)]
    detections = 0

    def sense(k: int) -> int:
        time = START + datetime.timedelta(seconds=k * setup.time_step)
        for i, truth in enumerate(truths):
            truth.append(GroundTruthState(states[k, i].reshape(4, 1), timestamp=time))
        # a list, not a set: the sensor draws the noise in this order (a set's order would
        # change from run to run)
        measured = {d.groundtruth_path.id: d for d in sensor.measure(truths, noise=True)}
        for track in tracks:
            prediction = predictor.predict(track.state, timestamp=time)
            detection = measured.get(track.id)
            track.append(
                prediction
                if detection is None
                else updater.update(SingleHypothesis(prediction, detection))
            )
        return len(measured)

    detections += sense(0)
    for k in range(1, setup.steps + 1):
        time = START + datetime.timedelta(seconds=k * setup.time_step)
        for config in manager.choose_actions(set(tracks), time):
            for actionable, actions in config.items():
                actionable.add_actions(actions)
                actionable.act(time)
        detections += sense(k)

    path = np.array(
        [
            np.asarray(s.state_vector, dtype=float).ravel()
            for s in platform.movement_controller.states
        ]
    )
    _, covs = hptrack_beliefs([track.state for track in tracks])
    return Run(
        name, position_logdet(covs), detections, float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
    )


def compare(setup: Setup, planner: str, options: dict | None) -> tuple[Run, Run]:
    """The same mission flown by the hptrack manager with ``planner`` and by the hover one."""
    seed = int(np.random.SeedSequence(setup.seed).spawn(3)[2].generate_state(1)[0])
    q = process_noise_of(transition_model(setup))

    def hptrack_manager(platform):
        return HptrackSensorManager(
            process_noise=q,
            time_step=setup.time_step,
            planner=planner,
            planner_options=options,
            budget=setup.steps * setup.time_step,
            platforms={platform},
            seed=seed,
        )

    return (
        fly(setup, hptrack_manager, f"hptrack {planner}"),
        fly(setup, lambda platform: HoverSensorManager(platforms={platform}), "hover"),
    )


def report(setup: Setup, runs: tuple[Run, Run]) -> str:
    lines = [
        f"{setup.n_targets} targets, {setup.steps} steps of {setup.time_step} s, "
        f"seed {setup.seed}: mean final log det Sigma_xy (log m^4, lower is tighter)"
    ]
    for run in runs:
        per_track = " ".join(f"{v:.2f}" for v in run.logdets)
        lines.append(
            f"  {run.manager:<16} {run.mean_logdet:8.3f}   per track: {per_track}   "
            f"detections {run.detections}, flown {run.distance_m:.0f} m"
        )
    lines.append(f"  hptrack - hover  {runs[0].mean_logdet - runs[1].mean_logdet:8.3f}")
    return "\n".join(lines)


def _option(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, value


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planner", default="mcts", help="hptrack planner (default mcts)")
    parser.add_argument(
        "-o",
        "--option",
        type=_option,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="planner option (mcts default: iterations=300)",
    )
    parser.add_argument("--targets", type=int, default=Setup.n_targets)
    parser.add_argument("--steps", type=int, default=Setup.steps)
    parser.add_argument("--time-step", type=float, default=Setup.time_step, help="s")
    parser.add_argument("--seed", type=int, default=Setup.seed)
    args = parser.parse_args(argv)
    options = dict(args.option) or (DEFAULT_MCTS_OPTIONS if args.planner == "mcts" else None)
    setup = Setup(
        n_targets=args.targets, steps=args.steps, time_step=args.time_step, seed=args.seed
    )
    print(report(setup, compare(setup, args.planner, options)))


if __name__ == "__main__":
    main()
