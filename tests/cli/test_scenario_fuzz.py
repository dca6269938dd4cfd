"""Property test: mutated scenario files never make the CLI crash, hang or print a non-finite
number. Every outcome is a finished run with a finite U, or a one-line refusal with exit 2."""

import copy
import json
import math

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

VALID = {
    "time_step": 0.5,
    "budget": 30.0,
    "seed": 3,
    "process_noise_form": "continuous",
    "agent": {
        "position": [0.0, 0.0],
        "speed": 30.0,
        "sensor_diameter": 100.0,
        "measurement_noise_std": 3.1623,
    },
    "targets": [
        {
            "id": "t1",
            "mean": [120.0, -80.0, 1.5, -2.0],
            "covariance": [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
            "process_noise": 0.0003,
            "truth": [130.0, -70.0, 1.4, -2.2],
        },
        {
            "id": "t2",
            "mean": [-150.0, 60.0, 0.0, 1.0],
            "covariance": [[900, 0, 0, 0], [0, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
            "process_noise": 0.0002,
        },
    ],
}

ODD_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e300, -1e300, 1e12, 5e-324, 0.5, 7]),
    st.text(max_size=12),
    st.sampled_from(["[/x]", "[bold]", "nan", "inf", "1e999", "", "t1"]),
    st.lists(st.floats(allow_nan=False, width=32), max_size=5),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _paths(node, prefix=()):
    """Every path to a node of the nested scenario."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _paths(value, (*prefix, i))


PATHS = [p for p in _paths(VALID) if p]


@st.composite
def mutated(draw):
    data = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(PATHS))
        parent = data
        try:
            for key in path[:-1]:
                parent = parent[key]
            action = draw(st.sampled_from(["set", "delete", "extra"]))
            if action == "set":
                parent[path[-1]] = draw(ODD_VALUES)
            elif action == "delete":
                del parent[path[-1]]
            elif isinstance(parent, dict):
                parent[draw(st.text(min_size=1, max_size=6))] = draw(ODD_VALUES)
        except (KeyError, IndexError, TypeError):
            continue
    text = yaml.safe_dump(data, allow_unicode=True)
    if draw(st.booleans()):  # a duplicated top-level key, written by hand
        text += f"budget: {draw(st.sampled_from(['30', 'true', '1e7', '-1']))}\n"
    return text


def _finite_numbers(value):
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite_numbers(v) for v in value.values())
    if isinstance(value, list):
        return all(_finite_numbers(v) for v in value)
    return True


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(text=mutated())
def test_mutated_scenarios_run_or_are_refused_in_one_line(cli, tmp_path, text):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    out = tmp_path / "o.json"
    out.unlink(missing_ok=True)
    for args in (
        ["scenario", "check", path],
        ["simulate", path, "--planner", "greedy", "--json", out],
    ):
        result = cli(*args)
        assert result.code in (0, 2), (result.code, result.err[-2000:])
        assert "Traceback" not in result.err
        if result.code == 2:
            assert len(result.error_lines) == 1, result.err
            return
        assert "nan" not in result.out.lower() and "inf " not in result.out.lower()
    summary = json.loads(out.read_text())
    assert math.isfinite(summary["U"])
    assert _finite_numbers(summary)


def _edited(**changes) -> str:
    data = copy.deepcopy(VALID)
    for path, value in changes.items():
        *parents, last = path.split("__")
        node = data
        for key in parents:
            node = node[int(key)] if key.isdigit() else node[key]
        if value is KeyError:
            node.pop(last)
        else:
            node[last] = value
    return yaml.safe_dump(data)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (_edited(budget=1e308), "budget 1e+308 s is infinitely many steps of 0.5 s"),
        (_edited(time_step=1e-3, budget=1e300), "budget 1e+300 s is 1e+303 steps of 0.001 s"),
        (_edited(budget=KeyError, budgett=30.0), "budgett: unknown field; did you mean budget?"),
        (
            _edited(targets__1__process_noise=KeyError, targets__1__process_nosie=2e-4),
            "targets.1.process_nosie: unknown field; did you mean process_noise? (value 0.0002)",
        ),
        (_edited(agent__colour="red"), "agent.colour: unknown field; the fields are position,"),
        (_edited().replace("id: t1", 'id: !!binary "aGVsbG8="'), "targets.0.id: Input should be"),
        (_edited().replace("id: t1", 'id: "t\\x1b[31m"'), "targets.0.id: must be printable"),
    ],
)
def test_typos_huge_budgets_and_binary_ids_are_one_line(cli, tmp_path, text, needle):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    result = cli("scenario", "check", path)
    assert result.code == 2 and "Traceback" not in result.err, result.err
    assert len(result.error_lines) == 1 and needle in result.err, result.err
    assert "Field required" not in result.err  # a typo's field is named once, as the typo
