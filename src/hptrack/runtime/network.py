"""UDP addresses of the flight adapters (``udp://HOST:PORT``)."""

from __future__ import annotations

import ipaddress

from hptrack.interface import InputError


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
