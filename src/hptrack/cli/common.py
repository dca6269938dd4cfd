"""Shared CLI helpers: the rich consoles, progress display, planner options, output paths and
JSON output.

Errors are not handled here: `hptrack.cli.app.main` turns an
`InputError` (and a command-line usage error) into one line and exit
code 2, and lets every other exception show its traceback with exit code 1.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import Progress, ProgressColumn

from hptrack.interface import InputError, shown
from hptrack.jsonout import json_text
from hptrack.registry import PLANNERS, planner_entry
from hptrack.settings import MAX_ITERATIONS, MAX_TIME_LIMIT_S, PlannerSettings

console = Console()
error_console = Console(stderr=True)

PLAIN_PROGRESS_INTERVAL_S = 30.0
"""Time between two lines of `PlainProgress`, s."""


class PlainProgress:
    """Progress as plain lines, for a log file or a pipe (rich's bar is for terminals): the
    subset of `rich.progress.Progress` that the commands use. A line at a task's first
    update, then every `PLAIN_PROGRESS_INTERVAL_S`, and when it completes,
    e.g. ``benchmark: 12/30 episodes (40 %), 00:01:10; mcts n=2 seed=3: U=40.12``."""

    def __init__(self, label: str, unit: str, output: Console | None = None) -> None:
        self.label, self.unit, self.console = label, unit, output or console
        self._tasks: list[dict[str, Any]] = []
        self._start = time.monotonic()

    def __enter__(self) -> PlainProgress:
        return self

    def __exit__(self, *_exc: object) -> None:
        return None

    def add_task(self, description: str, total: float | None = None, **_fields: Any) -> int:
        self._tasks.append({"description": description, "total": total, "completed": 0})
        return len(self._tasks) - 1

    def update(
        self,
        task_id: int,
        *,
        completed: float | None = None,
        total: float | None = None,
        description: str | None = None,
        **_fields: Any,
    ) -> None:
        task = self._tasks[task_id]
        before = task["completed"]
        changes = {"completed": completed, "total": total, "description": description}
        task.update({key: value for key, value in changes.items() if value is not None})
        done, whole, now = task["completed"], task["total"], time.monotonic()
        last = task.get("shown_at")
        finished = bool(whole) and done >= whole > before
        if not (last is None or finished or (now - last >= PLAIN_PROGRESS_INTERVAL_S)):
            return
        task["shown_at"] = now
        count = f"{done:,.0f}/{whole:,.0f}" if whole else f"{done:,.0f}"
        share = f" ({100 * done / whole:.0f} %)" if whole else ""
        elapsed = time.strftime("%H:%M:%S", time.gmtime(now - self._start))
        what = f"; {task['description']}" if task["description"] else ""
        self.console.print(
            f"{self.label}: {count} {self.unit}{share}, {elapsed}{what}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )


def progress_display(
    label: str, unit: str, *columns: str | ProgressColumn, transient: bool = False
) -> Progress | PlainProgress:
    """A rich progress bar of ``columns`` on a terminal; `PlainProgress` lines
    (``label: done/total unit``) otherwise."""
    if console.is_terminal:
        return Progress(*columns, console=console, transient=transient)
    return PlainProgress(label, unit)


SETTING_HELP = (
    "Shared q and prior for all targets (the paper's ARVI/A* setting) or drawn per "
    "target; default heterogeneous."
)


def check_seed(seed: int | None, option: str = "--seed") -> None:
    """Refuse a seed that is not a non-negative 63-bit integer."""
    if seed is not None and not 0 <= seed < 2**63:
        raise InputError(f"{option} must be a non-negative integer below 2^63, got {seed}")


def parse_value(text: str) -> Any:
    """A ``-o`` value: an integer, a number, ``true``/``false``, ``none``, or the text as is
    (comma-separated lists stay text; the settings model splits them)."""
    lowered = text.strip().lower()
    if lowered in ("none", "null"):
        return None
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def planner_options(pairs: list[str] | None, planners: tuple[str, ...]) -> dict[str, dict]:
    """``-o`` options per planner: ``PLANNER.KEY=VALUE``, or ``KEY=VALUE`` when only one planner
    runs. Keys may use ``-`` for ``_`` (planner names keep theirs: ``team-mcts.share-period``).

    Raises:
        InputError: a malformed option, a planner that is not running, or a bare key with
            several planners.
    """
    out: dict[str, dict] = {p: {} for p in planners}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        prefix, dot, name = key.strip().partition(".")
        if not dot:
            prefix, name = "", prefix
        key = name = name.replace("-", "_")
        if not sep or not key:
            raise InputError(f"--option expects KEY=VALUE or PLANNER.KEY=VALUE, got {pair!r}")
        if dot:
            if prefix not in PLANNERS:
                raise InputError(
                    f"--option {pair!r}: unknown planner {prefix!r}; choose from "
                    f"{', '.join(sorted(PLANNERS))}"
                )
            if prefix not in out:
                raise InputError(
                    f"--option {pair!r}: planner {prefix!r} is not running "
                    f"(running: {', '.join(planners)})"
                )
            out[prefix][name] = parse_value(value)
        elif len(planners) == 1:
            out[planners[0]][key] = parse_value(value)
        else:
            having = [p for p in planners if key in planner_entry(p).settings_type.model_fields]
            if not having:
                raise InputError(
                    f"--option {pair!r}: none of the running planners "
                    f"({', '.join(planners)}) has an option {key}"
                )
            choices = " or ".join(f"{p}.{key}={value}" for p in having)
            raise InputError(f"--option {pair!r}: say which planner, {choices}")
    return out


def planner_settings_for(
    planners: tuple[str, ...],
    pairs: list[str] | None,
    iterations: int | None,
    time_limit: float | None,
) -> dict[str, PlannerSettings]:
    """Validated settings of each planner from ``-o`` options and the effort flags (which only
    set the planners that have such a notion, with a warning line for each planner that has
    none; an explicit ``-o`` wins)."""
    if iterations is not None and not 1 <= iterations <= MAX_ITERATIONS:
        raise InputError(
            f"--iterations must be a positive integer of at most {MAX_ITERATIONS:g}, "
            f"got {shown(iterations)}"
        )
    if time_limit is not None and not (0 < time_limit <= MAX_TIME_LIMIT_S):
        raise InputError(
            f"--time-limit must be a positive number of seconds of at most "
            f"{MAX_TIME_LIMIT_S:g} (an hour per decision), got {time_limit}"
        )
    options = planner_options(pairs, planners)
    out = {}
    for name in planners:
        entry = planner_entry(name)
        for flag, value in (("--iterations", iterations), ("--time-limit", time_limit)):
            if (
                value is not None
                and flag[2:].replace("-", "_") not in entry.settings_type.effort_fields
            ):
                error_console.print(
                    f"warning: planner {name!r} has no {flag[2:]} effort: {flag} {value} is "
                    "ignored for it",
                    highlight=False,
                    markup=False,
                    soft_wrap=True,
                )
        merged = {**entry.settings_type.effort_options(iterations, time_limit), **options[name]}
        out[name] = entry.settings_type.from_options(name, merged)
    return out


def available_memory() -> int:
    """Memory the machine can still give, bytes (``MemAvailable`` of ``/proc/meminfo``, else
    the free physical pages)."""
    try:
        with open("/proc/meminfo") as file:
            for line in file:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def check_memory(need: float, what: str) -> None:
    """Refuse, before allocating, work that needs more than half the available memory."""
    have = available_memory()
    if need > 0.5 * have:
        raise InputError(
            f"{what} needs about {need / 2**30:.3g} GiB of memory; this machine has "
            f"{have / 2**30:.3g} GiB available (at most half of it is used)"
        )


def check_workers(workers: int, tasks: int, option: str = "--workers") -> int:
    """The worker processes to start: at least 1, refused above the machine's cores (more
    processes than cores only share them), and never more than ``tasks``."""
    cores = os.cpu_count() or 1
    if not 1 <= workers <= cores:
        raise InputError(
            f"{option} must be between 1 and the {cores} cores of this machine, got {workers}"
        )
    return max(1, min(workers, tasks))


def check_output_path(path: Path | None, option: str) -> None:
    """Refuse, before any work, an output path that cannot be written: a folder, a device or
    a FIFO (``/dev/full``), or a place where the file cannot be created (the check creates it
    and removes it again if it was not there)."""
    if path is None:
        return
    if path.is_dir():
        raise InputError(f"{option} {path}: is a folder, not a file")
    if path.exists() and not path.is_file():
        raise InputError(f"{option} {path}: not a regular file (a device, a FIFO or a socket)")
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{option} {path}: cannot create its folder ({err.strerror})") from None
    existed = path.exists()
    try:
        with path.open("ab"):
            pass
        if not existed:
            path.unlink()
    except OSError as err:
        raise InputError(f"{option} {path}: not writable ({err.strerror})") from None


def check_figure_path(path: Path | None, option: str) -> None:
    """`check_output_path` for a figure, whose suffix must be a format matplotlib writes
    (without one, matplotlib would add ``.png`` and write another file)."""
    if path is None:
        return
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix.lower().lstrip(".") not in formats:
        raise InputError(
            f"{option} {path}: unknown figure format {path.suffix or '(none)'!r}; use one of "
            + ", ".join(f".{f}" for f in sorted(formats))
        )
    check_output_path(path, option)


@contextmanager
def writing(path: Path, option: str) -> Iterator[None]:
    """Turn a failed write of ``path`` (disk full, read-only, removed folder) into one line."""
    try:
        yield
    except OSError as err:
        raise InputError(f"{option} {path}: the write failed ({err.strerror})") from None


def check_output_dir(path: Path, option: str) -> None:
    """Refuse, before any work, an output folder that cannot be created or written."""
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} {path}: is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{option} {path}: cannot create it ({err.strerror})") from None
    if not os.access(path, os.W_OK):
        raise InputError(f"{option} {path}: not writable")


def write_json(path: Path, data: object, option: str = "--json") -> None:
    """Write ``data`` as indented strict JSON (`hptrack.jsonout.json_text`: a number that
    is not finite as the string ``"inf"``, ``"-inf"`` or ``"nan"``); a failed write is one line
    naming ``option``."""
    text = json_text(data, indent=2) + "\n"
    with writing(path, option):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
