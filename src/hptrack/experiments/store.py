"""SQLite store of finished episodes: written as each one finishes, so a crash or Ctrl-C loses
nothing already done, and a re-run resumes by skipping the keys already stored."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import asdict, dataclass
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS episodes (
    planner TEXT NOT NULL,
    n_targets INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    setting TEXT NOT NULL,
    effort TEXT NOT NULL,
    uncertainty REAL NOT NULL,
    never_observed REAL NOT NULL,
    detections INTEGER NOT NULL,
    wall_time_s REAL NOT NULL,
    info TEXT NOT NULL,
    PRIMARY KEY (planner, n_targets, seed, setting, effort)
)
"""


@dataclass(frozen=True)
class EpisodeKey:
    """What identifies one benchmark episode."""

    planner: str
    n_targets: int
    seed: int
    setting: str  # "homogeneous" or "heterogeneous"
    effort: str  # planning effort, e.g. "iterations=2000" or "time_limit=1.0"


@dataclass(frozen=True)
class EpisodeRow:
    """One finished episode: its key, ``U``, the never-observed ``U`` of the same scenario,
    the number of detection steps, the wall time (s) and planner metadata."""

    key: EpisodeKey
    uncertainty: float
    never_observed: float
    detections: int
    wall_time_s: float
    info: dict


class ResultStore:
    """Episodes in an SQLite file (one row per :class:`EpisodeKey`, inserted once)."""

    def __init__(self, path: str | Path) -> None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(str(path))
        self._db.execute(SCHEMA)
        self._db.commit()

    def add(self, row: EpisodeRow) -> None:
        """Insert a finished episode and commit at once (a duplicate key is ignored)."""
        key = asdict(row.key)
        self._db.execute(
            "INSERT OR IGNORE INTO episodes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (key["planner"], key["n_targets"], key["seed"], key["setting"], key["effort"],
             row.uncertainty, row.never_observed, row.detections, row.wall_time_s,
             json.dumps(row.info)))
        self._db.commit()

    def done(self) -> set[EpisodeKey]:
        """Keys of every stored episode."""
        cur = self._db.execute(
            "SELECT planner, n_targets, seed, setting, effort FROM episodes")
        return {EpisodeKey(*r) for r in cur}

    def rows(self) -> list[EpisodeRow]:
        """Every stored episode, in key order."""
        cur = self._db.execute("SELECT * FROM episodes ORDER BY planner, n_targets, seed")
        return [EpisodeRow(EpisodeKey(*r[:5]), r[5], r[6], r[7], r[8], json.loads(r[9]))
                for r in cur]

    def close(self) -> None:
        self._db.close()
