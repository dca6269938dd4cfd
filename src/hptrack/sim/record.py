"""Episode record: everything a mission produced, saved to one compressed ``.npz`` file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hptrack.jsonout import json_text
from hptrack.models.beliefs import position_logdet

PLANNED_ACTIONS = ("plan_after_find", "plan_after_miss", "plan_after_dwell")
"""Sub-task log entries holding the next planned action: a target index, or ``n`` the dwell."""


def subtasks_with_ids(entries: list[dict], target_ids: tuple[str, ...]) -> list[dict]:
    """A planner's sub-task log (indices into ``target_ids``, as planners keep it) naming
    targets by id: ``target_index`` becomes ``target``, ``follow`` and ``dwell`` hold ids, and a
    planned action is an id, ``"dwell"`` (action ``n``), ``"dwell j"`` (action ``n + j``, the
    ``j``-th dwell length) or ``None``."""
    n = len(target_ids)
    out = []
    for entry in entries:
        named = {}
        for key, value in entry.items():
            if key == "target_index":
                named["target"] = target_ids[value]
            elif key in ("follow", "dwell"):
                named[key] = None if value is None else target_ids[value]
            elif key in PLANNED_ACTIONS and value is not None:
                named[key] = (
                    target_ids[value]
                    if value < n
                    else "dwell"
                    if value == n
                    else f"dwell {value - n}"
                )
            else:
                named[key] = value
        out.append(named)
    return out


@dataclass
class EpisodeRecord:
    """The outcome of one simulated mission.

    Attributes:
        planner: planner name.
        seed: the seed that drove truth and noise.
        target_ids: target names, ``(n,)``.
        time_step: ``tau``, s.
        sensor_diameter: ``w``, m.
        agent_path: ``(K+1, 2)`` agent positions at steps ``0..K``, m.
        true_states: ``(K+1, n, 4)`` true target states.
        belief_steps: ``(M,)`` the steps at which beliefs were stored (a stride, last step kept).
        belief_means: ``(M, n, 4)``.
        belief_covariances: ``(M, n, 4, 4)``.
        detections: ``(K+1, n)`` which targets were measured at each step.
        per_target_logdet: ``(n,)`` final ``log det Sigma^xy`` per target.
        info: planner-specific metadata (JSON-serialisable), e.g. its sub-task log.
    """

    planner: str
    seed: int
    target_ids: tuple[str, ...]
    time_step: float
    sensor_diameter: float
    agent_path: np.ndarray
    true_states: np.ndarray
    belief_steps: np.ndarray
    belief_means: np.ndarray
    belief_covariances: np.ndarray
    detections: np.ndarray
    per_target_logdet: np.ndarray
    info: dict = field(default_factory=dict)

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
                agent_path=self.agent_path,
                true_states=self.true_states,
                belief_steps=self.belief_steps,
                belief_means=self.belief_means,
                belief_covariances=self.belief_covariances,
                detections=self.detections,
                per_target_logdet=self.per_target_logdet,
            )

    @classmethod
    def load(cls, path: str | Path) -> EpisodeRecord:
        """Read a record written by `save`."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in data.files if k != "meta"}
        return cls(
            planner=meta["planner"],
            seed=meta["seed"],
            target_ids=tuple(meta["target_ids"]),
            time_step=meta["time_step"],
            sensor_diameter=meta["sensor_diameter"],
            info=meta["info"],
            **arrays,
        )
