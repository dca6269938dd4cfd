"""Estimate a tree-search effort comparable to the paper's: the simulations that this project's
search completes in the paper's 30 s planning limit when it runs as plain Python.

The paper planned with a Python implementation and a 30 s limit per search (Sec. V-B). Our search
is compiled with numba; here the same code runs interpreted (``NUMBA_DISABLE_JIT=1``, with the
compile-time dispatch of the MDP kernels replaced by direct calls), on the first plan of the
homogeneous benchmark scenarios, and the simulations it completes in ``--seconds`` are counted.
The paper's code is unknown; an object-based Python search is unlikely to be faster than this
array-based one, so the count is an upper bound on the paper's effort. The compiled search's
count over 1 s is printed beside it.

    python3 benchmarks/paper_effort.py --seconds 30 --seeds 3
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import statistics
import subprocess
import sys
import time
import warnings


def plain_python_search() -> object:
    """The search module with every kernel running as plain Python (call in a fresh process)."""
    os.environ["NUMBA_DISABLE_JIT"] = "1"
    search = importlib.import_module("hptrack.planning.search")
    mdp = importlib.import_module("hptrack.planning.subtask_mdp")
    rollout = importlib.import_module("hptrack.planning.rollout")
    backups = importlib.import_module("hptrack.planning.backups")

    def back_up(backup, tree, path_state, path_action, path_outcome, depth, ret):
        backups.back_sampled(backup, tree, path_state, path_action, path_outcome, depth, ret)
        tree.value_range[0] = min(tree.value_range[0], ret)
        tree.value_range[1] = max(tree.value_range[1], ret)
        tree.counts[2] += 1

    search.mdp_copy_state = mdp.copy_state
    search.mdp_is_available = mdp.is_available
    search.mdp_expand = mdp.expand_outcomes
    search.mdp_apply = mdp.apply_outcome
    search.mdp_value = mdp.terminal_value
    rollout.mdp_is_available = mdp.is_available
    search.choose_action = rollout.uniform_random  # the paper's random rollout policy
    search.back_up = back_up  # the paper's backup
    search.pairs_outcomes = lambda backup: False
    return importlib.import_module("hptrack.planning.subtask_search")


def first_plan(n: int, seed: int):
    from hptrack.planning.subtask_mdp import PlanningProblem
    from hptrack.scenario.random import random_scenario

    scenario = random_scenario(n, seed=seed, homogeneous=True)
    spec = scenario.mission_spec()
    return PlanningProblem(
        spec.record,
        scenario.agent.position,
        scenario.means(),
        scenario.covariances(),
        scenario.budget,
    )


def count(mode: str, n: int, seed: int, seconds: float) -> int:
    """Simulations of one first-plan search of ``seconds`` (``mode``: python or compiled)."""
    if mode == "python":
        warnings.simplefilter("ignore")  # uint64 wrap-around of the random stream
        search = plain_python_search()
    else:
        search = importlib.import_module("hptrack.planning.subtask_search")
        search.search(first_plan(n, seed), iterations=64)  # load the compiled kernels
    start = time.perf_counter()
    result = search.search(first_plan(n, seed), time_limit=seconds, seed=0)
    assert time.perf_counter() - start < seconds + 5.0
    return result.simulations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--seeds", type=int, default=3, help="scenario seeds 0..N-1")
    parser.add_argument("--targets", default="2,3,4,5,6")
    parser.add_argument("--one", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        mode, n, seed, seconds = args.one
        print(count(mode, int(n), int(seed), float(seconds)))
        return

    def run(mode: str, n: int, seed: int, seconds: float) -> int:
        out = subprocess.run(
            [sys.executable, __file__, "--one", mode, str(n), str(seed), str(seconds)],
            check=True,
            capture_output=True,
            text=True,
        )
        return int(out.stdout.split()[-1])

    rows = {}
    head = f"python sims in {args.seconds:g}s"
    print(f"{'n':>3} {head:>22} {'compiled sims in 1s':>20}")
    for n in (int(x) for x in args.targets.split(",")):
        py = [run("python", n, s, args.seconds) for s in range(args.seeds)]
        jit = [run("compiled", n, s, 1.0) for s in range(args.seeds)]
        rows[n] = {"python": py, "compiled_1s": jit, "python_median": statistics.median(py)}
        print(
            f"{n:>3} {statistics.median(py):>22,.0f} {statistics.median(jit):>20,.0f}  "
            f"(per seed {py} / {jit})",
            flush=True,
        )
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
