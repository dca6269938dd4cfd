"""The mission log: JSON lines, one record per event or decision, flushed as each is written.

Every record is a JSON object with ``kind`` (``header`` first, then ``odometry``,
``detection``, ``tick``, ``look`` (without identity: a tick's associations), ``plan``, ``late``,
``mode``, ``end``, and the adapters' ``status``,
``safety``, ``vehicle`` (a change of the vehicle's flight mode or arming), ``foreign`` (the first
odometry from another MAVLink source) and ``abort`` (why a mission never started)), ``t`` the
mission time in s where it has one, ``wall`` the wall-clock time (Unix s) when it was written,
and ``seq`` its line number from 0. Non-finite numbers of rejected
inputs are written as the strings ``"nan"``, ``"inf"``, ``"-inf"`` so that every line is strict
JSON. `read_log` reads a log back; a last line cut short by a crash or a kill is dropped
and reported, so a log always replays up to where it ends.
"""

from __future__ import annotations

import contextlib
import json
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Annotated, Any

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
)

from hptrack.interface import InputError, one_line, shown
from hptrack.jsonout import json_ready

LOG_VERSION = 1
"""Format version written in the header record."""


def log_float(value: Any) -> float:
    """A number read back from a log (the strings ``"nan"``, ``"inf"``, ``"-inf"`` included);
    anything else that is not a number is NaN."""
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def log_array(value: Any) -> np.ndarray:
    """A nested list read back from a log as a float array (bad entries NaN)."""
    if isinstance(value, list | tuple):
        parts = [log_array(v) for v in value]
        try:
            return np.array(parts, dtype=float)
        except ValueError:  # ragged: keep the shape error for the controller to reject
            return np.full(len(parts), math.nan)
    return np.array(log_float(value))


ABORT = "abort"
"""Kind of the record an adapter writes when its mission could not start (``reason``, a short
name, and ``detail``, one line)."""
MISSION_START_MESSAGE = "offboard started: mission time 0"
"""The message of the ``status`` record a flight writes when its mission starts (a ``fly`` log
without it never started)."""

LOG_STOPPED = "log stopped"
"""Kind of the last line a file log writes when it stops at its size limit."""
_STOP_LINE_RESERVE_BYTES = 1024
"""Room kept under the size limit for the ``log stopped`` line."""


