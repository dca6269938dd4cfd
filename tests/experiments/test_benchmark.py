import json
import multiprocessing
import sqlite3

import numpy as np
import pytest

from hptrack.baselines.stationary import StationaryPlanner
from hptrack.experiments.benchmark import (
    BenchmarkConfig,
    reductions,
    run_benchmark,
    scenario_for,
    summarise,
)
from hptrack.experiments.store import ResultStore
from hptrack.interface import InputError
from hptrack.registry import planner_settings
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode


def config(planners=("greedy", "stationary"), options=None, **kw):
    options = options or {}
    settings = {p: planner_settings(p, options.get(p)) for p in planners}
    kw.setdefault("target_counts", (2, 3))
    kw.setdefault("scenarios", 2)
    return BenchmarkConfig(planners=planners, settings=settings, **kw)


CONFIG = config()


def test_interrupted_run_keeps_finished_episodes_and_resumes_without_duplicates(tmp_path):
    store = ResultStore(tmp_path / "b.db")

    def stop_after_three(row, finished, total):
        if finished == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_benchmark(CONFIG, store, on_done=stop_after_three)
    assert len(store.rows()) == 3
    store.close()
    store = ResultStore(tmp_path / "b.db")
    assert run_benchmark(CONFIG, store) == len(CONFIG.keys()) - 3
    assert run_benchmark(CONFIG, store) == 0
    rows = store.rows()
    assert len(rows) == len({r.key for r in rows}) == 8


def test_parallel_run_equals_serial_run(tmp_path):
    serial, parallel = ResultStore(tmp_path / "s.db"), ResultStore(tmp_path / "p.db")
    run_benchmark(CONFIG, serial)
    run_benchmark(CONFIG, parallel, workers=2)
    u = {r.key: r.uncertainty for r in serial.rows()}
    assert u == {r.key: r.uncertainty for r in parallel.rows()}


def test_never_observed_equals_a_mission_that_sees_nothing():
    scenario = random_scenario(3, seed=1, agent={"position": (1e6, 1e6)})
    record = run_episode(scenario, StationaryPlanner())
    assert not record.detections.any()
    assert scenario.never_observed_uncertainty() == pytest.approx(record.uncertainty, rel=1e-12)
    # the scale of docs/protocols.md: about 25.65 per target with the paper's priors and Q
    values = [random_scenario(1, seed=s).never_observed_uncertainty() for s in range(300)]
    assert np.mean(values) == pytest.approx(25.65, abs=0.1)


def test_summary_and_reductions_arithmetic(tmp_path):
    store = ResultStore(tmp_path / "b.db")
    run_benchmark(CONFIG, store)
    summary = summarise(store.rows())
    cell = summary["greedy"][2]
    u = [r.uncertainty for r in store.rows() if r.key.planner == "greedy" and r.key.n_targets == 2]
    assert cell["mean"] == pytest.approx(np.mean(u)) and cell["std"] == pytest.approx(np.std(u))
    red = reductions(summary, "greedy")[("greedy", "stationary")][2]
    base = summary["stationary"][2]["mean"]
    assert red == pytest.approx(100 * (base - cell["mean"]) / base)


def test_scenarios_follow_seeds_and_setting():
    key = CONFIG.keys()[0]
    assert scenario_for(key) == random_scenario(key.n_targets, key.seed, homogeneous=True)


def test_the_printed_q_form_is_part_of_the_setting_and_of_the_scenario(tmp_path):
    printed = config(process_noise_form="paper_text")
    key, base = printed.keys()[0], CONFIG.keys()[0]
    assert (key.setting, base.setting) == ("homogeneous+paper_text", "homogeneous")
    assert scenario_for(key) == random_scenario(
        key.n_targets, key.seed, homogeneous=True, process_noise_form="paper_text"
    )
    store = ResultStore(tmp_path / "r.db")
    run_benchmark(config(target_counts=(2,), scenarios=1), store)
    run_benchmark(config(target_counts=(2,), scenarios=1, process_noise_form="paper_text"), store)
    rows = {r.key.setting: r.uncertainty for r in store.rows() if r.key.planner == "greedy"}
    store.close()
    assert set(rows) == {"homogeneous", "homogeneous+paper_text"}
    assert rows["homogeneous"] != rows["homogeneous+paper_text"]


