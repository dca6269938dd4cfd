"""Episode record: everything a mission produced, saved to one compressed ``.npz`` file."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hptrack.jsonout import json_text
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import FenceSpec
from hptrack.models.state import POSITION, positions
from hptrack.sim.metrics import gospa_cutoff, gospa_history, never_detected, track_lost
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
        mean_positions: ``(K+1, n, 2)`` the belief means' positions at every step, m (what
            the metrics need, whatever the belief stride; ``None`` in a record of an older
            hptrack or of a flight log, whose metrics then use the stored belief steps).
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
    fence: FenceSpec | None = None
    mean_positions: np.ndarray | None = None
    associations: np.ndarray | None = None
    claims: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.agent_paths.ndim == 2:
            self.agent_paths = self.agent_paths[:, None, :]
        if self.mean_positions is None and len(self.belief_steps) == len(self.agent_paths):
            self.mean_positions = positions(self.belief_means)

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

    def gospa_history(self) -> tuple[np.ndarray, np.ndarray]:
        """``(steps, GOSPA)``: GOSPA (`hptrack.sim.metrics`, ``c = w / 2``) between the belief
        means and the true positions at every step (at the stored belief steps in a record
        without `mean_positions`), m; ``GOSPA`` is NaN where the record has no truth."""
        if self.mean_positions is None:
            steps, means = self.belief_steps, positions(self.belief_means)
        else:
            steps, means = np.arange(len(self.mean_positions)), self.mean_positions
        truths = positions(self.true_states)[steps]
        known = np.isfinite(truths).all(axis=(1, 2))
        values = np.full(len(steps), np.nan)
        values[known] = gospa_history(
            means[known], truths[known], gospa_cutoff(self.sensor_diameter)
        )
        return np.asarray(steps), values

    def tracks_lost(self) -> np.ndarray | None:
        """``(n,)`` which targets' tracks are lost at the end (`hptrack.sim.metrics.track_lost`:
        truth outside the belief's 99 % ellipse, or a swapped track; without identity also a
        belief whose last report came from another source, `swapped`); ``None`` without the
        truth."""
        truth = positions(self.true_states[-1])
        if not np.isfinite(truth).all():
            return None
        lost = track_lost(
            positions(self.belief_means[-1]),
            self.belief_covariances[-1][:, POSITION, POSITION],
            truth,
            gospa_cutoff(self.sensor_diameter),
        )
        return lost | self.swapped()

    def metrics(self) -> dict:
        """The tracking metrics beside ``U`` (`hptrack.sim.metrics`): ``gospa_mean`` (over
        `gospa_history`'s steps) and ``gospa_end`` (at the last step), m, ``track_loss`` (the
        targets whose tracks are lost at the end), ``tracks_lost`` (their ids) and
        ``targets_never_detected``; the truth's metrics are ``None`` in a record without it."""
        _, history = self.gospa_history()
        lost = self.tracks_lost()
        known = bool(np.isfinite(history).all())
        return {
            "gospa_mean": float(history.mean()) if known else None,
            "gospa_end": float(history[-1]) if known else None,
            "track_loss": None if lost is None else int(lost.sum()),
            "tracks_lost": None
            if lost is None
            else [t for t, gone in zip(self.target_ids, lost, strict=True) if gone],
            "targets_never_detected": never_detected(self.detections),
        }

    def summary(self) -> dict:
        """JSON-ready summary: ``U``, the tracking metrics (`metrics`), per-target log det and
        detections, planner, seed, and the planner's metadata with its sub-tasks naming targets
        by id (`subtasks_with_ids`)."""
        info = dict(self.info)
        if info.get("subtasks"):
            info["subtasks"] = subtasks_with_ids(info["subtasks"], self.target_ids)
        return {
            "U": self.uncertainty,
            **self.metrics(),
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
        lost = self.tracks_lost()
        return {
            "tracking": {
                "reports": len(self.associations),
                "false_alarms": int(np.sum(self.associations[:, 3] < 0)),
                "false_alarms_taken": int(
                    np.sum((self.associations[:, 3] < 0) & (self.associations[:, 4] >= 0))
                ),
                "wrong_associations": self.wrong_associations(),
                "claims": len(self.claims),
                "tracks_lost": None if lost is None else int(np.sum(lost)),
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
        arrays: dict[str, Any] = {
            "agent_paths": self.agent_paths,
            "true_states": self.true_states,
            "belief_steps": self.belief_steps,
            "belief_means": self.belief_means,
            "belief_covariances": self.belief_covariances,
            "detections": self.detections,
            "per_target_logdet": self.per_target_logdet,
        }
        if self.mean_positions is not None:
            arrays["mean_positions"] = self.mean_positions
        arrays |= self._tracking_arrays()
        with open(path, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json_text(meta)), **arrays)

    def _tracking_arrays(self) -> dict:
        if self.associations is None or self.claims is None:
            return {}
        return {"associations": self.associations, "claims": self.claims}

    @classmethod
    def load(cls, path: str | Path) -> EpisodeRecord:
        """Read a record written by `save` (also by an older hptrack, whose file holds one
        vehicle's ``agent_path`` and no ``mean_positions``)."""
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
    the same scenario, the number of detection steps, the wall time (s), planner
    metadata and the tracking metrics (`EpisodeRecord.metrics`; ``None`` in a row stored
    before hptrack kept them). Its ``info`` holds ``targets_never_detected``."""

    key: EpisodeKey
    uncertainty: float
    never_observed: float
    detections: int
    wall_time_s: float
    info: dict
    gospa_mean: float | None = None
    gospa_end: float | None = None
    track_loss: int | None = None

    def metric(self, name: str) -> float | None:
        """The value of a metric of `METRICS` (a count is an int; ``None``: the row does not
        hold it)."""
        if name == "U":
            return self.uncertainty
        if name == "never_detected":
            return self.info.get("targets_never_detected")
        return getattr(self, name)


METRICS = {
    "U": "U (sum of the final log det of the position covariances)",
    "gospa_mean": "GOSPA over the mission's steps, mean, m",
    "gospa_end": "GOSPA at the budget's end, m",
    "track_loss": "targets whose tracks are lost at the end",
    "never_detected": "targets never detected",
}
"""The metrics an `EpisodeRow` holds, each with what a report calls it (all lower is
better)."""
