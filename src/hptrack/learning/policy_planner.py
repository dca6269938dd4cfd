"""Learned policies as hptrack planners: ``adfq`` (a Deep ADFQ network) and ``sb3`` (a
stable-baselines3 model trained on ``hptrack/Tracking-v0``).

Each step the planner encodes the `Observation` exactly as the
environment does (`hptrack.envs.observation.ObservationLayout`), asks the policy for one
of the 13 discrete actions (`hptrack.envs.tracking.HEADINGS`: 12 headings 30 degrees apart,
then hover) and returns the waypoint one step length away on that heading (the agent's own
position for hover), so ``run_episode`` flies the same mission as the environment.

Without a ``model`` option the planner takes the model shipped with the package for the
mission's number of targets (``hptrack/learning/models/adfq-n<N>.pt``, ``ppo-n<N>.zip``).
torch, stable-baselines3 and gymnasium are imported only when a planner is reset.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from importlib import resources
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import Field

from hptrack.interface import CurrentPlan, InputError, MissionSpec, Observation, one_vehicle
from hptrack.models.beliefs import position_logdet
from hptrack.settings import PlannerSettings

PACKAGED_MODELS = {"adfq": "adfq-n{n}.pt", "sb3": "ppo-n{n}.zip"}
"""File name pattern of the shipped model of each planner, by number of targets."""


def packaged_model(planner: str, n_targets: int) -> Path:
    """Path of the shipped model of ``planner`` for ``n_targets`` targets (may not exist)."""
    folder = resources.files("hptrack.learning") / "models"
    return Path(str(folder / PACKAGED_MODELS[planner].format(n=n_targets)))


def _model_path(planner: str, option: str | None, n_targets: int) -> Path:
    if option is not None:
        path = Path(option).expanduser()
        if not path.is_file():
            raise InputError(f"planner {planner!r}: option model: no file {option!r}")
        return path
    path = packaged_model(planner, n_targets)
    if not path.is_file():
        raise InputError(
            f"planner {planner!r}: no shipped model for {n_targets} targets; "
            f"give -o model=PATH (train one with 'hptrack learn')"
        )
    return path


class AdfqSettings(PlannerSettings):
    """A Deep ADFQ policy flown greedily on its means."""

    model: str | None = None
    """Policy file (``best.pt`` of ``hptrack learn adfq``); default: the shipped model."""
    epsilon: Annotated[float, Field(ge=0.0, le=1.0)] = 0.05
    """Probability of a uniformly random action per step (the published test policy: 0.05)."""


class Sb3Settings(PlannerSettings):
    """A stable-baselines3 PPO policy."""

    model: str | None = None
    """Model file (``best.zip`` of ``hptrack learn sb3-ppo``); default: the shipped model."""
    deterministic: bool = True
    """Take the policy's most likely action (else sample it with the planner's generator)."""


class _DiscretePolicyPlanner(ABC):
    """Shared part: observation encoding and action -> waypoint."""

    name: str
    settings: AdfqSettings | Sb3Settings

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        from hptrack.envs.observation import ObservationLayout
        from hptrack.envs.tracking import HEADINGS

        one_vehicle(self.name, mission)

        self._mission, self._rng = mission, rng
        self._layout = ObservationLayout(mission.n_targets, masked=False)
        self._headings = np.asarray(HEADINGS)
        self._model_file = _model_path(self.name, self.settings.model, mission.n_targets)
        self._load(self._model_file)
        self._actions = np.zeros(len(self._headings), dtype=np.int64)

    @abstractmethod
    def _load(self, path: Path) -> None:
        """Load the policy file and check its sizes."""

    @abstractmethod
    def _choose(self, vector: np.ndarray) -> int:
        """The action for one observation vector."""

    def _check_sizes(self, obs_dim: int, n_actions: int) -> None:
        if obs_dim != self._layout.size or n_actions != len(self._headings):
            raise InputError(
                f"planner {self.name!r}: model {self._model_file} takes {obs_dim} inputs and "
                f"{n_actions} actions; a {self._mission.n_targets}-target mission needs "
                f"{self._layout.size} and {len(self._headings)}"
            )

    def encode(self, observation: Observation) -> np.ndarray:
        """The environment's observation vector of ``observation``."""
        return self._layout.encode(
            observation.agent_position,
            observation.means,
            position_logdet(observation.covariances),
            observation.detected,
            observation.remaining_budget / self._mission.budget,
        )

    def act(self, observation: Observation) -> np.ndarray:
        action = self._choose(self.encode(observation))
        self._actions[action] += 1
        return observation.agent_position + self._mission.step_length * self._headings[action]

    def current_plan(self) -> CurrentPlan:
        """No sub-tasks: nothing to show."""
        return CurrentPlan()

    def episode_info(self) -> dict[str, Any]:
        return {
            "settings": self.settings.as_json(),
            "model_file": str(self._model_file),
            "action_counts": self._actions.tolist(),
        }


class AdfqPlanner(_DiscretePolicyPlanner):
    """Flies a Deep ADFQ network: greedy on the means, ``epsilon``-random."""

    name = "adfq"

    def __init__(self, settings: AdfqSettings | None = None) -> None:
        self.settings = settings or AdfqSettings()

    def _load(self, path: Path) -> None:
        import torch

        from hptrack.learning.agent import load_policy, set_torch_threads

        set_torch_threads()
        try:
            self._network, self._metadata = load_policy(str(path))
        except ValueError as err:
            raise InputError(f"planner 'adfq': {err}") from None
        self._check_sizes(self._network.obs_dim, self._network.n_actions)
        self._torch = torch

    def _choose(self, vector: np.ndarray) -> int:
        if self.settings.epsilon > 0.0 and self._rng.random() < self.settings.epsilon:
            return int(self._rng.integers(len(self._headings)))
        with self._torch.no_grad():
            mean, _ = self._network(self._torch.from_numpy(vector[None]))
        return int(mean[0].argmax())

    def episode_info(self) -> dict[str, Any]:
        return {**super().episode_info(), "training_steps": self._metadata.get("step")}


class Sb3Planner(_DiscretePolicyPlanner):
    """Flies the actor of a stable-baselines3 PPO model, read as weights only
    (`hptrack.learning.sb3.load_actor`)."""

    name = "sb3"

    def __init__(self, settings: Sb3Settings | None = None) -> None:
        self.settings = settings or Sb3Settings()

    def _load(self, path: Path) -> None:
        from hptrack.learning.agent import set_torch_threads
        from hptrack.learning.sb3 import load_actor

        set_torch_threads()
        try:
            self._actor = load_actor(path)
        except ValueError as err:
            raise InputError(f"planner 'sb3': {err}") from None
        self._check_sizes(self._actor.obs_dim, self._actor.n_actions)

    def _choose(self, vector: np.ndarray) -> int:
        distribution = self._actor.distribution(vector)
        if self.settings.deterministic:
            return int(distribution.mode[0])
        probs = distribution.probs[0].numpy()
        return int(self._rng.choice(len(probs), p=probs / probs.sum()))
