"""Multi-target benchmark (the paper's Sec. V-B, Tables II-III; ``docs/protocols.md``).

For each number of targets ``n`` and each scenario seed, every planner flies the same random
scenario once for the whole budget. Episodes run on worker processes (or any
`concurrent.futures.Executor`, e.g. a Dask cluster's) and are stored as each one finishes
(`hptrack.experiments.store`); a re-run with the same arguments skips what is done, and two
runs on one database share the work. Next to every ``U`` the store keeps the scenario's *never
observed* score: the ``U`` of a mission that measures nothing, which depends only on the priors
and the budget.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hptrack.experiments.store import EpisodeKey, ResultStore
from hptrack.experiments.workers import stop_workers, worker_pool
from hptrack.interface import InputError, MissionSpec
from hptrack.registry import check_team, planner_entry, planner_settings
from hptrack.scenario.model import (
    MAX_AGENTS,
    MAX_DETECTION_CORRELATION_TIME,
    MAX_FALSE_ALARM_DENSITY,
    FootprintSensorSpec,
    Scenario,
)
from hptrack.scenario.random import random_scenario, with_no_fly
from hptrack.settings import PlannerSettings
from hptrack.sim.episode import run_episode
from hptrack.sim.record import METRICS, EpisodeRow

MAX_SEED = 2**63 - 1
"""Largest scenario seed (SQLite's largest integer)."""
OTHER_RUN_POLL_S = 2.0
"""How often a run waiting for another run's episodes looks at the database, s."""


@dataclass(frozen=True)
class BenchmarkConfig:
    """What to run.

    Attributes:
        planners: registered planner names.
        settings: each planner's validated settings (all of ``planners``).
        target_counts: the values of ``n``.
        scenarios: scenarios per ``n`` (seeds ``first_seed .. first_seed + scenarios - 1``).
        homogeneous: the paper's setting for ARVI and A* (shared ``q`` and prior).
        first_seed: first scenario seed.
        process_noise_form: the scenarios' per-step ``Q`` (`hptrack.models.motion`).
        motion: the scenarios' ``motion:`` block as `motion_label` writes it (``""``: the
            paper's constant velocity), e.g. ``"ornstein_uhlenbeck:0.01"``.
        detection_probability: the scenarios' sensor's chance of detecting a target inside its
            footprint at each look (1: the paper's sensor).
        blind: the planners are told the paper's sensor (``Pd = 1``, no false alarms) while the
            world's detector misses or reports false alarms
            (`hptrack.sim.episode.run_episode`'s ``planner_mission``).
        labelled: every detection names its target (the paper's sensor); false: detections are
            positions only, associated by the tracker (``sensor.labelled``, GNN).
        false_alarm_density: the sensor's false alarms per m^2 per look inside its footprint
            (``sensor.false_alarm_density``; above 0 only with ``labelled`` false).
        detection_correlation_time: s, how long one detection draw holds while a target stays
            in the footprint (``sensor.detection_correlation_time``; 0: independent looks).
        no_fly: each scenario gets random no-fly circles
            (`hptrack.scenario.random.with_no_fly`).
        team: UAVs per scenario, all from the start (1: the paper's one UAV).
    """

    planners: tuple[str, ...]
    settings: dict[str, PlannerSettings] = field(default_factory=dict)
    target_counts: tuple[int, ...] = (2, 3, 4, 5, 6)
    scenarios: int = 100
    homogeneous: bool = True
    first_seed: int = 0
    process_noise_form: str = "continuous"
    motion: str = ""
    detection_probability: float = 1.0
    blind: bool = False
    no_fly: bool = False
    team: int = 1
    labelled: bool = True
    false_alarm_density: float = 0.0
    detection_correlation_time: float = 0.0

    def __post_init__(self) -> None:
        missing = [p for p in self.planners if p not in self.settings]
        if missing:
            raise ValueError(f"no settings for planners {missing}")
        if not 0 <= self.first_seed <= MAX_SEED - self.scenarios + 1:
            raise InputError(
                f"seeds {self.first_seed} .. {self.first_seed + self.scenarios - 1} (first seed, "
                f"{self.scenarios} scenarios) must lie between 0 and {MAX_SEED} (2^63 - 1)"
            )
        p = self.detection_probability
        if isinstance(p, bool) or not (isinstance(p, int | float) and 0.0 < p <= 1.0):
            raise InputError(f"--detection-probability must be in (0, 1], got {p!r}")
        clutter = _within(
            self.false_alarm_density,
            "--false-alarm-density",
            MAX_FALSE_ALARM_DENSITY,
            "per m^2 per look",
        )
        if self.blind and p == 1.0 and clutter == 0.0:
            raise InputError(
                "--blind needs a --detection-probability below 1 or a --false-alarm-density "
                "above 0 (nothing to hide)"
            )
        hold = _within(
            self.detection_correlation_time,
            "--detection-correlation-time",
            MAX_DETECTION_CORRELATION_TIME,
            "s",
        )
        if hold > 0.0 and p == 1.0:
            raise InputError(
                "--detection-correlation-time needs a --detection-probability below 1 (no misses "
                "to correlate)"
            )
        if clutter > 0.0 and self.labelled:
            raise InputError(
                f"--false-alarm-density {clutter:g} needs --unlabelled (a false alarm names no "
                "target)"
            )
        if isinstance(self.team, bool) or not 1 <= self.team <= MAX_AGENTS:
            raise InputError(f"--team must be between 1 and {MAX_AGENTS}, got {self.team!r}")

    @property
    def setting(self) -> str:
        return setting_name(
            self.homogeneous,
            self.process_noise_form,
            self.motion,
            self.detection_probability,
            self.blind,
            self.no_fly,
            self.team,
            self.labelled,
            self.false_alarm_density,
            self.detection_correlation_time,
        )

    def keys(self) -> list[EpisodeKey]:
        """Every episode of the benchmark, in run order."""
        seeds = range(self.first_seed, self.first_seed + self.scenarios)
        return [
            EpisodeKey(p, n, s, self.setting, self.settings[p].canonical())
            for n in self.target_counts
            for s in seeds
            for p in self.planners
        ]


def _within(value: Any, option: str, most: float, unit: str) -> float:
    """``value`` if it is a number in ``[0, most]``, else an `InputError` naming ``option``."""
    if isinstance(value, bool) or not (isinstance(value, int | float) and 0.0 <= value <= most):
        raise InputError(f"{option} must be between 0 and {most:g} {unit}, got {value!r}")
    return float(value)


MOTION_PARAMETERS = {
    "random_walk": ("diffusion",),
    "ornstein_uhlenbeck": ("damping",),
    "singer": ("damping", "acceleration_std"),
    "constant_acceleration": ("jerk_intensity", "acceleration_std"),
}
"""The parameters of each belief motion a benchmark's ``motion`` label names, in order."""


def motion_label(label: str) -> dict | None:
    """The scenario ``motion:`` block of a label ``MODEL:VALUE[:VALUE]`` (``random_walk:5``:
    diffusion 5 m^2/s; ``ornstein_uhlenbeck:0.01``: damping 0.01 1/s; ``singer:0.02:0.05``:
    damping 0.02 1/s, acceleration_std 0.05 m/s^2; ``constant_acceleration:1e-6``: jerk
    intensity 1e-6 m^2/s^5; values left out take the model's defaults); ``None`` for ``""`` or
    ``constant_velocity``.

    Raises:
        InputError: an unknown model or a value that is not a number.
    """
    if label in ("", "constant_velocity"):
        return None
    model, *values = label.split(":")
    if model not in MOTION_PARAMETERS:
        raise InputError(
            f"--motion {label!r}: the model is one of constant_velocity, "
            f"{', '.join(m + ':VALUE' * len(p) for m, p in MOTION_PARAMETERS.items())}"
        )
    fields = MOTION_PARAMETERS[model]
    if len(values) > len(fields):
        raise InputError(
            f"--motion {label!r}: {model} takes at most {len(fields)} values ({', '.join(fields)})"
        )
    block: dict = {"model": model}
    for name, value in zip(fields, values, strict=False):
        if not value:
            continue
        try:
            block[name] = float(value)
        except ValueError:
            raise InputError(f"--motion {label!r}: {value!r} is not a number") from None
    return block


def setting_name(
    homogeneous: bool,
    process_noise_form: str = "continuous",
    motion: str = "",
    detection_probability: float = 1.0,
    blind: bool = False,
    no_fly: bool = False,
    team: int = 1,
    labelled: bool = True,
    false_alarm_density: float = 0.0,
    detection_correlation_time: float = 0.0,
) -> str:
    """The setting part of an episode's identity: ``"homogeneous"`` or ``"heterogeneous"``,
    with ``"+paper_text"`` when ``Q`` is the paper's printed form, ``"+MODEL:VALUE"`` under
    another belief motion (`motion_label`), ``"+pd:P"`` when the sensor detects with
    probability ``P < 1``, ``"+blind"`` when the planners are told ``Pd = 1``, ``"+nofly"``
    with random no-fly circles, ``"+team:M"`` with ``M > 1`` UAVs, ``"+unlabelled"`` for
    detections without identity, ``"+clutter:L"`` for ``L > 0`` false alarms per m^2 per
    look and ``"+correlation:T"`` for detection draws held ``T > 0`` s (`BenchmarkConfig`)."""
    base = "homogeneous" if homogeneous else "heterogeneous"
    parts = [base] + ([process_noise_form] if process_noise_form != "continuous" else [])
    parts += [motion] if motion_label(motion) is not None else []
    parts += (
        [f"{DETECTION_PART}{float(detection_probability)!r}"] if detection_probability != 1 else []
    )
    hold = float(detection_correlation_time)
    parts += [f"{CORRELATION_PART}{hold!r}"] if hold > 0 else []
    parts += [BLIND_PART] if blind else []
    parts += [NO_FLY_PART] if no_fly else []
    parts += [f"{TEAM_PART}{team}"] if team > 1 else []
    parts += [] if labelled else [UNLABELLED_PART]
    parts += [f"{CLUTTER_PART}{float(false_alarm_density)!r}"] if false_alarm_density > 0 else []
    return "+".join(parts)


DETECTION_PART = "pd:"
"""The prefix of a setting's detection probability part (`setting_name`)."""
BLIND_PART = "blind"
"""The setting part of planners told the paper's certain sensor (`setting_name`)."""
NO_FLY_PART = "nofly"
"""The setting part of scenarios with random no-fly circles (`setting_name`)."""
TEAM_PART = "team:"
"""The prefix of a setting's team size part (`setting_name`)."""
UNLABELLED_PART = "unlabelled"
"""The setting part of a sensor whose detections name no target (`setting_name`)."""
CLUTTER_PART = "clutter:"
"""The prefix of a setting's false alarm density part (`setting_name`)."""
CORRELATION_PART = "correlation:"
"""The prefix of a setting's detection correlation time part (`setting_name`)."""


def _setting_parts(setting: str) -> tuple[str, dict, float, bool]:
    """``(base, scenario fields, detection probability, blind)`` of a `setting_name`."""
    base, *rest = setting.split("+")
    forms = [part for part in rest if part in ("continuous", "paper_text")]
    pds = [float(part[len(DETECTION_PART) :]) for part in rest if part.startswith(DETECTION_PART)]
    blind = BLIND_PART in rest
    clutters = [float(part[len(CLUTTER_PART) :]) for part in rest if part.startswith(CLUTTER_PART)]
    holds = [
        float(part[len(CORRELATION_PART) :]) for part in rest if part.startswith(CORRELATION_PART)
    ]
    motions = [
        motion_label(part)
        for part in rest
        if part not in forms
        and not part.startswith((DETECTION_PART, TEAM_PART, CLUTTER_PART, CORRELATION_PART))
        and part not in (BLIND_PART, NO_FLY_PART, UNLABELLED_PART)
    ]
    fields: dict = {"process_noise_form": forms[0] if forms else "continuous"}
    if motions:
        fields["motion"] = motions[0]
    sensor: dict = {"detection_probability": pds[0]} if pds else {}
    if UNLABELLED_PART in rest:
        sensor["labelled"] = False
    if clutters:
        sensor["false_alarm_density"] = clutters[0]
    if holds:
        sensor["detection_correlation_time"] = holds[0]
    if sensor:
        fields["sensor"] = FootprintSensorSpec(**sensor)
    teams = [int(part[len(TEAM_PART) :]) for part in rest if part.startswith(TEAM_PART)]
    if teams:
        fields["team"] = teams[0]
    return base, fields, pds[0] if pds else 1.0, blind


def scenario_for(key: EpisodeKey) -> Scenario:
    """The random scenario of a benchmark episode."""
    base, fields, _, _ = _setting_parts(key.setting)
    scenario = random_scenario(
        key.n_targets, seed=key.seed, homogeneous=base == "homogeneous", **fields
    )
    if NO_FLY_PART in key.setting.split("+"):
        return with_no_fly(scenario, key.seed)
    return scenario


def planner_mission_for(key: EpisodeKey, scenario: Scenario) -> MissionSpec | None:
    """The mission a benchmark episode's planner is told: the scenario's own (``None``), or
    under ``"+blind"`` the same with the paper's certain sensor (``Pd = 1``, no false alarms)."""
    if not _setting_parts(key.setting)[3]:
        return None
    return dataclasses.replace(
        scenario.mission_spec(), detection_probability=1.0, false_alarm_density=0.0
    )


def planner_for(key: EpisodeKey):
    """A fresh planner of a benchmark episode, from the settings stored in its key."""
    entry = planner_entry(key.planner)
    return entry.factory(entry.settings_type.from_canonical(key.planner_settings))


WARM_UP_STEPS = 10
"""Steps of the untimed warm-up mission (`warm_up`)."""

_warmed: set[tuple[str, str]] = set()
"""The planners (name, canonical settings) this process has warmed up."""


def warm_up(key: EpisodeKey) -> None:
    """Once per planner and settings in this process, fly the first `WARM_UP_STEPS`
    steps of ``key``'s scenario with a fresh planner, untimed: the first call of a planner
    in a process loads or compiles its kernels (tens of seconds on a cold cache), which the
    episode's wall time would count otherwise. A fresh planner and seed per episode keep the
    episode's result the same."""
    if (key.planner, key.planner_settings) in _warmed:
        return
    scenario = scenario_for(key)
    short = scenario.model_copy(
        update={"budget": min(scenario.budget, WARM_UP_STEPS * scenario.time_step)}
    )
    run_episode(
        short,
        planner_for(key),
        belief_stride=short.n_steps,
        planner_mission=planner_mission_for(key, short),
    )
    _warmed.add((key.planner, key.planner_settings))


def run_one(key: EpisodeKey) -> EpisodeRow:
    """Fly one benchmark episode (a top-level function, so worker processes can run it); its
    wall time is that of the mission alone, after `warm_up`. Its ``info`` adds the targets
    never detected and, for detections without identity, the tracking summary
    (`hptrack.sim.record.EpisodeRecord.tracking_summary`)."""
    warm_up(key)
    scenario = scenario_for(key)
    planner = planner_for(key)
    start = time.perf_counter()
    told = planner_mission_for(key, scenario)
    record = run_episode(scenario, planner, belief_stride=scenario.n_steps, planner_mission=told)
    wall = time.perf_counter() - start
    metrics = record.metrics()
    return EpisodeRow(
        key,
        record.uncertainty,
        scenario.never_observed_uncertainty(),
        int(record.detections.sum()),
        wall,
        {
            **record.info,
            "targets_never_detected": metrics["targets_never_detected"],
            **record.tracking_summary(),
        },
        metrics["gospa_mean"],
        metrics["gospa_end"],
        metrics["track_loss"],
    )


def run_benchmark(
    config: BenchmarkConfig,
    store: ResultStore,
    workers: int = 1,
    on_done: Callable[[EpisodeRow, int, int], None] | None = None,
    executor: Executor | None = None,
    on_wait: Callable[[int, int], None] | None = None,
) -> int:
    """Run every episode not yet in ``store``; each is claimed before it runs and stored as soon
    as it finishes. Episodes that another run on the database holds are waited for, until that
    run stores them or its claims are released (`ResultStore.release_stale_claims`: it
    died, is no run of this database, or held them too long), and then run here if need be.

    Args:
        config: what to run.
        store: the results database.
        workers: episodes in flight at once (worker processes unless ``executor`` is given).
        on_done: ``on_done(row, finished, total)`` reports progress.
        executor: where episodes run (e.g. a Dask ``Client.get_executor()``); default this
            process (``workers == 1``) or a process pool of ``workers``.
        on_wait: ``on_wait(stored, total)`` says that the rest is another run's, every
            `OTHER_RUN_POLL_S` while this run waits for it.

    Returns:
        The number of episodes run now.
    """
    keys = config.keys()
    ran = 0
    while True:
        ran += run_keys(keys, store, workers, on_done, executor)
        stored = len(set(keys) & store.done())
        if stored == len(keys):
            return ran
        if on_wait:
            on_wait(stored, len(keys))
        time.sleep(OTHER_RUN_POLL_S)


def run_keys(
    keys: Iterable[EpisodeKey],
    store: ResultStore,
    workers: int = 1,
    on_done: Callable[[EpisodeRow, int, int], None] | None = None,
    executor: Executor | None = None,
) -> int:
    """`run_benchmark` on any list of episodes (in this order)."""
    store.release_stale_claims()
    done = store.done()
    todo = [k for k in keys if k not in done]
    total = len(todo)
    finished = 0

    def record(row: EpisodeRow) -> None:
        nonlocal finished
        store.add(row)
        finished += 1
        if on_done:
            on_done(row, finished, total)

    if executor is None and workers <= 1:
        try:
            for key in todo:
                if store.claim(key):
                    record(run_one(key))
        except BaseException:
            store.release_all()
            raise
        return finished
    own_pool = executor is None
    if own_pool:
        workers = max(1, min(workers, len(todo)))
    pool = worker_pool(workers) if own_pool else executor
    pending: dict[Future, EpisodeKey] = {}
    queue = iter(todo)
    try:
        while True:
            while len(pending) < workers:
                key = next((k for k in queue if store.claim(k)), None)
                if key is None:
                    break
                pending[pool.submit(run_one, key)] = key
            if not pending:
                break
            ready, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in ready:
                pending.pop(future)
                record(future.result())
    except BaseException:  # an interrupt or a failure: stop the episodes in flight now
        for future in pending:
            future.cancel()
        if own_pool:
            stop_workers(pool)
        store.release_all()
        raise
    finally:
        if own_pool:
            pool.shutdown(wait=True, cancel_futures=True)
    return finished


def run_variants(
    configs: dict[Any, BenchmarkConfig], store: ResultStore, workers: int, run: bool = True
) -> dict[Any, dict[tuple[int, int], Any]]:
    """Run each named benchmark on ``store`` (unless ``run`` is false: report only) and return
    its stored rows, ``{name: {(n, seed): row}}`` (the benchmark scripts' side-by-side runs)."""
    out = {}
    for name, config in configs.items():
        if run:
            run_benchmark(config, store, workers)
        wanted = set(config.keys())
        out[name] = {(r.key.n_targets, r.key.seed): r for r in store.rows() if r.key in wanted}
    return out


def benchmark(
    planners: Sequence[str] = ("mcts", "greedy"),
    target_counts: Sequence[int] = (2, 3, 4, 5, 6),
    scenarios: int = 10,
    *,
    homogeneous: bool = True,
    options: dict[str, dict[str, Any]] | None = None,
    db: str | Path = ":memory:",
    workers: int = 1,
    first_seed: int = 0,
    iterations: int | None = None,
    time_limit: float | None = None,
    detection_probability: float = 1.0,
    blind: bool = False,
    no_fly: bool = False,
    team: int = 1,
    labelled: bool = True,
    false_alarm_density: float = 0.0,
    detection_correlation_time: float = 0.0,
    metric: str = "U",
) -> dict:
    """Fly every planner once on each random scenario and summarise ``U`` or another
    ``metric`` (the library face of ``hptrack benchmark``).

    Args:
        planners: registered planner names.
        target_counts: the values of ``n``.
        scenarios: scenarios per ``n`` (seeds ``first_seed ..``).
        homogeneous: the paper's ARVI/A* setting (shared prior and ``q``); else heterogeneous.
        options: each planner's options, e.g. ``{"mcts": {"iterations": 20_000}}``.
        db: a results database file to store episodes in and resume from (default in memory);
            episodes another run on it holds are waited for (`run_benchmark`).
        workers: episodes in flight at once (worker processes).
        first_seed: first scenario seed.
        iterations: tree-search iterations per decision of every planner that searches (an
            option in ``options`` wins).
        time_limit: planning seconds per decision, likewise; not with ``iterations``.
        detection_probability: the sensor's chance of detecting a target inside its footprint
            at each look (1: the paper's).
        blind: the planners are told the paper's certain sensor (`BenchmarkConfig`).
        no_fly: random no-fly circles in every scenario (`BenchmarkConfig`).
        team: UAVs per scenario (`BenchmarkConfig`).
        labelled: detections name their targets; false: positions only (`BenchmarkConfig`).
        false_alarm_density: false alarms per m^2 per look, only unlabelled (`BenchmarkConfig`).
        detection_correlation_time: s a detection draw holds (`BenchmarkConfig`).
        metric: what to summarise, one of `hptrack.sim.record.METRICS` (`summarise`).

    Returns:
        ``{planner: {n: {"mean", "std", "episodes", "never_observed", "wall_time_s"}}}``.

    Raises:
        InputError: bad options, both ``iterations`` and ``time_limit``, or an unknown
            ``metric``.
    """
    check_metric(metric)
    options = options or {}
    unknown = sorted(set(options) - set(planners))
    if unknown:
        raise InputError(f"options given for planners not benchmarked: {', '.join(unknown)}")
    check_effort(iterations, time_limit)
    settings = {
        p: planner_settings(
            p,
            {
                **planner_entry(p).settings_type.effort_options(iterations, time_limit),
                **options.get(p, {}),
            },
        )
        for p in planners
    }
    config = BenchmarkConfig(
        tuple(planners),
        settings,
        tuple(target_counts),
        scenarios,
        homogeneous,
        first_seed,
        detection_probability=detection_probability,
        blind=blind,
        no_fly=no_fly,
        team=team,
        labelled=labelled,
        false_alarm_density=false_alarm_density,
        detection_correlation_time=detection_correlation_time,
    )
    check_team(planners, team)
    store = ResultStore(db)
    try:
        run_benchmark(config, store, workers)
        wanted = set(config.keys())
        return summarise((row for row in store.rows() if row.key in wanted), planners, metric)
    finally:
        store.close()


def check_effort(iterations: int | None, time_limit: float | None) -> None:
    """Refuse both effort limits of a benchmark at once: its planners are compared at one kind
    of effort."""
    if iterations is not None and time_limit is not None:
        raise InputError("give --iterations or --time-limit (iterations or time_limit), not both")


def check_metric(metric: str) -> str:
    """``metric`` if it names one of `hptrack.sim.record.METRICS`.

    Raises:
        InputError: another name.
    """
    if metric not in METRICS:
        raise InputError(f"--metric must be one of {', '.join(METRICS)}, got {metric!r}")
    return metric


def summarise(rows: Iterable[EpisodeRow], order: Iterable[str] = (), metric: str = "U") -> dict:
    """``{planner: {n: {"mean", "std", "episodes", "never_observed", "wall_time_s"}}}`` of
    ``metric`` (`hptrack.sim.record.METRICS`, default ``U``) over the episodes that hold it
    (``episodes`` counts them; mean and std are NaN when none does); planners in ``order``
    first (in that order), then the others as they first appear in ``rows``."""
    check_metric(metric)
    groups: dict = {planner: {} for planner in order}
    for row in rows:
        groups.setdefault(row.key.planner, {}).setdefault(row.key.n_targets, []).append(row)
    out: dict = {}
    for planner, by_n in groups.items():
        if not by_n:
            continue
        out[planner] = {}
        for n, items in sorted(by_n.items()):
            values = [v for v in (r.metric(metric) for r in items) if v is not None]
            u = np.array(values)
            out[planner][n] = {
                "mean": float(u.mean()) if values else math.nan,
                "std": float(u.std()) if values else math.nan,
                "episodes": len(values),
                "never_observed": float(np.mean([r.never_observed for r in items])),
                "wall_time_s": float(np.mean([r.wall_time_s for r in items])),
            }
    return out


def reductions(summary: dict, planner: str) -> dict:
    """Reduction of ``planner``'s mean ``U`` against each other planner's, percent (the paper's
    "our method reduces U by ... compared to ARVI"):
    ``{(planner, baseline): {n: 100 (U_baseline - U_planner) / U_baseline}}``."""
    mine = summary[planner]
    out = {}
    for baseline, theirs in summary.items():
        if baseline == planner:
            continue
        shared = sorted(set(mine) & set(theirs))
        out[(planner, baseline)] = {
            n: 100.0 * (theirs[n]["mean"] - mine[n]["mean"]) / theirs[n]["mean"] for n in shared
        }
    return out


def gap_closed(summary: dict, floor: str = "greedy", reference: str = "clairvoyant") -> dict:
    """Share of the gap from ``floor`` (no look-ahead) to ``reference`` (reads the truth) that
    each planner's mean ``U`` closes, percent: ``{planner: {n: 100 (U_floor - U) / (U_floor -
    U_reference)}}`` (empty without both; a team's ``team-greedy`` and ``team-clairvoyant``
    stand in for the two when only they ran)."""
    if (floor not in summary or reference not in summary) and {
        f"team-{floor}",
        f"team-{reference}",
    } <= set(summary):
        floor, reference = f"team-{floor}", f"team-{reference}"
    if floor not in summary or reference not in summary:
        return {}
    low, ref = summary[floor], summary[reference]
    return {
        planner: {
            n: 100.0 * (low[n]["mean"] - cell["mean"]) / (low[n]["mean"] - ref[n]["mean"])
            for n, cell in by_n.items()
            if n in low and n in ref and low[n]["mean"] != ref[n]["mean"]
        }
        for planner, by_n in summary.items()
    }
