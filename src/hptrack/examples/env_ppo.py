"""Train stable-baselines3's PPO briefly on the Gymnasium environment, then score it.

Needs ``pip install "hptrack[learn]"``. A few thousand steps only show the loop; the shipped
models trained for 100,000 (``hptrack learn sb3-ppo``).

    python3 env_ppo.py [--targets 2] [--steps 4096]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
from stable_baselines3 import PPO

import hptrack.envs  # noqa: F401  (registers hptrack/Tracking-v0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=2)
    parser.add_argument("--steps", type=int, default=4096)
    args = parser.parse_args()

    env = gym.make("hptrack/Tracking-v0", n_targets=args.targets, setting="heterogeneous")
    model = PPO("MlpPolicy", env, n_steps=1024, seed=0, verbose=0)
    model.learn(total_timesteps=args.steps)

    obs, info = env.reset(seed=123)
    done = False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    print(f"after {args.steps} steps of PPO: U = {info['U']:.3f}")


if __name__ == "__main__":
    main()
