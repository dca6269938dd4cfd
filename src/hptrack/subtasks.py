"""The sub-task vocabulary (paper Sec. IV-C): the actions a sub-task planner chooses among, the
table that numbers them for compiled code, and the record of a sub-task flown, as logs and
episode info hold it.

Action kinds (`SubtaskAction`):

* ``"pursue"`` target ``i``: intercept its belief mean, then fly the shifting spiral until it
  is measured or ``t_cutoff`` (Sec. IV-A, IV-B);
* ``"follow"`` target ``i``, the one just found: fly at its predicted position to the end of
  the budget;
* ``"dwell"`` on the target just found (beyond the paper, the ``dwell`` option): follow it for
  ``parameter`` steps, then choose again;
* ``"hover"``: stay where the vehicle is (nothing left to do).

The compiled search numbers them (`ActionTable`): index ``i < n`` is target ``i``, pursued, or
followed when it is the target just found; index ``n + j`` is the ``j``-th dwell length. That
layout is written here once, as the compiled helpers `is_dwell_index` and `dwell_number` and
the table's `ActionTable.action` and `ActionTable.index` built on them.

A sub-task flown is one `Subtask` record: its action, start, estimate, outcome and the plan
after it. `Subtask.to_json` writes the one JSON shape of logs and episode info;
`Subtask.from_json` also reads the shapes of older logs and results.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numba

ActionKind = Literal["pursue", "follow", "dwell", "hover"]
KINDS: tuple[str, ...] = ("pursue", "follow", "dwell", "hover")
"""The sub-task kinds (module docstring)."""


@numba.njit(cache=True, inline="always")
def is_dwell_index(n_targets, a):
    """Whether action index ``a`` is a dwell: the indices after the ``n_targets`` targets."""
    return a >= n_targets


@numba.njit(cache=True, inline="always")
def dwell_number(n_targets, a):
    """Which dwell length (``j``) the dwell index ``a`` stands for: ``a = n + j``."""
    return a - n_targets


def _target_json(target: int | None, target_ids: Sequence[str] | None) -> Any:
    return target if target is None or target_ids is None else target_ids[target]


def _target_index(value: Any, target_ids: Sequence[str]) -> int | None:
    """A target given by index or by id, as an index."""
    if value is None:
        return None
    return list(target_ids).index(value) if isinstance(value, str) else int(value)


@dataclass(frozen=True)
class SubtaskAction:
    """One action of a sub-task planner (module docstring).

    Attributes:
        kind: ``"pursue"``, ``"follow"``, ``"dwell"`` or ``"hover"``.
        target: the target's index (``None`` for a hover).
        parameter: a dwell's length in steps (``None`` for the other kinds, or a dwell read
            from an older log, which did not say).
    """

    kind: ActionKind
    target: int | None = None
    parameter: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"sub-task kind must be one of {KINDS}, got {self.kind!r}")

    def to_json(self, target_ids: Sequence[str] | None = None) -> dict[str, Any]:
        """``{"kind", "target", "parameter"}`` (``None`` ones left out); targets by id when
        ``target_ids`` is given, else by index."""
        out: dict[str, Any] = {"kind": self.kind}
        if self.target is not None:
            out["target"] = _target_json(self.target, target_ids)
        if self.parameter is not None:
            out["parameter"] = self.parameter
        return out

    @classmethod
    def from_json(cls, value: dict[str, Any], target_ids: Sequence[str]) -> SubtaskAction:
        """Read `to_json`'s output (targets by index or by id)."""
        return cls(
            value["kind"], _target_index(value.get("target"), target_ids), value.get("parameter")
        )


HOVER = SubtaskAction("hover")


