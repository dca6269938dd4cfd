"""A written scenario file says the unit of every field and loads back to the same scenario."""

import re

import pytest

from hptrack.scenario import load_scenario, random_scenario, save_scenario
from hptrack.scenario.io import FIELD_COMMENTS, IDENTITY_DEFAULTS


def _fields_without_a_comment(text: str) -> list[str]:
    """The lines of a field with a value or a block (not a target's id) and no comment."""
    return [
        line
        for line in text.splitlines()
        if re.match(r"^\s*(- )?\w+:", line)
        and not re.match(r"^\s*(- )?(id|agent|targets):", line)
        and "  # " not in line
    ]


@pytest.mark.parametrize("homogeneous", [True, False])
def test_the_random_scenario_command_writes_units_and_the_same_scenario(cli, tmp_path, homogeneous):
    path = tmp_path / "x.yaml"
    setting = "--homogeneous" if homogeneous else "--heterogeneous"
    result = cli("scenario", "random", "--targets", "3", "--seed", "4", setting, "-o", path)
    assert result.code == 0, result.out + result.err
    text = path.read_text()
    assert load_scenario(path) == random_scenario(3, seed=4, homogeneous=homogeneous)
    assert _fields_without_a_comment(text) == []
    assert text.startswith("# hptrack scenario")
    assert "time_step: 0.5                  # s, the step tau" in text
    assert text.count("# q, m^2/s^3") == 3 and "# m/s" in text


def test_every_field_round_trips_with_its_comment(tmp_path):
    base = random_scenario(2, seed=7)
    odd_ids = ["a #b: c", "x" * 200]  # a comment sign and a colon inside, the longest id
    targets = [
        t.model_copy(update={"id": tid, "truth": (1.0, 2.0, 0.5, -0.25)})
        for t, tid in zip(base.targets, odd_ids, strict=True)
    ]
    agent = base.agent.model_copy(update={"measurement_noise_covariance": ((4.0, 0.5), (0.5, 9.0))})
    scenario = type(base).model_validate(
        {
            **base.model_dump(),
            "targets": [t.model_dump() for t in targets],
            "agent": agent.model_dump(),
            "process_noise_form": "paper_text",
            "budget": 120.0,
            "truth_motion": {"model": "coordinated_turn", "turn_rate": 0.01, "turn_rate_sd": 0.005},
        }
    )
    path = tmp_path / "s.yaml"
    save_scenario(scenario, path)
    text = path.read_text()
    assert load_scenario(path) == scenario
    assert _fields_without_a_comment(text) == []
    written = {
        m.group(1) for m in re.finditer(r"^\s*(?:- )?(\w+):.*  # ", text, flags=re.MULTILINE)
    }
    # the parameters of the other truth motions
    other_motions = {"diffusion", "damping", "acceleration_std", "jerk_intensity"}
    blocks = {"sensor", "sensor.model", "diameter", "vehicle", "vehicle.model", "motion"}  # unset
    blocks |= {"sensor.detection_probability", "sensor.negative_information"}  # when not default
    blocks |= {"sensor.detection_probability"}  # written only when not 1
    blocks |= {f"sensor.{name}" for name in IDENTITY_DEFAULTS}  # written when not the default
    assert written == set(FIELD_COMMENTS) - other_motions - blocks  # every field: its comment
    for motion, parameter in (
        ("random_walk", "diffusion"),
        ("ornstein_uhlenbeck", "damping"),
        ("singer", "acceleration_std"),
        ("constant_acceleration", "jerk_intensity"),
    ):
        moving = type(base).model_validate(
            {**base.model_dump(), "truth_motion": {"model": motion, parameter: 0.5}}
        )
        save_scenario(moving, path)
        assert load_scenario(path) == moving
        assert re.search(rf"^\s+{parameter}: 0.5\s+# ", path.read_text(), flags=re.MULTILINE)
