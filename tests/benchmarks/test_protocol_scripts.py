"""The planner comparison scripts (``benchmarks/paper_flight.py`` and the reference rows of
``benchmarks/quality_vs_time.py``) on inputs whose answers are known exactly."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from hptrack.experiments.store import EpisodeKey, EpisodeRow, ResultStore
from hptrack.planning.hierarchical import MctsSettings
from hptrack.settings import NoSettings

BENCHMARKS = Path(__file__).parents[2] / "benchmarks"


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def paper_flight():
    return _script("paper_flight")


@pytest.fixture(scope="module")
def quality():
    return _script("quality_vs_time")


def test_visits_are_runs_of_detections_split_by_gaps_of_two_seconds(paper_flight):
    """0.5 s steps: a gap of 4 steps without a detection (2 s) starts a new visit, one of 3
    steps does not; a target never measured has no visit."""
    column = np.zeros(30, dtype=bool)
    column[[0, 1, 2, 6, 7, 11, 20, 21]] = True  # gaps: 3 (same visit), 3, 8 (new visit)
    detections = np.stack([column, np.zeros(30, dtype=bool), column[::-1]], axis=1)
    assert paper_flight.visits(detections, 0.5) == [2, 0, 2]
    column[26] = True  # 4 steps (2 s) without a detection since step 21: a third visit
    assert paper_flight.visits(column[:, None], 0.5) == [3]


def test_paper_flight_rows_and_report(paper_flight, tmp_path):
    """Three episodes of seed 0 (greedy, the reference, a 200-simulation search): their rows
    are what ``run`` returns, and the report's difference from greedy and share of the gap
    closed are the arithmetic of their U."""
    search = MctsSettings.from_options("mcts", {"preset": "improved", "iterations": 200})
    jobs = [
        ("greedy", "greedy", 0.0, 0, NoSettings().canonical()),
        ("clairvoyant", "clairvoyant", 0.0, 0, NoSettings().canonical()),
        ("mcts", "improved", 0.0, 0, search.canonical()),
    ]
    path = tmp_path / "runs.csv"
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, paper_flight.FIELDS)
        writer.writeheader()
        rows = [paper_flight.run(job) for job in jobs]
        writer.writerows(rows)
    g, c, u = (float(r["U"]) for r in rows)
    assert c < g  # the reference reads the truth
    paper_flight.report(path, tmp_path / "out")
    table = (tmp_path / "out" / "table.md").read_text()
    line = next(x for x in table.splitlines() if x.startswith("| improved |"))
    cells = [x.strip() for x in line.strip("|").split("|")]
    assert cells[3] == f"{u:.2f} +- nan"
    assert cells[4] == f"{u - g:+.2f} +- nan"
    assert cells[5] == f"{100.0 * (g - u) / (g - c):.0f}"
    alternating = int(min(json.loads(rows[2]["visits"])) >= 3)
    assert cells[6] == f"{alternating} of 1"
    assert (tmp_path / "out" / "paper-flight.png").stat().st_size > 0
    assert paper_flight.identity(rows[2]) == ("mcts", search.canonical(), 0)


def test_quality_report_gives_the_gap_closed_and_the_targets_never_detected(quality, tmp_path):
    """Two scenarios at n = 3: greedy 100 and 80, clairvoyant 20 and 40, the paper's search
    at 0.05 s 60 and 50 (never detected 1 and 0): the gap closed is 100 (90 - 55) / (90 - 30)
    = 58 %, and 0.5 targets per episode are never detected."""
    store = ResultStore(tmp_path / "toy.db")
    paper = quality.settings("paper", 0.05)
    values = {"greedy": (100.0, 80.0), "clairvoyant": (20.0, 40.0), "mcts": (60.0, 50.0)}
    for planner, us in values.items():
        for seed, u in enumerate(us):
            text = paper if planner == "mcts" else NoSettings().canonical()
            key = EpisodeKey(planner, 3, seed, quality.SETTING, text)
            store.add(EpisodeRow(key, u, 77.0, 1, 0.1, {"targets_never_detected": 1 - seed}))
    store.close()
    quality.report(tmp_path / "toy.db", tmp_path / "out", [0.05], ["paper"])
    table = (tmp_path / "out" / "table.md").read_text()
    assert "| paper @ 0.05 s | 58 (2) |" in table
    assert "| paper | 0.05 | 0.50 |" in table
    assert "| clairvoyant | - | 30.00 +- 10.00 (2) |" in table


def test_truth_mismatch_rows_and_their_report(tmp_path):
    """``benchmarks/truth_mismatch.py``: a row is the episode the simulator flies (same ``U``
    as running it directly, the truth motion applied), and the report's means, standard errors
    and paired differences are the arithmetic of the rows."""
    from hptrack.registry import make_planner
    from hptrack.sim.episode import run_episode

    mismatch = _script("truth_mismatch")
    row = mismatch.episode(("greedy", "turn_0.02", 2, 1, 2000))
    scenario = mismatch.scenario(2, 1, "turn_0.02")
    assert scenario.truth_motion.model == "coordinated_turn"
    assert float(row["U"]) == run_episode(scenario, make_planner("greedy")).uncertainty
    assert row["planner_settings"] == make_planner("greedy").settings.canonical()
    assert mismatch.scenario(2, 1, "constant_velocity").truth_motion is None
    path = tmp_path / "rows.csv"
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, mismatch.FIELDS)
        writer.writeheader()
        for seed, (m, g, c) in enumerate([(10.0, 14.0, 5.0), (12.0, 13.0, 6.0)]):
            for planner, u in (("mcts", m), ("greedy", g), ("clairvoyant", c)):
                writer.writerow(
                    dict(
                        zip(mismatch.FIELDS, (planner, "{}", "ou_0.01", 6, seed, u, 1), strict=True)
                    )
                )
    args = type("Args", (), {"csv": str(path), "out": str(tmp_path / "out")})
    mismatch.report(args)
    table = (tmp_path / "out" / "table.md").read_text()
    assert "| 6 | ou_0.01 | mcts | 2 | 11.00 | 1.00 | 1.00 |" in table
    assert "| 6 | ou_0.01 | -2.50 | 1.50 |" in table  # differences -4 and -1


def test_search_fingerprints_are_the_searches_statistics_and_repeat():
    """``benchmarks/search_fingerprint.py``: a fingerprint holds a search's root statistics as
    the search returns them, and the same code gives the same fingerprints."""
    from hptrack.planning.subtask_mdp import PlanningProblem
    from hptrack.planning.subtask_search import search
    from hptrack.scenario.random import random_scenario

    fingerprint = _script("search_fingerprint")
    first = fingerprint.fingerprints(counts=(2,), seeds=(0,), iterations=100)
    assert len(first) == 2 * len(fingerprint.VARIANTS)
    assert fingerprint.fingerprints(counts=(2,), seeds=(0,), iterations=100) == first
    scenario = random_scenario(2, seed=0, homogeneous=True)
    problem = PlanningProblem.from_observation(
        scenario.mission_spec().record, scenario.initial_observation()
    )
    settings = MctsSettings.model_validate({"preset": "paper", "iterations": 100})
    result = search(
        problem, settings.search_options(), settings.subtask_options(), iterations=100, seed=7
    )
    best, root, after, simulations, *_ = first[(2, 0, 0, None)]
    assert (best, simulations, after) == (result.best_action, result.simulations, [])
    assert root[:2] == (result.root.actions.tolist(), result.root.visits.tolist())
    assert root[2] == result.root.values.tobytes()


def test_the_sensing_table_flies_the_blind_search_only_below_pd_one_and_pairs_it(tmp_path):
    """``benchmarks/sensing_table.py``: the blind variant only where the detector misses, every
    sensor its own setting; the report's paired difference is the mean of the per-scenario
    differences (known 10, 14; blind 13, 13: -1 +- 2) and the metrics are the rows' means."""
    table = _script("sensing_table")
    wanted = table.configs(
        ("default", "blind"), (3,), 2, {"iterations": 50}, (1.0, 0.7), 1e-6, 0.0, ("labelled",)
    )
    assert set(wanted) == {
        ("Pd 1, labelled", "default"),
        ("Pd 0.7, labelled", "default"),
        ("Pd 0.7, labelled", "blind"),
    }
    assert wanted["Pd 0.7, labelled", "blind"].setting == "homogeneous+pd:0.7+blind"
    held = table.configs(("default",), (3,), 2, {"iterations": 50}, (0.7,), 1e-6, 5.0)
    assert {c.setting for c in held.values()} == {
        "homogeneous+pd:0.7+correlation:5.0",
        "homogeneous+pd:0.7+correlation:5.0+unlabelled",
        "homogeneous+pd:0.7+correlation:5.0+unlabelled+clutter:1e-06",
    }

    def row(u: float, seed: int) -> EpisodeRow:
        key = EpisodeKey("mcts", 3, seed, "s", MctsSettings().canonical())
        return EpisodeRow(key, u, 77.0, 1, 0.1, {"targets_never_detected": seed}, 5.0, 7.0, 1)

    by = {
        ("Pd 0.7, labelled", "default"): {(3, 0): row(10.0, 0), (3, 1): row(14.0, 1)},
        ("Pd 0.7, labelled", "blind"): {(3, 0): row(13.0, 0), (3, 1): row(13.0, 1)},
    }
    table.report(by, tmp_path, "command", "50 simulations per decision")
    paired = list(csv.DictReader((tmp_path / "paired.csv").read_text().splitlines()))
    assert len(paired) == 1
    assert float(paired[0]["known_minus_blind"]) == pytest.approx(-1.0)
    assert float(paired[0]["se"]) == pytest.approx(2.0)
    lines = (tmp_path / "rows.csv").read_text().splitlines()
    rows = {r["planner"]: r for r in csv.DictReader(lines)}
    assert float(rows["default"]["mean_U"]) == pytest.approx(12.0)
    assert float(rows["default"]["never_detected"]) == pytest.approx(0.5)
    assert float(rows["blind"]["gospa_end"]) == pytest.approx(7.0)


