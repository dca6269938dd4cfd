"""Speed of the Gymnasium environments: environment steps per second on one core.

``hptrack/Tracking-v0`` made with ``gym.make`` (its default wrappers included), Discrete actions
from a uniform random policy (drawn beforehand, so the policy's own cost is excluded), whole
900 s episodes of the paper's random heterogeneous scenarios, resets included. For
``hptrack/SubtaskTracking-v0`` it reports decisions per second and the simulator steps per
second flown inside them. Numba kernels are compiled (or loaded from the cache) before timing.

The work is single-threaded (one core at a time); ``--pin CPU`` also binds it to one CPU. Rates
are given per second of wall time and per second of the process's CPU time; on a machine shared
with other work the second is the steadier figure. Run:

    python3 benchmarks/bench_envs.py --targets 2,6 --seconds 10
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np

import hptrack.envs  # noqa: F401  (registers the environments)


def pin(cpu: int | None) -> str:
    """Bind this process to ``cpu`` (Linux) if given; returns a description."""
    if cpu is None:
        return "not pinned"
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def measure(env_id: str, n_targets: int, seconds: float, seed: int = 0) -> dict:
    """Fly whole episodes for at least ``seconds``; steps (and decisions) per second."""
    env = gym.make(env_id, n_targets=n_targets)
    rng = np.random.default_rng(seed)
    actions = rng.integers(env.action_space.n, size=100_000)
    env.reset(seed=seed)
    env.step(int(actions[0]))  # compile / load before timing
    decisions = steps = episodes = 0
    start, cpu_start = time.perf_counter(), time.process_time()
    while time.perf_counter() - start < seconds:
        _, info = env.reset()
        truncated = False
        while not truncated:
            _, _, _, truncated, info = env.step(actions[decisions % actions.shape[0]])
            decisions += 1
        steps += info["step"]
        episodes += 1
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return {
        "steps_per_s": steps / elapsed,
        "steps_per_cpu_s": steps / cpu,
        "decisions_per_s": decisions / elapsed,
        "decisions_per_cpu_s": decisions / cpu,
        "episodes": episodes,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="2,6", help="comma-separated numbers of targets")
    parser.add_argument("--seconds", type=float, default=10.0, help="timing per case, s")
    parser.add_argument(
        "--pin", type=int, default=None, metavar="CPU", help="bind the process to this CPU"
    )
    args = parser.parse_args()
    print(f"hptrack env benchmark ({pin(args.pin)}); per wall second / per CPU second")
    for n in (int(v) for v in args.targets.split(",")):
        r = measure("hptrack/Tracking-v0", n, args.seconds)
        print(
            f"Tracking-v0         n={n}: env steps/s {r['steps_per_s']:9,.0f} / "
            f"{r['steps_per_cpu_s']:9,.0f} ({r['episodes']} episodes)"
        )
        r = measure("hptrack/SubtaskTracking-v0", n, args.seconds)
        print(
            f"SubtaskTracking-v0  n={n}: decisions/s {r['decisions_per_s']:7,.1f} / "
            f"{r['decisions_per_cpu_s']:7,.1f}, simulator steps/s {r['steps_per_s']:9,.0f} / "
            f"{r['steps_per_cpu_s']:9,.0f} ({r['episodes']} episodes)"
        )


if __name__ == "__main__":
    main()
