"""Planner settings as validated data, and part of every result's identity.

Each planner declares its settings as one `PlannerSettings` subclass (pydantic: types,
ranges, defaults, one docstring line per field with its unit). Options from the command line
(``-o KEY=VALUE``, values read as integers, numbers, ``true``/``false``, ``none`` or text,
`hptrack.cli.common.parse_value`) or from Python are validated into it, and a bad
value is refused with one line that names the planner, the option and the value:

    planner 'mcts': option exploration must be > 0, got -1

`PlannerSettings.canonical` is the settings' canonical JSON (every field, defaults
included, keys sorted); `PlannerSettings.digest` hashes it. The benchmark store keys every
episode by it, so a run with another value of any option never reuses another run's rows.

The generic effort flags of the CLI (``--iterations``, ``--time-limit``) map to a planner's own
fields through ``effort_fields``; a planner without such a notion has none, and its results do
not claim an effort.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, Self

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hptrack.interface import InputError, shown

MAX_ITERATIONS = 10**9
"""Most search iterations (or expansions, or nodes) per decision: at 1e4 to 1e5 a second, a
billion take hours for one decision."""
MAX_TIME_LIMIT_S = 3600.0
"""Longest planning time per decision, s (an hour)."""
Iterations = Annotated[int, Field(ge=1, le=MAX_ITERATIONS)]
"""A per-decision effort count, bounded by `MAX_ITERATIONS`."""
TimeLimit = Annotated[float, Field(gt=0.0, le=MAX_TIME_LIMIT_S)]
"""A per-decision planning time, s, bounded by `MAX_TIME_LIMIT_S`."""

_PHRASES = {
    "greater_than": "must be > {gt}",
    "greater_than_equal": "must be >= {ge}",
    "less_than": "must be < {lt}",
    "less_than_equal": "must be <= {le}",
    "int_parsing": "must be an integer",
    "int_type": "must be an integer",
    "int_from_float": "must be a whole number",
    "int_parsing_size": f"must be at most {MAX_ITERATIONS:g}",
    "float_parsing": "must be a number",
    "float_type": "must be a number",
    "finite_number": "must be a finite number",
    "bool_parsing": "must be true or false",
    "bool_type": "must be true or false",
    "string_type": "must be a text",
    "missing": "is required",
    "literal_error": "must be {expected}",
}


def _phrase(error: Mapping[str, Any]) -> str:
    template = _PHRASES.get(error["type"])
    if template is None:
        return error["msg"].removeprefix("Value error, ")
    return template.format(
        **{
            k: f"{v:g}" if isinstance(v, int | float) else v
            for k, v in (error.get("ctx") or {}).items()
        }
    )


def _json_value(value: Any) -> Any:
    """``value`` in strict JSON: non-finite floats as strings, tuples as lists."""
    if isinstance(value, tuple | list):
        return [_json_value(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def digest_of(canonical: str) -> str:
    """The short hash of a canonical settings JSON text (a result's settings identity)."""
    return hashlib.sha256(canonical.encode()).hexdigest()[:16]


class PlannerSettings(BaseModel):
    """Base of every planner's settings: frozen, no unknown options, finite numbers unless a
    field says otherwise."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True
    )

    effort_fields: ClassVar[dict[str, str]] = {}
    """Generic effort flag (``iterations``, ``time_limit``) -> the field it sets."""

    @classmethod
    def from_options(cls, planner: str, options: dict[str, Any] | None = None) -> Self:
        """Validate ``options`` (strings are parsed by each field's type).

        Raises:
            InputError: one line naming the planner, the option and the value.
        """
        options = dict(options or {})
        try:
            return cls.model_validate(options)
        except ValidationError as err:
            first = err.errors()[0]
            # the field, then list positions (not the names of a union's members)
            parts = [p for k, p in enumerate(first["loc"]) if k == 0 or isinstance(p, int)]
            option = ".".join(str(p) for p in parts) or "settings"
            if first["type"] == "extra_forbidden":
                known = ", ".join(sorted(cls.model_fields)) or "none"
                raise InputError(
                    f"planner {planner!r}: unknown option {option} (its options: {known})"
                ) from None
            given = f", got {shown(first['input'])}" if first["type"] != "missing" else ""
            if not first["loc"]:  # a check across fields: the message names them
                raise InputError(f"planner {planner!r}: {_phrase(first)}") from None
            raise InputError(
                f"planner {planner!r}: option {option} {_phrase(first)}{given}"
            ) from None

    @classmethod
    def effort_options(cls, iterations: int | None, time_limit: float | None) -> dict[str, Any]:
        """The options that the generic effort flags set on this planner (none if it has no
        such notion)."""
        out = {}
        for flag, value in (("iterations", iterations), ("time_limit", time_limit)):
            if value is not None and flag in cls.effort_fields:
                out[cls.effort_fields[flag]] = value
        return out

    def as_json(self) -> dict[str, Any]:
        """Every field, in strict JSON types."""
        return {k: _json_value(v) for k, v in self.model_dump().items()}

    @classmethod
    def from_canonical(cls, text: str) -> Self:
        """The settings a `canonical` text stands for (a stored result's identity)."""
        return cls.model_validate(json.loads(text))

    def canonical(self) -> str:
        """Canonical JSON of every field (sorted keys, no spaces): part of a result's identity."""
        return json.dumps(self.as_json(), sort_keys=True, separators=(",", ":"))

    def digest(self) -> str:
        """A short hash of `canonical`."""
        return digest_of(self.canonical())

    def effort_label(self) -> str:
        """The effort fields that are set, e.g. ``"iterations=100000"`` (``"none"`` without)."""
        values = self.model_dump()
        parts = [
            f"{flag}={values[name]}"
            for flag, name in sorted(self.effort_fields.items())
            if values.get(name) is not None
        ]
        return ",".join(parts) or "none"


class NoSettings(PlannerSettings):
    """A planner without options."""