def test_the_sensing_table_pairs_each_search_with_its_own_blind_twin(tmp_path):
    """``benchmarks/sensing_table.py``: with the revisit search and its blind twin beside the
    default pair, each known search is paired with its own twin, and the table names it."""
    table = _script("sensing_table")
    wanted = table.configs(
        ("revisit", "blind-revisit"), (3,), 2, {}, (0.7,), 1e-6, 0.0, ("labelled",)
    )
    known, blind = (wanted["Pd 0.7, labelled", v] for v in ("revisit", "blind-revisit"))
    assert known.settings["mcts"] == blind.settings["mcts"]
    assert (known.settings["mcts"].rollout, known.blind, blind.blind) == ("tour_plan", False, True)

    def row(u: float, seed: int) -> EpisodeRow:
        key = EpisodeKey("mcts", 3, seed, "s", MctsSettings().canonical())
        return EpisodeRow(key, u, 77.0, 1, 0.1, {"targets_never_detected": 0}, 5.0, 7.0, 1)

    sensor = "Pd 0.7, labelled"
    by = {
        (sensor, "default"): {(3, 0): row(10.0, 0), (3, 1): row(14.0, 1)},
        (sensor, "blind"): {(3, 0): row(13.0, 0), (3, 1): row(13.0, 1)},
        (sensor, "revisit"): {(3, 0): row(9.0, 0), (3, 1): row(9.0, 1)},
        (sensor, "blind-revisit"): {(3, 0): row(12.0, 0), (3, 1): row(14.0, 1)},
    }
    table.report(by, tmp_path, "command", "its default effort")
    paired = list(csv.DictReader((tmp_path / "paired.csv").read_text().splitlines()))
    assert [(p["search"], float(p["known_minus_blind"])) for p in paired] == [
        ("default", -1.0),
        ("revisit", -4.0),
    ]
    text = (tmp_path / "table.md").read_text()
    assert "| 3 | Pd 0.7, labelled | revisit | 2 | -4.00 | 1.00 | 4.0 |" in text


