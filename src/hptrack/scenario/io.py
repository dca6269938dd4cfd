"""YAML load and save of scenarios, with one-line error messages that name field and value."""

from __future__ import annotations

import difflib
import math
import re
import stat
import typing
from collections.abc import Mapping
from pathlib import Path

import yaml
from pydantic import BaseModel, ValidationError

from hptrack.interface import InputError, one_line, shown
from hptrack.scenario.model import DEFAULT_CONFIRMATION, NOISE_FIELDS, Scenario


class ScenarioError(InputError):
    """A scenario file that cannot be read or is invalid; the message is one line."""


MAX_FILE_BYTES = 2**18
"""Largest scenario file, bytes (62 targets written in full take about 40 KB; the
`hptrack.models.mission.MAX_TARGETS` of 256 as `save_scenario` writes them, about 120 KB)."""
MAX_VALUES = 20_000
"""Most values (numbers, strings, lists, mappings) a file may hold, as written and once its
YAML aliases are expanded (a few aliases can name billions of values: a "YAML bomb"); 62
targets take about 2,500, 256 as `save_scenario` writes them about 8,500. Parsing 20,000
values takes about a second."""
MAX_DEPTH = 32
"""Deepest nesting of lists and mappings (a scenario is four levels deep)."""
MAX_INT_DIGITS = 100
"""Longest integer literal (a seed below 2^63 has 19 digits)."""
MAX_LISTED_PROBLEMS = 3
"""Problems of a validation error named in its one-line message."""

_INT = re.compile(r"^[-+]?(0b[0-1_]+|0[0-7_]+|(0|[1-9][0-9_]*)|0x[0-9a-fA-F_]+)$")
_FLOAT = re.compile(
    r"^([-+]?(\.[0-9]+|[0-9][0-9_]*(\.[0-9_]*)?)([eE][-+]?[0-9]+)?"
    r"|[-+]?\.(inf|Inf|INF)|\.(nan|NaN|NAN))$"
)


class _ScenarioLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses a mapping with the same key twice (PyYAML keeps the
    last one silently) and integers of more than `MAX_INT_DIGITS` digits, keeps merge
    keys (``<<: *defaults``), reads ``1e-4`` as a number (YAML 1.1 needs a dot) and ``1:00``
    as text (YAML 1.1 would read 60)."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._events = 0

    def get_event(self):
        self._events += 1
        if self._events > 2 * MAX_VALUES:
            raise yaml.parser.ParserError(
                None, None, f"more than {MAX_VALUES:,} values", self.peek_event().start_mark
            )
        return super().get_event()

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicated = key in seen
            except TypeError:  # an unhashable key: the base class refuses it
                break
            if duplicated:
                mark = key_node.start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicated key {shown(key)} at line {mark.line + 1}", mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        digits = sum(c.isalnum() for c in str(node.value))
        if digits > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {digits} digits", node.start_mark
            )
        return super().construct_yaml_int(node)


_ScenarioLoader.add_constructor("tag:yaml.org,2002:int", _ScenarioLoader.construct_yaml_int)
# YAML 1.1's base-60 numbers (``1:00`` is 60) are text here: resolve int and float anew
_ScenarioLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if not tag.endswith((":int", ":float"))]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_ScenarioLoader.add_implicit_resolver("tag:yaml.org,2002:int", _INT, list("-+0123456789"))
_ScenarioLoader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))


def _check_size(data: object, path: Path) -> None:
    """Refuse data of more than `MAX_VALUES` values or `MAX_DEPTH` levels, looking
    at no more than that (aliases make the expanded data far larger than the file)."""
    stack, count = [(data, 1)], 0
    while stack:
        node, depth = stack.pop()
        count += 1
        if count > MAX_VALUES:
            raise ScenarioError(
                f"{path}: more than {MAX_VALUES:,} values once its YAML aliases are expanded"
            )
        if depth > MAX_DEPTH:
            raise ScenarioError(f"{path}: nested more than {MAX_DEPTH} levels deep")
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
            count += len(node)
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)


