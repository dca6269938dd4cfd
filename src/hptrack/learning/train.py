"""Training loop of Deep ADFQ with validation on fixed scenarios, the best model kept, and
checkpoints from which a killed run resumes.

A run lives in one folder:

* ``config.json``: the task and hyperparameters (a restart with other values is refused, except
  a larger number of steps, which extends the run);
* ``checkpoint.pt`` + ``replay-<step>.npz``: networks, optimiser, step, episode count, the
  numpy generator state, the training curve and the best validation score, and the replay
  memory. Checkpoints are taken at episode ends (at least ``checkpoint_interval`` steps apart)
  and when the run ends. Every episode's scenario seed and every random choice come from the
  one generator, so a run resumed from a checkpoint taken at an episode end continues exactly
  as it would have without the interruption; only the end of a run may fall inside an episode
  (extending such a run starts a fresh episode);
* ``best.pt``: the policy with the lowest mean final ``U`` on the validation scenarios
  (`hptrack.learning.agent.save_policy`);
* ``curve.json``: the training curve (one entry per episode, one per validation).

Validation flies the test policy (greedy on the means, ``validation_epsilon``-random, with a
generator seeded by the run's seed and the step) on every validation episode in lockstep,
before training (the untrained network) and every ``validation_interval`` steps.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from hptrack.interface import InputError, shown
from hptrack.learning.agent import (
    AdfqAgent,
    AdfqConfig,
    greedy_actions,
    save_policy,
    set_torch_threads,
)
from hptrack.learning.network import GaussianQNetwork
from hptrack.learning.weights import load_weights

VALIDATION_FIRST_SEED = 1_000_000_000
"""Scenario seed of the first validation scenario (benchmarks use small seeds)."""
RECENT_EPISODES = 10
"""Episodes averaged in the progress report's recent return."""


@dataclass(frozen=True)
class Task:
    """An environment to learn and its validation episodes.

    Attributes:
        env_id: a registered Gymnasium id.
        env_kwargs: arguments of ``gym.make``.
        validation: the ``reset`` keyword arguments of each validation episode.
        description: JSON-ready identity of the task (what ``config.json`` stores).
    """

    env_id: str
    env_kwargs: dict[str, Any]
    validation: tuple[dict[str, Any], ...]
    description: dict[str, Any]

    def make_env(self) -> gym.Env:
        return gym.make(self.env_id, **self.env_kwargs)


def tracking_task(
    n_targets: int,
    homogeneous: bool = False,
    validation_scenarios: int = 50,
    action_repeat: int = 1,
) -> Task:
    """``hptrack/Tracking-v0`` with ``n_targets`` random targets and validation on the random
    scenarios of seeds ``VALIDATION_FIRST_SEED + i``."""
    import hptrack.envs  # noqa: F401  (registers the environments)
    from hptrack.scenario import random_scenario

    if n_targets < 1:
        raise InputError(f"--targets must be at least 1, got {n_targets}")
    if validation_scenarios < 1:
        raise InputError(f"--validation-scenarios must be at least 1, got {validation_scenarios}")
    setting = "homogeneous" if homogeneous else "heterogeneous"
    scenarios = tuple(
        random_scenario(n_targets, VALIDATION_FIRST_SEED + i, homogeneous)
        for i in range(validation_scenarios)
    )
    return Task(
        "hptrack/Tracking-v0",
        {"n_targets": n_targets, "setting": setting},
        tuple({"options": {"scenario": s}} for s in scenarios),
        {
            "env": "hptrack/Tracking-v0",
            "n_targets": n_targets,
            "setting": setting,
            "validation_scenarios": validation_scenarios,
            "validation_first_seed": VALIDATION_FIRST_SEED,
        },
    )


@dataclass(frozen=True)
class TrainConfig:
    """The training run (the agent's hyperparameters in ``agent``)."""

    steps: int
    seed: int = 0
    validation_interval: int = 25_000
    validation_epsilon: float = 0.05
    checkpoint_interval: int = 10_000
    agent: AdfqConfig = field(default_factory=AdfqConfig)

    def identity(self) -> dict[str, Any]:
        """Everything but ``steps`` (a run may be extended)."""
        out = asdict(self)
        out.pop("steps")
        out["agent"] = self.agent.as_json()
        return out


