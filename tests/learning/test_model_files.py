"""Model and run files are data, never code: a pickle planted in a model, a checkpoint or a log's
model is refused in one line (exit code 2) or never loaded, and no payload runs; other wrong
files are one line too."""

import json
import pickle

import numpy as np
import pytest
import torch
from conftest import payload_pickle, ppo_zip_with, refused_in_one_line

from hptrack.learning.agent import save_policy
from hptrack.learning.network import GaussianQNetwork
from hptrack.learning.policy_planner import packaged_model
from hptrack.learning.sb3 import PpoConfig, PpoTrainer
from hptrack.learning.train import TrainConfig, Trainer, tracking_task
from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog
from hptrack.runtime.simulated import run_simulated
from hptrack.scenario import random_scenario

SIMULATE = ("simulate", "--random", "--targets", 2, "--seed", 1)


@pytest.fixture
def marker(tmp_path):
    path = tmp_path / "payload-ran"
    yield path
    assert not path.exists(), "the planted pickle ran"


def test_the_planted_payload_is_live(tmp_path):
    """The payload of these tests does run when unpickled (so its absence means something)."""
    marker = tmp_path / "m"
    pickle.loads(payload_pickle(marker))
    assert marker.exists()


def test_sb3_refuses_a_pickle_in_the_policy_tensors(cli, tmp_path, marker):
    model = ppo_zip_with(
        tmp_path / "evil.zip", packaged_model("sb3", 2), {"policy.pth": payload_pickle(marker)}
    )
    refused_in_one_line(
        cli(*SIMULATE, "--planner", "sb3", "-o", f"model={model}"),
        "planner 'sb3'",
        "evil.zip",
        "refused",
    )


def test_sb3_never_unpickles_the_zip_data(cli, tmp_path, marker):
    """stable-baselines3's ``PPO.load`` would unpickle the ``:serialized:`` fields of ``data``;
    the planner reads only its plain JSON and flies the weights."""
    source = packaged_model("sb3", 2)
    import base64
    import zipfile

    with zipfile.ZipFile(source) as archive:
        data = json.loads(archive.read("data"))
    data["policy_class"][":serialized:"] = base64.b64encode(payload_pickle(marker)).decode()
    model = ppo_zip_with(tmp_path / "evil.zip", source, {"data": json.dumps(data).encode()})
    result = cli(
        *SIMULATE,
        "--planner",
        "sb3",
        "-o",
        f"model={model}",
    )
    assert result.code == 0, result.err


def test_adfq_refuses_a_pickle_without_torch_warnings(cli, tmp_path, marker):
    model = tmp_path / "evil.pt"
    model.write_bytes(payload_pickle(marker))
    line = refused_in_one_line(
        cli(*SIMULATE, "--planner", "adfq", "-o", f"model={model}"), "planner 'adfq'", "refused"
    )
    assert "weights_only" not in line


def test_a_ppo_resume_refuses_a_pickle_in_its_checkpoint(cli, tmp_path, marker):
    out = tmp_path / "run"
    PpoTrainer(tracking_task(2, False, 1), PpoConfig(steps=1800), out)  # writes config.json
    ppo_zip_with(
        out / "checkpoint-1800.zip",
        packaged_model("sb3", 2),
        {"policy.pth": payload_pickle(marker)},
    )
    state = {
        "step": 1800,
        "episodes": 1,
        "last_checkpoint": 1800,
        "curve": [],
        "best_u": 60.0,
        "best_step": 0,
        "checkpoint": "checkpoint-1800.zip",
    }
    (out / "state.json").write_text(json.dumps(state))
    args = ["learn", "sb3-ppo", "--targets", 2, "--steps", 3600, "--validation-scenarios", 1]
    refused_in_one_line(cli(*args, "--out", out), f"--out {out}", "checkpoint-1800.zip", "refused")
    (out / "state.json").write_text(json.dumps({**state, "checkpoint": "../elsewhere.zip"}))
    refused_in_one_line(cli(*args, "--out", out), "state.json", "checkpoint")