def test_the_scale_benchmark_runs_each_search_at_its_presets_default_effort_or_a_time_limit():
    """``benchmarks/scale_benchmark.py``: ``--default-effort`` leaves every search at its
    preset's simulations per search (the revisit preset's own, a fifth of the others'); a time
    limit replaces them; the gap table is the share of the greedy-to-clairvoyant gap closed."""
    scale = _script("scale_benchmark")
    default = scale.configs(("revisit", "improved", "greedy"), (4,), 2, None)
    revisit, improved = (default[v].settings["mcts"] for v in ("revisit", "improved"))
    assert (revisit.iterations, revisit.time_limit, revisit.rollout) == (20_000, None, "tour_plan")
    assert (improved.iterations, improved.rollout) == (100_000, "uniform")
    timed = scale.configs(("revisit",), (4,), 2, 0.5)["revisit"].settings["mcts"]
    assert (timed.iterations, timed.time_limit) == (None, 0.5)
    assert "default effort" in scale.effort_text(None) and scale.effort_text(1.0) == (
        "at 1 s per decision"
    )

    def row(u):
        key = EpisodeKey("mcts", 4, 0, "s", "{}")
        return EpisodeRow(key, u, 0.0, 0, 0.0, {"targets_never_detected": 0})

    by_variant = {  # U: greedy 100, clairvoyant 60; revisit 70 (75 % of the gap), tour 90
        "revisit": {(4, 0): row(70.0), (4, 1): row(70.0)},
        "tour": {(4, 0): row(90.0)},
        "greedy": {(4, 0): row(100.0), (4, 1): row(100.0)},
        "clairvoyant": {(4, 0): row(60.0), (4, 1): row(60.0)},
    }
    assert scale.gap_closed(by_variant, "revisit", 4) == (75.0, 2)
    assert scale.gap_closed(by_variant, "tour", 4) == (25.0, 1)
    rows = [
        {"planner": p, "n": 4, "gap_closed_percent": g, "gap_scenarios": k}
        for p, g, k in (("revisit", 75.0, 2), ("tour", 25.0, 1), ("greedy", 0.0, 2))
    ]
    lines = scale.gap_table(rows, [4, 6])
    assert lines[-2:] == ["| revisit | 75 (2) | - |", "| tour | 25 (1) | - |"]
    assert scale.gap_table([{**r, "gap_scenarios": 0} for r in rows], [4]) == []