@dataclass(frozen=True)
class Progress:
    """What a progress bar shows after each step."""

    step: int
    total: int
    episodes: int
    recent_return: float
    validation_u: float
    best_u: float


@dataclass
class _State:
    step: int = 0
    episodes: int = 0
    last_checkpoint: int = 0
    curve: list[dict[str, Any]] = field(default_factory=list)
    best_u: float = float("inf")
    best_step: int = -1


def run_validation(
    policy: Callable[[np.ndarray], np.ndarray], task: Task
) -> list[dict[str, float]]:
    """Fly ``policy`` (observations ``(B, d)`` -> actions ``(B,)``) on every validation episode
    of ``task`` in lockstep (one batched call per step); returns per episode the return, the
    final ``U`` and the never-observed ``U`` (``info["never_observed_U"]``, NaN without)."""
    envs = [task.make_env() for _ in task.validation]
    obs = np.stack(
        [env.reset(**kwargs)[0] for env, kwargs in zip(envs, task.validation, strict=True)]
    )
    returns = np.zeros(len(envs))
    results: list[dict[str, float]] = [{} for _ in envs]
    active = np.arange(len(envs))
    while len(active):
        actions = policy(obs[active])
        still = []
        for j, i in enumerate(active):
            obs[i], reward, terminated, truncated, info = envs[i].step(int(actions[j]))
            returns[i] += reward
            if terminated or truncated:
                results[i] = {
                    "return": float(returns[i]),
                    "U": float(info["U"]),
                    "never_observed_U": float(info.get("never_observed_U", np.nan)),
                }
            else:
                still.append(i)
        active = np.asarray(still, dtype=int)
    for env in envs:
        env.close()
    return results


def validation_entry(step: int, results: list[dict[str, float]]) -> dict[str, Any]:
    """The training-curve entry of one validation."""
    u = np.array([r["U"] for r in results])
    gap = u - np.array([r["never_observed_U"] for r in results])

    def sem(x: np.ndarray) -> float:
        return float(x.std(ddof=1) / np.sqrt(len(x))) if len(x) > 1 else 0.0

    return {
        "kind": "validation",
        "step": step,
        "mean_U": float(u.mean()),
        "sem_U": sem(u),
        "mean_never_observed_U": float(np.mean([r["never_observed_U"] for r in results])),
        "mean_delta_U": float(gap.mean()),
        "sem_delta_U": sem(gap),
        "mean_return": float(np.mean([r["return"] for r in results])),
    }


