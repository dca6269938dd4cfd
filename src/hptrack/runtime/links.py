"""Checks of the vehicle's connection URL before a flight: a malformed URL, a serial device
that does not exist, a UDP port in use or an address not on this machine is one line, found
before anything is commanded."""

from __future__ import annotations

import errno
import socket
from pathlib import Path

from hptrack.interface import InputError

SCHEMES = ("udpin", "udpout", "tcpin", "tcpout", "serial", "serial_flowcontrol")
"""MAVSDK 4 connection schemes."""

_CAUSES = {
    "CONNECTION_URL_INVALID": "not a connection URL MAVSDK understands",
    "SOCKET_ERROR": "the host is not an IP address MAVSDK can use",
    "BIND_ERROR": "the port is in use or the address is not on this machine",
    "CONNECTION_ERROR": "the device or host cannot be opened",
}


def connection_problem(url: str, error: str) -> str:
    """One line for MAVSDK's connection error ``error`` (``Connection failed: BIND_ERROR``)."""
    code = error.rsplit(":", 1)[-1].strip()
    return f"--connection {url[:80]!r}: {_CAUSES.get(code, code)}"


def check_connection(url: str) -> None:
    """Refuse a connection URL that cannot work (module docstring).

    Raises:
        InputError: one line naming ``--connection`` and the URL.
    """
    scheme, sep, rest = url.partition("://")
    shown = repr(url[:80])
    if not sep or scheme not in SCHEMES or not rest:
        raise InputError(
            f"--connection {shown}: expected {', '.join(s + '://' for s in SCHEMES)}"
            " (e.g. udpin://0.0.0.0:14540 or serial:///dev/ttyACM0:57600)"
        )
    if scheme.startswith("serial"):
        device = rest.rsplit(":", 1)[0] if rest.rsplit(":", 1)[-1].isdigit() else rest
        if not Path(device).exists():
            raise InputError(f"--connection {shown}: no serial device {device}")
        return
    host, colon, port_text = rest.rpartition(":")
    if not colon or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise InputError(f"--connection {shown}: expected HOST:PORT with a port 1-65535")
    if scheme == "udpin":
        bind_check(host, int(port_text), "--connection", url)


def bind_check(host: str, port: int, option: str, url: str) -> None:
    """Refuse a UDP address this machine cannot receive on (port in use, foreign address)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            sock.bind((host, port))
        except OSError as err:
            cause = (
                "the port is in use"
                if err.errno == errno.EADDRINUSE
                else f"cannot receive there ({err.strerror or err})"
            )
            raise InputError(f"{option} {url[:80]!r}: {cause}") from None
