"""The scenario file boundary: hostile files are refused in one bounded line, fast, and valid
YAML (merge keys, aliases, exponents) is read as written; a fuzz over YAML text keeps it so."""

import copy
import os
import time

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.models.mission import MAX_TARGETS
from hptrack.scenario import ScenarioError, load_scenario, parse_scenario
from hptrack.scenario.io import MAX_VALUES

FUZZ = settings.get_profile(os.environ.get("HPTRACK_FUZZ", "fuzz-ci"))

TARGET = {
    "id": "t1",
    "mean": [120.0, -80.0, 1.5, -2.0],
    "covariance": [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
    "process_noise": 0.0003,
}
VALID = {"time_step": 0.5, "budget": 30.0, "seed": 3, "targets": [TARGET]}


def refused(tmp_path, text, *needles, name="s.yaml"):
    path = tmp_path / name
    path.write_text(text)
    start = time.perf_counter()
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert time.perf_counter() - start < 30.0
    assert "\n" not in message and len(message) < 700, message
    assert "\x1b" not in message
    for needle in needles:
        assert needle in message, message
    return message


def with_target(**changes):
    data = copy.deepcopy(VALID)
    data["targets"][0].update(changes)
    return yaml.safe_dump(data)


def test_a_yaml_bomb_is_refused_before_it_is_expanded(tmp_path):
    text = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        text += f"{name}: &{name} [" + ",".join([f"*{prev}"] * 9) + "]\n"
    refused(tmp_path, text + "targets: *i\n", "more than 20,000 values")


@pytest.mark.parametrize(
    "text",
    ["a: " + "[" * 20000 + "]" * 20000, "a: " + "{x: " * 20000 + "1" + "}" * 20000],
)
def test_deep_nesting_is_one_line(tmp_path, text):
    refused(tmp_path, text, "nested more than")


def test_a_long_integer_is_refused_by_its_digit_count(tmp_path):
    text = yaml.safe_dump(VALID).replace("seed: 3", "seed: " + "9" * 5000)
    refused(tmp_path, text, "5000 digits")


def test_long_lists_and_ids_are_shortened(tmp_path):
    long_mean = refused(tmp_path, with_target(mean=[1.0] * 3000), "targets.0.mean", "3000 items")
    long_id = refused(tmp_path, with_target(id="x" * 100_000), "targets.0.id", "...")
    assert len(long_mean) < 300 and len(long_id) < 300


def test_terminal_escapes_in_an_id_are_refused_and_never_printed_raw(tmp_path):
    refused(tmp_path, with_target(id="\x1b[2J\x1b[31mred\x07"), "printable", r"\x1b[2J")


@pytest.mark.parametrize(
    ("old", "new", "needle"),
    [("time_step: 0.5", 'time_step: "0.5"', "'0.5'"), ("budget: 30.0", "budget: 1:00", "'1:00'")],
)
def test_text_is_never_read_as_a_number(tmp_path, old, new, needle):
    refused(tmp_path, yaml.safe_dump(VALID).replace(old, new), "valid number", needle)


def test_a_fifo_or_a_device_is_refused_without_reading(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero", tmp_path):
        with pytest.raises(ScenarioError, match="not a regular file|a folder"):
            load_scenario(path)


def test_merge_keys_aliases_and_exponents_are_valid_yaml(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text(
        "time_step: 0.5\nbudget: 3.0e+1\n"
        "targets:\n"
        "  - &first\n"
        "    id: a\n"
        "    mean: [1, 2, 0, 0]\n"
        "    covariance: [[900, 0, 0, 0], [0, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]]\n"
        "    process_noise: 3e-4\n"
        "  - {<<: *first, id: b, process_noise: 1e-4}\n"
    )
    scenario = load_scenario(path)
    assert scenario.target_ids == ("a", "b")
    assert [t.process_noise for t in scenario.targets] == [3e-4, 1e-4]
    assert scenario.targets[1].covariance == scenario.targets[0].covariance
    assert scenario.budget == 30.0
    path.write_text(path.read_text().replace("id: b,", "id: b, id: c,"))
    refused(tmp_path, path.read_text(), "duplicated key 'id'", name="twice.yaml")


def diagonal(*variances):
    return [[v if i == j else 0 for j in range(4)] for i, v in enumerate(variances)]


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"covariance": diagonal(1e16, 1e16, 1e4, 1e4)}, "1e+13"),
        ({"covariance": diagonal(1e-300, 1e-300, 1, 1)}, "-inf"),
        ({"covariance": diagonal(900, 900, 1e-300, 1)}, "-inf"),
        ({"truth": [0.0, 0.0, 1e300, 0.0]}, "10000 m/s"),
        ({"truth": [9.99e6, 0.0, 1000.0, 0.0]}, "area"),
    ],
)
def test_physical_bounds_say_why(changes, needle):
    data = copy.deepcopy(VALID)
    data["targets"][0].update(changes)
    with pytest.raises(ScenarioError, match="targets.0") as err:
        parse_scenario(data)
    assert needle in str(err.value)


def test_the_kalman_bound_follows_the_measurement_noise():
    data = copy.deepcopy(VALID)
    data["targets"][0]["covariance"] = diagonal(1e12, 1e12, 1e3, 1e3)
    parse_scenario(data)  # 1e12 m^2 is within 1e12 R = 1e13 m^2
    data["agent"] = {"measurement_noise_std": 0.1}
    with pytest.raises(ScenarioError, match="Kalman update"):
        parse_scenario(data)


# --- fuzz: YAML text built from valid pieces, aliases and merge keys, mutated ------------------
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**40), 10**40),
    st.sampled_from(["1e999", "1:00", '"0.5"', "0x10", "1_000", ".5", "-.inf", "yes", "~"]),
)
PIECES = st.one_of(
    NUMBERS.map(str),
    st.text(max_size=6).map(lambda t: yaml.safe_dump(t).strip().removesuffix("...").strip()),
    st.sampled_from(["*p", "*q", "[*p, *p]", "{<<: *m}", "{<<: [*m, *m]}", "[]", "{}", "&z 1"]),
)


@st.composite
def yaml_texts(draw):
    lines = [
        "x: &p [1, 2]",
        "y: &q [*p, *p, *p]",
        "z: &m {process_noise: 3.0e-4, id: m}",
    ]
    keep_helpers = draw(st.booleans())
    body = yaml.safe_dump(VALID, default_flow_style=True).strip().splitlines()
    text = "\n".join(body)
    for _ in range(draw(st.integers(1, 4))):
        pattern = draw(st.sampled_from(["0.5", "30.0", "3", "t1", "120.0", "0.0003", "900", "0.4"]))
        text = text.replace(pattern, draw(PIECES), 1)
    if keep_helpers:
        text = "\n".join(lines) + "\n" + text.replace("{budget", "{<<: *m, budget", 1)
    return text


@FUZZ
@given(text=yaml_texts())
def test_fuzz_yaml_text_loads_or_is_refused_in_one_line(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("fuzz") / "s.yaml"
    path.write_text(text)
    try:
        scenario = load_scenario(path)
    except ScenarioError as err:
        message = str(err)
        assert "\n" not in message and len(message) < 700 and "\x1b" not in message
        return
    assert 1 <= len(scenario.targets) and scenario.n_steps >= 1
    assert all(isinstance(v, float) for v in scenario.means().ravel())


def test_the_value_count_bound_counts_expanded_aliases():
    assert MAX_VALUES >= MAX_TARGETS * 40  # the largest scenario fits
