"""YAML load and save of scenarios, with one-line error messages that name field and value."""

from __future__ import annotations

import math
from pathlib import Path

import yaml
from pydantic import ValidationError

from hptrack.interface import InputError
from hptrack.scenario.model import Scenario


class ScenarioError(InputError):
    """A scenario file that cannot be read or is invalid; the message is one line."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses a mapping with the same key twice (PyYAML keeps the
    last one silently)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicated = key in seen
            except TypeError:  # an unhashable key: the base class refuses it
                break
            if duplicated:
                mark = key_node.start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicated key {key!r} at line {mark.line + 1}", mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: str | Path, what: str = "file") -> object:
    """Parse a YAML file (UTF-8 text, no duplicated keys), or raise :class:`ScenarioError`
    naming the file."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise ScenarioError(f"{path}: cannot read {what} ({err.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(
            f"{path}: not a UTF-8 text file (byte {err.start}); is it a {what}?"
        ) from None
    if "\x00" in text:
        raise ScenarioError(f"{path}: a binary file, not a {what}")
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise ScenarioError(f"{path}: malformed YAML{where}: {problem}") from None


def format_validation_error(error: ValidationError) -> str:
    """One line per problem: ``field.path: message (value ...)``, joined with ``; ``."""
    parts = []
    for item in error.errors():
        loc = ".".join(str(p) for p in item["loc"]) or "scenario"
        msg = item["msg"].removeprefix("Value error, ")
        value = item.get("input")
        large = isinstance(value, float) and math.isfinite(value) and abs(value) >= 1e6
        text = f"{value:g}" if large else repr(value)
        shown = "" if isinstance(value, dict) or "value" in msg else f" (value {text})"
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
    return parse_scenario(read_yaml(path, "scenario file"), str(path))


def save_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario as YAML (lists, not tuples, so any YAML reader can load it)."""
    data = scenario.model_dump(mode="json", exclude_none=True)
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
