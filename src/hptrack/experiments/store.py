"""SQLite store of finished episodes: written as each one finishes, so a crash or Ctrl-C loses
nothing already done, and a re-run resumes by skipping the keys already stored.

An episode's identity is its planner, number of targets, scenario seed, scenario setting and the
planner's full canonical settings (`hptrack.settings.PlannerSettings.canonical`: every
option, stored as JSON beside its hash), so a run with another value of any option never reuses
another's rows.
Before running an episode a run *claims* it (a row in ``claims`` with its process id and host);
two runs on one database therefore share the work instead of both computing everything. Claims
of a process that no longer runs (on this host) or older than `STALE_CLAIM_S` are released.

A database of an older layout is migrated when it is opened (`MIGRATIONS`, one step per
version). A change of what identifies a result (a new planner option, say) is such a step: it
bumps `SCHEMA_VERSION` and rewrites the stored identities to what the code now builds for
the same runs (the new option's value that the old rows were run with), so that stored and
published results keep their identity without the settings carrying their history.

Claims dated more than `FUTURE_CLAIM_S` ahead, and those of a live process on this host that is
not a run of this database (another program under a reused id), are released too. A failure of
the database itself (a full disk, a read-only file, a lock another process holds for longer
than `LOCK_WAIT_S`, a trigger that refuses a write, a value of the wrong type) is an
`InputError` of one line naming the file: the episodes stored before it are kept, and the next
run resumes from them.
"""

from __future__ import annotations

import json
import math
import os
import socket
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from hptrack.experiments.workers import process_alive, runs_with_file_open
from hptrack.interface import InputError
from hptrack.jsonout import json_text
from hptrack.settings import digest_of
from hptrack.sim.record import EpisodeRow

SCHEMA_VERSION = 10
SCHEMA = """
CREATE TABLE IF NOT EXISTS episodes (
    planner TEXT NOT NULL,
    n_targets INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    setting TEXT NOT NULL,
    planner_settings_hash TEXT NOT NULL,
    planner_settings TEXT NOT NULL,
    uncertainty REAL NOT NULL,
    never_observed REAL NOT NULL,
    detections INTEGER NOT NULL,
    wall_time_s REAL NOT NULL,
    info TEXT NOT NULL,
    gospa_mean REAL,
    gospa_end REAL,
    track_loss INTEGER,
    PRIMARY KEY (planner, n_targets, seed, setting, planner_settings_hash)
);
CREATE TABLE IF NOT EXISTS claims (
    planner TEXT NOT NULL,
    n_targets INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    setting TEXT NOT NULL,
    planner_settings_hash TEXT NOT NULL,
    host TEXT NOT NULL,
    pid INTEGER NOT NULL,
    claimed_at REAL NOT NULL,
    PRIMARY KEY (planner, n_targets, seed, setting, planner_settings_hash)
);
"""
STALE_CLAIM_S = 6 * 3600.0
"""A claim older than this is released whatever its owner (a run on another host that died)."""
FUTURE_CLAIM_S = 300.0
"""A claim dated more than this ahead of this host's clock is released (no run made it)."""
LOCK_WAIT_S = 30.0
"""How long a read or write waits for a lock that another process holds on the database, s."""


_LEFT_OUT_BY_LAYOUT_2 = {
    "mcts": {
        "backup": "sampled",
        "max_weight": 1.0,
        "root_split": "even",
        "common_rollouts": False,
        "rollout": "uniform",
        "rollout_epsilon": 0.1,
        "estimator": "paper",
        "dwell": 0.0,
        "threads": 1,
    }
}
"""The mcts options that layout 2 left out of an identity when they had these values (the
paper's search on one tree; ``rollout_epsilon`` also whenever the rollout took none)."""


def _with_options(options: dict[str, dict], planner: str, text: str) -> str:
    """The identity ``text`` of ``planner`` with ``options[planner]`` where it has none."""
    values = {**options.get(planner, {}), **json.loads(text)}
    return json.dumps(values, sort_keys=True, separators=(",", ":"))


def _full_identity(planner: str, text: str) -> str:
    """Layout 2 -> 3: the identity with every option (`_LEFT_OUT_BY_LAYOUT_2`)."""
    return _with_options(_LEFT_OUT_BY_LAYOUT_2, planner, text)