def test_the_target_mix_splits_u_and_the_gap_by_the_kind_each_target_ends_in(tmp_path):
    """``benchmarks/target_mix.py``: a target's kind by its last detection; on hand-made
    episodes, the counts, the mean ``log det`` of each kind and the gap to the clairvoyant
    split by kind; a flown episode's targets add up to its U and its never-measured U."""
    mix = _script("target_mix")

    def entry(logdets, lasts):
        return {
            "budget_s": 100.0,
            "logdet": logdets,
            "never_logdet": [30.0] * len(logdets),
            "last_detection_s": lasts,
        }

    outcome = mix.TargetOutcome(1.0, 30.0, 74.9)
    assert mix.kind(outcome, 100.0, 0.25) == "lost"
    assert mix.kind(mix.TargetOutcome(1.0, 30.0, 75.0), 100.0, 0.25) == "kept"
    assert mix.kind(mix.TargetOutcome(30.0, 30.0, None), 100.0, 0.25) == "never"
    episodes = {  # two scenarios; the planner leaves target 0 never, 1 lost, 2 kept
        "search": {
            0: entry([30.0, 12.0, 5.0], [None, 10.0, 99.0]),
            1: entry([30.0, 14.0, 7.0], [None, 20.0, 80.0]),
        },
        "clairvoyant": {
            0: entry([6.0, 6.0, 5.0], [90.0, 95.0, 99.0]),
            1: entry([8.0, 6.0, 5.0], [90.0, 95.0, 99.0]),
        },
    }
    search, reference = mix.summarise(episodes, 0.25)
    assert (search["never_per_episode"], search["lost_per_episode"]) == (1.0, 1.0)
    assert (search["never_mean_logdet"], search["lost_mean_logdet"]) == (30.0, 13.0)
    assert search["kept_mean_logdet"] == 6.0 and search["mean_U"] == 49.0
    assert search["never_gap"] == pytest.approx((23.0, 1.0))  # 24 and 22
    assert search["lost_gap"] == pytest.approx((7.0, 1.0))  # 6 and 8
    assert search["kept_gap"] == pytest.approx((1.0, 1.0))  # 0 and 2
    assert reference["kept_per_episode"] == 3.0 and reference["never_gap"] is None

    variants = mix._scale_variants()
    key = mix.variant_key("greedy", 3, 0, variants)
    assert mix.variant_key("revisit@500", 3, 0, variants).planner_settings != (
        mix.variant_key("revisit", 3, 0, variants).planner_settings
    )
    cache = tmp_path / "mix.jsonl"
    flown = mix.run([key], cache, workers=1)[key]
    scenario = mix.scenario_for(key)
    record = mix.run_episode(scenario, mix.planner_for(key), belief_stride=scenario.n_steps)
    assert sum(flown["logdet"]) == pytest.approx(record.uncertainty, abs=1e-9)
    assert sum(flown["never_logdet"]) == pytest.approx(scenario.never_observed_uncertainty())
    never = [i for i, last in enumerate(flown["last_detection_s"]) if last is None]
    assert never == [i for i in range(3) if not record.detections[:, i].any()]
    for i in never:
        assert flown["logdet"][i] == pytest.approx(flown["never_logdet"][i], abs=1e-9)
    assert (
        mix.run([key], cache, workers=1)[key] == flown and len(cache.read_text().splitlines()) == 1
    )


