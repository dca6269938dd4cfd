"""Episode record: everything a mission produced, saved to one compressed ``.npz`` file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hptrack.jsonout import json_text
from hptrack.models.beliefs import position_logdet
from hptrack.models.tracking import lost_tracks
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
        associations: ``(m, 6)`` detections without identity: which report went to which
            belief (`hptrack.sim.step.World.associations`); ``None`` with identity.
        claims: ``(c, 3)`` the confirmed tentative tracks' claims
            (`hptrack.sim.step.World.claims`); ``None`` with identity.
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
    associations: np.ndarray | None = None
    claims: np.ndarray | None = None

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
        } | self.tracking_summary()

    def tracking_summary(self) -> dict:
        """Detections without identity: the reports, false alarms (and those a belief took),
        wrong associations (`wrong_associations`), claims and tracks lost (`tracks_lost`);
        empty with identity."""
        if self.associations is None or self.claims is None:
            return {}
        return {
            "tracking": {
                "reports": len(self.associations),
                "false_alarms": int(np.sum(self.associations[:, 3] < 0)),
                "false_alarms_taken": int(
                    np.sum((self.associations[:, 3] < 0) & (self.associations[:, 4] >= 0))
                ),
                "wrong_associations": self.wrong_associations(),
                "claims": len(self.claims),
                "tracks_lost": int(np.sum(self.tracks_lost())),
            }
        }

    def wrong_associations(self) -> int:
        """Reports that went to a belief not of their source (false alarms included) and
        claims of a belief by another target's (or a false alarm's) track; 0 with identity."""
        if self.associations is None or self.claims is None:
            return 0
        rows, claims = self.associations, self.claims
        wrong = (rows[:, 4] >= 0) & (rows[:, 3] != rows[:, 4])
        return int(np.sum(wrong) + np.sum(claims[:, 1] != claims[:, 2]))

    def swapped(self) -> np.ndarray:
        """``(n,)`` the beliefs whose last report or claim came from another source (a
        target's track swapped, or a false alarm's); none with identity."""
        out = np.zeros(len(self.target_ids), dtype=bool)
        if self.associations is None or self.claims is None:
            return out
        rows = self.associations[self.associations[:, 4] >= 0]
        events = np.concatenate([rows[:, [0, 4, 3]], self.claims])
        for _, belief, source in events[np.argsort(events[:, 0], kind="stable")]:
            out[int(belief)] = source != belief
        return out

    def tracks_lost(self) -> np.ndarray:
        """``(n,)`` the targets lost at the end: outside their belief's 99 % ellipse
        (`hptrack.models.tracking.lost_tracks`) or their belief swapped (`swapped`)."""
        lost = lost_tracks(self.true_states[-1], self.belief_means[-1], self.belief_covariances[-1])
        return lost | self.swapped()

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
                **self._tracking_arrays(),
            )

    def _tracking_arrays(self) -> dict:
        if self.associations is None or self.claims is None:
            return {}
        return {"associations": self.associations, "claims": self.claims}

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