class MissionLog:
    """Writes records as JSON lines (flushed per line) and keeps them in memory.

    The file is created at the first record, so a run that writes nothing leaves no file. A
    file log never raises on a write: when a write fails (a full disk) or the next line would
    take the file beyond ``max_bytes`` (then a last ``log stopped`` line says so), the file
    stops growing, `stopped` says why and `unwritten` counts the records not in
    the file.

    Args:
        path: the file to write (created or truncated at the first record); ``None`` keeps the
            records in memory only.
        clock: wall clock for each record's ``wall`` field, s.
        max_bytes: size limit of the file, bytes (``None``: no limit).
        keep_records: also keep every record in `records` (off for a long flight, whose
            memory then stays bounded).
    """

    def __init__(
        self,
        path: str | Path | None = None,
        clock: Callable[[], float] = time.time,
        max_bytes: int | None = None,
        keep_records: bool = True,
    ) -> None:
        self.path = None if path is None else Path(path)
        self._clock = clock
        self._lock = threading.Lock()
        self.max_bytes = max_bytes
        self.keep_records = keep_records
        self.records: list[dict] = []
        self.seq = 0
        """Records written so far (the next one's ``seq``)."""
        self.bytes_written = 0
        self.stopped: str | None = None
        """Why the file stopped growing (``None`` while it grows)."""
        self.unwritten = 0
        """Records not in the file because it stopped."""
        self._file: IO[str] | None = None

    def write(self, record: dict) -> dict:
        """Append ``record`` (``wall`` and ``seq`` are added) and flush it to the file."""
        with self._lock:
            full = {**json_ready(record), "wall": self._clock(), "seq": self.seq}
            self.seq += 1
            if self.path is not None:
                self._write_line(full)
            if self.keep_records:
                self.records.append(full)
            return full

    def _write_line(self, full: dict) -> None:
        if self.stopped is not None:
            self.unwritten += 1
            return
        line = json.dumps(full, allow_nan=False) + "\n"
        size = len(line.encode("utf-8"))
        try:
            if self._file is None:
                self._file = open(self.path, "w", encoding="utf-8")  # noqa: SIM115
            if self.max_bytes is not None and (
                self.bytes_written + size > self.max_bytes - _STOP_LINE_RESERVE_BYTES
            ):
                reason = f"it reached its size limit of {self.max_bytes} bytes"
                stop = {
                    "kind": LOG_STOPPED,
                    "t": full.get("t"),
                    "reason": reason,
                    "wall": full["wall"],
                    "seq": full["seq"],
                }
                self._file.write(json.dumps(stop) + "\n")
                self._file.flush()
                self._stop(reason)
                return
            self._file.write(line)
            self._file.flush()
            self.bytes_written += size
        except OSError as err:
            self._stop(f"the write failed ({err.strerror or err})")

    def _stop(self, reason: str) -> None:
        self.stopped = reason
        self.unwritten += 1
        if self._file is not None:
            with contextlib.suppress(OSError):  # a full disk refuses the buffered rest too
                self._file.close()
            self._file = None
            if self.bytes_written == 0:  # not a single line: leave no empty file behind
                with contextlib.suppress(OSError):
                    self.path.unlink()

    def close(self) -> None:
        """Close the file (records stay in memory)."""
        with self._lock:
            if self._file is not None:
                try:
                    self._file.close()
                except OSError as err:
                    self.stopped = self.stopped or f"the write failed ({err.strerror or err})"
                self._file = None

    def __enter__(self) -> MissionLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


MAX_LOG_DEPTH = 16
"""Deepest nesting of a log record (a tick's covariances are four levels deep)."""
MAX_LOG_TIME_S = 1e9
"""Largest mission time of a record, s (a mission has at most a million steps of a minute)."""
MAX_LOG_INDEX = 2**62
"""Largest step, call or line number of a record."""
_NON_FINITE = ("nan", "inf", "-inf")


def _log_number(value: Any) -> Any:
    if value in _NON_FINITE:
        return float(value)
    return value


def _bounded_time(value: float) -> float:
    if math.isfinite(value) and abs(value) > MAX_LOG_TIME_S:
        raise ValueError(f"a mission time beyond {MAX_LOG_TIME_S:g} s")
    return value


LogNumber = Annotated[float, BeforeValidator(_log_number), Strict()]
"""A number as the log writes it: a JSON number, or ``"nan"``, ``"inf"``, ``"-inf"``."""
LogTime = Annotated[LogNumber, AfterValidator(_bounded_time)]
Index = Annotated[int, Strict(), Field(ge=0, le=MAX_LOG_INDEX)]


class _Record(BaseModel):
    """The fields every record shares (others are kept as they are)."""

    model_config = ConfigDict(extra="allow")

    kind: Annotated[str, Strict(), Field(max_length=40)]
    t: LogTime | None = None
    seq: Index | None = None
    call: Index | None = None


class _Input(_Record):
    """An odometry or detection record (one with ``raw`` was refused before it had fields)."""

    t: LogTime | None
    position: Any


class _Step(_Record):
    k: Index


class _Truth(_Step):
    states: list[tuple[LogNumber, LogNumber, LogNumber, LogNumber]]


class _End(_Record):
    t: LogTime
    reason: Annotated[str, Strict(), Field(max_length=200)]
    U: LogNumber | None = None


