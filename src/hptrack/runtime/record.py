"""What a mission leaves for the mission figure: the agent and the beliefs at each processed
tick and at the end, the detections per tick, rebuilt as an
`EpisodeRecord` (the simulator's record)."""

from __future__ import annotations

import numpy as np

from hptrack.interface import MissionSpec
from hptrack.models.beliefs import position_logdet
from hptrack.runtime.clock import step_of
from hptrack.sim.record import EpisodeRecord


class MissionHistory:
    """The rows of a mission, one per processed tick, and its end.

    Args:
        mission: the mission's facts.
        start: the agent's start ``(2,)`` m (its position until the first odometry); a
            team's ``(m, 2)``, each row one UAV's.
    """

    def __init__(self, mission: MissionSpec, start: np.ndarray) -> None:
        self.mission = mission
        self.start = np.asarray(start, dtype=float)
        self.rows: list[dict] = []
        """Per processed tick: ``k``, ``agent`` (or ``None``), ``means``, ``covariances``,
        ``detected``."""
        self.final: dict | None = None
        """At the end: ``time``, ``means``, ``covariances``, ``agent``, ``detected``."""

    def tick(
        self,
        k: int,
        agent: np.ndarray | None,
        means: np.ndarray,
        covariances: np.ndarray,
        detected: np.ndarray,
    ) -> None:
        """Tick ``k``: the agent (``None`` before odometry), the beliefs at ``k tau``, the
        targets measured since the last tick."""
        self.rows.append(
            {
                "k": k,
                "agent": agent,
                "means": means,
                "covariances": covariances,
                "detected": detected,
            }
        )

    def end(
        self,
        time_s: float,
        agent: np.ndarray | None,
        means: np.ndarray,
        covariances: np.ndarray,
        detected: np.ndarray,
    ) -> None:
        """The mission ended at ``time_s`` s with these beliefs and measurements."""
        self.final = {
            "time": time_s,
            "means": means,
            "covariances": covariances,
            "agent": agent,
            "detected": detected,
        }

    def episode_record(
        self, planner: str, seed: int, info: dict, truth: np.ndarray | None = None
    ) -> EpisodeRecord:
        """The mission as an episode record: the agent at each tick (held between processed
        ticks), the beliefs at each processed tick and at the end, the detections per tick;
        ``truth`` ``(K+1, n, 4)`` if known, else NaN."""
        if self.final is None:
            raise RuntimeError("episode_record() needs a finished mission")
        tau, n = self.mission.time_step, self.mission.n_targets
        last = step_of(self.final["time"], tau)
        agent_path = np.empty((last + 1, *self.start.shape))
        detections = np.zeros((last + 1, n), dtype=bool)
        position = self.start
        rows = {row["k"]: row for row in self.rows if row["k"] <= last}
        final = {"agent": self.final["agent"], "detected": self.final["detected"]}
        for k in range(last + 1):
            for row in (rows.get(k), final if k == last else None):
                if row is not None:
                    if row["agent"] is not None:
                        position = row["agent"]
                    detections[k] |= row["detected"]
            agent_path[k] = position
        stored = [row for row in rows.values() if row["k"] < last]
        steps = [row["k"] for row in stored] + [last]
        means = np.array([row["means"] for row in stored] + [self.final["means"]])
        covs = np.array([row["covariances"] for row in stored] + [self.final["covariances"]])
        if truth is None:
            truth = np.full((last + 1, n, 4), np.nan)
        return EpisodeRecord(
            planner=planner,
            seed=seed,
            target_ids=self.mission.target_ids,
            time_step=tau,
            sensor_diameter=self.mission.sensor_diameter,
            agent_paths=agent_path,
            true_states=np.asarray(truth)[: last + 1],
            belief_steps=np.asarray(steps),
            belief_means=means,
            belief_covariances=covs,
            detections=detections,
            per_target_logdet=position_logdet(self.final["covariances"]),
            info=info,
            fence=self.mission.fence,
        )
