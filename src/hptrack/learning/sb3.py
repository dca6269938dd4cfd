"""PPO from stable-baselines3 on ``hptrack/Tracking-v0``: the ecosystem's standard learner as a
reference for Deep ADFQ, trained, validated and checkpointed like it
(`hptrack.learning.train`).

The policy is stable-baselines3's ``MlpPolicy`` with its default PPO hyperparameters, except one
rollout per episode (``n_steps`` = 1800, the episode length) and mini-batches of 60 that divide
it. A time-limit truncation is bootstrapped (stable-baselines3 treats it as non-terminal).

A run folder holds ``config.json``, ``checkpoint-<step>.zip`` (the model with its optimiser and
step count) with ``state.json`` (the training curve, best score and the name of the checkpoint;
written last, so it always names a complete checkpoint), ``best.zip`` (the best validation
score, deterministic policy) and ``curve.json``. Checkpoints are taken at rollout ends. A resumed
run continues from the checkpoint's step with the curve of that moment (no entry is repeated);
it is not bit-identical to an uninterrupted run: the environment starts a fresh episode and
the random streams are reseeded from the seed and the step.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, NonNegativeInt, ValidationError

from hptrack.interface import InputError, shown
from hptrack.learning.agent import set_torch_threads
from hptrack.learning.train import (
    Progress,
    Task,
    atomic_write,
    check_run_config,
    run_validation,
    validation_entry,
)
from hptrack.learning.weights import SB3_POLICY_MEMBER, describe, load_weights, read_zip_member


@dataclass(frozen=True)
class PpoConfig:
    """PPO run: stable-baselines3 defaults except ``n_steps`` and ``batch_size``."""

    steps: int
    seed: int = 0
    validation_interval: int = 25_000
    checkpoint_interval: int = 10_000
    n_steps: int = 1800
    batch_size: int = 60
    learning_rate: float = 3e-4
    n_epochs: int = 10
    gamma: float = 0.99
    gae_lambda: float = 0.95
    ent_coef: float = 0.0

    def identity(self) -> dict[str, Any]:
        out = asdict(self)
        out.pop("steps")
        return out


PPO_POLICY_PREFIXES = (
    "mlp_extractor.policy_net.",
    "mlp_extractor.value_net.",
    "action_net.",
    "value_net.",
)
"""Tensor name prefixes of the ``MlpPolicy`` (``ActorCriticPolicy``) that PPO trains."""


def read_ppo_tensors(path: str | Path) -> dict[str, Any]:
    """The tensors of a stable-baselines3 zip (``policy.pth`` and, for a checkpoint,
    ``policy.optimizer.pth``) read as weights only; the zip's pickled ``data`` is never
    unpickled. Returns ``{"policy": state_dict}``, with ``"policy.optimizer"`` when the zip
    holds the optimiser (a checkpoint).

    Raises:
        ValueError: the file is not such a model, or holds pickled objects (one line naming it).
    """
    label = f"PPO model {path}"
    what = describe(path)
    if what != "a stable-baselines3 model":
        hint = ": fly it with --planner adfq" if what == "a torch file" else ""
        raise ValueError(f"{label}: not a stable-baselines3 model ({what}{hint})")
    try:
        data = json.loads(read_zip_member(path, "data", label))
    except (ValueError, UnicodeDecodeError):
        raise ValueError(f"{label}: its data entry is not JSON") from None
    if not isinstance(data, dict) or data.get("policy_kwargs", {}) != {}:
        raise ValueError(
            f"{label}: not the default MlpPolicy of hptrack learn sb3-ppo (policy_kwargs "
            f"{shown(data.get('policy_kwargs') if isinstance(data, dict) else data)})"
        )
    policy = load_weights(read_zip_member(path, SB3_POLICY_MEMBER, label), label)
    if not isinstance(policy, dict) or not all(
        isinstance(k, str) and k.startswith(PPO_POLICY_PREFIXES) for k in policy
    ):
        raise ValueError(f"{label}: not the tensors of a PPO MlpPolicy")
    with zipfile.ZipFile(path) as archive:
        has_optimizer = "policy.optimizer.pth" in archive.namelist()
    if not has_optimizer:
        return {"policy": policy}
    optimizer = load_weights(read_zip_member(path, "policy.optimizer.pth", label), label)
    return {"policy": policy, "policy.optimizer": optimizer}


class PpoActor:
    """The actor of a PPO ``MlpPolicy`` rebuilt from its tensors: linear layers with tanh
    between them (the policy's default), then the action logits; it computes what
    ``PPO.predict`` computes, without stable-baselines3 or any unpickling.

    Raises:
        ValueError: the tensors do not chain into such a network (``label`` names the file).
    """

    def __init__(self, tensors: dict[str, Any], label: str) -> None:
        import torch
        from torch import nn

        prefix = "mlp_extractor.policy_net."
        indices = sorted(
            {int(k[len(prefix) :].split(".")[0]) for k in tensors if k.startswith(prefix)}
        )
        names = [f"{prefix}{i}" for i in indices] + ["action_net"]
        layers: list[nn.Module] = []
        width = None
        for name in names:
            weight, bias = tensors.get(f"{name}.weight"), tensors.get(f"{name}.bias")
            if (
                not isinstance(weight, torch.Tensor)
                or not isinstance(bias, torch.Tensor)
                or weight.ndim != 2
                or bias.shape != weight.shape[:1]
                or (width is not None and weight.shape[1] != width)
            ):
                raise ValueError(f"{label}: its layer {name} does not fit the network")
            linear = nn.Linear(weight.shape[1], weight.shape[0])
            linear.load_state_dict({"weight": weight, "bias": bias})
            layers += [linear, nn.Tanh()]
            width = weight.shape[0]
        self.network = nn.Sequential(*layers[:-1]).eval()
        self.obs_dim = int(layers[0].in_features)
        self.n_actions = int(width)
        self._torch = torch

    def distribution(self, obs: np.ndarray):
        """The categorical action distribution of one observation vector (``d``,)."""
        with self._torch.no_grad():
            logits = self.network(self._torch.as_tensor(obs, dtype=self._torch.float32)[None])
        return self._torch.distributions.Categorical(logits=logits)


def load_actor(path: str | Path) -> PpoActor:
    """The actor of a PPO model file (`read_ppo_tensors`, `PpoActor`)."""
    return PpoActor(read_ppo_tensors(path)["policy"], f"PPO model {path}")


def _policy(model) -> Callable[[np.ndarray], np.ndarray]:
    def policy(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    return policy


class PpoState(BaseModel):
    """``state.json`` of a PPO run folder, validated before anything it names is read."""

    model_config = ConfigDict(extra="forbid")

    step: NonNegativeInt
    episodes: NonNegativeInt
    last_checkpoint: NonNegativeInt
    curve: list[dict[str, Any]]
    best_u: float
    best_step: int
    checkpoint: Annotated[str, Field(pattern=r"^checkpoint-\d+\.zip$")] | None


def read_state(path: Path) -> dict[str, Any]:
    """The validated ``state.json`` at ``path`` (`PpoState`), as a dict.

    Raises:
        InputError: it is not JSON or not such a state (one line naming the file).
    """
    try:
        return PpoState.model_validate_json(path.read_bytes()).model_dump()
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "the file"
        raise InputError(
            f"{path}: not a state of hptrack learn sb3-ppo ({where}: {first['msg']})"
        ) from None


def trained_steps(steps: int, rollout_steps: int) -> int:
    """The steps a PPO run of ``steps`` trains: whole rollouts of ``rollout_steps``
    (``n_steps``), so ``steps`` rounded up to a multiple of it (a resumed run restarts from a
    rollout's end)."""
    return -(-steps // rollout_steps) * rollout_steps


class PpoTrainer:
    """One PPO run of ``task`` in folder ``out`` (module docstring)."""

    def __init__(self, task: Task, config: PpoConfig, out: Path) -> None:
        if config.steps < 1:
            raise InputError(f"--steps must be at least 1, got {config.steps}")
        if config.n_steps % config.batch_size:
            raise InputError(f"batch_size {config.batch_size} must divide n_steps {config.n_steps}")
        self.task, self.config, self.out = task, config, Path(out)
        self.metadata = {
            "task": task.description,
            "train": {"algorithm": "PPO", **config.identity()},
        }
        check_run_config(self.out, self.metadata)
        set_torch_threads()
        self.state: dict[str, Any] = {
            "step": 0,
            "episodes": 0,
            "last_checkpoint": 0,
            "curve": [],
            "best_u": float("inf"),
            "best_step": -1,
            "checkpoint": None,
        }
        if (self.out / "state.json").exists():
            self.state = read_state(self.out / "state.json")

    def _make_model(self):
        from stable_baselines3 import PPO
        from stable_baselines3.common.monitor import Monitor
        from stable_baselines3.common.vec_env import DummyVecEnv

        cfg = self.config
        env = DummyVecEnv([lambda: Monitor(self.task.make_env())])
        model = PPO(
            "MlpPolicy",
            env,
            learning_rate=cfg.learning_rate,
            n_steps=cfg.n_steps,
            batch_size=cfg.batch_size,
            n_epochs=cfg.n_epochs,
            gamma=cfg.gamma,
            gae_lambda=cfg.gae_lambda,
            ent_coef=cfg.ent_coef,
            seed=cfg.seed,
            device="cpu",
            verbose=0,
        )
        if self.state["checkpoint"] is not None:
            # weights only: the checkpoint's pickled data is never loaded; the step count
            # comes from state.json
            try:
                tensors = read_ppo_tensors(self.out / self.state["checkpoint"])
            except ValueError as err:
                raise InputError(f"--out {self.out}: {err}") from None
            try:
                model.set_parameters(tensors, exact_match=True, device="cpu")
            except (ValueError, RuntimeError, KeyError) as err:
                raise InputError(
                    f"--out {self.out}: checkpoint {self.state['checkpoint']} does not fit this "
                    f"run's network ({str(err).splitlines()[0][:120]})"
                ) from None
            model.num_timesteps = int(self.state["step"])
            model.set_random_seed(
                int(np.random.SeedSequence([cfg.seed, self.state["step"]]).generate_state(1)[0])
            )
        return model

    def save_checkpoint(self, model) -> None:
        """The model first, then the state that names it."""
        step = int(model.num_timesteps)
        name = f"checkpoint-{step}.zip"
        tmp = self.out / (name + ".tmp")
        with open(tmp, "wb") as file:
            model.save(file)
        os.replace(tmp, self.out / name)
        self.state.update(step=step, last_checkpoint=step, checkpoint=name)
        atomic_write(json.dumps(self.state) + "\n", self.out / "state.json")
        atomic_write(json.dumps(self.state["curve"]) + "\n", self.out / "curve.json")
        for old in self.out.glob("checkpoint-*.zip"):
            if old.name != name:
                old.unlink()

    def validate(self, model) -> dict[str, Any]:
        entry = validation_entry(
            int(model.num_timesteps), run_validation(_policy(model), self.task)
        )
        self.state["curve"].append(entry)
        if entry["mean_U"] < self.state["best_u"]:
            self.state["best_u"], self.state["best_step"] = entry["mean_U"], entry["step"]
            model.save(str(self.out / "best"))
        return entry

    def _recent_return(self) -> float:
        returns = [e["return"] for e in self.state["curve"] if e["kind"] == "episode"]
        return float(np.mean(returns[-10:])) if returns else float("nan")

    def _last_validation(self) -> float:
        values = [e["mean_U"] for e in self.state["curve"] if e["kind"] == "validation"]
        return values[-1] if values else float("nan")

    def run(self, on_progress: Callable[[Progress], None] | None = None) -> dict[str, Any]:
        """Train until `trained_steps` (whole rollouts); returns a summary."""
        from stable_baselines3.common.callbacks import BaseCallback

        trainer, cfg = self, self.config
        model = self._make_model()
        state = self.state

        class _Callback(BaseCallback):
            def _on_step(self) -> bool:
                step = int(self.num_timesteps)
                for info in self.locals["infos"]:
                    if "episode" in info:
                        state["episodes"] += 1
                        state["curve"].append(
                            {
                                "kind": "episode",
                                "step": step,
                                "episode": state["episodes"],
                                "return": float(info["episode"]["r"]),
                                "U": float(info.get("U", np.nan)),
                                "never_observed_U": float(info.get("never_observed_U", np.nan)),
                            }
                        )
                state["step"] = step
                if step % cfg.validation_interval == 0:
                    trainer.validate(self.model)
                if on_progress is not None:
                    on_progress(
                        Progress(
                            step,
                            cfg.steps,
                            state["episodes"],
                            trainer._recent_return(),
                            trainer._last_validation(),
                            state["best_u"],
                        )
                    )
                return True

            def _on_rollout_end(self) -> None:
                if self.num_timesteps - state["last_checkpoint"] >= cfg.checkpoint_interval:
                    trainer.save_checkpoint(self.model)

        if state["step"] == 0 and not state["curve"]:
            self.validate(model)
        remaining = cfg.steps - int(model.num_timesteps)
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=_Callback(), reset_num_timesteps=False)
        step = int(model.num_timesteps)
        validated = any(e["kind"] == "validation" and e["step"] == step for e in state["curve"])
        if not validated:
            self.validate(model)
        if not validated or state["last_checkpoint"] != step:
            self.save_checkpoint(model)
        model.get_env().close()
        return {
            "steps": step,
            "episodes": state["episodes"],
            "best_U": state["best_u"],
            "best_step": state["best_step"],
            "last_validation_U": self._last_validation(),
            "best_model": str(self.out / "best.zip"),
            # validated before the first update (which follows the first rollout)
            "best_untrained": state["best_step"] <= cfg.n_steps,
        }
