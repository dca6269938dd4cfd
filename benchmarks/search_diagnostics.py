"""Diagnostics of the tree search quoted in the README and ``docs/results/search-options.md``.

    # early follows (the first "follow" before 60 % of the budget) per setting, n and settings
    python3 benchmarks/search_diagnostics.py follows --db results/effort.db
    # paired U differences of one database's mcts episodes against another's, same scenarios
    python3 benchmarks/search_diagnostics.py paired --db results/default-effort.db \\
        --against docs/results/benchmark/episodes.csv \\
        --against docs/results/learning-benchmark/episodes.csv
    # ... of some of its episodes against others of the same database (resolved mcts options)
    python3 benchmarks/search_diagnostics.py paired --db results/default-effort.db \\
        --where dwell=20 --against results/default-effort.db --against-where dwell=0
    # simulations per second of each backup on a first plan
    python3 benchmarks/search_diagnostics.py rates --targets 6,12
    # what a rollout is: sub-tasks, how often it ends in a follow, its time, per policy
    python3 benchmarks/search_diagnostics.py rollouts --targets 6,12
    # the sub-tasks each preset flies on a scenario file, each pursuit with its estimate
    python3 benchmarks/search_diagnostics.py subtasks examples/paper-flight.yaml --seed 0
    python3 benchmarks/search_diagnostics.py subtasks examples/paper-flight.yaml --seed 6 \\
        --options '{"estimator": "sharp", "miss": "keep"}'
    # the MDP's exact best plan from a small scenario's start, per estimator, against the search
    python3 benchmarks/search_diagnostics.py optimum examples/paper-flight.yaml
    # how well the MDP predicts the sub-tasks flown: durations and find rates, per n and outcome
    python3 benchmarks/search_diagnostics.py model-accuracy --db results/targets.db
    # what a dwell after a find buys: the belief's uncertainty later, with and without it
    python3 benchmarks/search_diagnostics.py dwell
    # the targets a search never finds, and what U is with none, one, two... of them
    python3 benchmarks/search_diagnostics.py lost --db results/targets.db --where time_limit=1
"""

from __future__ import annotations

import argparse
import csv
import functools
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

EARLY = 0.6
"""A follow that starts before this fraction of the budget is an early follow."""


def _rows(path: Path) -> list:
    from hptrack.experiments.store import ResultStore

    store = ResultStore(path)
    try:
        return [r for r in store.rows() if r.key.planner == "mcts"]
    finally:
        store.close()


def _subtasks(row, kind: str) -> list:
    """The sub-tasks of ``kind`` (``"pursue"``, ``"follow"``...) in a stored episode's log, in
    any shape it was written in (`hptrack.subtasks.read_subtasks`)."""
    from hptrack.subtasks import read_subtasks

    ids = [str(i) for i in range(row.key.n_targets)]
    entries = (row.info or {}).get("subtasks", [])
    return [e for e in read_subtasks(entries, ids) if e.kind == kind]


def follows(db: Path) -> None:
    from hptrack.experiments.benchmark import scenario_for

    counts, totals = defaultdict(int), defaultdict(int)
    for r in _rows(db):
        group = (r.key.setting, r.key.n_targets, r.key.planner_settings)
        totals[group] += 1
        entries = _subtasks(r, "follow")
        limit = EARLY * scenario_for(r.key).n_steps
        counts[group] += bool(entries and entries[0].start_step < limit)
    for group in sorted(totals):
        print(
            f"{group[0]} n={group[1]} {group[2]}: {counts[group]} of {totals[group]} "
            "episodes follow early"
        )


@functools.cache
def _options(settings: str) -> dict:
    """The options of a canonical settings text (read once per text)."""
    return json.loads(settings)


