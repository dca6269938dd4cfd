"""The controller's side of the mission log: every record it writes, the number of the
``setpoint`` call that made it (so that a replay makes the same calls), and the counts of
accepted and refused inputs by reason."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

from hptrack.runtime.log import MissionLog


class Journal:
    """Writes the controller's records to ``log`` (default: memory only) and counts inputs.

    Attributes:
        accepted: accepted inputs by kind (``"odometry"``, ``"detection"``, ``"fallback"``).
        rejected: refused inputs by ``"kind: reason"``.
    """

    def __init__(self, log: MissionLog | None = None) -> None:
        self.log = log if log is not None else MissionLog()
        self.accepted: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self._calls = 0
        self._call: int | None = None

    @contextmanager
    def call(self) -> Iterator[int]:
        """Number the records written inside one ``setpoint`` call."""
        self._calls += 1
        self._call = self._calls
        try:
            yield self._call
        finally:
            self._call = None

    def write(self, record: dict) -> dict:
        """Write ``record`` (with the current call's number); returns it as written."""
        if self._call is not None:
            record = {**record, "call": self._call}
        return self.log.write(record)

    def accept(self, kind: str, record: dict) -> bool:
        """Count and write an accepted input; ``True``."""
        self.accepted[kind] += 1
        self.write({**record, "accepted": True})
        return True

    def refuse(self, kind: str, record: dict, reason: str, detail: str) -> bool:
        """Count and write a refused input with its reason; ``False``."""
        self.rejected[f"{kind}: {reason}"] += 1
        self.write({**record, "accepted": False, "reason": reason, "detail": detail})
        return False
