"""Multi-target benchmark (the paper's Sec. V-B, Tables II-III; notes "Multi-target benchmark").

For each number of targets ``n`` and each scenario seed, every planner flies the same random
scenario once for the whole budget. Episodes run on worker processes and are stored as each one
finishes (:mod:`hptrack.experiments.store`); a re-run with the same arguments skips what is done.
Next to every ``U`` the store keeps the scenario's *never observed* score: the ``U`` of a mission
that measures nothing, which depends only on the priors and the budget.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from hptrack.experiments.store import EpisodeKey, EpisodeRow, ResultStore
from hptrack.models.beliefs import position_logdet
from hptrack.registry import PLANNERS, make_planner
from hptrack.scenario.model import Scenario
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode


@dataclass(frozen=True)
class BenchmarkConfig:
    """What to run.

    Attributes:
        planners: registered planner names.
        target_counts: the values of ``n``.
        scenarios: scenarios per ``n`` (seeds ``first_seed .. first_seed + scenarios - 1``).
        homogeneous: the paper's setting for ARVI and A* (shared ``q`` and prior).
        first_seed: first scenario seed.
        effort: planning effort passed to planners that take it, e.g. ``{"iterations": 2000}``
            or ``{"time_limit": 1.0}`` (seconds per decision).
        options: extra options per planner name.
    """

    planners: tuple[str, ...]
    target_counts: tuple[int, ...] = (2, 3, 4, 5, 6)
    scenarios: int = 100
    homogeneous: bool = True
    first_seed: int = 0
    effort: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)

    @property
    def setting(self) -> str:
        return "homogeneous" if self.homogeneous else "heterogeneous"

    @property
    def effort_label(self) -> str:
        return ",".join(f"{k}={v}" for k, v in sorted(self.effort.items())) or "default"

    def keys(self) -> list[EpisodeKey]:
        """Every episode of the benchmark, in run order."""
        seeds = range(self.first_seed, self.first_seed + self.scenarios)
        return [EpisodeKey(p, n, s, self.setting, self.effort_label)
                for n in self.target_counts for s in seeds for p in self.planners]

    def planner_options(self, name: str) -> dict:
        """The effort options ``name``'s factory accepts, plus its own options."""
        params = inspect.signature(PLANNERS[name]).parameters
        accepted = {k: v for k, v in self.effort.items() if k in params}
        return {**accepted, **self.options.get(name, {})}


def scenario_for(key: EpisodeKey) -> Scenario:
    """The random scenario of a benchmark episode."""
    return random_scenario(key.n_targets, seed=key.seed,
                           homogeneous=key.setting == "homogeneous")


def never_observed_uncertainty(scenario: Scenario) -> float:
    """``U`` of a mission that measures nothing: every prior grown to the budget's end."""
    mission = scenario.mission_spec()
    _, covs = mission.motion.predict(scenario.means(), scenario.covariances(),
                                     mission.process_noise, mission.n_steps)
    return float(position_logdet(covs).sum())


def run_one(key: EpisodeKey, options: dict) -> EpisodeRow:
    """Fly one benchmark episode (a top-level function, so worker processes can run it)."""
    scenario = scenario_for(key)
    planner = make_planner(key.planner, **options)
    start = time.perf_counter()
    record = run_episode(scenario, planner, belief_stride=scenario.mission_spec().n_steps)
    wall = time.perf_counter() - start
    return EpisodeRow(key, record.uncertainty, never_observed_uncertainty(scenario),
                      int(record.detections.sum()), wall, record.info)


def run_benchmark(config: BenchmarkConfig, store: ResultStore, workers: int = 1,
                  on_done: Callable[[EpisodeRow, int, int], None] | None = None) -> int:
    """Run every episode not yet in ``store``; each is stored as soon as it finishes.

    Returns the number of episodes run now. ``on_done(row, finished, total)`` reports progress.
    """
    done = store.done()
    todo = [k for k in config.keys() if k not in done]
    total = len(todo)
    if total == 0:
        return 0
    jobs = ((k, config.planner_options(k.planner)) for k in todo)
    finished = 0
    if workers <= 1:
        for key, options in jobs:
            row = run_one(key, options)
            store.add(row)
            finished += 1
            if on_done:
                on_done(row, finished, total)
        return finished
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(run_one, k, o) for k, o in jobs]
        try:
            for future in as_completed(futures):
                row = future.result()
                store.add(row)
                finished += 1
                if on_done:
                    on_done(row, finished, total)
        except BaseException:
            for f in futures:
                f.cancel()
            raise
    return finished


def summarise(rows: Iterable[EpisodeRow]) -> dict:
    """``{planner: {n: {"mean", "std", "episodes", "never_observed"}}}`` of ``U``."""
    groups: dict = {}
    for row in rows:
        groups.setdefault(row.key.planner, {}).setdefault(row.key.n_targets, []).append(row)
    out: dict = {}
    for planner, by_n in groups.items():
        out[planner] = {}
        for n, items in sorted(by_n.items()):
            u = np.array([r.uncertainty for r in items])
            out[planner][n] = {"mean": float(u.mean()), "std": float(u.std()),
                               "episodes": len(items),
                               "never_observed": float(np.mean([r.never_observed
                                                                for r in items])),
                               "wall_time_s": float(np.mean([r.wall_time_s for r in items]))}
    return out


def reductions(summary: dict) -> dict:
    """Reduction of each planner's mean ``U`` against each other planner's, percent:
    ``{(planner, baseline): {n: 100 (U_baseline - U_planner) / U_baseline}}``."""
    out = {}
    for a, by_a in summary.items():
        for b, by_b in summary.items():
            if a == b:
                continue
            shared = sorted(set(by_a) & set(by_b))
            out[(a, b)] = {n: 100.0 * (by_b[n]["mean"] - by_a[n]["mean"]) / by_b[n]["mean"]
                           for n in shared}
    return out
