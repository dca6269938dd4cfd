"""The estimator-accuracy experiment: the paper's first table and its CDF figure (Sec. V-A).

Protocol (``docs/protocols.md``, "Estimator validation"): for each random single-target case and
each departure delay ``t_d``, the agent waits ``t_d`` at its start, intercepts the belief mean and
flies the shifting spiral until ``t_cutoff`` (Secs. IV-A, IV-B). The agent path and the estimate are
fixed; ``runs`` target trajectories are sampled from the prior and the motion model, and each is
checked for detection (``|target - agent| <= w/2``) at every step from departure. Detections during
the intercept flight count at coverage time 0. Empirical ``P_find`` is the fraction detected by
``t_cutoff``; empirical ``E[T_find]`` is the mean detection time of those found, in seconds from the
start of the coverage, the same clock as the estimate. ``MAPE = mean |est - emp| / emp * 100``.

Two variants are recorded for the write-up: the sensor switched off during the intercept flight
(only detections on the spiral count), and times measured from departure instead of from the
start of the coverage (the estimate then adds the intercept flight).

Both estimators are evaluated on the same Monte Carlo truth: the paper's
(`coverage_outcome`: ``P_find`` against the empirical ``P_find``,
``E[T_find]`` against the empirical time from the start of the coverage) and the sharp one
(`hptrack.coverage.sharp_estimator`: ``P_find`` against the same empirical ``P_find``, its
expected duration given a find against the empirical detection time from departure). They share
``t_cutoff``, hence the plan and the simulation.

The agent's path is the hierarchical planner's own sub-task
(`CoverageSubtask`), and the true motion is the simulator's (`hptrack.models.truth_motion`), by
the same model as the beliefs (constant velocity by default; ``ValidationConfig.motion``).
A sensor that detects a target inside its footprint with a probability below one
(``ValidationConfig.mission``'s ``detection_probability``) detects it at each step with
``Pd(d)`` (`hptrack.models.sensor.sensor_detects`, the simulator's rule), from a stream of its
own, ``spawn_key=(i, 1 + d, 0)``: the trajectories are the paper's sensor's.
Sampling: no detection is checked while the agent waits, so the true state at departure
is drawn exactly from the belief propagated ``t_d`` (Eq. (1) in closed form); from there
trajectories are advanced step by step, all runs at once, with the process noise drawn in blocks of
steps and runs dropped once detected. Randomness: the case ``i`` is drawn from ``SeedSequence(seed,
spawn_key=(i, 0))`` and its Monte Carlo for a delay of ``d`` steps from ``spawn_key=(i, 1 + d)``, so
every number depends only on ``(seed, case, delay)``, whatever the worker count or order.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path

import numba
import numpy as np

from hptrack.coverage.estimator import CoverageEstimate
from hptrack.coverage.sharp_estimator import SharpEstimate
from hptrack.coverage.subtask import CoverageSubtask
from hptrack.experiments.workers import worker_pool
from hptrack.interface import InputError, MissionSpec
from hptrack.jsonout import json_text
from hptrack.models.belief_motion import extended_prior
from hptrack.models.sensor import (
    certain,
    detected_mask,
    detection_hold,
    draws_detection,
    held_draw,
    held_draws,
    measured_mask,
    sensor_detects,
    sensor_draws,
    sensor_hold_looks,
    sensor_measures,
)
from hptrack.models.state import position_of, positions, velocities
from hptrack.models.truth_motion import ConstantVelocityTruth, advance_truth
from hptrack.scenario.model import ConstantVelocitySpec, MotionSpec
from hptrack.scenario.random import random_mean, random_prior

PAPER_MAPE = {"0": (3.58, 5.18), "100": (2.46, 3.42), "200": (5.46, 3.73)}
"""The paper's Table I: ``delay -> (MAPE(P_find), MAPE(E[T_find]))`` in percent."""
BLOCK_STEPS = 64
"""Steps of process noise drawn at a time for all runs still undetected."""
RUN_BYTES = 8 * (8 + 4 * BLOCK_STEPS)
"""Memory of one sampled trajectory while its case runs, bytes (its state, first detections
and a block of noise), to refuse a ``runs`` that does not fit before it starts."""
DETECTION_KEY = 0
"""The last entry of the spawn key of a case's detection draws, ``(i, 1 + d, 0)`` (a sensor
that detects with a probability below one; the paper's draws none)."""
CASES_FILE = "cases.csv"
CONFIG_FILE = "config.json"