def _matches(settings: str, where: list[str]) -> bool:
    """Whether the mcts settings (canonical text: every option) have every ``option=value`` of
    ``where``."""
    resolved = _options(settings)
    for condition in where:
        key, _, value = condition.partition("=")
        have = resolved[key]
        if (have != float(value)) if isinstance(have, float) else (str(have) != value):
            return False
    return True


def _published(paths: list[Path], where: list[str]) -> dict:
    out = {}
    for path in paths:
        if path.suffix == ".csv":
            with path.open(newline="") as fh:
                for r in csv.DictReader(fh):
                    if r["planner"] == "mcts":
                        out[(r["setting"], int(r["n_targets"]), int(r["seed"]))] = float(r["U"])
        else:
            for r in _rows(path):
                if _matches(r.key.planner_settings, where):
                    out[(r.key.setting, r.key.n_targets, r.key.seed)] = r.uncertainty
    return out


def paired(db: Path, against: list[Path], where: list[str], against_where: list[str]) -> None:
    reference = _published(against, against_where)
    diffs = defaultdict(list)
    for r in _rows(db):
        if not _matches(r.key.planner_settings, where):
            continue
        ref = reference.get((r.key.setting, r.key.n_targets, r.key.seed))
        if ref is not None:
            diffs[(r.key.setting, r.key.n_targets)].append(r.uncertainty - ref)
    print("| setting | n | U minus the reference, mean +- standard error (scenarios) |")
    print("|---|---|---|")
    for (setting, n), d in sorted(diffs.items()):
        a = np.array(d)
        se = a.std(ddof=1) / math.sqrt(a.size) if a.size > 1 else math.nan
        print(f"| {setting} | {n} | {a.mean():+.2f} +- {se:.2f} ({a.size}) |")


def _first_problem(n: int):
    from hptrack.planning.subtask_mdp import PlanningProblem
    from hptrack.scenario.random import random_scenario

    sc = random_scenario(n, seed=0, homogeneous=True)
    spec = sc.mission_spec()
    return PlanningProblem(spec.record, sc.agent.position, sc.means(), sc.covariances(), sc.budget)


def rates(targets: list[int], seconds: float) -> None:
    from hptrack.planning import SearchOptions, search
    from hptrack.planning.backups import BACKUPS, backup_of

    for n in targets:
        problem = _first_problem(n)
        search(problem, iterations=64)  # load the kernels
        for backup in BACKUPS:
            result = search(
                problem, SearchOptions(backup=backup_of(backup)), time_limit=seconds, seed=0
            )
            print(
                f"n={n} {backup}: {result.simulations / result.elapsed:,.0f} simulations/s, "
                f"{result.state_nodes:,} state nodes"
            )


def rollouts(targets: list[int], count: int) -> None:
    import time

    import numba

    from hptrack.planning import subtask_mdp as mdp
    from hptrack.planning.rollout import UniformRandom, choose_action
    from hptrack.planning.stream import uniform
    from hptrack.planning.subtask_rollout import Nearest, UniformNoFollow

    @numba.njit
    def run(env, root, state, policy, rng, candidates, work, count):
        """``count`` rollouts from ``root`` as the search runs them (its ``rollout``), counted."""
        subtasks, follows, total = 0, 0, 0.0
        for _ in range(count):
            mdp.copy_state(env, root, state)
            while True:
                a = choose_action(policy, env, state, rng, candidates)
                if a < 0:
                    break
                follows += a == state[0][mdp.I_LAST]
                p, payload0, payload1 = mdp.expand_action(env, state, a, work)
                found = uniform(rng) < p
                outcome, payload = (mdp.FIND, payload0) if found else (mdp.MISS, payload1)
                mdp.apply_outcome(env, state, a, outcome, payload, work)
                subtasks += 1
            total += mdp.terminal_value(env, state)
        return subtasks, follows, total

    print(
        "| rollout policy | n | sub-tasks per rollout | rollouts that end in a follow | "
        "time per rollout | mean U |"
    )
    print("|---|---|---|---|---|---|")
    for n in targets:
        problem = _first_problem(n)
        for name, policy in (
            ("uniform", UniformRandom()),
            ("uniform_no_follow", UniformNoFollow()),
            ("nearest, epsilon 0.6", Nearest(0.6)),
        ):
            env = problem.env()
            root = problem.root_state()
            state = tuple(a.copy() for a in root)
            args = (np.array([3], dtype=np.uint64), np.empty(n, dtype=np.int64), mdp.new_work())
            run(env, root, state, policy, *args, 10)  # compile
            start = time.perf_counter()
            steps, follows, total = run(env, root, state, policy, *args, count)
            elapsed = time.perf_counter() - start
            print(
                f"| `{name}` | {n} | {steps / count:.1f} | {100 * follows / count:.0f} % | "
                f"{elapsed / count * 1e6:.0f} us | {-total / count:.1f} |"
            )


