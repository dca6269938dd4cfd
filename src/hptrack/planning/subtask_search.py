"""The tree search (`hptrack.planning.search`) on the sub-task MDP
(`hptrack.planning.subtask_mdp`): Algorithm 1's ``TreeSearch`` from a
`PlanningProblem`, its root parallelism, and the warm-up that
loads its compiled kernels.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from hptrack.models.mission import mission_record, state_size
from hptrack.planning import subtask_mdp
from hptrack.planning.search import (
    PAPER_SEARCH,
    SearchOptions,
    SearchResult,
    check_limits,
    merged,
    run_simulations,
    search_mdp,
)
from hptrack.planning.stream import seed_value


@numba.njit(cache=True, nogil=True)
def run_subtask_simulations(
    tree, env, root, state, work, options, n_actions, max_depth, fixed, n_simulations
):
    """`run_simulations` on the sub-task MDP, compiled once and
    cached on disk.

    The generic loop is not cached itself: its cache index would hold the signature of every
    MDP it ever ran on (test toys included), and another process that cannot import one of
    them could not read it. It releases the GIL, so root-parallel trees run on several cores.
    """
    return run_simulations(
        tree, env, root, state, work, options, n_actions, max_depth, fixed, n_simulations
    )


def search(
    problem: subtask_mdp.PlanningProblem,
    options: SearchOptions = PAPER_SEARCH,
    subtask: subtask_mdp.SubtaskOptions = subtask_mdp.PAPER_SUBTASK,
    iterations: int | None = None,
    time_limit: float | None = None,
    seed: int | np.random.Generator = 0,
    threads: int = 1,
) -> SearchResult:
    """Plan from ``problem``'s root state with Algorithm 1 (``TreeSearch``) on the sub-task MDP.

    Args:
        problem: root state and model; with ``current_action`` set, re-planning mode: the root's
            only action is the current one and the result gives the best next action after
            each of its outcomes (Algorithm 1 lines 9-12).
        options: the search's options (`SearchOptions`,
            default the paper's search).
        subtask: the sub-task MDP's options (estimator, dwell; default the paper's MDP). With
            a dwell, ``problem.current_action`` may be the dwell.
        iterations: stop after this many simulations.
        time_limit: stop once this wall time (s) has passed, checked between chunks of
            simulations. With both limits, whichever comes first.
        seed: an integer or a `numpy.random.Generator` (one ``uint64`` is drawn from it).
            The same seed and number of simulations give the same tree and plan.
        threads: root parallelism: this many independent trees (each with its own stream,
            seeded from ``seed``, and the limits above), searched on as many threads and
            merged (`merge_stats`). 1 is the paper's single tree.

    Raises:
        ValueError: no limit given, a limit not positive, a bad option, or a current action
            that cannot be carried out in the remaining budget.
    """
    check_limits(iterations, time_limit)
    if threads < 1:
        raise ValueError(f"threads must be positive, got {threads}")
    start = time.perf_counter()
    root = problem.root_state()
    fixed = -1 if problem.current_action is None else problem.current_action
    envs = [problem.env(subtask) for _ in range(threads)]  # one memo per tree: kernels write it
    if fixed >= 0 and not subtask_mdp.is_available(envs[0], root, fixed):
        raise ValueError(f"current action {fixed} cannot be carried out in the remaining budget")

    def one(env: subtask_mdp.SubtaskEnv, tree_seed: int | np.random.Generator) -> SearchResult:
        return search_mdp(
            env,
            root,
            subtask_mdp.n_actions(problem.n_targets, subtask),
            problem.n_steps + 2,
            subtask_mdp.new_work(state_size(problem.mission)),
            options,
            iterations=iterations,
            time_limit=time_limit,
            seed=tree_seed,
            fixed=fixed,
            start=start,
            kernel=run_subtask_simulations,
        )

    if threads == 1:
        return one(envs[0], seed)
    seeds = np.random.SeedSequence(seed_value(seed)).generate_state(threads, np.uint64)
    with ThreadPoolExecutor(threads) as pool:
        results = list(pool.map(one, envs, (int(s) for s in seeds)))
    return merged(results, fixed)


_warmed: set[tuple] = set()
"""Compiled signatures (rollout, backup and estimator classes) this process has loaded."""


def warm_up(
    options: SearchOptions = PAPER_SEARCH,
    subtask: subtask_mdp.SubtaskOptions = subtask_mdp.PAPER_SUBTASK,
) -> None:
    """Load (or compile) the search's kernels for ``options``' rollout and backup classes and
    ``subtask``'s estimator once per process with a tiny search, so that the first timed search
    of a process gets as many simulations as the later ones."""
    key = (type(options.rollout), type(options.backup), subtask.estimator)
    if key in _warmed:
        return
    cov = np.diag([1000.0, 1000.0, 0.4, 0.4])
    mission = mission_record(0.5, 60.0, 30.0, 100.0, 10.0 * np.eye(2), np.full(2, 3e-4))
    means = np.array([[300.0, 0, 1, 0], [-300.0, 0, 0, 1]])
    for fixed in (None, 0):
        problem = subtask_mdp.PlanningProblem(
            mission, np.zeros(2), means, np.stack([cov, cov]), 60.0, current_action=fixed
        )
        search(problem, options, subtask, iterations=64, seed=0)
    _warmed.add(key)
