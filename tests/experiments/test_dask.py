"""Benchmark episodes on a Dask cluster: the same results as the local process pool, streamed
into the same resumable store."""

import multiprocessing
import socket
import sqlite3
import sys

import pytest

pytest.importorskip("distributed")

from hptrack.experiments.benchmark import BenchmarkConfig, run_benchmark, run_one  # noqa: E402
from hptrack.experiments.dask_cluster import dask_executor  # noqa: E402
from hptrack.experiments.store import ResultStore  # noqa: E402
from hptrack.registry import planner_settings  # noqa: E402

PLANNERS = ("greedy", "stationary")
CONFIG = BenchmarkConfig(
    planners=PLANNERS,
    settings={p: planner_settings(p) for p in PLANNERS},
    target_counts=(2,),
    scenarios=3,
    homogeneous=False,
)
ARGS = ("--targets", 2, "--scenarios", 3, "--planners", "greedy,stationary")


@pytest.fixture(scope="module")
def scheduler():
    """The address of a local two-process Dask cluster shared by this module's tests."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        yield cluster.scheduler_address


def _u_table(table_md: str) -> str:
    """The U and reduction tables of a report (the wall-time table differs between runs)."""
    return table_md.split("Mean wall time")[0]


def _claims(path) -> int:
    with sqlite3.connect(path) as db:
        return db.execute("SELECT COUNT(*) FROM claims").fetchone()[0]


def test_dask_local_gives_the_table_of_the_process_pool(cli, tmp_path):
    args = (
        "--targets",
        2,
        "--scenarios",
        2,
        "--planners",
        "greedy,stationary,mcts",
        "-o",
        "mcts.iterations=200",
        "--figure-planners",
        "stationary",
    )
    pool = cli(
        "benchmark", *args, "--workers", 2, "--db", tmp_path / "p.db", "--out", tmp_path / "p"
    )
    assert pool.code == 0, pool.err
    dask = cli(
        "benchmark", *args, "--dask-local", 2, "--db", tmp_path / "d.db", "--out", tmp_path / "d"
    )
    assert dask.code == 0, dask.err
    assert "2 worker threads, 2 episodes in flight" in dask.out
    assert "6 episodes run now, 6 of 6" in dask.out
    rows = {r.key: r for r in ResultStore(tmp_path / "p.db").rows()}
    dask_rows = {r.key: r for r in ResultStore(tmp_path / "d.db").rows()}
    assert set(rows) == set(dask_rows) and len(rows) == 6
    for key, row in rows.items():  # bit for bit
        assert dask_rows[key].uncertainty == row.uncertainty, key
        assert dask_rows[key].detections == row.detections, key
    assert len({r.uncertainty for r in rows.values()}) > 3  # the planners really differ
    table, dask_table = ((tmp_path / d / "table.md").read_text() for d in ("p", "d"))
    assert _u_table(dask_table) == _u_table(table)


def test_interrupted_dask_run_releases_its_claims_and_resumes(scheduler, tmp_path):
    store = ResultStore(tmp_path / "b.db")

    def stop_after_two(row, finished, total):
        if finished == 2:
            raise KeyboardInterrupt

    with dask_executor(scheduler=scheduler) as pool, pytest.raises(KeyboardInterrupt):
        run_benchmark(
            CONFIG, store, workers=pool.threads, on_done=stop_after_two, executor=pool.executor
        )
    assert len(store.rows()) == 2
    assert _claims(tmp_path / "b.db") == 0  # the episode still in flight was given back
    with dask_executor(scheduler=scheduler) as pool:
        assert run_benchmark(CONFIG, store, workers=2, executor=pool.executor) == 4
    rows = store.rows()
    assert len(rows) == len({r.key for r in rows}) == len(CONFIG.keys())


def _killed_client(address, path):
    """A benchmark client that dies (SIGKILL, no clean-up) after its first stored episode: the
    other of the two it claimed at the start (two workers) is still in flight, so its claim is
    left behind whatever the order in which they finish."""
    import os
    import signal

    def die(row, finished, total):
        if finished == 1:
            os.kill(os.getpid(), signal.SIGKILL)

    store = ResultStore(path)
    with dask_executor(scheduler=address) as pool:
        run_benchmark(CONFIG, store, workers=2, on_done=die, executor=pool.executor)


def test_killed_client_resumes_on_the_scheduler_with_the_local_values(scheduler, cli, tmp_path):
    path = tmp_path / "b.db"
    process = multiprocessing.get_context("spawn").Process(
        target=_killed_client, args=(scheduler, path)
    )
    process.start()
    process.join(timeout=120)
    assert process.exitcode == -9
    assert len(ResultStore(path).rows()) == 1
    assert _claims(path) >= 1  # the dead client's episode in flight is still claimed
    result = cli(
        "benchmark",
        *ARGS,
        "--scheduler",
        scheduler,
        "--db",
        path,
        "--out",
        tmp_path / "out",
        "--figure-planners",
        "stationary",
    )
    assert result.code == 0, result.err
    assert "5 episodes run now, 6 of 6" in result.out
    rows = ResultStore(path).rows()
    assert len(rows) == len({r.key for r in rows}) == len(CONFIG.keys())
    assert _claims(path) == 0
    for row in rows:
        assert row.uncertainty == run_one(row.key).uncertainty, row.key


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ("--scheduler", "tcp://127.0.0.1:8786", "--dask-local", 2),
            "give --scheduler (tcp://127.0.0.1:8786) or --dask-local (2), not both",
        ),
        (("--dask-local", 0), "--dask-local must be a positive number of worker processes, got 0"),
        (
            ("--scheduler", "bad://nowhere"),
            "--scheduler bad://nowhere: not a Dask scheduler address",
        ),
        (
            ("--scheduler", "tcp://127.0.0.1:{port}", "--scheduler-timeout", 1),
            "--scheduler tcp://127.0.0.1:{port}: no Dask scheduler answered within 1 s",
        ),
        (
            ("--scheduler", "tcp://x:1", "--scheduler-timeout", 0),
            "--scheduler-timeout must be a positive number of seconds of at most 3600, got 0.0",
        ),
    ],
)
def test_bad_dask_options_are_one_line_refusals(cli, tmp_path, args, message):
    port = _free_port()
    args = [str(a).format(port=port) for a in args]
    result = cli("benchmark", *ARGS, *args, "--db", tmp_path / "b.db", "--out", tmp_path / "o")
    assert result.code == 2, result.err
    assert len(result.error_lines) == 1, result.err
    assert message.format(port=port) in result.err
    assert not (tmp_path / "o" / "table.md").exists()


def test_missing_dask_is_a_one_line_refusal(cli, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    result = cli("benchmark", *ARGS, "--dask-local", 2, "--db", tmp_path / "b.db")
    assert result.code == 2
    assert len(result.error_lines) == 1, result.err
    assert "--dask-local 2: Dask is not installed" in result.err
    assert "pip install 'hptrack[dask]'" in result.err
    assert not (tmp_path / "b.db").exists()