def subtasks(path: Path, iterations: int, seed: int | None = None, options: str = "{}") -> None:
    """The sub-tasks each preset flies on a scenario file (seed: the file's, or ``seed``;
    ``options``: more mcts options, JSON); a pursuit is shown with the MDP's estimate when it
    started: ``p_find``, and the intercept plus the expected time to find, s."""
    from hptrack.registry import make_planner
    from hptrack.scenario.io import load_scenario
    from hptrack.sim.episode import run_episode
    from hptrack.subtasks import read_subtasks

    scenario = load_scenario(path)
    ids = scenario.target_ids
    for preset in ("paper", "improved"):
        record = run_episode(
            scenario,
            make_planner(
                "mcts", {"preset": preset, "iterations": iterations, **json.loads(options)}
            ),
            seed=seed,
        )
        steps = [
            f"{ids[e.target]} {e.outcome or ''} (p_find {e.p_find:.2f}, "
            f"{e.intercept_time + e.expected_time:.1f} s)"
            if e.kind == "pursue"
            else ("hover" if e.target is None else f"{e.kind} {ids[e.target]}")
            for e in read_subtasks(record.info["subtasks"], ids)
        ]
        print(f"{preset}: U = {record.uncertainty:.2f}; " + ", ".join(steps))


def optimum(path: Path, iterations: int, miss: str) -> None:
    """The sub-task MDP's exact best plan from a scenario file's start (a few targets), per
    estimator: its expected ``U``, its first actions, the exact ``U`` of following the first
    target found to the end against the best plan after that find, and the improved search's
    value with ``iterations`` simulations."""
    from hptrack.planning import PlanningProblem, search
    from hptrack.planning.hierarchical import MctsSettings
    from hptrack.planning.subtask_mdp import FIND, SubtaskOptions, apply_outcome, new_work
    from hptrack.planning.subtask_optimum import action_values, optimal_plan
    from hptrack.scenario.io import load_scenario

    scenario = load_scenario(path)
    ids = scenario.target_ids
    problem = PlanningProblem.from_observation(
        scenario.mission_spec().record, scenario.initial_observation()
    )
    for estimator in ("paper", "sharp"):
        options = SubtaskOptions(estimator=estimator, miss=miss)
        try:
            best = optimal_plan(problem, options)
        except ValueError as error:  # too many histories to enumerate
            print(f"{estimator}: {error}")
            continue
        env, state = problem.env(options), problem.root_state()
        first = best.actions[0]
        apply_outcome(env, state, first, FIND, best.steps[0], new_work())
        after = action_values(env, state)
        settings = MctsSettings(preset="improved", estimator=estimator, miss=miss)
        found = search(problem, settings.search_options(), options, iterations=iterations)
        plan = ", ".join(
            f"{ids[a]} (p_find {p:.2f}, {s * scenario.time_step:g} s)"
            for a, p, s in zip(best.actions[:6], best.p_find, best.steps, strict=False)
        )
        print(
            f"{estimator}: best expected U {-best.value:.2f} ({best.nodes} states; the search, "
            f"{iterations} simulations: {-found.root.values.max():.2f}); switches "
            f"{sum(a != b for a, b in zip(best.actions, best.actions[1:], strict=False))}; "
            f"plan {plan}, ...; after finding {ids[first]}: following it "
            f"{-after[first]:.2f}, best {-max(after.values()):.2f}"
        )