def test_fence_coverage_lays_the_circle_across_the_intercept_on_request():
    """``benchmarks/fence_coverage.py --placement path``: the circle's centre lies on the straight
    flight from the agent's start (the origin) to where the coverage starts, with the same offset
    and radius as the random-angle placement of the same case."""
    coverage = _script("fence_coverage")
    anywhere = coverage.fenced_case(3, 0, 0.0, 20)
    across = coverage.fenced_case(3, 0, 0.0, 20, "path")
    start, centre = np.array(across["coverage_start"]), np.array(across["centre"])
    assert abs(start[0] * centre[1] - start[1] * centre[0]) <= 1e-6 * np.dot(start, start)
    assert 0.0 <= np.dot(centre, start) <= np.dot(start, start)
    assert across["radius_sigma"] == anywhere["radius_sigma"]
    assert across["offset_sigma"] == pytest.approx(anywhere["offset_sigma"])
    assert anywhere["centre"] != across["centre"]


def test_the_team_benchmark_adds_the_revisit_search_and_may_leave_out_the_references(tmp_path):
    """``benchmarks/team_benchmark.py --revisit --no-references``: team-mcts at the revisit
    preset beside its own, no greedy or clairvoyant team; the report pairs the two searches
    and has no gap closed."""
    team = _script("team_benchmark")
    plain = team.configs((4,), 2, 2, 0.05, False)
    assert list(plain) == ["team-greedy", "team-mcts", "team-cbba", "team-clairvoyant"]
    both = team.configs((4,), 2, 2, 0.05, False, revisit=True, references=False)
    assert list(both) == ["team-mcts", "team-cbba", team.REVISIT]
    mine, theirs = (both[v].settings["team-mcts"] for v in ("team-mcts", team.REVISIT))
    assert (mine.rollout, theirs.rollout) == ("uniform", "tour_plan")
    assert mine.time_limit == theirs.time_limit == 0.05

    def row(u):
        key = EpisodeKey("team-mcts", 4, 0, "s", "{}")
        return EpisodeRow(key, u, 0.0, 0, 0.0, {"targets_never_detected": 1})

    by_team = {
        2: {
            "team-mcts": {(4, 0): row(50.0), (4, 1): row(54.0)},
            "team-cbba": {(4, 0): row(60.0), (4, 1): row(60.0)},
            team.REVISIT: {(4, 0): row(49.0), (4, 1): row(51.0)},
        }
    }
    team.report(by_team, tmp_path, "cmd")
    text = (tmp_path / "table.md").read_text()
    assert "| 4 | 2 | team-mcts | 2 | 52.00 +- 2.00 | - | 1.00 |" in text
    assert f"| 4 | 2 | team-mcts - {team.REVISIT} | 2 | +2.00 +- 1.00 |" in text


