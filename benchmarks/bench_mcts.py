"""Speed and memory of the tree search (paper Algorithm 1) for n = 2..6 targets.

For each n, in a fresh process (numba's cache warmed by a first throw-away process):

* startup: wall time of ``import hptrack.planning`` (numba, numpy) and of the first plan of
  2000 simulations (numba's JIT start-up and loading the cached kernels, then the search):
  what a simulator pays when it starts;
* simulations per second over the first 2000 simulations of a fresh tree (median of 5);
* simulations per second over one search of ``--duration`` seconds, by wall time and by the
  process's CPU time (they differ when other processes share the cores);
* the tree's arrays and the process's peak resident memory.

The scenario is drawn from the paper's distributions (Sec. V-A): 900 s budget, tau = 0.5 s,
30 m/s agent, 100 m footprint, R = 10 I.

    python3 benchmarks/bench_mcts.py                  # n = 2..6, 10 s searches
    python3 benchmarks/bench_mcts.py --duration 2 --targets 6

``--compare SRC`` times another checkout's code side by side in the same run (each ``n`` of the
two in turn, in fresh processes, ``--repeats`` times interleaved) and prints the ratios new / old
of the medians, e.g. the code before a refactor::

    git worktree add /tmp/hptrack-before 9dd0bbd
    python3 benchmarks/bench_mcts.py --compare /tmp/hptrack-before/src --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time


def _problem(n: int, seed: int):
    import numpy as np

    from hptrack.planning import PlanningProblem
    from hptrack.scenario.random import random_mean, random_prior

    rng = np.random.default_rng(seed)
    priors = [random_prior(rng) for _ in range(n)]
    means = np.array([random_mean(rng) for _ in range(n)])
    covs, q, noise = np.array([c for c, _ in priors]), np.array([q for _, q in priors]), np.eye(2)
    try:
        from hptrack.models.mission import mission_record
    except ImportError:  # a checkout before the mission record (--compare)
        return PlanningProblem(
            np.zeros(2), means, covs, q, 900.0, 0.5, 0.5, 30.0, 100.0, 10.0 * noise
        )
    mission = mission_record(0.5, 900.0, 30.0, 100.0, 10.0 * noise, q)
    return PlanningProblem(mission, np.zeros(2), means, covs, 900.0)


def worker(n: int, seed: int, duration: float) -> dict:
    """Measure one ``n`` in this (fresh) process."""
    start = time.perf_counter()
    from hptrack.planning import search

    imported = time.perf_counter() - start
    problem = _problem(n, seed)
    start = time.perf_counter()
    first = search(problem, iterations=2000, seed=0)
    first_plan = time.perf_counter() - start
    rates = []
    for rep in range(5):
        result = search(_problem(n, seed), iterations=2000, seed=rep)
        rates.append(result.simulations / result.elapsed)
    cpu = time.process_time()
    long = search(_problem(n, seed), time_limit=duration, seed=0)
    cpu = time.process_time() - cpu
    return {
        "n": n,
        "import_s": imported,
        "first_plan_s": first_plan,
        "plan": first.best_action,
        "fresh_2000_per_s": sorted(rates)[2],
        "long_per_s": long.simulations / long.elapsed,
        "long_per_cpu_s": long.simulations / cpu,
        "long_simulations": long.simulations,
        "long_elapsed_s": long.elapsed,
        "state_nodes": long.state_nodes,
        "action_nodes": long.action_nodes,
        "tree_mb": long.tree_bytes / 2**20,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    parser.add_argument(
        "--duration", type=float, default=10.0, help="length of the long search, s (default 10)"
    )
    parser.add_argument("--seed", type=int, default=0, help="scenario seed")
    parser.add_argument(
        "--compare", metavar="SRC", help="another checkout's src/ folder, timed side by side"
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="with --compare: runs of each side per n, interleaved; ratios of the medians",
    )
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(args.worker, args.seed, args.duration)))
        return

    def run(n: int, duration: float, src: str | None = None) -> dict:
        env = dict(os.environ)
        if src is not None:
            env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")])
        out = subprocess.run(
            [
                sys.executable,
                "-W",
                "ignore",
                __file__,
                "--worker",
                str(n),
                "--seed",
                str(args.seed),
                "--duration",
                str(duration),
            ],
            check=True,
            capture_output=True,
            text=True,
            env=env,
            cwd=src or None,
        )
        return json.loads(out.stdout.strip().splitlines()[-1])

    run(args.targets[0], 0.1)  # compile and cache the kernels
    if args.compare:
        run(args.targets[0], 0.1, args.compare)
        print(f"side by side with {args.compare}: ratios new / old (higher is faster)")
        header = (
            "n",
            "sims/s first 2000",
            f"sims/s {args.duration:g} s",
            "sims/CPU-s",
            "first plan s (old, new)",
        )
        print(" | ".join(header))
        print(" | ".join("---" for _ in header))
        for n in args.targets:
            runs = {"old": [], "new": []}
            for _ in range(max(1, args.repeats)):
                runs["old"].append(run(n, args.duration, args.compare))
                runs["new"].append(run(n, args.duration))
            old, new = (
                {key: statistics.median(r[key] for r in runs[side]) for key in runs[side][0]}
                for side in ("old", "new")
            )
            print(
                f"{n} | {new['fresh_2000_per_s'] / old['fresh_2000_per_s']:.3f} | "
                f"{new['long_per_s'] / old['long_per_s']:.3f} | "
                f"{new['long_per_cpu_s'] / old['long_per_cpu_s']:.3f} | "
                f"{old['first_plan_s']:.2f}, {new['first_plan_s']:.2f}",
                flush=True,
            )
        return
    print(
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; long search "
        f"{args.duration:g} s; scenario seed {args.seed}"
    )
    header = (
        "n",
        "import s",
        "first plan s",
        "sims/s first 2000",
        f"sims/s {args.duration:g} s",
        "sims/CPU-s",
        "simulations",
        "state nodes",
        "action nodes",
        "tree MB",
        "peak RSS MB",
    )
    print(" | ".join(header))
    print(" | ".join("---" for _ in header))
    for n in args.targets:
        r = run(n, args.duration)
        print(
            f"{n} | {r['import_s']:.2f} | {r['first_plan_s']:.2f} | "
            f"{r['fresh_2000_per_s']:,.0f} | "
            f"{r['long_per_s']:,.0f} | {r['long_per_cpu_s']:,.0f} | "
            f"{r['long_simulations']:,} | {r['state_nodes']:,} | {r['action_nodes']:,} | "
            f"{r['tree_mb']:.1f} | {r['peak_rss_mb']:.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