def model_accuracy(db: Path) -> None:
    """Each pursuit sub-task flown by the max-backup searches of ``db``: its duration against
    the MDP's (intercept plus ``E[T_find]`` or ``t_cutoff``), and the find rate against the
    mean ``p_find``."""
    from hptrack.experiments.benchmark import scenario_for

    flown = defaultdict(list)
    for r in _rows(db):
        if not _matches(r.key.planner_settings, ["backup=max"]):
            continue
        tau = scenario_for(r.key).time_step
        for e in _subtasks(r, "pursue"):
            if e.outcome is not None:
                found = e.outcome == "found"
                predicted = e.intercept_time + (e.expected_time if found else e.t_cutoff)
                flown[r.key.n_targets].append(
                    (found, (e.end_step - e.start_step) * tau, predicted, e.p_find)
                )
    for n in sorted(flown):
        rows = np.array(flown[n])
        for found, name in ((1.0, "found"), (0.0, "missed")):
            part = rows[rows[:, 0] == found]
            if len(part):
                print(
                    f"n={n} {name}: {len(part)} sub-tasks, mean duration "
                    f"{part[:, 1].mean():.1f} s flown against {part[:, 2].mean():.1f} s "
                    "predicted"
                )
        print(
            f"n={n}: find rate {rows[:, 0].mean():.3f} against mean p_find {rows[:, 3].mean():.3f}"
        )


def lost(db: Path, where: list[str]) -> None:
    """Per ``n`` and settings of ``db``'s homogeneous mcts episodes matching ``where``: the
    targets no pursuit found (never pursued, or only missed), mean ``U`` by their number, and
    what one such target adds to ``U`` if nothing else measures it (its prior grown to the end:
    the never-observed ``U`` over ``n``, the same for every target of a homogeneous scenario)."""
    groups = defaultdict(list)
    for r in _rows(db):
        if r.key.setting != "homogeneous" or not _matches(r.key.planner_settings, where):
            continue
        tried, found = set(), set()
        for e in _subtasks(r, "pursue"):
            tried.add(e.target)
            if e.outcome == "found":
                found.add(e.target)
        n = r.key.n_targets
        groups[(n, r.key.planner_settings)].append(
            (r.uncertainty, n - len(tried), len(tried - found), r.never_observed / n)
        )
    for (n, settings), rows in sorted(groups.items()):
        a = np.array(rows)
        lost_count = a[:, 1] + a[:, 2]
        by = ", ".join(
            f"{k:.0f}: {a[lost_count == k, 0].mean():.1f} ({(lost_count == k).sum()})"
            for k in np.unique(lost_count)
        )
        share = (lost_count * a[:, 3]).sum() / a[:, 0].sum()
        others = (a[:, 0] - lost_count * a[:, 3]).sum() / (n * len(a) - lost_count.sum())
        print(
            f"n={n} {settings}: {len(a)} episodes, mean U {a[:, 0].mean():.2f}; never found "
            f"{lost_count.mean():.2f} per episode (never pursued {a[:, 1].mean():.2f}, only "
            f"missed {a[:, 2].mean():.2f}), each worth up to {a[:, 3].mean():.2f} of U, "
            f"together at most {100 * share:.0f} % of U; the others at least "
            f"{others:.1f} per target; mean U by the number never found: {by}"
        )


