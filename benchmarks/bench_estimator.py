"""Speed of the coverage outcome estimator (paper Sec. IV-B), the hot call of the tree search.

Run: ``python benchmarks/bench_estimator.py [--n 20000]``. Prints estimates per second for
beliefs drawn from the paper's distributions after 0 to 600 s without observation:

* ``kernel``: :func:`coverage_outcome` in a compiled loop, as the tree search calls it at each
  node expansion (the covariance at the start of the coverage given);
* ``wrapper``: the validated Python :func:`estimate_coverage` (with the CDF array);
* ``spiral``: shifting-spiral steps per second (:class:`ShiftingSpiral`).
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from hptrack.coverage import ShiftingSpiral, coverage_outcome, estimate_coverage, intercept_steps
from hptrack.interface import MissionSpec
from hptrack.scenario.random import random_mean, random_prior


@numba.njit(cache=True)
def estimate_all(covs, qs, tau, c_per_step, speed, diameter, max_steps):
    """One estimate per start covariance, as the tree search calls it per node expansion."""
    total = 0.0
    for i in range(covs.shape[0]):
        k, p, e = coverage_outcome(covs[i], qs[i], tau, c_per_step, speed, diameter, max_steps)
        total += p + 1e-9 * (k + e)
    return total


def start_covariances(n: int, settings: MissionSpec, seed: int = 0
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beliefs of the paper's distributions left unobserved 0 to 600 s, then intercepted from the
    origin: ``(means, covariances at the start of coverage, q)``."""
    rng = np.random.default_rng(seed)
    motion = settings.motion
    means, covs, qs = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty(n)
    for i in range(n):
        cov, q = random_prior(rng)
        m, c = motion.predict(random_mean(rng)[None], cov[None], q,
                              rng.integers(0, 1201) * settings.time_step)
        steps = intercept_steps(0.0, 0.0, *m[0], settings.agent_speed, settings.time_step,
                                settings.sensor_radius)
        start = motion.predict(m, c, q, steps * settings.time_step)[1][0]
        means[i], covs[i], qs[i] = m[0], start, q
    return means, covs, qs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20000, help="beliefs per measurement")
    args = parser.parse_args()
    settings = MissionSpec()
    means, covs, qs = start_covariances(args.n, settings)
    call = (settings.time_step, settings.c_per_step, settings.agent_speed,
            settings.sensor_diameter, 1800)
    estimate_all(covs[:10], qs[:10], *call)  # compile
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        estimate_all(covs, qs, *call)
        best = min(best, time.perf_counter() - start)
    cutoffs = [estimate_coverage(c, q, settings, 900.0).cutoff_steps
               for c, q in zip(covs[:2000], qs[:2000], strict=True)]
    print(f"kernel : {args.n / best:12,.0f} estimates/s  ({best / args.n * 1e6:.2f} us each; "
          f"mean t_cutoff {np.mean(cutoffs):.0f} steps)")

    m = min(args.n, 5000)
    start = time.perf_counter()
    for c, q in zip(covs[:m], qs[:m], strict=True):
        estimate_coverage(c, q, settings, remaining_time=900.0)
    elapsed = time.perf_counter() - start
    print(f"wrapper: {m / elapsed:12,.0f} estimates/s  ({elapsed / m * 1e6:.1f} us each)")

    spiral = ShiftingSpiral(np.zeros(2), means[0, 2:], covs[0, :2, :2], settings.agent_speed,
                            settings.time_step, settings.sensor_diameter)
    spiral.positions(10)
    start = time.perf_counter()
    spiral.positions(20000)
    elapsed = time.perf_counter() - start
    print(f"spiral : {20000 / elapsed:12,.0f} steps/s")


if __name__ == "__main__":
    main()
