"""The one look-up of every registry of compiled parts (MDPs, rollout policies, backups, outcome
estimators, truth motions): a part is a ``NamedTuple`` class, and compiled code is given what was
registered for the class of the value it is typed with, at compile time (numba's ``overload``).
"""

from __future__ import annotations

from typing import Any

import numba


def registered(table: dict[type, Any], value: Any, what: str) -> Any:
    """What ``table`` holds for the class of the numba-typed ``value``.

    Raises:
        numba.errors.TypingError: nothing is registered for it (naming ``what``).
    """
    cls = getattr(value, "instance_class", None)
    if cls not in table:
        raise numba.errors.TypingError(f"no {what} registered for {value}")
    return table[cls]