@dataclass(frozen=True)
class ActionTable:
    """The action indices of the sub-task MDP (module docstring): ``n_targets`` targets, then
    one dwell per length.

    Attributes:
        n_targets: ``n``.
        stay_steps: the dwell lengths in steps (index ``n + j`` dwells ``stay_steps[j]``).
    """

    n_targets: int
    stay_steps: tuple[int, ...] = ()

    @property
    def size(self) -> int:
        """Number of action indices."""
        return self.n_targets + len(self.stay_steps)

    def action(self, index: int | None, last_found: int | None = None) -> SubtaskAction | None:
        """The action of ``index`` in a state whose last found target is ``last_found``
        (choosing it again follows it; a dwell dwells on it); ``None`` for ``None``.

        Raises:
            ValueError: an index outside the table.
        """
        if index is None:
            return None
        if not 0 <= index < self.size:
            raise ValueError(f"action index {index} is not in a table of {self.size} actions")
        if is_dwell_index(self.n_targets, index):
            steps = self.stay_steps[dwell_number(self.n_targets, index)]
            return SubtaskAction("dwell", last_found, steps)
        return SubtaskAction("follow" if index == last_found else "pursue", index)

    def index(self, action: SubtaskAction) -> int:
        """The index of ``action`` (a dwell: the first of its length).

        Raises:
            ValueError: a hover, or a dwell of a length the table does not have.
        """
        if action.kind == "dwell":
            if action.parameter not in self.stay_steps:
                raise ValueError(f"no dwell of {action.parameter} steps in {self.stay_steps}")
            return self.n_targets + self.stay_steps.index(action.parameter)
        if action.target is None:
            raise ValueError(f"a {action.kind} has no action index")
        return action.target


PLAN_KEYS = {"after_find": "plan_after_find", "after_miss": "plan_after_miss"}
"""JSON keys of the planned actions (`Subtask.after_find`, `Subtask.after_miss`)."""


@dataclass(frozen=True)
class Subtask:
    """A sub-task being flown or flown (paper Sec. IV): the one record of logs, episode info
    and `CurrentPlan`.

    Attributes:
        kind: ``"pursue"``, ``"follow"``, ``"dwell"`` or ``"hover"`` (`SubtaskAction`).
        target: the target's index (``None`` for a hover).
        start_step: the step it began at.
        parameter: a dwell's length, steps.
        intercept_time: a pursuit's intercept flight, s.
        t_cutoff: a pursuit's ``t_cutoff``, s from the start of its coverage.
        p_find: a pursuit's estimated chance of finding the target, ``p_max``.
        expected_time: a pursuit's ``E[T_find]``, s from the start of its coverage.
        budget_limited: whether the budget's end (or a coverage limit) cut a pursuit's
            estimate short.
        end_step: the step it ended at (``None`` while flown, and for a follow or hover).
        outcome: how it ended: ``"found"`` or ``"missed"`` (a pursuit; the sub-task
            environment also says ``"budget"``, ``"followed"`` and ``"infeasible"``).
        after_find: the action planned after a find (after a dwell: when it ends).
        after_miss: the action planned after a miss.
    """

    kind: ActionKind
    target: int | None
    start_step: int
    parameter: int | None = None
    intercept_time: float | None = None
    t_cutoff: float | None = None
    p_find: float | None = None
    expected_time: float | None = None
    budget_limited: bool | None = None
    end_step: int | None = None
    outcome: str | None = None
    after_find: SubtaskAction | None = None
    after_miss: SubtaskAction | None = None

    def __post_init__(self) -> None:
        SubtaskAction(self.kind)  # checks the kind

    @property
    def action(self) -> SubtaskAction:
        """The action this sub-task flies."""
        return SubtaskAction(self.kind, self.target, self.parameter)

    @property
    def since_step(self) -> int:
        """The step it began at (`start_step`)."""
        return self.start_step

    def ended(self, step: int, outcome: str | None = None) -> Subtask:
        """This record ended at ``step`` with ``outcome``."""
        return dataclasses.replace(self, end_step=step, outcome=outcome)

    def to_json(self, target_ids: Sequence[str] | None = None) -> dict[str, Any]:
        """The JSON shape of logs and episode info: the fields that are set (``kind``,
        ``target``, ``start_step`` always), the planned actions as ``plan_after_find`` and
        ``plan_after_miss`` (`SubtaskAction.to_json`); targets by id when ``target_ids`` is
        given, else by index."""
        out: dict[str, Any] = {"kind": self.kind, "target": _target_json(self.target, target_ids)}
        for f in dataclasses.fields(self)[2:]:
            value = getattr(self, f.name)
            if value is None:
                continue
            if f.name in PLAN_KEYS:
                out[PLAN_KEYS[f.name]] = value.to_json(target_ids)
            else:
                out[f.name] = value
        return out

    @classmethod
    def from_json(cls, entry: dict[str, Any], target_ids: Sequence[str]) -> Subtask:
        """Read a sub-task entry of a log or of episode info: `to_json`'s shape (targets by
        index or by id), or one of the shapes written before it (`_older_shape`)."""
        if "kind" not in entry:
            return _older_shape(entry, target_ids)
        values = {k: v for k, v in entry.items() if k not in ("kind", "target")}
        for name, key in PLAN_KEYS.items():
            if values.pop(key, None) is not None:
                values[name] = SubtaskAction.from_json(entry[key], target_ids)
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(
            entry["kind"],
            _target_index(entry.get("target"), target_ids),
            **{k: v for k, v in values.items() if k in known},
        )


