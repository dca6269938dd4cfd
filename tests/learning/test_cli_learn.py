"""``hptrack learn``: bad input is one InputError line; a short run trains, resumes, plots."""

import json

import pytest
import typer
from conftest import CHAIN_ID
from typer.testing import CliRunner

from hptrack.cli.learn import register
from hptrack.interface import InputError
from hptrack.learning.sb3 import PpoConfig, PpoTrainer
from hptrack.learning.train import Task


@pytest.fixture
def app():
    app = typer.Typer()

    @app.callback()
    def _root() -> None:
        """hptrack."""

    register(app)
    return app


@pytest.mark.parametrize(
    "args, message",
    [
        (["--targets", "0", "--steps", "10"], "--targets must be between 1 and 62, got 0"),
        (["--targets", "2", "--steps", "0"], "--steps must be between 1 and 1e+10, got 0"),
        (["--targets", "2", "--steps", "10", "--seed", "-1"], "--seed"),
        (
            ["--targets", "2", "--steps", "10", "--validation-scenarios", "0"],
            "--validation-scenarios must be at least 1",
        ),
    ],
)
@pytest.mark.parametrize("command", ["adfq", "sb3-ppo"])
def test_bad_options_are_one_line_input_errors(app, tmp_path, command, args, message):
    result = CliRunner().invoke(app, ["learn", command, *args, "--out", str(tmp_path / "r")])
    assert isinstance(result.exception, InputError)
    assert message in str(result.exception) and "\n" not in str(result.exception)


def test_out_that_is_a_file_is_refused(app, tmp_path):
    (tmp_path / "f").write_text("")
    result = CliRunner().invoke(
        app, ["learn", "adfq", "--targets", "2", "--steps", "10", "--out", str(tmp_path / "f")]
    )
    assert isinstance(result.exception, InputError) and "is a file" in str(result.exception)


def test_learn_adfq_trains_resumes_and_plots(app, tmp_path):
    out = tmp_path / "run"
    args = [
        "learn",
        "adfq",
        "--targets",
        "2",
        "--steps",
        "300",
        "--warmup",
        "200",
        "--validation-scenarios",
        "2",
        "--validation-interval",
        "300",
        "--out",
        str(out),
    ]
    first = CliRunner().invoke(app, args)
    assert first.exit_code == 0, first.output
    assert "300 steps" in first.output
    assert {
        "best.pt",
        "checkpoint.pt",
        "config.json",
        "curve.json",
        "curve.png",
        "replay-300.npz",
    } <= {p.name for p in out.iterdir()}
    again = CliRunner().invoke(app, args)
    assert again.exit_code == 0 and "0 s this session" in again.output
    curve = json.loads((out / "curve.json").read_text())
    assert [e["step"] for e in curve if e["kind"] == "validation"] == [0, 300]
    other = CliRunner().invoke(app, [*args[:-2], "--homogeneous", "--out", str(out)])
    assert isinstance(other.exception, InputError)
    assert "setting='heterogeneous'" in str(other.exception)
    plot = CliRunner().invoke(app, ["learn", "plot", str(out), "-o", str(tmp_path / "c.png")])
    assert plot.exit_code == 0 and (tmp_path / "c.png").stat().st_size > 0


def test_ppo_run_resumes_without_repeating_entries(tmp_path):
    task = Task(CHAIN_ID, {}, tuple({"seed": i} for i in range(2)), {"env": CHAIN_ID})

    def config(steps):
        return PpoConfig(
            steps=steps,
            seed=1,
            validation_interval=80,
            checkpoint_interval=40,
            n_steps=40,
            batch_size=20,
            n_epochs=2,
        )

    class Killed(Exception):
        pass

    def kill(p):
        if p.step == 130:
            raise Killed

    with pytest.raises(Killed):
        PpoTrainer(task, config(200), tmp_path).run(kill)
    resumed = PpoTrainer(task, config(200), tmp_path)
    assert resumed.state["step"] == 120 and resumed.state["checkpoint"] == "checkpoint-120.zip"
    summary = resumed.run()
    assert summary["steps"] == 200
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert [e["step"] for e in curve if e["kind"] == "validation"] == [0, 80, 160, 200]
    assert [e["episode"] for e in curve if e["kind"] == "episode"] == list(range(1, 11))
    assert (tmp_path / "best.zip").exists()


def test_adfq_below_the_warm_up_is_refused(app, tmp_path):
    out = tmp_path / "r"
    args = ["learn", "adfq", "--targets", "2", "--steps", "3000", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert isinstance(result.exception, InputError)
    assert "--steps 3000 is not above the warm-up of 10,000 steps" in str(result.exception)
    assert not (out / "best.pt").exists()


def test_ppo_says_when_it_rounds_the_steps_up(app, tmp_path, monkeypatch):
    import hptrack.cli.learn as learn_cli
    import hptrack.learning.sb3 as sb3

    assert [sb3.trained_steps(s, 1800) for s in (1, 1800, 1801, 3000, 3600)] == [
        1800,
        1800,
        3600,
        3600,
        3600,
    ]
    seen = {}
    monkeypatch.setattr(sb3, "PpoTrainer", lambda task, config, out: config)
    monkeypatch.setattr(
        learn_cli, "_train", lambda config, name, out, total: seen.update(total=total)
    )
    args = ["learn", "sb3-ppo", "--targets", "2", "--out", str(tmp_path / "r")]
    result = CliRunner().invoke(app, [*args, "--steps", "3000"])
    assert result.exit_code == 0, result.output
    assert "whole rollouts of 1,800 steps: --steps 3,000 trains 3,600 steps" in result.output
    assert seen == {"total": 3600}
    result = CliRunner().invoke(app, [*args, "--steps", "3600"])
    assert result.exit_code == 0 and "rollouts" not in result.output
