"""``hptrack/Tracking-v0``: the step-level tracking problem as a Gymnasium environment.

One environment step is one simulator step of ``tau`` = 0.5 s (`hptrack.sim.step.World`,
the simulator's compiled step: same seed, same mission as `hptrack.sim.episode.run_episode`).
The agent is holonomic. Actions:

* ``action_type="discrete"`` (default): ``Discrete(13)``; action ``k < 12`` flies at full speed
  ``v_a`` on the heading ``30 k`` degrees (counter-clockwise from the x axis), action 12 hovers;
* ``action_type="box"``: ``Box(-1, 1, (2,))``, the velocity as a fraction of ``v_a`` per axis
  (a vector longer than 1 is flown at ``v_a`` in its direction).

Observation: `hptrack.envs.observation`. Reward: ``-(U_k - U_{k-1}) / n``, so an episode's
rewards sum to ``-(U_K - U_0) / n``. An episode is truncated when the budget is spent
(``terminated`` is always False). ``info``: ``U``, ``per_target_logdet`` ``(n,)``,
``never_observed_U`` (the scenario's ``U`` if nothing is measured after the start),
``detected`` ``(n,)`` and ``step``; at the budget's end (every step with
``gospa_every_step=True``) ``gospa``, m, between the belief means and the true positions, and at
the end ``tracks_lost`` ``(n,)`` (`hptrack.sim.metrics`).

`MissionEnv` holds what both environments share (scenarios, the world, the observation,
``info``, rendering); `TrackingEnv` adds the step-level actions.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from hptrack.envs.observation import ObservationLayout
from hptrack.interface import InputError, shown
from hptrack.models.mission import MAX_TARGETS
from hptrack.models.state import POSITION, positions
from hptrack.scenario.model import Scenario
from hptrack.scenario.random import random_scenario
from hptrack.sim.metrics import gospa, gospa_cutoff, track_lost
from hptrack.sim.record import EpisodeRecord
from hptrack.sim.step import World

SETTINGS = ("heterogeneous", "homogeneous")
"""Random-scenario settings (paper Sec. V-A)."""
N_HEADINGS = 12
HOVER = N_HEADINGS
"""The discrete action that keeps the agent in place."""
HEADINGS = tuple(
    (math.cos(math.radians(30.0 * k)), math.sin(math.radians(30.0 * k))) for k in range(N_HEADINGS)
) + ((0.0, 0.0),)
"""Unit displacement of each discrete action (hover last)."""
RESET_OPTIONS = ("scenario", "seed")


def _target_range(n_targets: int | tuple[int, int]) -> tuple[int, int]:
    if isinstance(n_targets, int | np.integer) and not isinstance(n_targets, bool):
        lo = hi = int(n_targets)
    elif (
        isinstance(n_targets, tuple | list)
        and len(n_targets) == 2
        and all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in n_targets)
    ):
        lo, hi = int(n_targets[0]), int(n_targets[1])
    else:
        raise InputError(f"n_targets must be an int or a (min, max) pair, got {n_targets!r}")
    if not 1 <= lo <= hi <= MAX_TARGETS:
        raise InputError(
            f"n_targets must be between 1 and {MAX_TARGETS} (min <= max), got {n_targets!r}"
        )
    return lo, hi


def discrete_action(action: Any, n: int) -> int:
    """``action`` as an index ``0 .. n-1``: an integer (Python or numpy, also a one-element
    integer array as a policy returns it); a float, a text or a boolean is refused, never
    truncated.

    Raises:
        ValueError: anything else (one line with the shortened value).
    """
    value = action
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "iu":
        value = value.reshape(()).item()
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
        raise ValueError(f"action must be an integer in 0..{n - 1}, got {shown(action)}")
    return value


def action_waypoint(
    action_type: str, action: Any, agent: np.ndarray, step_length: float
) -> tuple[float, float]:
    """The waypoint (m) an action of ``action_type`` (``"discrete"`` or ``"box"``) gives an agent
    at ``agent`` moving at most ``step_length`` m per step (module docstring): the environment's
    rule, also for flying a learned policy as a planner in the simulator.

    Raises:
        ValueError: an action outside the space. A Box action only needs to be finite: one
            beyond the box is scaled back into it along its direction (the agent flies at most
            ``step_length`` anyway), so that no waypoint overflows.
    """
    if action_type == "discrete":
        ux, uy = HEADINGS[discrete_action(action, len(HEADINGS))]
    else:
        try:
            raw = np.asarray(action)
            # numbers only: a text or a boolean would otherwise be converted to one
            numeric = raw.dtype.kind in "iuf" and not (
                isinstance(action, list | tuple)
                and any(isinstance(v, bool | np.bool_ | str | bytes) for v in action)
            )
            a = raw.astype(float) if numeric else np.full(1, np.nan)
        except (TypeError, ValueError, OverflowError):
            a = np.full(1, np.nan)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be 2 finite numbers, got {shown(action)}")
        a = a / max(1.0, float(np.max(np.abs(a))))
        ux, uy = float(a[0]), float(a[1])
    return float(agent[0]) + step_length * ux, float(agent[1]) + step_length * uy


class MissionEnv(gym.Env):
    """Common base of the environments (module docstring of `hptrack.envs.tracking`).

    Args:
        n_targets: targets of the random scenarios: an int (default 4), or an inclusive
            ``(min, max)`` range drawn per episode (needs ``max_targets``).
        setting: ``"heterogeneous"`` (default: priors and ``q`` per target) or
            ``"homogeneous"`` (one prior and ``q`` per scenario).
        max_targets: pad the observation to this many target slots and append a mask
            (episodes may then have any ``n <= max_targets``); default: no padding, ``n`` slots.
        render_mode: ``None`` or ``"rgb_array"`` (the mission figure of the episode so far).
        gospa_every_step: ``info["gospa"]`` at every step, not only at the budget's end.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2}
    team_size = 1
    """The UAVs the environment flies (a team's environment: `hptrack.envs.team`)."""

    def __init__(
        self,
        n_targets: int | tuple[int, int] = 4,
        setting: str = "heterogeneous",
        max_targets: int | None = None,
        render_mode: str | None = None,
        gospa_every_step: bool = False,
    ) -> None:
        self._n_range = _target_range(n_targets)
        if not isinstance(gospa_every_step, bool | np.bool_):
            raise InputError(
                f"gospa_every_step must be True or False, got {shown(gospa_every_step)}"
            )
        self.gospa_every_step = bool(gospa_every_step)
        if setting not in SETTINGS:
            raise InputError(f"setting must be one of {', '.join(SETTINGS)}, got {setting!r}")
        if max_targets is not None and (
            isinstance(max_targets, bool)
            or not isinstance(max_targets, int | np.integer)
            or not self._n_range[1] <= max_targets <= MAX_TARGETS
        ):
            raise InputError(
                f"max_targets must be an int from n_targets {n_targets!r} to {MAX_TARGETS}, "
                f"got {shown(max_targets)}"
            )
        if self._n_range[0] != self._n_range[1] and max_targets is None:
            raise InputError(f"n_targets={n_targets!r} varies per episode: give max_targets")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.setting = setting
        self.render_mode = render_mode
        self.max_targets = None if max_targets is None else int(max_targets)
        self.layout = ObservationLayout(
            self._n_range[1] if max_targets is None else int(max_targets), max_targets is not None
        )
        low, high = self.layout.bounds()
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.world: World | None = None
        self.scenario: Scenario | None = None
        self.never_observed_uncertainty = math.nan
        self._history: list[tuple[np.ndarray, ...]] = []

    # --- episodes ----------------------------------------------------------------------------
    def _draw_scenario(self) -> Scenario:
        lo, hi = self._n_range
        n = int(self.np_random.integers(lo, hi + 1))
        seed = int(self.np_random.integers(2**63))
        return random_scenario(
            n, seed=seed, homogeneous=self.setting == "homogeneous", team=self.team_size
        )

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        """Start an episode: ``options={"scenario": Scenario}`` flies that scenario with its own
        seed (or ``options["seed"]``), exactly as the simulator; otherwise a random scenario of
        the env's setting is drawn from the env's generator (seeded by ``seed``)."""
        options = dict(options or {})
        for given, name in ((seed, "seed"), (options.get("seed"), 'options["seed"]')):
            if given is not None and (
                isinstance(given, bool)
                or not isinstance(given, int | np.integer)
                or not 0 <= given < 2**63
            ):
                raise InputError(
                    f"reset {name} must be an integer in 0 .. 2^63 - 1, got {shown(given)}"
                )
        super().reset(seed=None if seed is None else int(seed))
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise InputError(
                f"reset options: unknown {', '.join(map(repr, unknown))} "
                f"(known: {', '.join(RESET_OPTIONS)})"
            )
        scenario = options.get("scenario")
        if scenario is None:
            scenario = self._draw_scenario()
        elif not isinstance(scenario, Scenario):
            raise InputError(f"reset option scenario must be a Scenario, got {type(scenario)}")
        if scenario.n_vehicles != self.team_size:
            flies = "one" if self.team_size == 1 else f"a team of {self.team_size}"
            raise InputError(
                f"reset option scenario flies {scenario.n_vehicles} UAV"
                f"{'s' if scenario.n_vehicles > 1 else ''}; this env flies {flies} "
                "(TeamTracking-v0 flies a team, docs/envs.md)"
            )
        n = len(scenario.targets)
        if n > self.layout.n_slots or (not self.layout.masked and n != self.layout.n_slots):
            raise InputError(
                f"reset option scenario has {n} targets; this env observes "
                f"{self.layout.n_slots}"
                + ("" if self.layout.masked else " (give max_targets to pad)")
            )
        self.scenario = scenario
        self.world = World(scenario, options.get("seed"))
        self.never_observed_uncertainty = scenario.never_observed_uncertainty()
        self._history = []
        self._record()
        return self._observation(), self._info()

    @property
    def n_targets(self) -> int:
        """Targets of the current episode."""
        return self._world().n_targets

    def _world(self) -> World:
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        return self.world

    def _advance(self, waypoint_x: float, waypoint_y: float) -> None:
        """One simulator step towards the waypoint (m), recorded when rendering."""
        self._world().step(waypoint_x, waypoint_y)
        self._record()

    def _check_running(self) -> World:
        world = self._world()
        if world.done:
            raise RuntimeError("the episode was truncated at the end of the budget; call reset()")
        return world

    def _observation(self) -> np.ndarray:
        w = self._world()
        return self.layout.encode(
            w.agent, w.means, w.logdets, w.seen, w.remaining_budget / w.mission.budget
        )

    def _info(self) -> dict[str, Any]:
        w = self._world()
        info = {
            "U": w.uncertainty,
            "per_target_logdet": w.logdets.copy(),
            "never_observed_U": self.never_observed_uncertainty,
            "detected": w.seen.copy(),
            "step": w.step_index,
        }
        if w.done or self.gospa_every_step:
            cutoff = gospa_cutoff(w.mission.sensor_diameter)
            means, truth = positions(w.means), positions(w.truth)
            info["gospa"] = gospa(means, truth, cutoff)
            if w.done:
                covs = w.covariances[:, POSITION, POSITION]
                info["tracks_lost"] = track_lost(means, covs, truth, cutoff)
        return info

    # --- rendering ---------------------------------------------------------------------------
    def _record(self) -> None:
        if self.render_mode is not None:
            w = self._world()
            self._history.append(
                (
                    (w.agent if self.team_size == 1 else w.agents).copy(),
                    w.truth.copy(),
                    w.seen.copy(),
                    w.means.copy(),
                    w.covariances.copy(),
                )
            )

    def episode_record(self) -> EpisodeRecord:
        """The episode so far as an `EpisodeRecord` (only with
        ``render_mode="rgb_array"``, which keeps the history)."""
        if self.render_mode is None:
            raise RuntimeError("the episode history is kept only with render_mode='rgb_array'")
        w = self._world()
        agent, truth, seen, means, covs = (np.stack(a) for a in zip(*self._history, strict=True))
        m = w.mission
        return EpisodeRecord(
            planner=self.spec.id if self.spec is not None else type(self).__name__,
            seed=w.seed,
            target_ids=m.target_ids,
            time_step=m.time_step,
            sensor_diameter=m.sensor_diameter,
            agent_paths=agent,
            true_states=truth,
            belief_steps=np.arange(len(self._history)),
            belief_means=means,
            belief_covariances=covs,
            detections=seen,
            per_target_logdet=w.logdets.copy(),
            fence=m.fence,
        )

    def render(self) -> np.ndarray | None:
        """The mission figure of the episode so far (`hptrack.viz.mission.mission_figure`)
        as an RGB array ``(640, 640, 3)`` uint8; ``None`` without ``render_mode``."""
        if self.render_mode is None:
            return None
        from hptrack.viz.mission import mission_figure

        fig = mission_figure(self.episode_record(), 6.4, 6.4, dpi=100)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


class TrackingEnv(MissionEnv):
    """``hptrack/Tracking-v0`` (module docstring).

    Args:
        action_type: ``"discrete"`` (13 actions, default) or ``"box"`` (velocity fraction).
        **kwargs: `MissionEnv`'s.
    """

    def __init__(self, action_type: str = "discrete", **kwargs: Any) -> None:
        super().__init__(**kwargs)
        if action_type == "discrete":
            self.action_space = spaces.Discrete(len(HEADINGS))
        elif action_type == "box":
            self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        else:
            raise InputError(f"action_type must be 'discrete' or 'box', got {action_type!r}")
        self.action_type = action_type

    def waypoint(self, action: Any) -> tuple[float, float]:
        """Where ``action`` sends the agent this step, m."""
        w = self._world()
        return action_waypoint(self.action_type, action, w.agent, w.mission.step_length)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        world = self._check_running()
        before = world.uncertainty
        x, y = self.waypoint(action)
        self._advance(x, y)
        reward = -(world.uncertainty - before) / world.n_targets
        return self._observation(), float(reward), False, world.done, self._info()