def test_a_different_option_never_reuses_another_settings_rows(tmp_path):
    store = ResultStore(tmp_path / "b.db")
    small = config(("astar",), {"astar": {"horizon": 2}}, target_counts=(2,), scenarios=1)
    other = config(("astar",), {"astar": {"horizon": 3}}, target_counts=(2,), scenarios=1)
    assert run_benchmark(small, store) == 1
    assert run_benchmark(small, store) == 0  # resumed: nothing to do
    assert run_benchmark(other, store) == 1  # another horizon: its own episode
    rows = store.rows()
    assert len(rows) == 2
    horizons = sorted(json.loads(r.key.planner_settings)["horizon"] for r in rows)
    assert horizons == [2, 3]
    assert len({r.key.planner_settings_hash for r in rows}) == 2
    assert (
        rows[0].key.planner_settings_hash
        == planner_settings("astar", json.loads(rows[0].key.planner_settings)).digest()
    )


def _run_in_process(path, delay_s, queue):
    """A second benchmark process on the same database (for the claim test)."""
    import time

    from hptrack.experiments import benchmark

    real = benchmark.run_one

    def slow(key):
        time.sleep(delay_s)
        return real(key)

    benchmark.run_one = slow
    store = ResultStore(path)
    queue.put(run_benchmark(config(scenarios=3), store))


def test_two_runs_on_one_database_share_the_work(tmp_path):
    path = tmp_path / "b.db"
    ResultStore(path).close()
    queue = multiprocessing.get_context("spawn").Queue()
    procs = [
        multiprocessing.get_context("spawn").Process(
            target=_run_in_process, args=(path, 0.3, queue)
        )
        for _ in range(2)
    ]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=300)
    counts = sorted(queue.get(timeout=5) for _ in procs)
    total = len(config(scenarios=3).keys())
    assert sum(counts) == total  # every episode ran exactly once
    assert min(counts) > 0  # and both runs did part of it
    rows = ResultStore(path).rows()
    assert len(rows) == len({r.key for r in rows}) == total


class _StoresBefore:
    """A database connection that lets another run store ``row`` just before this one writes
    its claim (the interleaving a claim must survive)."""

    def __init__(self, db, other, row):
        self._db, self._other, self._row = db, other, row

    def execute(self, sql, *args):
        if sql.startswith("INSERT OR IGNORE INTO claims") and self._row is not None:
            self._other.add(self._row)
            self._row = None
        return self._db.execute(sql, *args)

    def __getattr__(self, name):
        return getattr(self._db, name)

    def __enter__(self):
        return self._db.__enter__()

    def __exit__(self, *exc):
        return self._db.__exit__(*exc)


def test_an_episode_stored_by_another_run_while_claiming_is_not_claimed(tmp_path):
    """Run A holds a claim and stores its episode (dropping the claim) while run B claims the
    same key: B must not get it, or the episode runs twice."""
    from hptrack.sim.record import EpisodeRow

    first, second = ResultStore(tmp_path / "b.db"), ResultStore(tmp_path / "b.db")
    key = CONFIG.keys()[0]
    assert first.claim(key)
    second._db = _StoresBefore(second._db, first, EpisodeRow(key, 10.0, 50.0, 3, 1.0, {}))
    assert not second.claim(key)
    assert [r.key for r in second.rows()] == [key]
    assert second._db.execute("SELECT COUNT(*) FROM claims").fetchone()[0] == 0


def test_claims_of_a_dead_run_are_released(tmp_path):
    store = ResultStore(tmp_path / "b.db")
    key = CONFIG.keys()[0]
    with sqlite3.connect(tmp_path / "b.db") as db:
        db.execute(
            "INSERT INTO claims VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (*key._id(), store._host, 2**22 + 12345, 0.0),
        )
    assert not store.claim(key)
    assert store.release_stale_claims() == 1
    assert store.claim(key)


