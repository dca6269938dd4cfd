"""Speed of the coverage outcome estimator (paper Sec. IV-B), the hot call of the tree search.

Run: ``python benchmarks/bench_estimator.py [--n 20000] [--age SECONDS]``. Prints estimates per
second for beliefs drawn from the paper's distributions after 0 to 600 s without observation (or
exactly ``--age`` seconds):

* ``kernel``: :func:`coverage_outcome` in a compiled loop, as the tree search calls it at each
  node expansion (the covariance at the start of the coverage given);
* ``sharp``: :func:`sharp_coverage_outcome` on the same beliefs (with their intercept flights),
  and its time per estimate over the paper kernel's, measured in the same run;
* ``wrapper``: the validated Python :func:`estimate_coverage` (with the CDF array);
* ``spiral``: shifting-spiral steps per second (:class:`ShiftingSpiral`).
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from hptrack.coverage import (
    ShiftingSpiral,
    coverage_outcome,
    estimate_coverage,
    sharp_coverage_outcome,
)
from hptrack.interface import MissionSpec
from hptrack.models.mission import approach_step_to, intercept_steps_to
from hptrack.scenario.random import random_mean, random_prior


@numba.njit(cache=True)
def estimate_all(covs, qs, mission, max_steps):
    """One estimate per start covariance, as the tree search calls it per node expansion."""
    total = 0.0
    for i in range(covs.shape[0]):
        k, p, e = coverage_outcome(mission, covs[i], qs[i], max_steps)
        total += p + 1e-9 * (k + e)
    return total


@numba.njit(cache=True)
def estimate_all_sharp(covs, qs, mission, max_steps, flights, approach):
    """:func:`estimate_all` with the sharp kernel (each belief's flight steps and approach)."""
    total = 0.0
    for i in range(covs.shape[0]):
        k, p, e = sharp_coverage_outcome(
            mission,
            covs[i],
            qs[i],
            max_steps,
            flights[i],
            approach[i, 0],
            approach[i, 1],
        )
        total += p + 1e-9 * (k + e)
    return total


def start_covariances(
    n: int, settings: MissionSpec, seed: int = 0, age: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Beliefs of the paper's distributions left unobserved 0 to 600 s (or ``age`` s), then
    intercepted from the origin: ``(means, covariances at the start of coverage, q, flight
    steps, approach per step)``."""
    rng = np.random.default_rng(seed)
    motion = settings.motion
    means, covs, qs = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty(n)
    flights, approach = np.empty(n, dtype=np.int64), np.empty((n, 2))
    for i in range(n):
        cov, q = random_prior(rng)
        mean = random_mean(rng)
        unobserved = rng.integers(0, 1201) * settings.time_step if age is None else age
        m, c = motion.predict(mean[None], cov[None], q, unobserved)
        steps = intercept_steps_to(settings.record, 0.0, 0.0, m[0])
        start = motion.predict(m, c, q, steps * settings.time_step)[1][0]
        means[i], covs[i], qs[i], flights[i] = m[0], start, q, steps
        approach[i] = approach_step_to(settings.record, 0.0, 0.0, m[0], steps)
    return means, covs, qs, flights, approach


def best_time(function, *args, repeats: int = 5) -> float:
    """Smallest wall time of ``repeats`` calls, s."""
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function(*args)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000, help="beliefs per measurement")
    parser.add_argument(
        "--age",
        type=float,
        default=None,
        help="seconds every belief goes unobserved (default: 0 to 600 s)",
    )
    args = parser.parse_args()
    settings = MissionSpec()
    means, covs, qs, flights, approach = start_covariances(args.n, settings, age=args.age)
    call = (settings.record, 1800)
    estimate_all(covs[:10], qs[:10], *call)  # compile
    estimate_all_sharp(covs[:10], qs[:10], *call, flights[:10], approach[:10])
    # alternate the two kernels so that both see the same machine load
    paper, sharp = math.inf, math.inf
    for _ in range(3):
        paper = min(paper, best_time(estimate_all, covs, qs, *call, repeats=1))
        sharp = min(
            sharp, best_time(estimate_all_sharp, covs, qs, *call, flights, approach, repeats=1)
        )
    cutoffs = [
        estimate_coverage(c, q, settings, 900.0).cutoff_steps
        for c, q in zip(covs[:2000], qs[:2000], strict=True)
    ]
    print(
        f"kernel : {args.n / paper:12,.0f} estimates/s  ({paper / args.n * 1e6:.2f} us each; "
        f"mean t_cutoff {np.mean(cutoffs):.0f} steps)"
    )
    print(
        f"sharp  : {args.n / sharp:12,.0f} estimates/s  ({sharp / args.n * 1e6:.2f} us each; "
        f"{sharp / paper:.2f} x the paper kernel's time)"
    )

    m = min(args.n, 5000)
    start = time.perf_counter()
    for c, q in zip(covs[:m], qs[:m], strict=True):
        estimate_coverage(c, q, settings, remaining_time=900.0)
    elapsed = time.perf_counter() - start
    print(f"wrapper: {m / elapsed:12,.0f} estimates/s  ({elapsed / m * 1e6:.1f} us each)")

    spiral = ShiftingSpiral(
        np.zeros(2),
        means[0, 2:],
        covs[0, :2, :2],
        settings.agent_speed,
        settings.time_step,
        settings.sensor_diameter,
    )
    spiral.positions(10)
    start = time.perf_counter()
    spiral.positions(20000)
    elapsed = time.perf_counter() - start
    print(f"spiral : {20000 / elapsed:12,.0f} steps/s")


if __name__ == "__main__":
    main()
