"""Whether a change of the search left its trees as they were: the statistics of many sub-task
searches (root and per-outcome children: actions, visits, values, outcome probabilities and
payloads; node counts; the plan), for this checkout and another one side by side.

The searches: random scenarios at n = 2, 4 and 6 (seeds 0 and 1, homogeneous and not), each
option set of `VARIANTS` (every backup, rollout, estimator, dwell, miss and passes option), a
first plan and a re-plan, ``--iterations`` simulations each. ``--compare SRC`` runs the same in
another checkout's ``src/`` (a fresh process) and prints every search whose statistics differ in
any bit; exit 1 if one does.

    git worktree add /tmp/hptrack-before 554d7a0
    python3 benchmarks/search_fingerprint.py --compare /tmp/hptrack-before/src
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile

import numpy as np

VARIANTS = (
    {"preset": "paper"},
    {"preset": "improved"},
    {"preset": "paper", "backup": "expected"},
    {"preset": "paper", "backup": "max", "max_weight": 0.7},
    {"preset": "paper", "backup": "robust", "root_split": "weighted", "common_rollouts": True},
    {"preset": "paper", "rollout": "most_uncertain", "dwell": 20, "miss": "keep"},
    {"preset": "paper", "estimator": "sharp", "passes": "credit", "rollout": "tour"},
    {"preset": "improved", "dwell": [5, 20], "rollout": "nearest"},
)
"""The mcts option sets searched."""


def _stats(stats) -> tuple | None:
    """One node's statistics as plain data; a checkout from before the search's per-outcome
    columns (``p_find``, ``find_steps``, ``miss_steps``) gives the same data."""
    if stats is None:
        return None
    if hasattr(stats, "p"):
        p0, payload = stats.p[:, 0], stats.payload
    else:
        p0, payload = stats.p_find, np.stack([stats.find_steps, stats.miss_steps], axis=-1)
    return (
        stats.actions.tolist(),
        stats.visits.tolist(),
        stats.values.tobytes(),
        np.asarray(p0).tobytes(),
        np.asarray(payload).reshape(-1, 2).tolist(),
    )


def fingerprints(counts=(2, 4, 6), seeds=(0, 1), iterations: int = 1500) -> dict:
    """``{(n, seed, variant, current action): statistics}`` of every search."""
    from hptrack.planning.hierarchical import MctsSettings
    from hptrack.planning.subtask_mdp import PlanningProblem
    from hptrack.planning.subtask_search import search
    from hptrack.scenario.random import random_scenario

    out = {}
    for n in counts:
        for seed in seeds:
            scenario = random_scenario(n, seed=seed, homogeneous=seed == 0)
            record, observation = scenario.mission_spec().record, scenario.initial_observation()
            for v, variant in enumerate(VARIANTS):
                settings = MctsSettings.model_validate({**variant, "iterations": iterations})
                for current in (None, 0):
                    problem = PlanningProblem.from_observation(
                        record, observation, current_action=current
                    )
                    r = search(
                        problem,
                        settings.search_options(),
                        settings.subtask_options(),
                        iterations=iterations,
                        seed=7,
                    )
                    after = getattr(r, "after", None)
                    if after is None:
                        after = (r.after_find, r.after_miss) if current is not None else ()
                    out[(n, seed, v, current)] = (
                        r.best_action,
                        _stats(r.root),
                        [_stats(a) for a in after],
                        r.simulations,
                        r.state_nodes,
                        r.action_nodes,
                    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--compare", metavar="SRC", help="another checkout's src/ folder")
    parser.add_argument("--iterations", type=int, default=1500)
    parser.add_argument("--write", metavar="FILE", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.write:
        with open(args.write, "wb") as f:
            pickle.dump(fingerprints(iterations=args.iterations), f)
        return
    ours = fingerprints(iterations=args.iterations)
    if not args.compare:
        print(f"{len(ours)} searches fingerprinted; give --compare SRC to compare")
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "other.pkl")
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([args.compare, os.environ.get("PYTHONPATH", "")]),
        }
        subprocess.run(
            [sys.executable, __file__, "--write", path, "--iterations", str(args.iterations)],
            check=True,
            env=env,
            cwd=args.compare,
        )
        with open(path, "rb") as f:
            theirs = pickle.load(f)
    differ = [key for key in ours if ours[key] != theirs.get(key)]
    for key in differ:
        print(f"differs: n={key[0]} seed={key[1]} variant={VARIANTS[key[2]]} current={key[3]}")
    print(f"{len(ours)} searches: {len(ours) - len(differ)} identical, {len(differ)} differ")
    sys.exit(1 if differ else 0)


if __name__ == "__main__":
    main()
