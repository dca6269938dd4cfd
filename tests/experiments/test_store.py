"""Result identity across store layouts: ``data/results-v2.db`` was written by the store of
layout 2 (identities without the mcts options that had the paper's value), one row for each
distinct planner, setting and settings of the published tables in ``docs/results``."""

from __future__ import annotations

import csv
import functools
import importlib.util
import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from hptrack.experiments import store as store_module
from hptrack.experiments.benchmark import BenchmarkConfig
from hptrack.experiments.store import SCHEMA_VERSION, ResultStore
from hptrack.interface import InputError
from hptrack.registry import planner_entry, planner_settings
from hptrack.settings import digest_of

ROOT = Path(__file__).parents[2]
LAYOUT_2 = Path(__file__).parent / "data" / "results-v2.db"


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def layout_2(tmp_path) -> Path:
    path = tmp_path / "old.db"
    shutil.copy(LAYOUT_2, path)
    return path


@functools.cache
def _rebuilt(planner: str, text: str) -> str:
    """The identity the current code gives the settings a text stands for."""
    return planner_entry(planner).settings_type.from_canonical(text).canonical()


def _raw(path: Path) -> list[tuple]:
    with sqlite3.connect(path) as db:
        return sorted(
            db.execute(
                "SELECT planner, n_targets, seed, setting, uncertainty, never_observed, "
                "detections, wall_time_s, info FROM episodes"
            ).fetchall()
        )


def test_a_layout_2_database_is_migrated_with_every_result(layout_2):
    before = _raw(layout_2)
    assert len(before) == 73
    store = ResultStore(layout_2)
    rows = store.rows()
    assert store.release_stale_claims() == 0  # the old layout's claim is gone with it
    store.close()
    assert _raw(layout_2) == before  # every result unchanged, only identities rewritten
    with sqlite3.connect(layout_2) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 10
    for r in rows:
        assert (r.gospa_mean, r.gospa_end, r.track_loss) == (None, None, None)
        text = r.key.planner_settings
        assert _rebuilt(r.key.planner, text) == text  # a full identity, as the code builds
        assert r.key.planner_settings_hash == digest_of(text)
    paper = [r for r in rows if r.info["source"] == "docs/results/benchmark/episodes.csv"]
    assert {r.key.planner for r in paper} == {"arvi", "astar", "greedy", "mcts", "stationary"}
    mcts = next(r for r in paper if r.key.planner == "mcts")
    paper_search = planner_settings("mcts", {"preset": "paper"}).as_json()
    del paper_search["preset"]
    assert json.loads(mcts.key.planner_settings) == paper_search
    reopened = ResultStore(layout_2)  # a second opening finds it migrated
    assert reopened.rows() == rows
    reopened.close()


def test_the_keys_the_scripts_build_find_the_migrated_rows(layout_2):
    store = ResultStore(layout_2)
    done, rows = store.done(), store.rows()
    store.close()
    check = _script("check_reproduction")
    published = [r for r in rows if r.info["source"] == "docs/results/benchmark/episodes.csv"]
    for r in published:
        assert check.published_key(r.key.planner, r.key.n_targets, r.key.seed) == r.key
    quality = _script("quality_vs_time")  # its published runs: two presets at three levels
    identities = {k.planner_settings for k in done}
    for variant in ("paper", "improved"):
        for level in (0.05, 0.2, 1.0):
            assert quality.settings(variant, level) in identities
    for options in ({"preset": "improved"}, {"preset": "improved", "dwell": 20.0}):
        config = BenchmarkConfig(
            planners=("mcts",),
            settings={"mcts": planner_settings("mcts", options)},
            target_counts=(2,),
            scenarios=1,
            homogeneous=False,
        )
        assert set(config.keys()) <= done  # a re-run of the published command resumes


