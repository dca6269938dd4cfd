"""Hand-built missions and observations for the step-level baselines."""

import numpy as np
import pytest

from hptrack.interface import MissionSpec, Observation

PRIOR = np.array(
    [[900.0, 100.0, 0.0, 0.0], [100.0, 800.0, 0.0, 0.0], [0.0, 0.0, 0.3, 0.0], [0.0, 0.0, 0.0, 0.3]]
)
"""A homogeneous prior covariance (m^2, (m/s)^2) shared by the targets of these tests."""


def _mission(
    n: int,
    q: float = 3e-4,
    budget: float = 900.0,
    form: str = "continuous",
    noise: np.ndarray | None = None,
) -> MissionSpec:
    """``n`` homogeneous targets, the project's defaults (tau 0.5 s, 30 m/s, w 100 m, R = 10 I
    unless ``noise`` gives another 2x2 ``R``)."""
    noise = 10.0 * np.eye(2) if noise is None else noise
    return MissionSpec(
        time_step=0.5,
        budget=budget,
        agent_speed=30.0,
        sensor_diameter=100.0,
        measurement_noise=noise,
        process_noise_form=form,
        process_noise=np.full(n, q),
        target_ids=tuple(f"t{i}" for i in range(n)),
    )


def _observation(
    means, covariances=None, agent=(0.0, 0.0), step: int = 0, budget: float = 900.0
) -> Observation:
    """The planner's view with beliefs ``means`` ``(n, 4)`` (``PRIOR`` covariances by default)."""
    means = np.asarray(means, dtype=float)
    if covariances is None:
        covariances = np.repeat(PRIOR[None], len(means), axis=0)
    return Observation(
        step=step,
        time=0.5 * step,
        remaining_budget=budget - 0.5 * step,
        agent_position=np.asarray(agent, dtype=float),
        means=means,
        covariances=np.asarray(covariances, dtype=float),
        detected=np.zeros(len(means), dtype=bool),
    )


@pytest.fixture(scope="session")
def make_mission():
    """Factory of hand-built :class:`MissionSpec` (see ``_mission``)."""
    return _mission


@pytest.fixture(scope="session")
def make_observation():
    """Factory of hand-built :class:`Observation` (see ``_observation``)."""
    return _observation
