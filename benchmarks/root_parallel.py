"""Root parallelism against one tree, from a benchmark database (paired, same scenarios).

The runs (iteration-limited, so the comparison does not depend on the machine's load):

    B="hptrack benchmark --homogeneous --targets 6,10 --scenarios 30 --planners mcts \
       --db results/root-parallel.db"
    $B --iterations 10000 -o mcts.preset=improved
    $B --iterations 10000 -o mcts.preset=improved -o mcts.threads=2
    $B --iterations 20000 -o mcts.preset=improved

Two trees of N simulations take the wall time of one tree of N on two idle cores, and the CPU
time of one tree of 2N. Prints mean U per run and the paired differences with their standard
errors; ``--scaling`` also times the simulations per wall second of one and two threads.

    python3 benchmarks/root_parallel.py --db results/root-parallel.db --scaling
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections import defaultdict
from pathlib import Path

import numpy as np


def scaling(seconds: float = 3.0) -> None:
    from hptrack.planning import SearchOptions, search
    from hptrack.planning.backups import Max
    from hptrack.planning.subtask_mdp import PlanningProblem
    from hptrack.scenario.random import random_scenario

    sc = random_scenario(10, seed=0, homogeneous=True)
    spec = sc.mission_spec()
    problem = PlanningProblem(
        spec.record, sc.agent.position, sc.means(), sc.covariances(), sc.budget
    )
    options = SearchOptions(backup=Max())
    search(problem, options, iterations=64, threads=2)  # load the kernels
    for threads in (1, 2):
        start = time.perf_counter()
        result = search(problem, options, time_limit=seconds, threads=threads)
        rate = result.simulations / (time.perf_counter() - start)
        print(f"threads={threads}: {rate:,.0f} simulations per wall second")


def main() -> None:
    from hptrack.experiments.store import ResultStore

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, default=Path("results/root-parallel.db"))
    parser.add_argument("--scaling", action="store_true")
    args = parser.parse_args()
    store = ResultStore(args.db)
    runs = defaultdict(dict)  # (label, n) -> {seed: U}
    for r in store.rows():
        s = json.loads(r.key.planner_settings)
        label = f"{s['threads']} x {s['iterations']:,}"
        runs[(label, r.key.n_targets)][r.key.seed] = r.uncertainty
    store.close()
    labels = sorted({lb for lb, _ in runs})
    ns = sorted({n for _, n in runs})
    print("| trees x simulations | " + " | ".join(f"n={n}" for n in ns) + " |")
    print("|---|" + "---|" * len(ns))
    for lb in labels:
        print(
            f"| {lb} | "
            + " | ".join(f"{np.mean(list(runs[(lb, n)].values())):.2f}" for n in ns)
            + " |"
        )
    two = next(lb for lb in labels if lb.startswith("2 x"))
    print("\nPaired differences of U, mean +- standard error (negative: two trees better):")
    for other in labels:
        if other == two:
            continue
        cells = []
        for n in ns:
            a, b = runs[(two, n)], runs[(other, n)]
            d = np.array([a[s] - b[s] for s in sorted(set(a) & set(b))])
            cells.append(
                f"n={n}: {d.mean():+.2f} +- {d.std(ddof=1) / math.sqrt(d.size):.2f} ({d.size})"
            )
        print(f"{two} - {other}: " + "; ".join(cells))
    if args.scaling:
        scaling()


if __name__ == "__main__":
    main()