_ESTIMATE = ("intercept_time", "t_cutoff", "p_find", "expected_time", "budget_limited")


def _older_planned(
    value: Any, n_targets: int, last_found: int | None, target_ids: Sequence[str]
) -> SubtaskAction | None:
    """A planned action as older entries held it: an index (``n + j`` the ``j``-th dwell, its
    length unknown), or, in an episode summary, an id, ``"dwell"`` or ``"dwell j"``."""
    if value is None:
        return None
    if isinstance(value, str):
        if value.startswith("dwell") and value not in target_ids:
            return SubtaskAction("dwell", last_found)
        value = list(target_ids).index(value)
    if value >= n_targets:
        return SubtaskAction("dwell", last_found)
    return SubtaskAction("follow" if value == last_found else "pursue", value)


def _older_shape(entry: dict[str, Any], target_ids: Sequence[str]) -> Subtask:
    """A sub-task entry in a shape written before `Subtask.to_json`: in episode info a pursuit
    ``{"target_index", "start_step", estimate, "plan_after_find", "plan_after_miss", "outcome",
    "end_step"}``, a follow ``{"follow": i, "start_step"}`` (``None``: a hover), a dwell
    ``{"dwell": i, "start_step", "dwell_steps", "plan_after_dwell", "end_step"}``; in a mission
    log's plan records ``{"target" | "follow" | "dwell": id, "since_step", "p_find"}``.

    Raises:
        ValueError: an entry of none of these shapes.
    """
    n = len(target_ids)
    start = int(entry.get("start_step", entry.get("since_step", 0)))
    common = {"end_step": entry.get("end_step"), "outcome": entry.get("outcome")}
    if "follow" in entry:
        target = _target_index(entry["follow"], target_ids)
        return Subtask("hover" if target is None else "follow", target, start, **common)
    if "dwell" in entry:
        target = _target_index(entry["dwell"], target_ids)
        after = _older_planned(entry.get("plan_after_dwell"), n, target, target_ids)
        return Subtask("dwell", target, start, entry.get("dwell_steps"), after_find=after, **common)
    key = "target_index" if "target_index" in entry else "target"
    if key not in entry:
        raise ValueError(f"not a sub-task entry: {sorted(entry)}")
    target = _target_index(entry[key], target_ids)
    return Subtask(
        "pursue",
        target,
        start,
        **{k: entry.get(k) for k in _ESTIMATE},
        after_find=_older_planned(entry.get("plan_after_find"), n, target, target_ids),
        after_miss=_older_planned(entry.get("plan_after_miss"), n, None, target_ids),
        **common,
    )


def read_subtasks(entries: Sequence[dict[str, Any]], target_ids: Sequence[str]) -> list[Subtask]:
    """A planner's sub-task log (``episode_info()["subtasks"]``, in any shape
    `Subtask.from_json` reads) as records."""
    return [Subtask.from_json(entry, target_ids) for entry in entries]
