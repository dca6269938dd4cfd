"""Episode record: everything a mission produced, saved to one compressed ``.npz`` file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hptrack.jsonout import json_text
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import FenceSpec
from hptrack.subtasks import read_subtasks

if TYPE_CHECKING:
    from hptrack.experiments.store import EpisodeKey


def subtasks_with_ids(entries: list[dict], target_ids: tuple[str, ...]) -> list[dict]:
    """A planner's sub-task log (indices into ``target_ids``, as planners keep it; any shape
    `hptrack.subtasks.Subtask.from_json` reads, older ones included) in the one JSON shape,
    naming targets by id."""
    return [entry.to_json(target_ids) for entry in read_subtasks(entries, target_ids)]


@dataclass
class EpisodeRecord:
    """The outcome of one simulated mission.

    Attributes:
        planner: planner name.
        seed: the seed that drove truth and noise.
        target_ids: target names, ``(n,)``.
        time_step: ``tau``, s.
        sensor_diameter: ``w``, m.
        agent_paths: ``(K+1, m, 2)`` the vehicles' positions at steps ``0..K``, m (a
            ``(K+1, 2)`` path given here is one vehicle's; `agent_path` is the first
            vehicle's).
        true_states: ``(K+1, n, 4)`` true target states.
        belief_steps: ``(M,)`` the steps at which beliefs were stored (a stride, last step kept).
        belief_means: ``(M, n, 4)``.
        belief_covariances: ``(M, n, 4, 4)``.
        detections: ``(K+1, n)`` which targets were measured at each step.
        per_target_logdet: ``(n,)`` final ``log det Sigma^xy`` per target.
        info: planner-specific metadata (JSON-serialisable), e.g. its sub-task log.
        fence: where the vehicles might fly (`hptrack.models.fence.FenceSpec`), ``None`` in
            open space.
    """

    planner: str
    seed: int
    target_ids: tuple[str, ...]
    time_step: float
    sensor_diameter: float
    agent_paths: np.ndarray
    true_states: np.ndarray
    belief_steps: np.ndarray
    belief_means: np.ndarray
    belief_covariances: np.ndarray
    detections: np.ndarray
    per_target_logdet: np.ndarray
    info: dict = field(default_factory=dict)
    fence: FenceSpec | None = None

    def __post_init__(self) -> None:
        if self.agent_paths.ndim == 2:
            self.agent_paths = self.agent_paths[:, None, :]

    @property
    def agent_path(self) -> np.ndarray:
        """``(K+1, 2)`` the first vehicle's positions, m (the one vehicle of every planner
        today)."""
        return self.agent_paths[:, 0]

    @property
    def n_vehicles(self) -> int:
        """``m``, the vehicles flown."""
        return self.agent_paths.shape[1]

    @property
    def uncertainty(self) -> float:
        """Mission score ``U = sum_i log det Sigma^xy_i`` at the budget's end (lower is better)."""
        return float(np.sum(self.per_target_logdet))

    @property
    def times(self) -> np.ndarray:
        """Time of every step, s."""
        return np.arange(self.agent_path.shape[0]) * self.time_step

    def detection_counts(self) -> np.ndarray:
        """Number of steps at which each target was measured."""
        return self.detections.sum(axis=0)

    def uncertainty_history(self) -> np.ndarray:
        """``U`` at each stored belief step."""
        return position_logdet(self.belief_covariances).sum(axis=1)

    def summary(self) -> dict:
        """JSON-ready summary: ``U``, per-target log det and detections, planner, seed, and
        the planner's metadata with its sub-tasks naming targets by id
        (`subtasks_with_ids`)."""
        info = dict(self.info)
        if info.get("subtasks"):
            info["subtasks"] = subtasks_with_ids(info["subtasks"], self.target_ids)
        return {
            "U": self.uncertainty,
            "per_target_logdet": dict(
                zip(self.target_ids, map(float, self.per_target_logdet), strict=True)
            ),
            "detections": dict(
                zip(self.target_ids, map(int, self.detection_counts()), strict=True)
            ),
            "planner": self.planner,
            "seed": self.seed,
            "time_step": self.time_step,
            "duration": float(self.times[-1]),
            "info": info,
        }

    def save(self, path: str | Path) -> None:
        """Write the record to one compressed ``.npz`` file."""
        meta = {
            "planner": self.planner,
            "seed": self.seed,
            "target_ids": list(self.target_ids),
            "time_step": self.time_step,
            "sensor_diameter": self.sensor_diameter,
            "info": self.info,
        }
        with open(path, "wb") as fh:
            np.savez_compressed(
                fh,
                meta=np.array(json_text(meta)),
                agent_paths=self.agent_paths,
                true_states=self.true_states,
                belief_steps=self.belief_steps,
                belief_means=self.belief_means,
                belief_covariances=self.belief_covariances,
                detections=self.detections,
                per_target_logdet=self.per_target_logdet,
            )

    @classmethod
    def load(cls, path: str | Path) -> EpisodeRecord:
        """Read a record written by `save` (also by an older hptrack, whose file holds one
        vehicle's ``agent_path``)."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in data.files if k != "meta"}
        if "agent_path" in arrays:
            arrays["agent_paths"] = arrays.pop("agent_path")
        return cls(
            planner=meta["planner"],
            seed=meta["seed"],
            target_ids=tuple(meta["target_ids"]),
            time_step=meta["time_step"],
            sensor_diameter=meta["sensor_diameter"],
            info=meta["info"],
            **arrays,
        )


@dataclass(frozen=True)
class EpisodeRow:
    """One finished episode as a results store keeps it
    (`hptrack.experiments.store.ResultStore`): its key, ``U``, the never-observed ``U`` of
    the same scenario, the number of detection steps, the wall time (s) and planner
    metadata."""

    key: EpisodeKey
    uncertainty: float
    never_observed: float
    detections: int
    wall_time_s: float
    info: dict