def test_a_file_that_is_not_a_results_database_is_refused(tmp_path):
    text = tmp_path / "notes.db"
    text.write_text("not sqlite\n" * 100)
    with pytest.raises(InputError, match="not an hptrack results database"):
        ResultStore(text)
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE things (x)")
    with pytest.raises(InputError, match="another layout"):
        ResultStore(other)


def test_benchmark_command_end_to_end(cli, tmp_path):
    result = cli(
        "benchmark",
        "--targets",
        2,
        "--scenarios",
        2,
        "--planners",
        "greedy,stationary",
        "--db",
        tmp_path / "b.db",
        "--out",
        tmp_path / "out",
        "--json",
        tmp_path / "b.json",
    )
    assert result.code == 0, result.err
    data = json.loads((tmp_path / "b.json").read_text())
    assert set(data) == {"greedy", "stationary"}
    assert data["greedy"]["2"]["episodes"] == 2
    for name in (
        "table.md",
        "episodes.csv",
        "episodes_summary.csv",
        "uncertainty_boxes.png",
        "trajectories.png",
    ):
        assert (tmp_path / "out" / name).exists(), name
    assert "never observed" in (tmp_path / "out" / "table.md").read_text()
    assert "greedy: none" in (tmp_path / "out" / "table.md").read_text()  # no effort claimed


def test_the_wall_time_leaves_out_the_warm_up_and_the_result_is_the_same(monkeypatch):
    from hptrack.experiments import benchmark
    from hptrack.experiments.store import EpisodeKey

    events = []
    real_run, real_clock = benchmark.run_episode, benchmark.time.perf_counter

    def run(scenario, planner, **kwargs):
        events.append(("mission", scenario.n_steps))
        return real_run(scenario, planner, **kwargs)

    def clock():
        events.append(("clock",))
        return real_clock()

    monkeypatch.setattr(benchmark, "run_episode", run)
    monkeypatch.setattr(benchmark.time, "perf_counter", clock)
    monkeypatch.setattr(benchmark, "_warmed", set())
    settings = planner_settings("greedy", None).canonical()
    first, second = (EpisodeKey("greedy", 2, s, "homogeneous", settings) for s in (0, 1))
    rows = [benchmark.run_one(first), benchmark.run_one(second), benchmark.run_one(first)]
    steps = scenario_for(first).n_steps
    mission, clocked = ("mission", steps), ("clock",)
    # the warm-up flies the first steps once for the planner, before the timed span opens
    assert events == [
        ("mission", benchmark.WARM_UP_STEPS),
        *[clocked, mission, clocked] * 3,
    ]
    # a warmed-up episode gives what a cold one gives
    alone = run_episode(scenario_for(first), benchmark.planner_for(first))
    assert rows[0].uncertainty == rows[2].uncertainty == alone.uncertainty
    assert rows[0].detections == int(alone.detections.sum())


@pytest.mark.parametrize(
    ("label", "block"),
    [
        ("", None),
        ("constant_velocity", None),
        ("random_walk:5", {"model": "random_walk", "diffusion": 5.0}),
        ("ornstein_uhlenbeck", {"model": "ornstein_uhlenbeck"}),
        ("singer:0.05:0.01", {"model": "singer", "damping": 0.05, "acceleration_std": 0.01}),
        ("singer::0.01", {"model": "singer", "acceleration_std": 0.01}),
        ("constant_acceleration:1e-7", {"model": "constant_acceleration", "jerk_intensity": 1e-7}),
    ],
)
def test_a_motion_label_names_the_scenarios_motion_block(label, block):
    from hptrack.experiments.benchmark import motion_label

    assert motion_label(label) == block


@pytest.mark.parametrize(
    ("label", "said"),
    [
        ("spin:1", "the model is one of"),
        ("singer:0.1:0.2:0.3", "at most 2 values"),
        ("random_walk:x", "'x' is not a number"),
    ],
)
def test_a_bad_motion_label_is_one_line(label, said):
    from hptrack.experiments.benchmark import motion_label

    with pytest.raises(InputError, match=said) as err:
        motion_label(label)
    assert "\n" not in str(err.value)
