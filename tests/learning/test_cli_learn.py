"""``hptrack learn``: bad input is one InputError line; a short run trains, resumes, plots."""

import json

import pytest
import typer
from conftest import CHAIN_ID, refused_in_one_line
from typer.testing import CliRunner

from hptrack.cli.learn import register
from hptrack.interface import InputError
from hptrack.learning.sb3 import PpoConfig, PpoTrainer
from hptrack.learning.train import Task, TrainConfig, Trainer, tracking_task


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
        (["--targets", "0", "--steps", "10"], "--targets must be between 1 and 256, got 0"),
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
    assert "setting 'heterogeneous' (given: 'homogeneous')" in str(other.exception)
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


def test_a_restart_with_changed_options_names_them_in_one_line(cli, tmp_path):
    out = tmp_path / "run"
    Trainer(tracking_task(2, False, 1), TrainConfig(steps=20_000), out)  # writes config.json
    args = ["learn", "adfq", "--targets", 2, "--steps", 20_000, "--validation-scenarios", 1]
    line = refused_in_one_line(
        cli(*args, "--warmup", 5000, "--seed", 3, "--out", out),
        f"--out {out}: this run was started with --seed 0 (given: 3), --warmup 10000 (given: "
        "5000); give the same options to resume it, or another --out to start a fresh run",
    )
    assert "{" not in line  # no config dicts


def test_a_refused_learn_leaves_no_folder(cli, tmp_path):
    out = tmp_path / "new" / "run"
    refused_in_one_line(
        cli("learn", "adfq", "--targets", 2, "--steps", 3000, "--out", out), "warm-up"
    )
    assert not (tmp_path / "new").exists()
    kept = tmp_path / "kept"
    kept.mkdir()
    refused_in_one_line(cli("learn", "adfq", "--targets", 2, "--steps", 3000, "--out", kept))
    assert kept.is_dir()  # a folder the command did not make stays


@pytest.mark.parametrize("command", ["adfq", "sb3-ppo"])
def test_validation_scenarios_are_bounded_before_any_work(cli, tmp_path, command):
    args = ["learn", command, "--targets", 2, "--steps", 20_000, "--out", tmp_path / "r"]
    refused_in_one_line(
        cli(*args, "--validation-scenarios", 1_000_000_000),
        "--validation-scenarios must be at most 10,000, got 1000000000",
    )
    assert not (tmp_path / "r").exists()


def test_an_untrained_best_model_is_said_plainly(cli, tmp_path):
    """--allow-untrained keeps the network of step 0 (no gradient step): the summary says so
    and a warning line ends the output."""
    out = tmp_path / "run"
    result = cli(
        "learn", "adfq", "--targets", 2, "--steps", 300, "--warmup", 300, "--allow-untrained",
        "--validation-scenarios", 1, "--validation-interval", 300, "--out", out,
    )  # fmt: skip
    assert result.code == 0, result.err
    assert "at step 0 (untrained)" in " ".join(result.out.split())
    assert result.error_lines == [
        f"warning: no validation of the trained policy beat the untrained one (best at step 0, "
        f"before any learning): {out / 'best.pt'} is the untrained policy; train longer (a "
        "larger --steps resumes this run)"
    ]


def test_ppo_reports_a_best_model_from_before_the_first_update(tmp_path):
    task = Task(CHAIN_ID, {}, tuple({"seed": i} for i in range(2)), {"env": CHAIN_ID})
    config = PpoConfig(steps=40, seed=1, validation_interval=40, n_steps=40, batch_size=20)
    summary = PpoTrainer(task, config, tmp_path / "a").run()
    # validations at steps 0 and 40, both before the first update (after the first rollout)
    assert summary["best_step"] in (0, 40) and summary["best_untrained"]