class _Header(BaseModel):
    model_config = ConfigDict(extra="allow")

    kind: str
    version: Any = None
    scenario: dict
    controller: dict
    planner: Annotated[str, Strict(), Field(max_length=100)]
    planner_settings: dict | None = None
    seed: Annotated[int, Strict(), Field(ge=0, lt=2**63)]


_SCHEMAS: dict[str, type[BaseModel]] = {
    "odometry": _Input,
    "detection": _Input,
    "plan": _Step,
    "tick": _Step,
    "late": _Step,
    "look": _Step,
    "truth": _Truth,
    "end": _End,
}


def _depth(value: Any) -> int:
    """Nesting depth of JSON data (iterative: a deep record cannot exhaust the stack)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        if depth > MAX_LOG_DEPTH:
            break
        if isinstance(node, dict):
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)
    return deepest


def check_record(record: dict, where: str, header: bool = False) -> None:
    """Refuse a record whose fields replay cannot use: the fields of its kind missing or of
    the wrong type (text for a number), numbers out of range, or nested deeper than
    `MAX_LOG_DEPTH`. Other fields are compared, not used, and may hold anything.

    Raises:
        InputError: one line naming the place, the field and the shortened value.
    """
    if _depth(record) > MAX_LOG_DEPTH:
        raise InputError(f"{where}: nested more than {MAX_LOG_DEPTH} levels deep")
    kind = record.get("kind")
    schema = (
        _Header if header else _SCHEMAS.get(kind, _Record) if isinstance(kind, str) else _Record
    )
    if "raw" in record and schema is _Input:
        schema = _Record
    try:
        schema.model_validate(record)
    except ValidationError as err:
        first = err.errors(include_url=False)[0]
        field = ".".join(str(p) for p in first["loc"]) or "record"
        value = "" if first["type"] == "missing" else f" (value {shown(first.get('input'))})"
        raise InputError(
            one_line(f"{where} ({shown(kind, 20)} record): {field}: {first['msg']}{value}")
        ) from None


@dataclass(frozen=True)
class LogContents:
    """A mission log read back.

    Attributes:
        header: the first record (mission, planner, seed, controller settings).
        records: every record after the header, in order.
        truncated: the last line was cut short (a crashed or killed run) and was dropped.
    """

    header: dict
    records: list[dict]
    truncated: bool


def read_log(path: str | Path) -> LogContents:
    """Read a mission log written by `MissionLog`.

    Raises:
        InputError: the file cannot be read, has no header, or has a malformed line other
            than the last one.
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: not a mission log (a folder, a device, a FIFO or a socket)")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise InputError(f"{path}: cannot read the mission log ({err.strerror})") from None
    except UnicodeDecodeError as err:
        raise InputError(
            f"{path}: not a mission log (not UTF-8 text at byte {err.start})"
        ) from None
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    records: list[dict] = []
    truncated = False
    for number, line in enumerate(lines, start=1):
        try:
            record = json.loads(line)
            if not isinstance(record, dict) or "kind" not in record:
                raise ValueError("not a log record")
        except RecursionError:
            raise InputError(
                f"{path}: line {number} is nested more than {MAX_LOG_DEPTH} levels deep"
            ) from None
        except ValueError:
            if number == len(lines) and not text.endswith("\n"):
                truncated = True
                break
            if number == 1:
                raise InputError(
                    f"{path}: not a mission log (line 1 is not a JSON record)"
                ) from None
            raise InputError(
                f"{path}: line {number} is not a mission-log record: {shown(line)}"
            ) from None
        if number > 1:
            check_record(record, f"{path}: line {number}")
        records.append(record)
    if not records or records[0]["kind"] != "header":
        raise InputError(f"{path}: not a mission log (no header record on line 1)")
    if records[0].get("version") != LOG_VERSION:
        raise InputError(
            f"{path}: mission-log version {records[0].get('version')!r} is not "
            f"supported (this hptrack reads version {LOG_VERSION})"
        )
    return LogContents(records[0], records[1:], truncated)