CASE_FIELDS = (
    "case",
    "delay",
    "mean_x",
    "mean_y",
    "vel_x",
    "vel_y",
    "var_x",
    "var_y",
    "cov_xy",
    "var_vx",
    "var_vy",
    "q",
    "intercept_time",
    "t_cutoff",
    "est_p_find",
    "emp_p_find",
    "est_expected_time",
    "emp_expected_time",
    "emp_found_in_flight",
    "emp_p_find_spiral_only",
    "emp_expected_time_spiral_only",
    "est_time_from_departure",
    "emp_time_from_departure",
    "sharp_p_find",
    "sharp_expected_time",
)


@dataclass(frozen=True)
class ValidationConfig:
    """Settings of the experiment (defaults: the paper's protocol).

    Attributes:
        cases: number of random single-target cases.
        runs: sampled target trajectories per case and delay.
        delays: departure delays ``t_d``, s (whole time steps).
        seed: root seed.
        mission: agent, sensor and model constants (its budget is not used: the coverage runs
            to ``t_cutoff``, or to ``budget``).
        motion: how the target moves, for the beliefs and the sampled truth alike (a scenario
            ``motion:`` spec, `hptrack.scenario.model.MotionSpec`); ``None``: constant
            velocity with the mission's ``Q`` form.
        budget: the mission's budget, s from the start (the delay included); ``None``: every
            coverage runs to ``t_cutoff`` (needed by beliefs under which ``P_cdf`` may never
            stop rising: random walk, Ornstein-Uhlenbeck).
    """

    cases: int = 1000
    runs: int = 10000
    delays: tuple[float, ...] = (0.0, 100.0, 200.0)
    seed: int = 0
    mission: MissionSpec = field(default_factory=MissionSpec)
    motion: MotionSpec | None = None
    budget: float | None = None

    def __post_init__(self) -> None:
        if self.motion is not None:
            part = self.motion.belief(self.mission.time_step, self.mission.process_noise_form)
            object.__setattr__(self, "mission", replace(self.mission, belief_motion=part))
        if self.budget is not None and not (math.isfinite(self.budget) and self.budget > 0.0):
            raise ValueError(f"budget must be a positive number of seconds, got {self.budget!r}")
        if self.cases < 1 or self.runs < 1:
            raise ValueError(f"cases and runs must be positive, got {self.cases}, {self.runs}")
        if not self.delays:
            raise ValueError("give at least one delay")
        for delay in self.delays:
            self.delay_steps(delay)
            if self.budget is not None and delay >= self.budget:
                raise ValueError(f"delay {delay:g} s is not before the budget {self.budget:g} s")

    def truth(self) -> tuple:
        """The sampled targets' truth motion (`hptrack.models.truth_motion`), the beliefs'."""
        spec = self.motion or ConstantVelocitySpec()
        return spec.build(1, np.random.default_rng(0))

    def delay_steps(self, delay: float) -> int:
        """The delay in whole steps; raises if it is negative or not a whole number of steps."""
        steps = delay / self.mission.time_step
        if not (math.isfinite(delay) and delay >= 0.0 and abs(steps - round(steps)) < 1e-9):
            raise ValueError(
                f"delay {delay!r} s is not a non-negative whole number of "
                f"{self.mission.time_step:g} s steps"
            )
        return round(steps)

    def identity(self) -> dict:
        """Everything that determines a case's rows (``cases`` excluded, so runs can extend)."""
        m = self.mission
        identity = {
            "runs": self.runs,
            "delays": [float(d) for d in self.delays],
            "seed": self.seed,
            "mission": {
                "time_step": m.time_step,
                "agent_speed": m.agent_speed,
                "sensor_diameter": m.sensor_diameter,
                "process_noise_form": m.process_noise_form,
            },
            "block_steps": BLOCK_STEPS,
            "sampler": "models.motion.advance_true_state",
            "estimators": ["paper", "sharp"],
        }
        if self.motion is not None:
            identity["motion"] = self.motion.model_dump(mode="json")
            identity["sampler"] = "models.truth_motion.advance_truth"
        if self.budget is not None:
            identity["budget"] = float(self.budget)
        if not certain(m.detection_probability):
            p = m.detection_probability
            identity["detection_probability"] = (
                float(p) if isinstance(p, int | float) else [[float(d), float(v)] for d, v in p]
            )
            if m.detection_correlation_time > 0.0:
                identity["detection_correlation_time"] = float(m.detection_correlation_time)
        return identity


