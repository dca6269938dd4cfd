"""The Deep ADFQ network: an MLP that outputs, per action, the mean and ``rho = -log sigma`` of
the Gaussian belief of ``Q(s, a)`` (Jeong & Lee, IJCAI 2019).

The last layer's weights start at zero and its biases at ``init_mean`` (means) and
``-log(init_sd)`` (rho), so every action starts with the same broad belief ``N(1, 10^2)``;
``sigma`` is clipped to ``[SD_MIN, SD_MAX]``.
"""

from __future__ import annotations

import math

import torch
from torch import nn

SD_MIN = 1e-5
SD_MAX = 1e5
HIDDEN = (64, 128, 64)
INIT_MEAN = 1.0
INIT_SD = 10.0


class GaussianQNetwork(nn.Module):
    """``obs (B, d) -> (mean (B, A), sd (B, A))`` through ReLU layers ``hidden``."""

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        hidden: tuple[int, ...] = HIDDEN,
        init_mean: float = INIT_MEAN,
        init_sd: float = INIT_SD,
    ) -> None:
        super().__init__()
        self.obs_dim, self.n_actions, self.hidden = obs_dim, n_actions, tuple(hidden)
        layers: list[nn.Module] = []
        width = obs_dim
        for size in hidden:
            layers += [nn.Linear(width, size), nn.ReLU()]
            width = size
        self.body = nn.Sequential(*layers)
        self.head = nn.Linear(width, 2 * n_actions)
        with torch.no_grad():
            self.head.weight.zero_()
            self.head.bias[:n_actions] = init_mean
            self.head.bias[n_actions:] = -math.log(init_sd)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Means and log standard deviations ``(B, A)`` (log sd clipped)."""
        out = self.head(self.body(obs))
        mean, rho = out[:, : self.n_actions], out[:, self.n_actions :]
        log_sd = torch.clamp(-rho, math.log(SD_MIN), math.log(SD_MAX))
        return mean, log_sd

    def config(self) -> dict[str, object]:
        """What `from_config` needs to rebuild the architecture."""
        return {"obs_dim": self.obs_dim, "n_actions": self.n_actions, "hidden": list(self.hidden)}

    @classmethod
    def from_config(cls, config: dict, state_dict: dict | None = None) -> GaussianQNetwork:
        """The network ``config`` describes (`config`).

        Raises:
            ValueError: ``state_dict`` is given and its tensor shapes are not those of the
                described network (checked before anything is allocated).
        """
        obs_dim, n_actions = int(config["obs_dim"]), int(config["n_actions"])
        hidden = tuple(int(h) for h in config["hidden"])
        if state_dict is not None:
            widths = (obs_dim, *hidden)
            expected: dict[str, tuple[int, ...]] = {
                f"body.{2 * i}.weight": (h, w)
                for i, (w, h) in enumerate(zip(widths[:-1], hidden, strict=True))
            }
            expected |= {f"body.{2 * i}.bias": (h,) for i, h in enumerate(hidden)}
            expected |= {"head.weight": (2 * n_actions, widths[-1]), "head.bias": (2 * n_actions,)}
            shapes = {k: tuple(getattr(v, "shape", ())) for k, v in state_dict.items()}
            if shapes != expected:
                raise ValueError(f"tensor shapes {shapes} are not those of the network {config}")
        return cls(obs_dim, n_actions, hidden)