def _read_regular_file(path: Path, what: str) -> bytes:
    """The bytes of a regular file of at most `MAX_FILE_BYTES` (a FIFO, a device or a
    folder is refused before it is opened: reading one may never end)."""
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise ScenarioError(f"{path}: {kind}, not a {what}")
        with path.open("rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise ScenarioError(f"{path}: cannot read {what} ({err.strerror})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ScenarioError(f"{path}: larger than {MAX_FILE_BYTES // 2**10} KiB; is it a {what}?")
    return raw


def read_yaml(path: str | Path, what: str = "file") -> object:
    """Parse a YAML file (UTF-8 text, no duplicated keys, bounded size), or raise
    `ScenarioError` naming the file."""
    path = Path(path)
    raw = _read_regular_file(path, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(
            f"{path}: not a UTF-8 text file (byte {err.start}); is it a {what}?"
        ) from None
    if "\x00" in text:
        raise ScenarioError(f"{path}: a binary file, not a {what}")
    try:
        data = yaml.load(text, Loader=_ScenarioLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise ScenarioError(f"{path}: malformed YAML{where}: {problem}") from None
    except RecursionError:
        raise ScenarioError(f"{path}: nested more than {MAX_DEPTH} levels deep") from None
    _check_size(data, path)
    return data


def _model_at(model: type[BaseModel], loc: tuple) -> type[BaseModel] | None:
    """The model whose field ``loc[-1]`` would be (``targets.0.x``: the target's), or ``None``."""
    node: object = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(node, "model_fields", {})
        if part not in fields:
            return None
        todo, node = [fields[part].annotation], None
        while todo and node is None:  # list[TargetSpec], Optional[...]: the model inside
            kind = todo.pop()
            if isinstance(kind, type) and issubclass(kind, BaseModel):
                node = kind
            todo.extend(typing.get_args(kind))
    return node if isinstance(node, type) and issubclass(node, BaseModel) else None


def _unknown_field(item: Mapping[str, typing.Any], model: type[BaseModel] | None) -> str | None:
    """``unknown field; did you mean X?`` for a key no field of its place has."""
    if item["type"] != "extra_forbidden" or model is None:
        return None
    place = _model_at(model, tuple(item["loc"]))
    names = list(place.model_fields) if place else []
    close = difflib.get_close_matches(str(item["loc"][-1]), names, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]}?" if close else f"the fields are {', '.join(names)}"
    return f"unknown field; {hint}" if names else "unknown field"


def format_validation_error(error: ValidationError, model: type[BaseModel] | None = None) -> str:
    """One bounded line: ``field.path: message (value ...)`` for the first few problems,
    joined with ``; `` (values shortened, never printed whole). With the ``model`` validated,
    an unknown key comes first, with the field it is closest to ("did you mean ..."), and that
    field's "Field required" is left out (the same mistake)."""
    parts = []
    problems = error.errors(include_url=False, include_context=False)
    unknown = {id(item): _unknown_field(item, model) for item in problems}
    meant = {
        (*item["loc"][:-1], text.removeprefix("unknown field; did you mean ").rstrip("?"))
        for item in problems
        if (text := unknown[id(item)]) and "did you mean" in text
    }
    problems = sorted(
        (i for i in problems if not (i["type"] == "missing" and tuple(i["loc"]) in meant)),
        key=lambda i: unknown[id(i)] is None,
    )
    for item in problems[:MAX_LISTED_PROBLEMS]:
        loc = ".".join(shown(p, 40).strip("'") for p in item["loc"]) or "scenario"
        msg = unknown[id(item)] or one_line(item["msg"].removeprefix("Value error, "), 300)
        value = item.get("input")
        large = isinstance(value, float) and math.isfinite(value) and abs(value) >= 1e6
        text = f"{value:g}" if large else shown(value)
        show = not isinstance(value, dict) and "value" not in msg
        parts.append(f"{loc}: {msg}" + (f" (value {text})" if show else ""))
    if len(problems) > MAX_LISTED_PROBLEMS:
        parts.append(f"and {len(problems) - MAX_LISTED_PROBLEMS} more problems")
    return "; ".join(parts)


def parse_scenario(data: object, source: str = "scenario") -> Scenario:
    """Validate already-parsed YAML/JSON data."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: expected a mapping at the top level, got {shown(data)}")
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(f"{source}: {format_validation_error(err, Scenario)}") from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a YAML scenario file."""
    return parse_scenario(read_yaml(path, "scenario file"), str(path))


FIELD_COMMENTS = {
    "time_step": "s, the step tau",
    "budget": "s, the mission's length",
    "seed": "drives the true initial states (when not given) and all noise",
    "process_noise_form": "the per-step Q: continuous or paper_text",
    "motion": "how the beliefs assume the targets move (and, by default, how they do)",
    "truth_motion": "how the simulated targets truly move when not as motion says",
    "model": "constant_velocity, coordinated_turn, random_walk or ornstein_uhlenbeck",
    "turn_rate": "rad/s, counter-clockwise positive",
    "turn_rate_sd": "rad/s, spread of the per-target rates",
    "diffusion": "m^2/s per axis",
    "damping": "1/s, the decay rate of the velocity (OU) or of the acceleration (Singer)",
    "acceleration_std": "m/s^2 per axis, the accelerations' spread",
    "jerk_intensity": "m^2/s^5 per axis, the white jerk's intensity",
    "position": "m, [x, y]",
    "speed": "m/s",
    "sensor_diameter": "m, the footprint's diameter w",
    "sensor": "what a look measures (the paper's footprint by default)",
    "sensor.model": "footprint: measures every target within diameter / 2",
    "sensor.detection_probability": "chance a look detects a target inside: a number, or "
    "rows [distance from the centre m, Pd]",
    "sensor.negative_information": "true: a look that sees nothing updates the beliefs",
    "sensor.false_alarm_density": "false detections per m^2 per look inside the footprint",
    "sensor.labelled": "true: detections name their target; false: positions only",
    "sensor.association": "gnn or jpda, for detections without identity",
    "sensor.confirmation": "[M, N]: a new track claims a target after M of N looks",
    "diameter": "m, the footprint's diameter w",
    "vehicle": "how the agent moves (the paper's holonomic point by default)",
    "vehicle.model": "holonomic: straight at up to speed, any direction",
    "measurement_noise_std": "m per axis (R = std^2 I)",
    "measurement_noise_covariance": "m^2, R (2x2)",
    "mean": "prior [x, y, vx, vy]: m, m, m/s, m/s",
    "covariance": "prior over [x, y, vx, vy]: m^2, m^2/s, (m/s)^2",
    "process_noise": "q, m^2/s^3",
    "truth": "true initial [x, y, vx, vy]: m, m, m/s, m/s",
}
"""The comment `save_scenario` writes after each field: its units and meaning (a key
``block.field`` is that field of a top-level block, before the field's own name)."""

SCENARIO_HEADER = (
    "# hptrack scenario (check it with: hptrack scenario check FILE); SI units: m, s, m/s\n"
)

_FIELD_LINE = re.compile(r"^\s*(?:- )?(\w+):")


class _BlockMappings(yaml.SafeDumper):
    """Every mapping in block style, one field a line (so each carries its comment); lists of
    numbers stay on one line."""


_BlockMappings.add_representer(
    dict,
    lambda dumper, data: dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=False),
)


IDENTITY_DEFAULTS = {
    "false_alarm_density": 0.0,
    "labelled": True,
    "association": "gnn",
    "confirmation": list(DEFAULT_CONFIRMATION),
}
"""The ``sensor:`` fields of detections without identity at their defaults (as JSON), which a
written file leaves out (so a file of the paper's sensor reads as before)."""


def file_data(scenario: Scenario) -> dict:
    """The scenario as the data of its file: every field, ``None`` left out; a ``sensor:`` or
    ``vehicle:`` block holds the facts it stands for (the ``agent:`` block then leaves them
    out, so that each is written once). A team's ``agents:`` keep their own speeds, diameters
    and noise, the blocks holding only what they give for all."""
    data = scenario.model_dump(mode="json", exclude_none=True)
    team = scenario.agents is not None
    if team:
        data.pop("agent")  # the team's agents: stand for it
    blocks = data["agents"] if team else [data["agent"]]
    if scenario.vehicle is not None:
        vehicle = scenario.vehicle if team else scenario.vehicle_spec()
        data["vehicle"] = vehicle.model_dump(mode="json", exclude_none=True)
        if not team or "speed" in scenario.vehicle.model_fields_set:
            for block in blocks:
                block.pop("speed")
        else:
            data["vehicle"].pop("speed")
    if scenario.sensor is not None:
        given = scenario.sensor.model_fields_set
        data["sensor"] = (scenario.sensor if team else scenario.sensor_spec()).model_dump(
            mode="json", exclude_none=True
        )
        if data["sensor"].get("detection_probability") == 1.0:  # the default, the paper's
            data["sensor"].pop("detection_probability")
        if data["sensor"].get("negative_information") is False:  # the default, the paper's
            data["sensor"].pop("negative_information")
        if data["sensor"].get("detection_correlation_time") == 0.0:  # independent looks
            data["sensor"].pop("detection_correlation_time")
        for name, default in IDENTITY_DEFAULTS.items():  # the paper's named detections
            if data["sensor"].get(name) == default:
                data["sensor"].pop(name)
        written = {"diameter"} & given, set(NOISE_FIELDS) & given
        for name, fields in zip(("diameter", "noise"), written, strict=True):
            if team and not fields:  # each UAV's own, in agents:
                for field in ("diameter",) if name == "diameter" else NOISE_FIELDS:
                    data["sensor"].pop(field, None)
                continue
            for block in blocks:
                for field in ("sensor_diameter",) if name == "diameter" else NOISE_FIELDS:
                    block.pop(field, None)
    return data


def save_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario as YAML (lists, not tuples, so any YAML reader can load it), each field
    followed by a comment of its units (`FIELD_COMMENTS`); it loads back to a scenario of the
    same mission (`file_data`)."""
    data = file_data(scenario)
    text = yaml.dump(
        data, Dumper=_BlockMappings, sort_keys=False, default_flow_style=None, width=math.inf
    )
    lines = [SCENARIO_HEADER.rstrip("\n")]
    block = ""
    for line in text.splitlines():
        field = _FIELD_LINE.match(line)
        if field and not line.startswith(" "):
            block = field.group(1)
        name = field.group(1) if field else ""
        comment = FIELD_COMMENTS.get(f"{block}.{name}", FIELD_COMMENTS.get(name))
        lines.append(f"{line.ljust(30)}  # {comment}" if comment else line)
    Path(path).write_text("\n".join(lines) + "\n")
