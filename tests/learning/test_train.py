"""The training loop: validation, best model, checkpoints and resuming after a kill."""

import json

import numpy as np
import pytest
from conftest import CHAIN_ID

from hptrack.interface import InputError
from hptrack.learning.agent import AdfqConfig, load_policy
from hptrack.learning.train import Task, TrainConfig, Trainer

TASK = Task(CHAIN_ID, {}, tuple({"seed": i} for i in range(4)), {"env": CHAIN_ID})


def _config(steps, **agent):
    return TrainConfig(
        steps=steps,
        seed=3,
        validation_interval=100,
        checkpoint_interval=40,
        agent=AdfqConfig(warmup_steps=50, target_update=25, buffer_size=500, **agent),
    )


class Killed(Exception):
    pass


def _kill_at(step):
    def on_progress(p):
        if p.step == step:
            raise Killed

    return on_progress


@pytest.mark.parametrize("prioritized", [False, True])
def test_resume_after_a_kill_continues_exactly(tmp_path, prioritized):
    """Killed at step 270 (last checkpoint at 240, an episode end), the same command resumes
    from step 240 and ends with the curve of an uninterrupted run, entry for entry."""
    straight = Trainer(TASK, _config(400, prioritized=prioritized), tmp_path / "a").run()
    trainer = Trainer(TASK, _config(400, prioritized=prioritized), tmp_path / "b")
    with pytest.raises(Killed):
        trainer.run(_kill_at(270))
    resumed = Trainer(TASK, _config(400, prioritized=prioritized), tmp_path / "b")
    assert resumed.state.step == 240
    steps = []
    summary = resumed.run(lambda p: steps.append(p.step))
    assert steps[0] == 241 and steps[-1] == 400
    curve_a = json.loads((tmp_path / "a" / "curve.json").read_text())
    curve_b = json.loads((tmp_path / "b" / "curve.json").read_text())
    assert curve_b == curve_a
    assert [e["step"] for e in curve_b if e["kind"] == "validation"] == [0, 100, 200, 300, 400]
    assert summary == {**straight, "best_model": str(tmp_path / "b" / "best.pt")}
    assert sorted(p.name for p in (tmp_path / "b").glob("replay-*")) == ["replay-400.npz"]


def test_a_finished_run_does_no_work_and_a_longer_one_extends_it(tmp_path):
    Trainer(TASK, _config(120), tmp_path).run()
    again = Trainer(TASK, _config(120), tmp_path)
    calls = []
    summary = again.run(lambda p: calls.append(p.step))
    assert calls == [] and summary["steps"] == 120
    longer = Trainer(TASK, _config(200), tmp_path).run()
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert longer["steps"] == 200
    assert [e["step"] for e in curve if e["kind"] == "validation"] == [0, 100, 120, 200]
    episode_steps = [e["step"] for e in curve if e["kind"] == "episode"]
    assert episode_steps == sorted(set(episode_steps))


def test_best_model_is_the_lowest_validation_u(tmp_path):
    summary = Trainer(TASK, _config(300), tmp_path).run()
    curve = json.loads((tmp_path / "curve.json").read_text())
    validations = [e for e in curve if e["kind"] == "validation"]
    best = min(validations, key=lambda e: e["mean_U"])
    assert summary["best_U"] == best["mean_U"] and summary["best_step"] == best["step"]
    _, metadata = load_policy(summary["best_model"])
    assert metadata["step"] == best["step"] and metadata["validation_mean_U"] == best["mean_U"]
    assert np.isfinite(best["sem_U"])


def test_a_restart_with_other_options_is_refused(tmp_path):
    Trainer(TASK, _config(60), tmp_path).run()
    with pytest.raises(InputError, match=r"started with --seed 3 \(given: 4\);"):
        Trainer(
            TASK,
            TrainConfig(
                steps=60,
                seed=4,
                validation_interval=100,
                checkpoint_interval=40,
                agent=AdfqConfig(warmup_steps=50, target_update=25, buffer_size=500),
            ),
            tmp_path,
        )


def test_a_run_that_cannot_leave_the_warm_up_is_refused_unless_allowed(tmp_path):
    with pytest.raises(InputError) as err:
        Trainer(TASK, _config(50), tmp_path / "a")  # warm-up of 50 steps
    message = str(err.value)
    assert "--steps 50 is not above the warm-up of 50 steps" in message
    assert "--allow-untrained" in message and "\n" not in message
    assert not (tmp_path / "a" / "config.json").exists()
    summary = Trainer(TASK, _config(50), tmp_path / "b", allow_untrained=True).run()
    assert summary["steps"] == 50
