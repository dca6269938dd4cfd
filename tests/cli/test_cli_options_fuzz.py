"""CLI options at the boundary: absurd effort, sizes, delays and outputs are refused before any
work in one line with exit 2; fuzzed option values give a finished run or such a refusal."""

import os
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

FUZZ = settings.get_profile(os.environ.get("HPTRACK_FUZZ", "fuzz-ci"))
# each example runs a whole (10-step) mission through the CLI: a third of the profile's budget
CLI_FUZZ = settings(FUZZ, max_examples=max(10, FUZZ.max_examples // 3))

SCENARIO = {
    "time_step": 0.5,
    "budget": 5.0,
    "seed": 1,
    "targets": [
        {
            "id": "t1",
            "mean": [40.0, -30.0, 1.0, 0.5],
            "covariance": [[900, 0, 0, 0], [0, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
            "process_noise": 0.0003,
        }
    ],
}


@pytest.fixture(scope="module")
def scenario_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "s.yaml"
    path.write_text(yaml.safe_dump(SCENARIO))
    return path


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["simulate", "--random", "--iterations", str(2 * 10**19)], "--iterations"),
        (["simulate", "--random", "-o", "iterations=100000000000000000000"], "iterations"),
        (["simulate", "--random", "-o", "iterations=1e20"], "iterations"),
        (["simulate", "--random", "--time-limit", "1e300"], "--time-limit"),
        (["validate-coverage", "--cases", str(10**12)], "--cases"),
        (["validate-coverage", "--runs", str(10**12)], "--runs"),
        (["validate-coverage", "--delays", "1e9"], "--delays"),
        (["validate-coverage", "--workers", "4096"], "--workers"),
        (["benchmark", "--workers", "4096", "--scenarios", "1"], "--workers"),
        (["benchmark", "--scenarios", str(10**12)], "--scenarios"),
        (["benchmark", "--scenarios", "2", "--first-seed", str(2**63 - 1)], "(2^63 - 1)"),
        (["benchmark", "--iterations", "10", "--time-limit", "1"], "not both"),
        (["replay", "/dev/zero"], "not a mission log (a folder, a device"),
        (["replay", "/dev/urandom"], "not a mission log (a folder, a device"),
        (["benchmark", "--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "inf"], "3600"),
        (["learn", "adfq", "--targets", "300", "--steps", "10", "--out", "x"], "--targets"),
        (
            ["learn", "adfq", "--targets", "2", "--steps", "10", "--out", "x", "--buffer", "1e12"],
            "--buffer",
        ),
        (["simulate", "--random", "--json", "/dev/full"], "not a regular file"),
        (["simulate", "--random", "--plot", "/dev/full"], "figure format"),
        (["simulate", "--random", "--plot", "x.nosuchformat"], "figure format"),
        (["simulate", "--random", "--plot", "/proc/x.png"], "--plot"),
        ([], "give a command"),
    ],
)
def test_absurd_options_are_refused_before_any_work(cli, tmp_path, args, needle):
    os.chdir(tmp_path)
    cli(*args).refused(needle)


def test_absurd_coverage_delay_is_one_line(cli, scenario_path):
    cli("coverage", scenario_path, "--target", "t1", "--delay", "1e308").refused("--delay")


def test_the_belief_stride_advice_is_the_smallest_that_fits():
    from hptrack.cli.app import MAX_RECORD_BYTES, _check_record_size
    from hptrack.interface import InputError
    from hptrack.sim.episode import record_bytes

    n, steps = 40, 1_000_000
    with pytest.raises(InputError, match=r"--belief-stride (\d+)") as err:
        _check_record_size(n, steps, 1)
    stride = int(err.value.args[0].split("--belief-stride ")[1].split()[0])
    assert record_bytes(n, steps, stride) <= MAX_RECORD_BYTES < record_bytes(n, steps, stride - 1)
    _check_record_size(n, steps, stride)


VALUES = st.one_of(
    st.integers(-(10**25), 10**25).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(str),
    st.sampled_from(["", "x", "1e20", "-0", "nan", "1:00", "0x10", "\x1b[2J", "9" * 400]),
)


@CLI_FUZZ
@given(
    planner=st.sampled_from(["greedy", "stationary"]),
    options=st.lists(
        st.tuples(
            st.sampled_from(["--iterations", "--time-limit", "--belief-stride", "--seed"]),
            VALUES,
        ),
        max_size=3,
    ),
    extra=st.sampled_from([[], ["-o", "x=1"], ["--json", "out.json"], ["--plot", "f.png"]]),
)
def test_fuzz_simulate_options_run_or_are_refused(cli, scenario_path, planner, options, extra):
    os.chdir(scenario_path.parent)
    args = ["simulate", scenario_path, "--planner", planner, *extra]
    for option, value in options:
        args += [option, value]
    result = cli(*args)
    assert "Traceback" not in result.err + result.out
    assert "\x1b" not in result.err
    if result.code == 0:
        assert "U" in result.out
        for output in ("out.json", "f.png"):
            if output in extra:
                assert Path(output).stat().st_size > 0
    else:
        result.refused()