def test_every_published_identity_is_the_one_the_code_builds():
    tables = sorted((ROOT / "docs" / "results").glob("*/episodes.csv"))
    assert len(tables) >= 10
    check = _script("check_reproduction")
    variants = _script("truth_mismatch").REGISTERED  # rows named by the script's variants
    for path in tables:
        with path.open(newline="") as fh:
            for r in csv.DictReader(fh):
                text = r["planner_settings"]
                planner = variants.get(r["planner"], r["planner"])
                assert _rebuilt(planner, text) == text, (path, text)
                if path.parent.name == "benchmark" and r["planner"] in ("mcts", "arvi", "astar"):
                    key = check.published_key(r["planner"], int(r["n_targets"]), int(r["seed"]))
                    assert key.planner_settings == text


def test_a_failed_migration_leaves_the_database_as_it_was(layout_2, monkeypatch):
    def broken(db):
        store_module._migrate_2_to_3(db)
        raise RuntimeError("a bug in a migration step")

    monkeypatch.setitem(store_module.MIGRATIONS, 2, broken)
    before = _raw(layout_2)
    with pytest.raises(RuntimeError, match="a bug"):
        ResultStore(layout_2)
    with sqlite3.connect(layout_2) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == 2
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        assert tables == {"episodes", "claims"}
        assert "settings_hash" in [c[1] for c in db.execute("PRAGMA table_info(episodes)")]
    assert _raw(layout_2) == before


def test_a_layout_without_a_migration_is_refused(tmp_path):
    path = tmp_path / "v1.db"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE episodes (planner, n_targets, seed, setting, effort)")
        db.execute("PRAGMA user_version = 1")
    with pytest.raises(InputError, match=r"another layout \(version 1"):
        ResultStore(path)


LAYOUT_6 = """
CREATE TABLE episodes (
    planner TEXT NOT NULL, n_targets INTEGER NOT NULL, seed INTEGER NOT NULL,
    setting TEXT NOT NULL, planner_settings_hash TEXT NOT NULL, planner_settings TEXT NOT NULL,
    uncertainty REAL NOT NULL, never_observed REAL NOT NULL, detections INTEGER NOT NULL,
    wall_time_s REAL NOT NULL, info TEXT NOT NULL,
    PRIMARY KEY (planner, n_targets, seed, setting, planner_settings_hash)
);
CREATE TABLE claims (
    planner TEXT NOT NULL, n_targets INTEGER NOT NULL, seed INTEGER NOT NULL,
    setting TEXT NOT NULL, planner_settings_hash TEXT NOT NULL, host TEXT NOT NULL,
    pid INTEGER NOT NULL, claimed_at REAL NOT NULL,
    PRIMARY KEY (planner, n_targets, seed, setting, planner_settings_hash)
);
"""
"""The tables of layout 6 (before the tracking metrics), as that store created them."""


def test_a_layout_6_database_gains_the_metrics_as_null(tmp_path):
    from hptrack.experiments.store import EpisodeKey
    from hptrack.sim.record import EpisodeRow

    path = tmp_path / "v6.db"
    text = planner_settings("greedy", None).canonical()
    with sqlite3.connect(path) as db:
        db.executescript(LAYOUT_6)
        db.execute(
            "INSERT INTO episodes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            ("greedy", 2, 0, "homogeneous", digest_of(text), text, 30.5, 51.0, 7, 1.5, "{}"),
        )
        db.execute("PRAGMA user_version = 6")
    store = ResultStore(path)
    (old,) = store.rows()
    assert (old.uncertainty, old.detections, old.info) == (30.5, 7, {})
    assert (old.gospa_mean, old.gospa_end, old.track_loss) == (None, None, None)
    key = EpisodeKey("greedy", 2, 1, "homogeneous", text)
    new = EpisodeRow(key, 29.0, 51.0, 9, 2.0, {"targets_never_detected": 1}, 61.25, 70.5, 1)
    store.add(new)
    assert store.rows() == [old, new]
    assert new.metric("never_detected") == 1 and new.metric("U") == 29.0
    assert old.metric("gospa_end") is None
    store.close()
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
        db.execute("UPDATE episodes SET gospa_end = 'far' WHERE seed = 1")
    with pytest.raises(InputError, match=r"seed=1: gospa_end is 'far', not a finite number"):
        ResultStore(path).rows()
