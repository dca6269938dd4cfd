"""A results database that fails (a full disk, a read-only file, a lock held elsewhere, a trigger,
values of the wrong type, no primary key) is one line naming the file, exit 2 in the CLI, and
keeps what was stored; claims that no run of the database holds are never waited on."""

from __future__ import annotations

import socket
import sqlite3
import subprocess
import sys
import time

import pytest

from hptrack.experiments import benchmark as benchmark_module
from hptrack.experiments import store as store_module
from hptrack.experiments.benchmark import BenchmarkConfig, run_benchmark
from hptrack.experiments.store import SCHEMA, SCHEMA_VERSION, ResultStore
from hptrack.interface import InputError
from hptrack.registry import planner_settings

CONFIG = BenchmarkConfig(
    planners=("stationary",),
    settings={"stationary": planner_settings("stationary")},
    target_counts=(2,),
    scenarios=8,
)
BENCHMARK = ["benchmark", "--targets", "2", "--scenarios", "3", "--planners", "stationary"]
STORED = BenchmarkConfig(  # what BENCHMARK runs
    planners=("stationary",),
    settings={"stationary": planner_settings("stationary")},
    target_counts=(2,),
    scenarios=3,
    homogeneous=False,
)


def _stored(path):
    """A database with every episode of BENCHMARK."""
    store = ResultStore(path)
    run_benchmark(STORED, store)
    store.close()
    return path


def _unique_rows(path) -> int:
    rows = ResultStore(path).rows()
    assert len(rows) == len({r.key for r in rows})
    return len(rows)


def _limit_pages(monkeypatch, extra: int = 0) -> None:
    """Every results database opened from now on can grow by ``extra`` pages only: SQLite's
    own "database or disk is full" at the first write that needs more."""
    real = sqlite3.connect

    def connect(path, **kw):
        db = real(path, **kw)
        if path != ":memory:":
            pages = db.execute("PRAGMA page_count").fetchone()[0]
            db.execute(f"PRAGMA max_page_count = {max(1, pages + extra)}")
        return db

    monkeypatch.setattr(sqlite3, "connect", connect)


def test_a_disk_that_fills_mid_run_keeps_the_rows_and_the_next_run_resumes(tmp_path, monkeypatch):
    path = tmp_path / "b.db"
    with sqlite3.connect(path) as raw:
        raw.execute("PRAGMA page_size = 512")  # a row or two per page
        raw.executescript(SCHEMA)
        raw.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    with monkeypatch.context() as patch:
        _limit_pages(patch, extra=1)
        store = ResultStore(path)
        with pytest.raises(InputError, match=f"--db {path}: the disk is full") as err:
            run_benchmark(CONFIG, store)
        store.close()
    assert "database or disk is full" in str(err.value) and "\n" not in str(err.value)
    kept = _unique_rows(path)
    assert 0 < kept < len(CONFIG.keys())  # the page held some, then the disk was full
    store = ResultStore(path)
    assert run_benchmark(CONFIG, store) == len(CONFIG.keys()) - kept  # the rest, once
    assert _unique_rows(path) == len(CONFIG.keys())


def test_a_full_disk_is_one_line_in_the_cli(cli, tmp_path, monkeypatch):
    db = tmp_path / "new.db"
    _limit_pages(monkeypatch)  # a new file: not even its tables fit
    cli(*BENCHMARK, "--db", db, "--out", tmp_path / "o").refused(str(db), "disk is full")


def _read_only(monkeypatch) -> None:
    real = sqlite3.connect
    monkeypatch.setattr(
        sqlite3,
        "connect",
        lambda path, **kw: (
            real(path, **kw) if path == ":memory:" else real(f"file:{path}?mode=ro", uri=True, **kw)
        ),
    )


def test_a_read_only_database_serves_a_finished_run_and_refuses_more(cli, tmp_path, monkeypatch):
    db = _stored(tmp_path / "b.db")
    _read_only(monkeypatch)
    result = cli(*BENCHMARK, "--db", db, "--out", tmp_path / "again")
    assert result.code == 0, result.err  # all stored: nothing to write
    assert "0 episodes run now, 3 of 3" in result.out
    more = [*BENCHMARK[:4], "4", *BENCHMARK[5:]]
    cli(*more, "--db", db, "--out", tmp_path / "o").refused(str(db), "cannot be written")


def _finished(tmp_path, sql: str) -> object:
    db = _stored(tmp_path / "b.db")
    with sqlite3.connect(db) as raw:
        raw.execute(sql)
    return db


