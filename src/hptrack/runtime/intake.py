"""The detection intake of a flight: datagrams from the detection port to the controller, off
the flight loop and bounded, so that no input load can starve the setpoint stream.

A thread of its own (`DetectionIntake`) reads the UDP socket, splits each datagram into
lines (a line is the text between newlines, blank ones are skipped) and hands at most
``lines_per_s`` lines per second to a handler (the flight's parser and the controller, which
log each one), in slices of ``slice_s``. It stops handling for the rest of a slice once it has
spent ``busy_fraction`` of it, an overrun being paid in the next slices, so that costly lines
(late detections that refilter a long history) take no more of the processor. The flight loop
itself never touches a detection.

Lines beyond the bounds are dropped and counted by reason:

* `OVER_DATAGRAM`: the lines of a datagram after its first ``lines_per_datagram``;
* `QUEUE_FULL`: lines arriving while ``queue_lines`` lines wait (at most about a second of
  handling, so that a queued line's time of arrival is still close to its age);
* `LEFT_AT_END`: lines still waiting when the intake stops.

Every line received is either handed on or counted as dropped:
``received == handled + sum(dropped.values())``. Datagrams the system dropped before they were
received (its receive buffer full) are counted apart, by `network.kernel_drops`.
"""

from __future__ import annotations

import contextlib
import select
import socket
import threading
import time
import traceback
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass

OVER_DATAGRAM = "datagram over its line limit"
QUEUE_FULL = "intake queue full"
LEFT_AT_END = "not handled by the end"

MAX_DATAGRAM_BYTES = 65_536
"""Largest UDP datagram read, bytes."""
_READS_PER_PASS = 64
"""Datagrams read from the socket between two lines handed on."""


@dataclass(frozen=True)
class IntakeLimits:
    """Bounds of the detection intake.

    Attributes:
        lines_per_s: lines handed to the controller per second at most (a detector at 30
            frames per second with 30 targets in view sends 900).
        lines_per_datagram: lines read from one datagram at most.
        queue_lines: lines waiting at most (one second of handling by default).
        slice_s: the handling budget is spent in slices of this length, s (the setpoint
            period in flight).
        busy_fraction: the share of each slice the handling may take.
    """

    lines_per_s: int = 1000
    lines_per_datagram: int = 100
    queue_lines: int = 1000
    slice_s: float = 0.05
    busy_fraction: float = 0.3


class DetectionIntake:
    """Reads detection datagrams from ``sock`` in its own thread and hands their lines to
    ``handle(line, received_s)`` within ``limits`` (module docstring).

    Args:
        sock: a bound UDP socket (the intake reads it, the caller closes it).
        handle: called with each line (bytes, stripped) and the clock's time at its arrival;
            it must not raise (an exception stops the intake and is kept in `error`).
        clock: the time of arrival given to ``handle`` (mission time, or ``None`` before it).
        limits: the bounds.
    """

    def __init__(
        self,
        sock: socket.socket,
        handle: Callable[[bytes, float | None], None],
        clock: Callable[[], float | None],
        limits: IntakeLimits | None = None,
    ) -> None:
        self.sock = sock
        self.handle = handle
        self.clock = clock
        self.limits = limits or IntakeLimits()
        self.received = 0
        """Lines received."""
        self.handled = 0
        """Lines handed on."""
        self.dropped: Counter[str] = Counter()
        """Lines dropped, by reason."""
        self.dropped_total = 0
        """Lines dropped, all reasons (read by other threads while the intake runs)."""
        self.error: str | None = None
        """The handler's traceback if it raised."""
        self._queue: deque[tuple[bytes, float | None]] = deque()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="detection intake", daemon=True)

    def start(self) -> None:
        """Start reading."""
        self.sock.setblocking(False)
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop reading (the line being handled is finished); what still waits is dropped and
        counted (`LEFT_AT_END`)."""
        self._stop.set()
        self._thread.join(timeout_s)
        if not self._thread.is_alive():
            self._drop(LEFT_AT_END, len(self._queue))
            self._queue.clear()

    def counts(self) -> dict:
        """The counts as JSON data: ``received``, ``handled``, ``dropped`` by reason."""
        return {"received": self.received, "handled": self.handled, "dropped": dict(self.dropped)}

    def _drop(self, reason: str, lines: int) -> None:
        if lines > 0:
            self.dropped[reason] += lines
            self.dropped_total += lines

    def receive(self, data: bytes, received_s: float | None) -> None:
        """Queue the lines of one datagram (what does not fit is dropped and counted)."""
        lines = [line for line in (part.strip() for part in data.split(b"\n")) if line]
        self.received += len(lines)
        limits = self.limits
        if len(lines) > limits.lines_per_datagram:
            self._drop(OVER_DATAGRAM, len(lines) - limits.lines_per_datagram)
            del lines[limits.lines_per_datagram :]
        room = max(0, limits.queue_lines - len(self._queue))
        self._drop(QUEUE_FULL, len(lines) - room)
        self._queue.extend((line, received_s) for line in lines[:room])

    def _read(self) -> None:
        for _ in range(_READS_PER_PASS):
            try:
                data = self.sock.recv(MAX_DATAGRAM_BYTES)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # the socket was closed under us: nothing more arrives
                self._stop.set()
                return
            self.receive(data, self.clock())

    def _run(self) -> None:
        limits = self.limits
        per_slice = max(1, round(limits.lines_per_s * limits.slice_s))
        busy_s = limits.busy_fraction * limits.slice_s
        slice_end, budget, busy = time.monotonic() + limits.slice_s, per_slice, 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= slice_end:  # a slice's overrun is paid in the next ones
                slice_end, budget, busy = now + limits.slice_s, per_slice, max(0.0, busy - busy_s)
            self._read()
            ready = budget > 0 and busy < busy_s
            if ready and self._queue:
                line, received_s = self._queue.popleft()
                try:
                    self.handle(line, received_s)
                except Exception:  # noqa: BLE001 - kept for the flight, which ends safely
                    self.error = traceback.format_exc()
                    return
                finally:
                    self.handled += 1
                busy += time.monotonic() - now
                budget -= 1
                continue
            with contextlib.suppress(OSError, ValueError):
                if ready:  # nothing waits: until a datagram comes, or the slice ends
                    select.select([self.sock], [], [], limits.slice_s)
                else:
                    time.sleep(max(0.0, slice_end - now))
