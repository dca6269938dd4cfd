"""YAML load and save of scenarios, with one-line error messages that name field and value."""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import ValidationError

from hptrack.scenario.model import Scenario


class ScenarioError(ValueError):
    """A scenario file that cannot be read or is invalid; the message is one line."""


def format_validation_error(error: ValidationError) -> str:
    """One line per problem: ``field.path: message (value ...)``, joined with ``; ``."""
    parts = []
    for item in error.errors():
        loc = ".".join(str(p) for p in item["loc"]) or "scenario"
        msg = item["msg"].removeprefix("Value error, ")
        value = item.get("input")
        shown = "" if isinstance(value, dict) or "value" in msg else f" (value {value!r})"
        parts.append(f"{loc}: {msg}{shown}")
    return "; ".join(parts)


def parse_scenario(data: object, source: str = "scenario") -> Scenario:
    """Validate already-parsed YAML/JSON data."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: expected a mapping at the top level, got {data!r}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(f"{source}: {format_validation_error(err)}") from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a YAML scenario file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise ScenarioError(f"{path}: cannot read ({err.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise ScenarioError(f"{path}: malformed YAML{where}: {problem}") from None
    return parse_scenario(data, str(path))


def save_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario as YAML (lists, not tuples, so any YAML reader can load it)."""
    data = scenario.model_dump(mode="json", exclude_none=True)
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