def test_an_adfq_resume_refuses_a_pickle_in_its_checkpoint(cli, tmp_path, marker):
    out = tmp_path / "run"
    Trainer(tracking_task(2, False, 1), TrainConfig(steps=20_000), out)  # writes config.json
    (out / "checkpoint.pt").write_bytes(payload_pickle(marker))
    args = ["learn", "adfq", "--targets", 2, "--steps", 20_000, "--validation-scenarios", 1]
    refused_in_one_line(cli(*args, "--out", out), f"--out {out}", "checkpoint.pt", "refused")
    torch.save({"replay_file": "replay-0.npz", "agent": {}}, out / "checkpoint.pt")
    refused_in_one_line(cli(*args, "--out", out), "checkpoint.pt does not fit this run")


def _hover_model(path, n_targets=2):
    net = GaussianQNetwork(6 * n_targets + 1, 13)
    with torch.no_grad():
        net.head.bias[12] = 2.0
    save_policy(str(path), net, {})
    return path


def test_replay_flies_the_logged_decisions_never_the_logged_model(cli, tmp_path, marker):
    """Replaying somebody's log must not load the model file it names: the decisions are the
    log's, the beliefs are recomputed and match."""
    model = _hover_model(tmp_path / "policy.pt")
    scenario = random_scenario(2, 0).model_copy(update={"budget": 20.0})
    log_path = tmp_path / "m.jsonl"
    log = MissionLog(log_path)
    run = run_simulated(scenario, make_planner("adfq", {"model": str(model)}), seed=1, log=log)
    log.close()
    model.write_bytes(payload_pickle(marker))  # the named model is now a payload
    result = cli("replay", log_path, "--plot", tmp_path / "r.png", "--json", tmp_path / "r.json")
    assert result.code == 0, result.err
    summary = json.loads((tmp_path / "r.json").read_text())
    assert summary["decisions"] == "logged" and summary["mismatches"] == 0
    assert summary["U"] == run.uncertainty and summary["plans"] > 30
    assert "decisions taken from the log" in " ".join(result.out.split())


def test_a_sb3_model_given_to_adfq_and_back_name_the_planner_to_use(cli, tmp_path):
    refused_in_one_line(
        cli(*SIMULATE, "--planner", "adfq", "-o", f"model={packaged_model('sb3', 2)}"),
        "is a stable-baselines3 model",
        "--planner sb3",
    )
    refused_in_one_line(
        cli(*SIMULATE, "--planner", "sb3", "-o", f"model={packaged_model('adfq', 2)}"),
        "not a stable-baselines3 model (a torch file",
        "--planner adfq",
    )


def test_wrong_adfq_model_files_are_one_line(cli, tmp_path):
    csv = tmp_path / "episodes.csv"
    csv.write_text("episode,seed\n1,2\n")
    refused_in_one_line(
        cli(*SIMULATE, "--planner", "adfq", "-o", f"model={csv}"), "episodes.csv", "cannot be read"
    )
    # a policy file whose network description does not fit its tensors
    good = torch.load(packaged_model("adfq", 2), weights_only=True)
    for network in ({**good["network"], "hidden": [64, 128]}, {"obs_dim": 13}):
        torch.save({**good, "network": network}, tmp_path / "bad.pt")
        refused_in_one_line(
            cli(*SIMULATE, "--planner", "adfq", "-o", f"model={tmp_path / 'bad.pt'}"),
            "bad.pt",
            "do not fit",
        )


def test_the_sb3_planner_decides_as_stable_baselines3(tmp_path):
    """The actor rebuilt from the shipped zip's tensors takes PPO.predict's deterministic
    actions and has its action probabilities (the shipped files are trusted)."""
    from stable_baselines3 import PPO

    from hptrack.learning.sb3 import load_actor

    path = packaged_model("sb3", 4)
    model, actor = PPO.load(str(path), device="cpu"), load_actor(path)
    obs = np.random.default_rng(0).normal(size=(300, 25)).astype(np.float32)
    expected = model.predict(obs, deterministic=True)[0]
    assert [int(actor.distribution(o).mode[0]) for o in obs] == expected.tolist()
    tensor, _ = model.policy.obs_to_tensor(obs[0])
    probs = model.policy.get_distribution(tensor).distribution.probs[0].detach().numpy()
    np.testing.assert_array_equal(actor.distribution(obs[0]).probs[0].numpy(), probs)
