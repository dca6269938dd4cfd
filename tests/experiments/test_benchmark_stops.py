"""A benchmark stops at once on Ctrl-C and a rerun resumes; the library refuses both effort
limits at once and seeds beyond SQLite's integers."""

import os
import signal
import subprocess
import sys
import time

import pytest

from hptrack.experiments.benchmark import BenchmarkConfig, benchmark, run_benchmark
from hptrack.experiments.store import ResultStore
from hptrack.interface import InputError
from hptrack.registry import planner_settings


def config(planners=("greedy", "stationary"), **kw):
    return BenchmarkConfig(
        planners=planners, settings={p: planner_settings(p) for p in planners}, **kw
    )


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT")
def test_ctrl_c_stops_the_workers_at_once_and_a_rerun_resumes(tmp_path):
    db = tmp_path / "b.db"
    args = [
        *("benchmark", "--targets", "6", "--scenarios", "1", "--planners", "greedy,arvi"),
        *("--workers", "2", "--db", str(db), "--out", str(tmp_path / "out")),
    ]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    run = subprocess.Popen(
        [sys.executable, "-m", "hptrack.cli.app", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert "benchmark: 1/2 episodes" in run.stdout.readline()  # greedy's first is stored
        run.send_signal(signal.SIGINT)  # while a worker flies ARVI's (seconds)
        start = time.monotonic()
        out, err = run.communicate(timeout=60)
        stopped = time.monotonic() - start
    finally:
        run.kill()
        run.wait()
    assert run.returncode == 130, err
    assert stopped < 5.0, stopped
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"kept in {db}; run the same command again to resume" in err
    store = ResultStore(db)
    assert len(store.rows()) == 1 and not store._db.execute("SELECT * FROM claims").fetchall()
    again = config(("greedy", "arvi"), target_counts=(6,), scenarios=1, homogeneous=False)
    assert run_benchmark(again, store) == 1  # ARVI's episode, once
    rows = store.rows()
    assert len(rows) == len({r.key for r in rows}) == 2


def test_the_library_refuses_both_effort_limits_and_seeds_past_sqlites_range(cli, tmp_path):
    with pytest.raises(InputError, match=r"--time-limit \(iterations or time_limit\), not both"):
        benchmark(("mcts",), (2,), 1, iterations=10, time_limit=1.0)
    with pytest.raises(InputError, match=r"must lie between 0 and 9223372036854775807"):
        config(first_seed=2**63 - 1, scenarios=2)
    assert config(first_seed=2**63 - 2, scenarios=2).keys()[-1].seed == 2**63 - 1
    out = tmp_path / "out"
    for args, needle in (
        (["--iterations", "10", "--time-limit", "1"], "not both"),
        (["--first-seed", str(2**63 - 1)], "seeds 9223372036854775807 .. 9223372036854775808"),
    ):
        result = cli(
            "benchmark", "--scenarios", "2", "--out", out, "--db", tmp_path / "b.db", *args
        )
        assert result.code == 2 and len(result.error_lines) == 1, result.err
        assert needle in result.err
