"""Random scenarios with the paper's distributions (Sec. V-A; ``docs/model.md``).

Per target: position mean uniform in [-1000, 1000] m per axis, velocity mean uniform in
[-3, 3] m/s per axis, position variances uniform in [500, 2000] m^2, correlation uniform in
[-0.8, 0.8], velocity variances uniform in [0.25, 0.5] (m/s)^2, q uniform in [1e-4, 5e-4].
The *homogeneous* setting (comparison with ARVI and A*) draws one q and one covariance per
scenario; the *heterogeneous* setting draws everything per target.

`with_no_fly` adds random no-fly circles to a scenario (beyond the paper: the fence
benchmark's protocol).
"""

from __future__ import annotations

import math

import numpy as np

from hptrack.scenario.model import AgentSpec, CircleZoneSpec, FenceBlockSpec, Scenario, TargetSpec

POSITION_RANGE_M = (-1000.0, 1000.0)
VELOCITY_RANGE_MPS = (-3.0, 3.0)
POSITION_VARIANCE_RANGE_M2 = (500.0, 2000.0)
CORRELATION_RANGE = (-0.8, 0.8)
VELOCITY_VARIANCE_RANGE = (0.25, 0.5)
PROCESS_NOISE_RANGE = (1e-4, 5e-4)


def random_prior(rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """One prior covariance ``(4, 4)`` and one ``q`` drawn from the paper's distributions."""
    var_x, var_y = rng.uniform(*POSITION_VARIANCE_RANGE_M2, size=2)
    rho = rng.uniform(*CORRELATION_RANGE)
    var_vx, var_vy = rng.uniform(*VELOCITY_VARIANCE_RANGE, size=2)
    cov = np.diag([var_x, var_y, var_vx, var_vy])
    cov[0, 1] = cov[1, 0] = rho * np.sqrt(var_x * var_y)
    return cov, float(rng.uniform(*PROCESS_NOISE_RANGE))


def random_mean(rng: np.random.Generator) -> np.ndarray:
    """One prior mean ``[x, y, vx, vy]``."""
    return np.concatenate(
        [rng.uniform(*POSITION_RANGE_M, size=2), rng.uniform(*VELOCITY_RANGE_MPS, size=2)]
    )


def random_scenario(
    n_targets: int,
    seed: int,
    homogeneous: bool = False,
    agent: AgentSpec | None = None,
    team: int = 1,
    **scenario_fields,
) -> Scenario:
    """The paper's random scenario with ``n_targets`` targets, fully determined by ``seed``;
    ``team > 1`` flies that many UAVs like ``agent``, all from its start (``agents:``; the
    targets are those of the same seed's scenario of one UAV).

    True initial states are left out: the simulator draws them from the prior with the seed.
    """
    if team < 1:
        raise ValueError(f"team must be at least 1, got {team}")
    if n_targets < 1:
        raise ValueError(f"n_targets must be at least 1, got {n_targets}")
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    shared = random_prior(rng) if homogeneous else None
    targets = []
    for i in range(n_targets):
        mean = random_mean(rng)
        cov, q = shared if shared is not None else random_prior(rng)
        targets.append(
            TargetSpec(
                id=f"t{i + 1}", mean=tuple(mean), covariance=tuple(map(tuple, cov)), process_noise=q
            )
        )
    if team > 1:
        scenario_fields["agents"] = [agent or AgentSpec()] * team
    else:
        scenario_fields["agent"] = agent or AgentSpec()
    return Scenario(seed=seed, targets=targets, **scenario_fields)


NO_FLY_CIRCLES = (1, 3)
"""Fewest and most random no-fly circles (`with_no_fly`)."""
NO_FLY_SHARE = (0.10, 0.25)
"""The range of the share of the targets' square (`POSITION_RANGE_M` per axis) they cover."""
NO_FLY_MARGIN_M = 10.0
"""The margin of a random fence, m."""
NO_FLY_KEY = 11
"""The spawn key of the no-fly circles' random stream (the scenario's own draws do not change)."""
NO_FLY_ATTEMPTS = 10_000
"""Most draws of the circles before giving up."""


def with_no_fly(scenario: Scenario, seed: int) -> Scenario:
    """``scenario`` with `NO_FLY_CIRCLES` random no-fly circles covering together a share in
    `NO_FLY_SHARE` of the targets' square (areas split at random; centres uniform in the
    square), kept `NO_FLY_MARGIN_M` from; the circles are drawn again until the start is free
    and every target's prior mean is in sight (`Scenario`'s fence checks), from ``seed``'s own
    stream.

    Raises:
        ValueError: no such circles in `NO_FLY_ATTEMPTS` draws.
    """
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(NO_FLY_KEY,)))
    low, high = POSITION_RANGE_M
    area = (high - low) ** 2
    data = scenario.model_dump()
    for _ in range(NO_FLY_ATTEMPTS):
        count = int(rng.integers(NO_FLY_CIRCLES[0], NO_FLY_CIRCLES[1] + 1))
        share = rng.uniform(*NO_FLY_SHARE)
        shares = share * rng.dirichlet(np.ones(count))
        circles = [
            CircleZoneSpec(
                circle=(*rng.uniform(low, high, size=2).tolist(), math.sqrt(a * area / math.pi))
            )
            for a in shares
        ]
        centres = np.array([c.circle[:2] for c in circles])
        radii = np.array([c.circle[2] for c in circles]) + NO_FLY_MARGIN_M
        sight = 0.5 * scenario.sensor_spec().diameter
        starts = scenario.starts()
        means = scenario.means()[:, :2]
        gaps = np.linalg.norm(means[:, None, :] - centres[None], axis=2)
        inside = np.linalg.norm(centres[None] - starts[:, None], axis=2) <= radii
        if np.any(inside) or np.any(gaps < radii - sight):
            continue  # a start in a circle, or a mean out of sight: draw again
        fence = FenceBlockSpec(exclusions=circles, margin=NO_FLY_MARGIN_M)
        try:
            return Scenario.model_validate({**data, "fence": fence})
        except ValueError:
            continue
    raise ValueError(f"no no-fly circles in {NO_FLY_ATTEMPTS} draws leave the targets in sight")
