"""The network boundary of the flight adapters: UDP addresses (``udp://HOST:PORT``) and the
detection lines that arrive there, parsed without ever raising (`parse_detection_line`)."""

from __future__ import annotations

import contextlib
import ipaddress
import json
import os
import socket
from dataclasses import dataclass
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator

from hptrack.interface import InputError, one_line, shown


def udp_address(url: str, option: str, loopback_only: bool = False) -> tuple[str, int]:
    """``(host, port)`` of ``udp://HOST:PORT`` (also ``udpin://``, ``udpout://``).

    Raises:
        InputError: a malformed URL, or (``loopback_only``) a host that is not a loopback
            address.
    """
    scheme, sep, rest = url.partition("://")
    host, colon, port_text = rest.rpartition(":")
    if not sep or scheme not in ("udp", "udpin", "udpout") or not colon or not host:
        raise InputError(f"{option} {url!r}: expected udp://HOST:PORT")
    try:
        port = int(port_text)
    except ValueError:
        raise InputError(f"{option} {url!r}: the port {port_text!r} is not a number") from None
    if not 0 < port < 65536:
        raise InputError(f"{option} {url!r}: the port must be 1-65535")
    if loopback_only:
        try:
            loop = host == "localhost" or ipaddress.ip_address(host).is_loopback
        except ValueError:
            loop = False
        if not loop:
            raise InputError(
                f"{option} {url!r}: the vehicle stub uses loopback addresses only "
                "(127.0.0.1 or localhost)"
            )
        host = "127.0.0.1" if host == "localhost" else host
    return host, port


MAX_DETECTION_LINE_CHARS = 4096
"""Longest detection line (a detection with a covariance takes about 150 characters)."""
MAX_NUMBER_CHARS = 40
"""Longest number literal in a detection (a float written in full takes 24)."""


@dataclass(frozen=True)
class DetectionMessage:
    """One detection line, well formed: ``target`` id (``None``: a detection without
    identity), ``position`` (x east, y north) m, ``covariance`` 2x2 m^2 or ``None``, ``stamp``
    Unix time s or ``None`` (time of arrival), ``confidence`` in ``[0, 1]`` or ``None`` (the
    detector's score, logged), ``vehicle`` the index of the team's UAV whose camera took it
    or ``None``."""

    target: str | None
    position: tuple[float, float]
    covariance: tuple[tuple[float, float], tuple[float, float]] | None
    stamp: float | None
    confidence: float | None = None
    vehicle: int | None = None


@dataclass(frozen=True)
class Refusal:
    """Why a line is not a detection: ``reason`` (counted) and ``detail`` (one line)."""

    reason: str
    detail: str


_Number = Annotated[float, Strict()]


class _DetectionFields(BaseModel):
    model_config = ConfigDict(extra="ignore", allow_inf_nan=False, frozen=True)

    id: Annotated[str, Strict(), Field(min_length=1, max_length=200)] | None = None
    x: _Number
    y: _Number
    t: _Number | None = None
    cov: tuple[tuple[_Number, _Number], tuple[_Number, _Number]] | None = None
    confidence: Annotated[_Number, Field(ge=0.0, le=1.0)] | None = None
    vehicle: Annotated[_Number, Field(ge=0, le=255)] | None = None

    @field_validator("vehicle")
    @classmethod
    def _whole(cls, value: float | None) -> float | None:
        if value is not None and not value.is_integer():
            raise ValueError("a vehicle index is a whole number")
        return value


def _number_token(text: str) -> float:
    if len(text) > MAX_NUMBER_CHARS:
        raise ValueError(f"a number of {len(text)} characters")
    return float(text)


def parse_detection_line(line: str) -> DetectionMessage | Refusal:
    """Parse one JSON detection line (``{"id": "t1", "x": east_m, "y": north_m}`` with optional
    ``"t"`` Unix time s, ``"cov"`` 2x2 m^2, ``"confidence"`` in ``[0, 1]`` and ``"vehicle"``,
    the index of the team's UAV whose camera took it; without ``"id"`` a detection without
    identity, which the controller takes only on a mission whose sensor has ``labelled:
    false``) without ever raising: anything else is a
    `Refusal` (too long, not JSON, nested, a number too long to be one, a field missing
    or of the wrong type, a non-finite number)."""
    if len(line) > MAX_DETECTION_LINE_CHARS:
        return Refusal("malformed", f"a line of {len(line)} characters")
    depth = max(line.count("["), line.count("{"))
    if depth > 8:  # a detection nests three levels; deep JSON would exhaust the stack
        return Refusal("malformed", "nested too deeply for a detection")
    try:
        message = json.loads(
            line, parse_int=_number_token, parse_float=_number_token, parse_constant=float
        )
    except (ValueError, RecursionError, OverflowError) as err:
        return Refusal("malformed", f"not a JSON detection ({one_line(str(err), 120)})")
    if not isinstance(message, dict):
        return Refusal("malformed", 'expected {"id": ..., "x": ..., "y": ...} (id optional)')
    try:
        fields = _DetectionFields.model_validate(message)
    except ValidationError as err:
        first = err.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"])
        reason = "non-finite" if first["type"] == "finite_number" else "malformed"
        return Refusal(reason, one_line(f"{where}: {first['msg']} ({shown(first['input'])})"))
    return DetectionMessage(
        fields.id,
        (fields.x, fields.y),
        fields.cov,
        fields.t,
        fields.confidence,
        None if fields.vehicle is None else int(fields.vehicle),
    )


RECEIVE_BUFFER_BYTES = 4 * 2**20
"""Receive buffer asked for the detection socket, bytes (about 30,000 detections: a burst is
queued, not dropped)."""


def enlarge_receive_buffer(sock: socket.socket) -> None:
    """Ask for a `RECEIVE_BUFFER_BYTES` receive buffer (the system may give less)."""
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)


def kernel_drops(sock: socket.socket) -> int | None:
    """Datagrams the kernel dropped on ``sock`` because its receive buffer was full (Linux:
    the ``drops`` column of ``/proc/net/udp``), or ``None`` where this is not known."""
    try:
        inode = str(os.fstat(sock.fileno()).st_ino)
        for table in ("/proc/net/udp", "/proc/net/udp6"):
            with open(table) as file:
                for line in file:
                    fields = line.split()
                    if len(fields) >= 13 and fields[9] == inode:
                        return int(fields[-1])
    except (OSError, ValueError):
        return None
    return None