def _migrate_2_to_3(db: sqlite3.Connection) -> None:
    """Full identities; the planner's settings columns say so (``planner_settings``)."""
    db.create_function("full_identity", 2, _full_identity, deterministic=True)
    db.create_function("digest_of", 1, digest_of, deterministic=True)
    db.execute("ALTER TABLE episodes RENAME TO episodes_layout_2")
    db.execute("DROP TABLE claims")  # claims of runs of the old layout: nothing to keep
    for statement in SCHEMA.split(";"):
        db.execute(statement)
    db.execute(
        f"INSERT INTO episodes ({', '.join(_LAYOUT_3_COLUMNS)}) SELECT planner, n_targets, "
        "seed, setting, digest_of(full_identity(planner, settings)), "
        "full_identity(planner, settings), uncertainty, never_observed, detections, "
        "wall_time_s, info FROM episodes_layout_2"
    )
    db.execute("DROP TABLE episodes_layout_2")


_LAYOUT_3_COLUMNS = (
    "planner",
    "n_targets",
    "seed",
    "setting",
    "planner_settings_hash",
    "planner_settings",
    "uncertainty",
    "never_observed",
    "detections",
    "wall_time_s",
    "info",
)
"""The columns of the episodes of layouts 3 to 6 (the step from layout 2 fills these)."""
METRIC_COLUMNS = (("gospa_mean", "REAL"), ("gospa_end", "REAL"), ("track_loss", "INTEGER"))
"""The tracking metrics layout 7 added (`hptrack.sim.record.EpisodeRow`); NULL in rows
stored before."""


def _add_metrics(db: sqlite3.Connection) -> None:
    """Layout 6 -> 7: the tracking metrics' columns, NULL in every stored row (their episodes
    did not keep what the metrics need)."""
    have = {c[1] for c in db.execute("PRAGMA table_info(episodes)")}
    for name, kind in METRIC_COLUMNS:
        if name not in have:  # the step from layout 2 builds the table of this layout
            db.execute(f"ALTER TABLE episodes ADD COLUMN {name} {kind}")


def _adding(added: dict[str, dict]) -> Callable[[sqlite3.Connection], None]:
    """A migration step that adds the options ``added[planner]`` to every identity of that
    planner, with the values every earlier run had."""

    def step(db: sqlite3.Connection) -> None:
        db.create_function(
            "with_added",
            2,
            lambda planner, text: _with_options(added, planner, text),
            deterministic=True,
        )
        db.create_function("digest_of", 1, digest_of, deterministic=True)
        db.execute("DELETE FROM claims")  # claims name the old hashes; their runs re-claim
        db.execute(
            "UPDATE OR IGNORE episodes SET "
            "planner_settings = with_added(planner, planner_settings), "
            "planner_settings_hash = digest_of(with_added(planner, planner_settings))"
        )

    return step


MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {
    2: _migrate_2_to_3,
    3: _adding({"mcts": {"miss": "drop"}}),  # the sub-task MDP's miss rule
    4: _adding({"mcts": {"passes": "ignore"}}),  # ... and its credit of passes
    5: _adding({"mcts": {"readmit": False, "commit": 0.0}}),  # re-admission, commitment
    6: _add_metrics,
    7: _adding({name: {"fortify": False} for name in ("mcts", "team-mcts", "team-cbba")}),
    8: _adding({name: {"false_finds": "ignore"} for name in ("mcts", "team-mcts", "team-cbba")}),
    9: _adding({name: {"coverage_limit": 0.0} for name in ("mcts", "team-mcts", "team-cbba")}),
}
"""Layout version -> the step that makes a database of that layout one of the next."""


@dataclass(frozen=True)
class EpisodeKey:
    """What identifies one benchmark episode.

    Attributes:
        planner: registered planner name.
        n_targets: number of targets.
        seed: scenario seed.
        setting: the scenarios' setting, ``"homogeneous"`` or ``"heterogeneous"`` (with
            ``"+paper_text"`` for the printed form of ``Q``).
        planner_settings: the planner's canonical settings JSON (every option).
    """

    planner: str
    n_targets: int
    seed: int
    setting: str
    planner_settings: str

    @property
    def planner_settings_hash(self) -> str:
        """A short hash of `planner_settings` (the same as the settings' ``digest()``)."""
        return digest_of(self.planner_settings)

    def _id(self) -> tuple:
        return (self.planner, self.n_targets, self.seed, self.setting, self.planner_settings_hash)