def test_the_false_finds_benchmark_pairs_the_search_with_its_false_find_twin(tmp_path):
    """``benchmarks/false_finds.py``: the two searches differ in ``false_finds`` only, on one
    cluttered setting per Pd; the paired rows are the means of the per-scenario differences
    (U 10, 14 against 13, 13: -1 +- 2; tracks lost 0, 2 against 1, 1: 0 +- 1)."""
    ff = _script("false_finds")
    wanted = ff.configs((3,), 2, (1.0, 0.7), 1e-6)
    assert {c.setting for c in wanted.values()} == {
        "homogeneous+unlabelled+clutter:1e-06",
        "homogeneous+pd:0.7+unlabelled+clutter:1e-06",
    }
    base, mine = (wanted["Pd 1, unlabelled, clutter 1e-06", v] for v in ("revisit", "false-finds"))
    assert (base.settings["mcts"].false_finds, mine.settings["mcts"].false_finds) == (
        "ignore",
        "model",
    )
    assert (
        base.settings["mcts"].model_copy(update={"false_finds": "model"}) == mine.settings["mcts"]
    )

    def row(u: float, seed: int, lost: int, taken: int | None = None) -> EpisodeRow:
        key = EpisodeKey("mcts", 3, seed, "s", MctsSettings().canonical())
        info: dict = {"targets_never_detected": 0}
        if taken is not None:  # a row stored with its tracking summary
            info["tracking"] = {"false_alarms_taken": taken}
        return EpisodeRow(key, u, 77.0, 1, 0.1, info, 5.0, 7.0, lost)

    sensor = "Pd 1, unlabelled, clutter 1e-06"
    by = {
        (sensor, "revisit"): {(3, 0): row(13.0, 0, 1), (3, 1): row(13.0, 1, 1, 5)},
        (sensor, "false-finds"): {(3, 0): row(10.0, 0, 0, 2), (3, 1): row(14.0, 1, 2, 4)},
    }
    ff.report(by, tmp_path, "command")
    text = (tmp_path / "table.md").read_text()
    assert "| 3 | Pd 1, unlabelled, clutter 1e-06 | revisit | 2 | 13.00 +- 0.00 |" in text
    assert text.count(" | 0.00 | - |") == 1  # one revisit row predates the summary
    assert " | 0.00 | 3.00 |" in text  # the false-finds rows took 2 and 4
    (paired,) = json.loads((tmp_path / "summary.json").read_text())["paired"]
    assert (paired["U_diff"], paired["U_se"]) == pytest.approx((-1.0, 2.0))
    assert (paired["track_loss_diff"], paired["track_loss_se"]) == pytest.approx((0.0, 1.0))
    assert paired["gospa_end_diff"] == 0.0
