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
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hptrack.interface import InputError
from hptrack.learning.agent import set_torch_threads
from hptrack.learning.train import (
    Progress,
    Task,
    atomic_write,
    check_run_config,
    run_validation,
    validation_entry,
)


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


def load_model(path: str | Path):
    """A PPO model saved by stable-baselines3 (on the CPU).

    Raises:
        ValueError: the file is not such a model (the message names it).
    """
    from stable_baselines3 import PPO

    try:
        return PPO.load(str(path), device="cpu")
    except (OSError, ValueError, KeyError, RuntimeError) as err:
        raise ValueError(f"PPO model {path}: cannot be read ({err})") from None


def _policy(model) -> Callable[[np.ndarray], np.ndarray]:
    def policy(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    return policy


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
            self.state = json.loads((self.out / "state.json").read_text())

    def _make_model(self):
        from stable_baselines3 import PPO
        from stable_baselines3.common.monitor import Monitor
        from stable_baselines3.common.vec_env import DummyVecEnv

        cfg = self.config
        env = DummyVecEnv([lambda: Monitor(self.task.make_env())])
        if self.state["checkpoint"] is not None:
            model = PPO.load(str(self.out / self.state["checkpoint"]), env=env, device="cpu")
            model.set_random_seed(
                int(np.random.SeedSequence([cfg.seed, self.state["step"]]).generate_state(1)[0])
            )
            return model
        return PPO(
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
        }