def check_columns(db: sqlite3.Connection, source: str) -> None:
    """Refuse a database whose tables lack columns of `SCHEMA` (a file edited by hand or
    written by another program): one line naming the table and the missing columns.

    Raises:
        InputError: a table of `SCHEMA` misses columns.
    """
    expected = sqlite3.connect(":memory:")
    expected.executescript(SCHEMA)
    for (table,) in expected.execute("SELECT name FROM sqlite_master WHERE type='table'"):
        want = expected.execute(f"PRAGMA table_info({table})").fetchall()
        have = db.execute(f"PRAGMA table_info({table})").fetchall()
        missing = [c[1] for c in want if c[1] not in {h[1] for h in have}]
        key = [c[1] for c in sorted(want, key=lambda c: c[5]) if c[5]]
        problem = (
            f"has no column {', '.join(missing)}"
            if missing
            else None
            if [c[1] for c in sorted(have, key=lambda c: c[5]) if c[5]] == key
            else f"has no primary key ({', '.join(key)})"
        )
        if problem:
            expected.close()
            db.close()
            raise InputError(
                f"{source}: table {table} {problem}; not a results database of this hptrack "
                "(use a new file)"
            )
    expected.close()


class ResultStore:
    """Episodes in an SQLite file (one row per `EpisodeKey`, inserted once).

    Raises:
        InputError: the file is not an hptrack results database, or one of a layout that
            cannot be migrated (`MIGRATIONS`).
    """

    def __init__(self, path: str | Path) -> None:
        path = Path(path)
        self.path = path
        if path.exists() and path.is_dir():
            raise InputError(f"--db {path}: is a folder, not a results database")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), timeout=LOCK_WAIT_S)
            with self._guard():
                version = self._db.execute("PRAGMA user_version").fetchone()[0]
                tables = {
                    r[0]
                    for r in self._db.execute("SELECT name FROM sqlite_master WHERE type='table'")
                }
        except InputError:
            self._db.close()
            raise
        except (sqlite3.DatabaseError, OSError) as err:
            raise InputError(f"--db {path}: not an hptrack results database ({err})") from None
        known = version == SCHEMA_VERSION or version in MIGRATIONS
        if tables and (not known or "episodes" not in tables):
            self._db.close()
            raise InputError(
                f"--db {path}: a database of another layout (version {version}, "
                f"tables {sorted(tables)}); use a new --db file"
            )
        with self._guard():
            if tables and version != SCHEMA_VERSION:
                self._migrate()
            if not {"episodes", "claims"} <= tables:
                self._db.executescript(SCHEMA)
            check_columns(self._db, f"--db {path}")
            if version != SCHEMA_VERSION:
                self._db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            self._db.commit()
        self._host = socket.gethostname()
        self._pid = os.getpid()

    @contextmanager
    def _guard(self) -> Iterator[None]:
        """Turn a failure of the database file (not of hptrack's SQL) into one line."""
        try:
            yield
        except sqlite3.ProgrammingError:
            raise
        except sqlite3.DatabaseError as err:
            self._db.rollback()
            raise InputError(database_failure(self.path, err)) from None

    def _migrate(self) -> None:
        """Bring the database to `SCHEMA_VERSION` in one transaction (a run that opens it
        meanwhile waits, then finds it migrated)."""
        self._db.execute("BEGIN IMMEDIATE")
        try:
            version = self._db.execute("PRAGMA user_version").fetchone()[0]
            for step in range(version, SCHEMA_VERSION):
                MIGRATIONS[step](self._db)
            self._db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        except BaseException:
            self._db.rollback()
            raise
        self._db.commit()

    def add(self, row: EpisodeRow) -> None:
        """Insert a finished episode, release its claim and commit at once (a duplicate key is
        ignored)."""
        with self._guard():
            self._add(row)

    def _add(self, row: EpisodeRow) -> None:
        key = row.key
        self._db.execute(
            "INSERT OR IGNORE INTO episodes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                *key._id(),
                key.planner_settings,
                row.uncertainty,
                row.never_observed,
                row.detections,
                row.wall_time_s,
                json_text(row.info),
                row.gospa_mean,
                row.gospa_end,
                row.track_loss,
            ),
        )
        self._db.execute(
            "DELETE FROM claims WHERE planner=? AND n_targets=? AND seed=? AND "
            "setting=? AND planner_settings_hash=?",
            key._id(),
        )
        self._db.commit()

    def done(self) -> set[EpisodeKey]:
        """Keys of every stored episode."""
        with self._guard():
            cur = self._db.execute(
                "SELECT planner, n_targets, seed, setting, planner_settings FROM episodes"
            )
            return {EpisodeKey(*r) for r in cur}

    def _claim_is_stale(self, host: str, pid: int, claimed_at: float, now: float) -> bool:
        if not -FUTURE_CLAIM_S <= now - claimed_at <= STALE_CLAIM_S:
            return True
        if host != self._host or pid == self._pid:
            return False
        return not process_alive(pid) or runs_with_file_open(pid, self.path) is False

    def release_stale_claims(self) -> int:
        """Release claims that are too old or from the future, and those of this host whose
        process is gone or is not a run of this database; returns how many were released."""
        now = time.time()
        with self._guard():
            rows = self._db.execute("SELECT rowid, host, pid, claimed_at FROM claims").fetchall()
            stale = [r[0] for r in rows if self._claim_is_stale(r[1], r[2], r[3], now)]
            if stale:
                self._db.executemany("DELETE FROM claims WHERE rowid=?", [(r,) for r in stale])
                self._db.commit()
        return len(stale)

    def claim(self, key: EpisodeKey) -> bool:
        """Claim ``key`` for this process; ``False`` if it is done or another run holds it.

        The claim is written first and the episode looked up after it, in one transaction: the
        write holds the database's lock, so no other run can store the episode (and drop its
        own claim) between the look-up and the claim."""
        with self._guard(), self._db:
            cur = self._db.execute(
                "INSERT OR IGNORE INTO claims VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (*key._id(), self._host, self._pid, time.time()),
            )
            if cur.rowcount != 1:
                return False
            if self._db.execute(
                "SELECT 1 FROM episodes WHERE planner=? AND n_targets=? AND "
                "seed=? AND setting=? AND planner_settings_hash=?",
                key._id(),
            ).fetchone():
                self._db.rollback()
                return False
            return True

    def release_all(self) -> None:
        """Give up every claim of this process (episodes that were not run after all)."""
        with self._guard():
            self._db.execute("DELETE FROM claims WHERE host=? AND pid=?", (self._host, self._pid))
            self._db.commit()

    def rows(self) -> list[EpisodeRow]:
        """Every stored episode, in key order.

        Raises:
            InputError: a stored value has the wrong type (a file edited by hand).
        """
        with self._guard():
            cur = self._db.execute(
                "SELECT planner, n_targets, seed, setting, planner_settings, uncertainty, "
                "never_observed, detections, wall_time_s, info, gospa_mean, gospa_end, "
                "track_loss FROM episodes ORDER BY planner, n_targets, seed"
            )
            return [self._row(r) for r in cur]

    def _row(self, r: tuple) -> EpisodeRow:
        """A stored row, checked: numbers where numbers belong, a JSON object as ``info``."""
        where = f"--db {self.path}: episode {r[0]} n={r[1]} seed={r[2]}"
        for name, value, kind in (
            ("n_targets", r[1], int),
            ("seed", r[2], int),
            ("uncertainty", r[5], float),
            ("never_observed", r[6], float),
            ("detections", r[7], int),
            ("wall_time_s", r[8], float),
            *(
                (name, value, int if kind == "INTEGER" else float)
                for (name, kind), value in zip(METRIC_COLUMNS, r[10:], strict=True)
                if value is not None
            ),
        ):
            if not isinstance(value, (int, float) if kind is float else int) or (
                kind is float and not math.isfinite(value)
            ):
                raise InputError(f"{where}: {name} is {value!r}, not a finite number")
        try:
            info = json.loads(r[9])
        except (TypeError, ValueError):
            info = None
        if not isinstance(info, dict):
            raise InputError(f"{where}: info is {str(r[9])[:60]!r}, not a JSON object")
        gospa_mean, gospa_end, track_loss = r[10:]
        return EpisodeRow(
            EpisodeKey(*r[:5]),
            float(r[5]),
            float(r[6]),
            r[7],
            float(r[8]),
            info,
            None if gospa_mean is None else float(gospa_mean),
            None if gospa_end is None else float(gospa_end),
            track_loss,
        )

    def close(self) -> None:
        self._db.close()


def database_failure(path: Path, err: sqlite3.DatabaseError) -> str:
    """One line for a failure of the database file ``path``: what it means for the run."""
    text = str(err)
    kept = "the episodes stored before are kept and the next run resumes from them"
    if "full" in text:
        return f"--db {path}: the disk is full ({text}); free some space: {kept}"
    if "readonly" in text or "read-only" in text:
        return f"--db {path}: cannot be written ({text}); {kept}"
    if "locked" in text or "busy" in text:
        return (
            f"--db {path}: locked by another process for more than {LOCK_WAIT_S:g} s "
            f"({text}); gave up: run again when that process is done"
        )
    if isinstance(err, sqlite3.IntegrityError):
        return f"--db {path}: the database refused a write ({text}); {kept}"
    return f"--db {path}: not an hptrack results database, or a damaged one ({text})"