def network_policy(
    network: GaussianQNetwork, epsilon: float, rng: np.random.Generator
) -> Callable[[np.ndarray], np.ndarray]:
    """The test policy of a Deep ADFQ network: greedy on the means, ``epsilon``-random."""

    def policy(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            mean, _ = network(torch.as_tensor(obs))
        return greedy_actions(mean.numpy(), epsilon, rng)

    return policy


def atomic_torch_save(data: Any, path: Path) -> None:
    """``torch.save`` to a temporary file, then renamed over ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(data, tmp)
    os.replace(tmp, path)


def atomic_write(text: str, path: Path) -> None:
    """Write ``text`` to a temporary file, then rename it over ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


OPTION_NAMES = {
    "n_targets": "--targets",
    "validation_scenarios": "--validation-scenarios",
    "seed": "--seed",
    "validation_interval": "--validation-interval",
    "checkpoint_interval": "--checkpoint-interval",
    "warmup_steps": "--warmup",
    "buffer_size": "--buffer",
    "prioritized": "--prioritized",
}
"""The ``hptrack learn`` option of a field of ``config.json`` (others are shown by name)."""


def _flat(config: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in config.items():
        if isinstance(value, dict):
            out |= _flat(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def check_run_config(out: Path, config: dict[str, Any]) -> None:
    """Create ``out/config.json``, or refuse (one line naming every option that differs, with
    the run's value and the given one) a restart whose task or training options differ from
    the saved ones."""
    path = out / "config.json"
    if not path.exists():
        out.mkdir(parents=True, exist_ok=True)
        atomic_write(json.dumps(config, indent=2) + "\n", path)
        return
    try:
        saved = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise InputError(f"--out {out}: {path.name} cannot be read as JSON ({err})") from None
    if not isinstance(saved, dict):
        raise InputError(f"--out {out}: {path.name} is not a run configuration")
    old = _flat({s: saved.get(s) if isinstance(saved.get(s), dict) else {} for s in config})
    new = _flat(config)
    differences = []
    for key in [*new, *(k for k in old if k not in new)]:
        if old.get(key) != new.get(key):
            name = key.rsplit(".", 1)[-1]
            option = OPTION_NAMES.get(name, name)
            differences.append(f"{option} {shown(old.get(key))} (given: {shown(new.get(key))})")
    if differences:
        raise InputError(
            f"--out {out}: this run was started with " + ", ".join(differences) + "; give the "
            "same options to resume it, or another --out to start a fresh run"
        )


class Trainer:
    """One Deep ADFQ run of ``task`` in folder ``out`` (module docstring).

    A run of no more steps than the warm-up (``config.agent.warmup_steps``) takes no gradient
    step and would keep the untrained network as ``best.pt``: it is refused unless
    ``allow_untrained``.
    """

    def __init__(
        self, task: Task, config: TrainConfig, out: Path, allow_untrained: bool = False
    ) -> None:
        if config.steps < 1:
            raise InputError(f"--steps must be at least 1, got {config.steps}")
        warmup = config.agent.warmup_steps
        if config.steps <= warmup and not allow_untrained:
            raise InputError(
                f"--steps {config.steps} is not above the warm-up of {warmup:,} steps "
                "(--warmup): no gradient step would be taken and best.pt would be the "
                "untrained network; give more steps or a shorter --warmup, or "
                "--allow-untrained to run it anyway"
            )
        for name in ("validation_interval", "checkpoint_interval"):
            if getattr(config, name) < 1:
                raise InputError(f"{name} must be at least 1, got {getattr(config, name)}")
        if not 0.0 <= config.validation_epsilon <= 1.0:
            raise InputError(
                f"validation_epsilon must be in [0, 1], got {config.validation_epsilon}"
            )
        self.task, self.config, self.out = task, config, Path(out)
        self.metadata = {"task": task.description, "train": config.identity()}
        check_run_config(self.out, self.metadata)
        set_torch_threads()
        self.env = task.make_env()
        space = self.env.observation_space
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(config.seed)
            self.agent = AdfqAgent(
                int(np.prod(space.shape)), int(self.env.action_space.n), config.agent
            )
        self.rng = np.random.default_rng(np.random.SeedSequence(config.seed))
        self.state = _State()
        if (self.out / "checkpoint.pt").exists():
            self._load()

    # --- checkpoints -------------------------------------------------------------------------
    def _load(self) -> None:
        """Resume from ``checkpoint.pt``, read as weights only; a damaged or foreign checkpoint
        is one line naming the run folder."""
        path = self.out / "checkpoint.pt"
        try:
            data = load_weights(path, f"--out {self.out}: checkpoint {path.name}")
        except ValueError as err:
            raise InputError(str(err)) from None
        replay_file = data.get("replay_file") if isinstance(data, dict) else None
        if not isinstance(replay_file, str) or not re.fullmatch(r"replay-\d+\.npz", replay_file):
            raise InputError(f"--out {self.out}: {path.name} is not a checkpoint of hptrack learn")
        try:
            self.agent.load_state_dict(data["agent"])
            with np.load(self.out / replay_file) as replay:
                self.agent.replay.load_state_dict(dict(replay))
            self.rng.bit_generator.state = data["rng"]
            self.state = _State(**data["state"])
        except (KeyError, TypeError, ValueError, RuntimeError, OSError) as err:
            reason = str(err).splitlines()[0][:120] if str(err) else type(err).__name__
            raise InputError(
                f"--out {self.out}: {path.name} does not fit this run (damaged or from another "
                f"version: {reason}); give another --out to start a fresh run"
            ) from None

    def save_checkpoint(self) -> None:
        """Replay file first, then the checkpoint that names it (an atomic switch)."""
        s = self.state
        replay_file = f"replay-{s.step}.npz"
        tmp = self.out / (replay_file + ".tmp.npz")
        np.savez(tmp, **self.agent.replay.state_dict())
        os.replace(tmp, self.out / replay_file)
        s.last_checkpoint = s.step
        atomic_torch_save(
            {
                "agent": self.agent.state_dict(),
                "rng": self.rng.bit_generator.state,
                "state": asdict(s),
                "replay_file": replay_file,
            },
            self.out / "checkpoint.pt",
        )
        atomic_write(json.dumps(s.curve) + "\n", self.out / "curve.json")
        for old in self.out.glob("replay-*.npz"):
            if old.name != replay_file:
                old.unlink()

    # --- validation --------------------------------------------------------------------------
    def validate(self) -> dict[str, Any]:
        s, cfg = self.state, self.config
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, s.step]))
        policy = network_policy(self.agent.online, cfg.validation_epsilon, rng)
        entry = validation_entry(s.step, run_validation(policy, self.task))
        s.curve.append(entry)
        if entry["mean_U"] < s.best_u:
            s.best_u, s.best_step = entry["mean_U"], s.step
            save_policy(
                str(self.out / "best.pt"),
                self.agent.online,
                {
                    **self.metadata,
                    "step": s.step,
                    "validation_mean_U": entry["mean_U"],
                    "validation_epsilon": cfg.validation_epsilon,
                },
            )
        return entry

    # --- the loop ----------------------------------------------------------------------------
    def _beta(self) -> float:
        b0 = self.config.agent.beta_start
        return b0 + (1.0 - b0) * min(1.0, self.state.step / self.config.steps)

    def _recent_return(self) -> float:
        returns = [e["return"] for e in self.state.curve if e["kind"] == "episode"]
        return float(np.mean(returns[-RECENT_EPISODES:])) if returns else float("nan")

    def _last_validation(self) -> float:
        values = [e["mean_U"] for e in self.state.curve if e["kind"] == "validation"]
        return values[-1] if values else float("nan")

    def run(self, on_progress: Callable[[Progress], None] | None = None) -> dict[str, Any]:
        """Train until ``config.steps`` (from the checkpoint, if any); returns a summary."""
        s, cfg, agent = self.state, self.config, self.agent
        acfg = cfg.agent
        obs = None
        episode_return, losses = 0.0, []
        if s.step == 0 and not s.curve:
            self.validate()
        while s.step < cfg.steps:
            if obs is None:
                obs, _ = self.env.reset(seed=int(self.rng.integers(2**63)))
                episode_return, losses = 0.0, []
            action = agent.thompson_action(obs, self.rng)
            next_obs, reward, terminated, truncated, info = self.env.step(action)
            agent.remember(obs, action, reward, next_obs, terminated)
            s.step += 1
            episode_return += reward
            if s.step > acfg.warmup_steps:
                losses.append(agent.train_step(self.rng, self._beta())["loss"])
                if s.step % acfg.target_update == 0:
                    agent.sync_target()
            if terminated or truncated:
                s.episodes += 1
                s.curve.append(
                    {
                        "kind": "episode",
                        "step": s.step,
                        "episode": s.episodes,
                        "return": episode_return,
                        "U": float(info.get("U", np.nan)),
                        "never_observed_U": float(info.get("never_observed_U", np.nan)),
                        "loss": float(np.mean(losses)) if losses else None,
                    }
                )
                obs = None
            else:
                obs = next_obs
            if s.step % cfg.validation_interval == 0:
                self.validate()
            if obs is None and s.step - s.last_checkpoint >= cfg.checkpoint_interval:
                self.save_checkpoint()
            if on_progress is not None:
                on_progress(
                    Progress(
                        s.step,
                        cfg.steps,
                        s.episodes,
                        self._recent_return(),
                        self._last_validation(),
                        s.best_u,
                    )
                )
        validated = any(e["kind"] == "validation" and e["step"] == s.step for e in s.curve)
        if not validated:
            self.validate()
        if not validated or s.last_checkpoint != s.step:
            self.save_checkpoint()
        self.env.close()
        return {
            "steps": s.step,
            "episodes": s.episodes,
            "best_U": s.best_u,
            "best_step": s.best_step,
            "last_validation_U": self._last_validation(),
            "best_model": str(self.out / "best.pt"),
            # no gradient step before the best validation: best.pt is the initial network
            "best_untrained": s.best_step <= acfg.warmup_steps,
        }
