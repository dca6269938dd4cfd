"""Shared CLI helpers: one-line errors, rich console, planner option parsing."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from pathlib import Path

import typer
import yaml
from rich.console import Console

console = Console()
error_console = Console(stderr=True)


@contextlib.contextmanager
def clean_errors() -> Iterator[None]:
    """Turn input errors into one red line on stderr and exit code 2 (no traceback)."""
    try:
        yield
    except (ValueError, OSError) as err:
        error_console.print(f"[bold red]error:[/] {err}", highlight=False, soft_wrap=True)
        raise typer.Exit(code=2) from None


def parse_options(pairs: list[str] | None) -> dict:
    """``["key=value", ...]`` to a dict, values parsed as YAML scalars (``3`` -> int)."""
    options = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--option expects KEY=VALUE, got {pair!r}")
        options[key.strip().replace("-", "_")] = yaml.safe_load(value)
    return options


def write_json(path: Path, data: object) -> None:
    """Write ``data`` as indented JSON, creating parent folders."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")