def dwell(unseen: float, q: float) -> None:
    """A target unseen for ``unseen`` s from a typical prior, found, optionally followed for a
    dwell, then left: its position ``log det Sigma^xy`` and variance later, per dwell length."""
    from hptrack.models.beliefs import position_logdet
    from hptrack.models.measurement import update_covariance
    from hptrack.models.motion import predict_covariance

    tau, noise = 0.5, 10.0 * np.eye(2)

    def grow(cov, seconds):
        out = np.empty((4, 4))
        predict_covariance(cov, q, round(seconds / tau), tau, tau, out)
        return out

    def measure(cov):
        out = np.empty((4, 4))
        update_covariance(cov, noise, out)
        return out

    found = measure(grow(np.diag([1000.0, 1000.0, 0.4, 0.4]), unseen))
    print(f"q = {q:g} m^2/s^3, unseen {unseen:g} s before the find, R = 10 I m^2, tau = {tau} s")
    print(
        "dwell s | velocity variance (m/s)^2 | log det after 60 / 150 / 300 s | x variance "
        "after 300 s, m^2"
    )
    for length in (0, 5, 10, 20, 40):
        cov = found
        for _ in range(round(length / tau)):
            cov = measure(grow(cov, tau))
        later = [grow(cov, s) for s in (60.0, 150.0, 300.0)]
        logdets = " / ".join(f"{v:.2f}" for v in position_logdet(np.array(later)))
        print(f"{length:7d} | {cov[2, 2]:.4f} | {logdets} | {later[2][0, 0]:.0f}")


def _where(parser: argparse.ArgumentParser, flag: str, text: str) -> None:
    parser.add_argument(flag, action="append", default=[], metavar="OPTION=VALUE", help=text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("follows")
    p.add_argument("--db", type=Path, required=True)
    p = sub.add_parser("paired")
    p.add_argument("--db", type=Path, required=True)
    p.add_argument(
        "--against",
        type=Path,
        action="append",
        required=True,
        help="a published episodes.csv or another results database",
    )
    _where(p, "--where", "only --db's episodes with this resolved mcts option")
    _where(p, "--against-where", "only the reference databases' episodes with this option")
    p = sub.add_parser("rates")
    p.add_argument("--targets", default="6,12")
    p.add_argument("--seconds", type=float, default=1.0)
    p = sub.add_parser("rollouts")
    p.add_argument("--targets", default="6,12")
    p.add_argument("--count", type=int, default=5000)
    p = sub.add_parser("subtasks")
    p.add_argument("scenario", type=Path)
    p.add_argument("--iterations", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--options", default="{}", help="more mcts options, JSON")
    p = sub.add_parser("optimum")
    p.add_argument("scenario", type=Path)
    p.add_argument("--iterations", type=int, default=100_000)
    p.add_argument("--miss", choices=("drop", "keep"), default="drop")
    p = sub.add_parser("model-accuracy")
    p.add_argument("--db", type=Path, required=True)
    p = sub.add_parser("lost")
    p.add_argument("--db", type=Path, required=True)
    _where(p, "--where", "only the episodes with this resolved mcts option")
    p = sub.add_parser("dwell")
    p.add_argument("--unseen", type=float, default=200.0, help="s")
    p.add_argument("--q", type=float, default=3e-4, help="m^2/s^3")
    args = parser.parse_args()
    if args.command == "follows":
        follows(args.db)
    elif args.command == "paired":
        paired(args.db, args.against, args.where, args.against_where)
    elif args.command == "rollouts":
        rollouts([int(n) for n in args.targets.split(",")], args.count)
    elif args.command == "rates":
        rates([int(n) for n in args.targets.split(",")], args.seconds)
    elif args.command == "model-accuracy":
        model_accuracy(args.db)
    elif args.command == "lost":
        lost(args.db, args.where)
    elif args.command == "dwell":
        dwell(args.unseen, args.q)
    elif args.command == "optimum":
        optimum(args.scenario, args.iterations, args.miss)
    else:
        subtasks(args.scenario, args.iterations, args.seed, args.options)


if __name__ == "__main__":
    main()
