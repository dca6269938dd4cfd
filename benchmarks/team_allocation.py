"""CBBA on the estimator's path values (`hptrack.planning.cbba`, `hptrack.planning.team_value`):
how often the marginal gains diminish, and whether the auction converges, how fast and how
close to the sequential greedy assignment.

Scenarios: the paper's random homogeneous ones (`hptrack.scenario.random_scenario`, seeds
``0 .. seeds - 1``), n targets, m UAVs of the scenario's agent, each started at the scenario's
start plus an offset uniform in +-300 m per axis (drawn from ``default_rng(seed)``), bundles of
``ceil(n / m)``, every UAV hearing every other.

Table 1 (one UAV, per n): from a random order of the targets, the first 3 make a path and the
4th is inserted at its best position; for every other target, whether its best marginal score
(over insertion positions) rose with the insertion. Table 2 (per n, m): CBBA with the paper's
bids and with warped bids (at most 200 rounds): the share that converged, the rounds, and the
team's total value over the sequential greedy assignment's (the same values, centralised).

    python3 benchmarks/team_allocation.py --out docs/results/team-allocation
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from hptrack.experiments.report import mean_se, write_tables
from hptrack.planning.cbba import cbba
from hptrack.planning.team_value import TeamPathValue, team_path_value
from hptrack.scenario import random_scenario

MAX_ROUNDS = 200
"""The round limit of every auction."""
OFFSET_M = 300.0
"""The UAVs' start offsets are uniform in +- this, per axis, m."""


def team(seed: int, n_targets: int, n_agents: int) -> TeamPathValue:
    """The path values of ``n_agents`` UAVs on scenario ``seed`` (module docstring)."""
    scenario = random_scenario(n_targets, seed=seed, homogeneous=True)
    obs = scenario.initial_observation()
    rng = np.random.default_rng(seed)
    positions = obs.agent_position + rng.uniform(-OFFSET_M, OFFSET_M, (n_agents, 2))
    return team_path_value(
        [scenario.mission_spec()] * n_agents,
        positions,
        obs.means,
        obs.covariances,
        obs.remaining_budget,
    )


def best_insertion(value: TeamPathValue, agent: int, path: tuple, task: int) -> tuple:
    """``(marginal score, path with the task at its best position)``, the later of equal
    positions."""
    base = value(agent, path)
    best = max(range(len(path) + 1), key=lambda n: (value(agent, (*path[:n], task, *path[n:])), n))
    longer = (*path[:best], task, *path[best:])
    return value(agent, longer) - base, longer


def gains_rise(seeds: int, n_targets: int) -> dict:
    """Table 1's row for ``n_targets``."""
    rises, relative = 0, []
    checks = 0
    for seed in range(seeds):
        value = team(seed, n_targets, 1)
        order = [int(j) for j in np.random.default_rng(seed).permutation(n_targets)]
        path, added = tuple(order[:3]), order[3]
        _, longer = best_insertion(value, 0, path, added)
        for task in order[4:]:
            before = best_insertion(value, 0, path, task)[0]
            after = best_insertion(value, 0, longer, task)[0]
            checks += 1
            if after > before:
                rises += 1
                relative.append((after - before) / before)
    return {
        "n_targets": n_targets,
        "checks": checks,
        "rise_share": rises / checks,
        "median_relative_rise": float(np.median(relative)) if relative else 0.0,
    }


def sequential_greedy_total(value: TeamPathValue, n_agents: int, max_bundle: int) -> float:
    """The total value of the sequential greedy assignment (the best pair first)."""
    paths: list[tuple] = [() for _ in range(n_agents)]
    free = set(range(value.n_targets))
    while free:
        choices = [
            (*best_insertion(value, i, paths[i], j), i, j)
            for i in range(n_agents)
            if len(paths[i]) < max_bundle
            for j in sorted(free)
        ]
        if not choices:
            break
        gain, longer, i, j = max(choices, key=lambda c: (c[0], -c[2], -c[3]))
        if gain <= 0.0:
            break
        paths[i] = longer
        free.discard(j)
    return sum(value(i, p) for i, p in enumerate(paths))


def auctions(seeds: int, n_targets: int, n_agents: int) -> dict:
    """Table 2's row for ``(n_targets, n_agents)``."""
    max_bundle = -(-n_targets // n_agents)
    row: dict = {"n_targets": n_targets, "n_agents": n_agents, "max_bundle": max_bundle}
    for warp in (False, True):
        converged, rounds, ratio, seconds = [], [], [], []
        for seed in range(seeds):
            start = time.perf_counter()
            value = team(seed, n_targets, n_agents)
            result = cbba(
                n_agents, n_targets, value, max_bundle, max_rounds=MAX_ROUNDS, warp_bids=warp
            )
            seconds.append(time.perf_counter() - start)
            converged.append(result.converged)
            if result.converged:
                rounds.append(result.rounds)
                total = sum(value(i, p) for i, p in enumerate(result.paths))
                ratio.append(total / sequential_greedy_total(value, n_agents, max_bundle))
        key = "warped" if warp else "paper"
        row[f"{key}_converged"] = float(np.mean(converged))
        row[f"{key}_rounds_mean"] = float(np.mean(rounds)) if rounds else float("nan")
        row[f"{key}_rounds_max"] = int(max(rounds)) if rounds else 0
        row[f"{key}_ratio_mean"], row[f"{key}_ratio_se"] = (
            mean_se(ratio) if ratio else (float("nan"), float("nan"))
        )
        row[f"{key}_ratio_min"] = float(min(ratio)) if ratio else float("nan")
        row[f"{key}_seconds_mean"] = float(np.mean(seconds))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--out", type=Path, default=Path("results/team-allocation"))
    args = parser.parse_args()
    gains = [gains_rise(args.seeds, n) for n in (12, 20)]
    rows = [auctions(args.seeds, n, m) for n in (12, 20) for m in (2, 3)]
    lines = [
        "| n | checks | marginal score rose | median relative rise |",
        "| --- | --- | --- | --- |",
    ]
    for g in gains:
        lines.append(
            f"| {g['n_targets']} | {g['checks']} | {g['rise_share']:.0%} "
            f"| {g['median_relative_rise']:.0%} |"
        )
    lines += [
        "",
        "| n | m | bundle | bids | converged | rounds (mean, max) "
        "| total / greedy (mean ± se, min) | s per auction |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        for key in ("paper", "warped"):
            rounds = (
                f"{r[f'{key}_rounds_mean']:.1f}, {r[f'{key}_rounds_max']}"
                if r[f"{key}_rounds_max"]
                else "-"
            )
            ratio = (
                f"{r[f'{key}_ratio_mean']:.3f} ± {r[f'{key}_ratio_se']:.3f}, "
                f"{r[f'{key}_ratio_min']:.3f}"
                if r[f"{key}_rounds_max"]
                else "-"
            )
            lines.append(
                f"| {r['n_targets']} | {r['n_agents']} | {r['max_bundle']} | {key} "
                f"| {r[f'{key}_converged']:.0%} | {rounds} | {ratio} "
                f"| {r[f'{key}_seconds_mean']:.2f} |"
            )
    write_tables(args.out, lines, {"seeds": args.seeds, "gains": gains, "auctions": rows})


if __name__ == "__main__":
    main()