@dataclass(frozen=True, eq=False)
class CoverageCase:
    """One random single-target case: prior ``mean`` (4,), ``covariance`` (4, 4) and ``q``."""

    index: int
    mean: np.ndarray
    covariance: np.ndarray
    q: float


def draw_case(index: int, seed: int) -> CoverageCase:
    """Case ``index`` of the experiment with root ``seed`` (the paper's distributions)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 0)))
    mean = random_mean(rng)
    covariance, q = random_prior(rng)
    return CoverageCase(index, mean, covariance, q)


@dataclass(frozen=True, eq=False)
class CoveragePlan:
    """The fixed agent path and estimate of one case and delay.

    Attributes:
        mean: ``(d,)`` belief mean at departure (``d`` the motion's state size).
        covariance: ``(d, d)`` belief covariance at departure.
        intercept_steps: whole steps of the intercept flight ``n``.
        estimate: the coverage estimate from the covariance at the start of the coverage.
        path: ``(n + t_cutoff + 1, 2)`` agent positions from departure to ``t_cutoff``, m.
        sharp: the sharp estimate of the same sub-task (same ``t_cutoff``).
    """

    mean: np.ndarray
    covariance: np.ndarray
    intercept_steps: int
    estimate: CoverageEstimate
    path: np.ndarray
    sharp: SharpEstimate


def plan_coverage(
    case: CoverageCase,
    delay_steps: int,
    mission: MissionSpec,
    agent_position: np.ndarray | None = None,
    budget: float | None = None,
) -> CoveragePlan:
    """Wait ``delay_steps`` at ``agent_position`` (default the origin), then fly the planner's
    coverage sub-task (intercept, spiral) to ``t_cutoff`` (or the end of ``budget`` s from
    the start)."""
    agent = np.zeros(2) if agent_position is None else np.asarray(agent_position, dtype=float)
    prior_mean, prior_cov = extended_prior(
        mission.motion.part, case.mean[None], case.covariance[None]
    )
    means, covs = mission.motion.predict(
        prior_mean, prior_cov, case.q, delay_steps * mission.time_step
    )
    mean, cov = means[0], covs[0]
    single = replace(mission, process_noise=np.array([case.q]), target_ids=("case",))
    left = None if budget is None else budget - delay_steps * mission.time_step
    subtask = CoverageSubtask(agent, mean, cov, case.q, single, left)
    return CoveragePlan(
        mean,
        cov,
        subtask.intercept.steps,
        subtask.estimate,
        subtask.planned_positions(),
        subtask.sharp_estimate,
    )


@numba.njit(cache=True)
def _advance_block(
    truth,
    mission,
    states,
    active,
    noise,
    path,
    first_step,
    flight_steps,
    sqrt_q,
    first_any,
    first_spiral,
    uniforms,
    held,
):
    """Advance the ``active`` runs through steps ``first_step ..`` by the ``truth`` motion
    with unit normal ``noise`` ``(runs, steps, d)`` and record detections; a run stops at its
    first detection on the spiral (step >= ``flight_steps``). ``mission`` is the mission
    record, ``sqrt_q`` ``(1,)``; a sensor that draws (`sensor_draws`) detects a target inside
    its footprint at step ``t`` of the block when ``sensor_detects`` with ``uniforms[a, t]``
    (``(runs, steps)``; unread otherwise), or with the draw it holds (`held_draw`, ``held``
    ``(runs, 2)``) when its draws hold for several looks."""
    sensor = mission.sensor
    hold = sensor_hold_looks(sensor)
    for a in range(active.shape[0]):
        i = active[a]
        for t in range(noise.shape[1]):
            advance_truth(truth, mission, states[i : i + 1], noise[a, t : t + 1], sqrt_q)
            j = first_step + t
            x, y = position_of(states[i])
            inside = sensor_measures(sensor, path[j, 0], path[j, 1], x, y)
            if sensor_draws(sensor):
                draw = held_draw(held, i, uniforms[a, t], hold, inside)
                if inside:
                    inside = sensor_detects(sensor, path[j, 0], path[j, 1], x, y, draw)
            if inside:
                if first_any[i] < 0:
                    first_any[i] = j
                if j >= flight_steps:
                    first_spiral[i] = j
                    break


def first_detections(
    plan: CoveragePlan,
    q: float,
    mission: MissionSpec,
    runs: int,
    rng: np.random.Generator,
    truth: tuple | None = None,
    detection_rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Monte Carlo of the fixed plan: for each of ``runs`` trajectories sampled by the
    ``truth`` motion (default constant velocity), the first step (from departure) at which
    the target is detected, and the first such step on the spiral (``>= n``); ``-1`` when not
    detected by ``t_cutoff``.

    A sensor that detects with a probability below one draws one uniform per run and step from
    ``detection_rng`` (needed then), in blocks as the noise, so that the trajectories are
    those of the same seed with the paper's sensor.
    """
    truth = ConstantVelocityTruth() if truth is None else truth
    sensor = mission.record.sensor
    draws = bool(draws_detection(sensor))
    if draws and detection_rng is None:
        raise ValueError("a sensor that detects with a probability below one needs detection_rng")
    states = rng.multivariate_normal(plan.mean, plan.covariance, size=runs, method="cholesky")
    n = plan.intercept_steps
    first_any = np.full(runs, -1, dtype=np.int64)
    first_spiral = np.full(runs, -1, dtype=np.int64)
    no_draws = np.zeros((0, 0))
    detection_rng = detection_rng if draws else None
    held = np.zeros((runs, 2))
    if detection_rng is not None and draws:
        uniforms = detection_rng.random(runs)
        inside = measured_mask(sensor, plan.path[0], positions(states))
        hold = int(detection_hold(sensor))
        uniforms[inside] = held_draws(held, inside, uniforms[inside], hold)
        hit = detected_mask(sensor, plan.path[0], positions(states), uniforms)
    else:
        hit = measured_mask(sensor, plan.path[0], positions(states))
    first_any[hit] = 0
    if n == 0:
        first_spiral[hit] = 0
    active = np.flatnonzero(first_spiral < 0)
    total = plan.path.shape[0]
    step = 1
    while step < total and active.size:
        block = min(BLOCK_STEPS, total - step)
        noise = rng.standard_normal((active.size, block, states.shape[1]))
        u = detection_rng.random((active.size, block)) if detection_rng is not None else no_draws
        _advance_block(
            truth,
            mission.record,
            states,
            active,
            noise,
            plan.path,
            step,
            n,
            np.array([math.sqrt(q)]),
            first_any,
            first_spiral,
            u,
            held,
        )
        active = active[first_spiral[active] < 0]
        step += block
    return first_any, first_spiral


def _mean_or_nan(values: np.ndarray) -> float:
    return float(np.mean(values)) if values.size else math.nan


def case_rows(
    case: CoverageCase, config: ValidationConfig, keep_times: bool = False
) -> tuple[list[dict], dict]:
    """Plan, estimate and simulate every delay of one case.

    Returns:
        the per-delay rows (keys `CASE_FIELDS`, times in s) and, with ``keep_times``, per
        delay the estimated CDF and the empirical coverage times of detection (s, NaN if missed).
    """
    s = config.mission
    rows, times = [], {}
    for delay in config.delays:
        d = config.delay_steps(delay)
        plan = plan_coverage(case, d, s, budget=config.budget)
        rng = np.random.default_rng(
            np.random.SeedSequence(config.seed, spawn_key=(case.index, 1 + d))
        )
        detection_rng = None
        if draws_detection(s.record.sensor):
            detection_rng = np.random.default_rng(
                np.random.SeedSequence(config.seed, spawn_key=(case.index, 1 + d, DETECTION_KEY))
            )
        first_any, first_spiral = first_detections(
            plan, case.q, s, config.runs, rng, config.truth(), detection_rng
        )
        n, est = plan.intercept_steps, plan.estimate
        found = first_any >= 0
        coverage_time = np.maximum(first_any[found] - n, 0) * s.time_step
        spiral_found = first_spiral >= 0
        rows.append(
            {
                "case": case.index,
                "delay": float(delay),
                "mean_x": positions(case.mean)[0],
                "mean_y": positions(case.mean)[1],
                "vel_x": velocities(case.mean)[0],
                "vel_y": velocities(case.mean)[1],
                "var_x": case.covariance[0, 0],
                "var_y": case.covariance[1, 1],
                "cov_xy": case.covariance[0, 1],
                "var_vx": case.covariance[2, 2],
                "var_vy": case.covariance[3, 3],
                "q": case.q,
                "intercept_time": n * s.time_step,
                "t_cutoff": est.cutoff_time,
                "est_p_find": est.p_find,
                "emp_p_find": float(np.mean(found)),
                "est_expected_time": est.expected_time,
                "emp_expected_time": _mean_or_nan(coverage_time),
                "emp_found_in_flight": float(np.mean(found & (first_any < n))),
                "emp_p_find_spiral_only": float(np.mean(spiral_found)),
                "emp_expected_time_spiral_only": _mean_or_nan(
                    (first_spiral[spiral_found] - n) * s.time_step
                ),
                "est_time_from_departure": n * s.time_step + est.expected_time,
                "emp_time_from_departure": _mean_or_nan(first_any[found] * s.time_step),
                "sharp_p_find": plan.sharp.p_find,
                "sharp_expected_time": plan.sharp.expected_time,
            }
        )
        if keep_times:
            detection = np.full(config.runs, math.nan)
            detection[found] = coverage_time
            times[f"{delay:g}"] = {
                "estimated_cdf": est.cdf,
                "detection_times": detection,
                "time_step": s.time_step,
            }
    return rows, times


def _run_case(index: int, config: ValidationConfig) -> list[dict]:
    return case_rows(draw_case(index, config.seed), config)[0]


def _ape(est: np.ndarray, emp: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(est - emp) / emp * 100.0


def summarise(rows: Sequence[dict], delays: Sequence[float]) -> dict[str, dict[str, float]]:
    """MAPE per delay (percent), with the number of cases and the two variants of the module
    docstring, for the paper's estimator and (``sharp_*``) the sharp one. Cases whose empirical
    value is 0 or undefined are left out of that MAPE; rows without the sharp estimator's
    columns give NaN for its figures."""
    out = {}
    for delay in delays:
        sel = [r for r in rows if float(r["delay"]) == float(delay)]

        def col(name: str, sel: list[dict] = sel) -> np.ndarray:
            return np.array([float(r.get(name, math.nan)) for r in sel])

        def mape(est: np.ndarray, emp: np.ndarray) -> float:
            ape = _ape(est, emp)
            ape = ape[np.isfinite(ape)]
            return float(np.mean(ape)) if ape.size else math.nan

        out[f"{delay:g}"] = {
            "cases": len(sel),
            "mape_p_find": mape(col("est_p_find"), col("emp_p_find")),
            "mape_expected_time": mape(col("est_expected_time"), col("emp_expected_time")),
            "mape_p_find_spiral_only": mape(col("est_p_find"), col("emp_p_find_spiral_only")),
            "mape_expected_time_spiral_only": mape(
                col("est_expected_time"), col("emp_expected_time_spiral_only")
            ),
            "mape_time_from_departure": mape(
                col("est_time_from_departure"), col("emp_time_from_departure")
            ),
            "mean_est_p_find": float(np.mean(col("est_p_find"))) if sel else math.nan,
            "mean_emp_p_find": float(np.mean(col("emp_p_find"))) if sel else math.nan,
            "mean_est_expected_time": float(np.mean(col("est_expected_time"))) if sel else math.nan,
            "mean_emp_expected_time": float(np.nanmean(col("emp_expected_time")))
            if sel
            else math.nan,
            "mean_found_in_flight": float(np.mean(col("emp_found_in_flight"))) if sel else math.nan,
            "sharp_mape_p_find": mape(col("sharp_p_find"), col("emp_p_find")),
            "sharp_mape_expected_time": mape(
                col("sharp_expected_time"), col("emp_time_from_departure")
            ),
            "mean_sharp_p_find": float(np.mean(col("sharp_p_find"))) if sel else math.nan,
            "mean_sharp_expected_time": float(np.mean(col("sharp_expected_time")))
            if sel
            else math.nan,
            "mean_emp_time_from_departure": float(np.nanmean(col("emp_time_from_departure")))
            if sel
            else math.nan,
        }
    return out


def read_rows(path: Path) -> list[dict]:
    """The per-case rows already in ``path`` (empty if it does not exist)."""
    if not path.exists():
        return []
    with path.open(newline="") as f:
        return [
            {k: float(v) if k != "case" else int(v) for k, v in row.items()}
            for row in csv.DictReader(f)
        ]


def _check_config(out_dir: Path, config: ValidationConfig) -> None:
    path = out_dir / CONFIG_FILE
    identity = config.identity()
    if path.exists():
        stored = json.loads(path.read_text())
        if stored != identity:
            raise InputError(
                f"--out {out_dir} holds results of another configuration "
                f"({stored}); use another --out folder"
            )
    else:
        path.write_text(json.dumps(identity, indent=2) + "\n")


def run_validation(
    config: ValidationConfig,
    out_dir: Path,
    workers: int = 1,
    on_case: Callable[[int, int], None] | None = None,
) -> list[dict]:
    """Run (or resume) the experiment, appending each finished case's rows to
    ``out_dir/cases.csv``; cases already there are skipped.

    Args:
        config: the protocol.
        out_dir: results folder (created).
        workers: worker processes (1 runs in this process).
        on_case: called as ``on_case(done, total)`` after each case (progress bars).

    Returns:
        All rows of cases ``0 .. cases - 1``, sorted by case and delay.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    _check_config(out_dir, config)
    csv_path = out_dir / CASES_FILE
    rows = [r for r in read_rows(csv_path) if r["case"] < config.cases]
    per_case: dict[int, int] = {}
    for r in rows:
        per_case[r["case"]] = per_case.get(r["case"], 0) + 1
    complete = {c for c, count in per_case.items() if count == len(config.delays)}
    rows = [r for r in rows if r["case"] in complete]
    todo = [i for i in range(config.cases) if i not in complete]
    new_file = not csv_path.exists() or len(complete) == 0
    with csv_path.open("w" if new_file else "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CASE_FIELDS)
        if new_file:
            writer.writeheader()
            for r in rows:
                writer.writerow(r)

        def record(case_rows_: list[dict]) -> None:
            writer.writerows(case_rows_)
            f.flush()
            rows.extend(case_rows_)
            if on_case is not None:
                on_case(len(rows) // len(config.delays), config.cases)

        if on_case is not None:
            on_case(len(complete), config.cases)
        if workers <= 1 or len(todo) <= 1:
            for i in todo:
                record(_run_case(i, config))
        else:
            with worker_pool(min(workers, len(todo))) as pool:
                futures = [pool.submit(_run_case, i, config) for i in todo]
                for future in as_completed(futures):
                    record(future.result())
    return sorted(rows, key=lambda r: (r["case"], r["delay"]))


def table_rows(summary: dict[str, dict[str, float]], unit: str = "") -> list[list[str]]:
    """The MAPE table's cells per delay (percent, two decimals, ``unit`` after each): delay,
    cases, then for ``P_find`` and ``E[T_find]`` the paper's estimator, the sharp one and the
    paper's published Table I (``-`` for a delay it has not)."""
    rows = []
    for delay, s in summary.items():
        paper = PAPER_MAPE.get(delay)
        published = [f"{v:.2f}{unit}" for v in paper] if paper else ["-", "-"]
        ours = [
            f"{s[k]:.2f}{unit}"
            for k in (
                "mape_p_find",
                "sharp_mape_p_find",
                "mape_expected_time",
                "sharp_mape_expected_time",
            )
        ]
        rows.append([delay, str(s["cases"]), *ours[:2], published[0], *ours[2:], published[1]])
    return rows


def table_markdown(summary: dict[str, dict[str, float]], wall_time: float | None = None) -> str:
    """The MAPE table (percent) of both estimators beside the paper's Table I, as Markdown."""
    lines = [
        "| t_d (s) | cases | MAPE(P_find), paper's estimator | sharp | paper's Table I | "
        "MAPE(E[T_find]), paper's estimator | sharp | paper's Table I |",
        "|---|---|---|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(summary, " %")]
    lines.append("")
    lines.append(
        "E[T_find]: the paper's estimator from the start of the coverage (flight "
        "detections at 0); the sharp estimator's expected sub-task duration given a "
        "find, from departure, against the simulated detection time from departure."
    )
    if wall_time is not None:
        lines.append("")
        lines.append(f"Wall time: {wall_time:.0f} s.")
    return "\n".join(lines) + "\n"


def write_reports(
    summary: dict[str, dict[str, float]], out_dir: Path, wall_time: float | None = None
) -> None:
    """``mape.md`` (the table), ``mape.csv`` (every summary figure per delay) and
    ``mape-both.json`` (`mape_json_both`)."""
    (out_dir / "mape.md").write_text(table_markdown(summary, wall_time))
    (out_dir / "mape-both.json").write_text(json_text(mape_json_both(summary), indent=2) + "\n")
    keys = ["delay", *next(iter(summary.values())).keys()]
    with (out_dir / "mape.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        for delay, s in summary.items():
            writer.writerow({"delay": delay, **s})


def mape_json(summary: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """``{"0": {"mape_p_find": .., "mape_expected_time": ..}, ...}`` (percent)."""
    return {
        d: {"mape_p_find": s["mape_p_find"], "mape_expected_time": s["mape_expected_time"]}
        for d, s in summary.items()
    }


def mape_json_both(summary: dict[str, dict[str, float]]) -> dict[str, dict[str, dict[str, float]]]:
    """``{"paper": mape_json(summary), "sharp": {delay: {"mape_p_find", "mape_expected_time"}}}``
    (percent; the sharp estimator's time is its duration from departure)."""
    return {
        "paper": mape_json(summary),
        "sharp": {
            d: {
                "mape_p_find": s["sharp_mape_p_find"],
                "mape_expected_time": s["sharp_mape_expected_time"],
            }
            for d, s in summary.items()
        },
    }