@pytest.mark.parametrize(
    ("sql", "needle"),
    [
        ("UPDATE episodes SET info = '{not json' WHERE seed = 1", "seed=1: info is '{not json'"),
        ("UPDATE episodes SET info = '[1, 2]' WHERE seed = 1", "not a JSON object"),
        ("UPDATE episodes SET uncertainty = 'low' WHERE seed = 2", "uncertainty is 'low'"),
        ("UPDATE episodes SET detections = 'x' WHERE seed = 0", "detections is 'x'"),
        ("UPDATE episodes SET never_observed = 9e999 WHERE seed = 0", "not a finite number"),
    ],
)
def test_a_stored_value_of_the_wrong_type_is_one_line(cli, tmp_path, sql, needle):
    db = _finished(tmp_path, sql)
    cli(*BENCHMARK, "--db", db, "--out", tmp_path / "o").refused(str(db), needle)


def test_a_trigger_that_refuses_inserts_is_one_line_and_frees_the_claim(cli, tmp_path):
    sql = (
        "CREATE TRIGGER no_more BEFORE INSERT ON episodes BEGIN SELECT RAISE(ABORT, 'frozen'); END"
    )
    db = _finished(tmp_path, sql)
    more = [*BENCHMARK[:4], "4", *BENCHMARK[5:]]
    cli(*more, "--db", db, "--out", tmp_path / "o").refused(str(db), "refused a write (frozen)")
    with sqlite3.connect(db) as raw:
        assert raw.execute("SELECT COUNT(*) FROM claims").fetchone() == (0,)
        assert raw.execute("SELECT COUNT(*) FROM episodes").fetchone() == (3,)


def test_a_table_without_its_primary_key_is_refused(tmp_path):
    path = tmp_path / "nokey.db"  # rows could be stored twice, claims taken twice
    with sqlite3.connect(path) as raw:
        raw.executescript(
            SCHEMA.replace(
                ",\n    PRIMARY KEY (planner, n_targets, seed, setting, planner_settings_hash)", ""
            )
        )
        raw.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    with pytest.raises(InputError, match=f"--db {path}: table episodes has no primary key"):
        ResultStore(path)


def test_a_lock_held_elsewhere_is_a_bounded_wait_then_one_line(tmp_path, monkeypatch):
    path = tmp_path / "b.db"
    ResultStore(path).close()
    holder = sqlite3.connect(path, isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    monkeypatch.setattr(store_module, "LOCK_WAIT_S", 0.5)
    start = time.monotonic()
    with pytest.raises(InputError, match=r"locked by another process for more than 0.5 s"):
        ResultStore(path)
    assert time.monotonic() - start < 10.0
    holder.rollback()
    ResultStore(path).close()  # free again: it opens


def _claim(path, key, host, pid, at) -> None:
    with sqlite3.connect(path) as raw:
        raw.execute(
            "INSERT INTO claims VALUES (?, ?, ?, ?, ?, ?, ?, ?)", (*key._id(), host, pid, at)
        )


HOLDER = """
import sqlite3, sys, time
db = sqlite3.connect(sys.argv[1])
db.execute("SELECT COUNT(*) FROM claims").fetchall()
print("open", flush=True)
time.sleep(float(sys.argv[2]))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_claims_no_run_of_the_database_holds_are_released(tmp_path):
    path = tmp_path / "b.db"
    store = ResultStore(path)
    keys = CONFIG.keys()
    other = subprocess.Popen(["sleep", "60"])  # alive, but not a run of this database
    run = subprocess.Popen([sys.executable, "-c", HOLDER, str(path), "60"], stdout=subprocess.PIPE)
    try:
        assert run.stdout.readline() == b"open\n"
        here, now = socket.gethostname(), time.time()
        _claim(path, keys[0], here, other.pid, now)
        _claim(path, keys[1], here, 2**22 + 4321, now)  # no such process
        _claim(path, keys[2], "elsewhere", 77, now + 86400.0)  # from the future
        _claim(path, keys[3], "elsewhere", 77, now - 7 * 3600.0)  # too old
        _claim(path, keys[4], here, run.pid, now)  # a live process with the database open
        _claim(path, keys[5], "elsewhere", 77, now)  # another host's recent claim
        assert store.release_stale_claims() == 4
        assert [store.claim(k) for k in keys[:6]] == [True] * 4 + [False] * 2
    finally:
        for proc in (other, run):
            proc.kill()
            proc.wait()
        run.stdout.close()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc")
def test_the_library_waits_for_another_runs_claims_then_runs_them(tmp_path, monkeypatch):
    path = tmp_path / "b.db"
    store = ResultStore(path)
    config = STORED
    run = subprocess.Popen([sys.executable, "-c", HOLDER, str(path), "3"], stdout=subprocess.PIPE)
    assert run.stdout.readline() == b"open\n"
    _claim(path, config.keys()[1], socket.gethostname(), run.pid, time.time())
    monkeypatch.setattr(benchmark_module, "OTHER_RUN_POLL_S", 0.2)
    waits = []
    try:
        ran = run_benchmark(config, store, on_wait=lambda stored, total: waits.append(stored))
    finally:
        run.wait()
        run.stdout.close()
    assert waits and set(waits) == {2}  # it waited while the other held seed 1...
    assert ran == 3 and _unique_rows(path) == 3  # ... then ran it when that run was gone
