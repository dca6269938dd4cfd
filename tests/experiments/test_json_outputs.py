"""The files written as JSON are strict JSON (RFC 8259) when a number is not finite: the
results store's episode info, an episode record's metadata, the ``--json`` summaries and the
coverage validation's ``mape-both.json`` write it as ``"inf"``, ``"-inf"`` or ``"nan"``."""

import json
import math
import sqlite3

import numpy as np

from hptrack.cli.common import write_json
from hptrack.experiments.coverage_validation import write_reports
from hptrack.experiments.store import EpisodeKey, EpisodeRow, ResultStore
from hptrack.jsonout import json_text
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.record import EpisodeRecord

ODD = {"stay_s": math.inf, "gap": -math.inf, "values": np.array([1.5, math.nan]), "n": np.int64(3)}
WRITTEN = {"stay_s": "inf", "gap": "-inf", "values": [1.5, "nan"], "n": 3}


def _strict(text: str):
    def refuse(token):
        raise AssertionError(f"JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def test_non_finite_numbers_are_written_as_strings():
    assert _strict(json_text(ODD)) == WRITTEN
    assert [float(v) for v in _strict(json_text([math.inf, -math.inf]))] == [math.inf, -math.inf]


def test_the_results_store_keeps_strict_json_info(tmp_path):
    path = tmp_path / "r.db"
    store = ResultStore(path)
    key = EpisodeKey("greedy", 2, 0, "homogeneous", "{}")
    store.add(EpisodeRow(key, 10.0, 50.0, 3, 1.0, ODD))
    assert store.rows()[0].info == WRITTEN
    store.close()
    with sqlite3.connect(path) as db:
        (text,) = db.execute("SELECT info FROM episodes").fetchone()
    assert _strict(text) == WRITTEN


def test_a_record_and_a_json_summary_are_strict(tmp_path):
    scenario = random_scenario(2, seed=3).model_copy(update={"budget": 5.0})
    record = run_episode(scenario, make_planner("greedy"))
    record.info = ODD
    record.save(tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as data:
        assert _strict(str(data["meta"]))["info"] == WRITTEN
    assert EpisodeRecord.load(tmp_path / "r.npz").info == WRITTEN
    write_json(tmp_path / "s.json", {"U": math.nan, **ODD})
    assert _strict((tmp_path / "s.json").read_text()) == {"U": "nan", **WRITTEN}


def test_an_undefined_mape_is_written_as_nan(tmp_path):
    figures = (
        "mape_p_find",
        "sharp_mape_p_find",
        "mape_expected_time",
        "sharp_mape_expected_time",
    )
    summary = {"0": {"cases": 2, **dict.fromkeys(figures, math.nan)}}
    write_reports(summary, tmp_path)
    both = _strict((tmp_path / "mape-both.json").read_text())
    assert both["paper"]["0"] == {"mape_p_find": "nan", "mape_expected_time": "nan"}
