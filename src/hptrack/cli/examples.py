"""``hptrack examples``: list the example scripts shipped with the package, or copy them out."""

from __future__ import annotations

import ast
import shutil
from importlib import resources
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from hptrack.cli.common import console, writing
from hptrack.interface import InputError

SUFFIXES = (".py", ".yaml")


def shipped_examples() -> dict[str, Path]:
    """``{file name: path}`` of every example installed with the package."""
    folder = Path(str(resources.files("hptrack") / "examples"))
    return {p.name: p for p in sorted(folder.iterdir()) if p.suffix in SUFFIXES}


def summary(path: Path) -> str:
    """The first line of a script's docstring, or of a YAML file's leading comment."""
    text = path.read_text()
    if path.suffix == ".py":
        doc = ast.get_docstring(ast.parse(text)) or ""
        return doc.splitlines()[0] if doc else ""
    first = text.splitlines()[0] if text else ""
    return first.lstrip("# ").strip()


def examples(
    names: Annotated[
        list[str] | None, typer.Argument(help="Examples to copy (default: all of them).")
    ] = None,
    to: Annotated[
        Path | None, typer.Option("--to", help="Folder to copy the examples into.")
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite files that already exist.")] = False,
) -> None:
    """List the shipped examples; with --to DIR, copy them (or the NAMES given) into DIR."""
    shipped = shipped_examples()
    chosen = names or list(shipped)
    unknown = [n for n in chosen if n not in shipped]
    if unknown:
        raise InputError(f"unknown example {unknown[0]!r}; choose from {', '.join(shipped)}")
    if to is None:
        for name in chosen:
            console.print(
                f"{name:<24} {escape(summary(shipped[name]))}", highlight=False, soft_wrap=True
            )
        console.print("copy them with: hptrack examples --to DIR", highlight=False)
        return
    if to.exists() and not to.is_dir():
        raise InputError(f"--to {to}: is a file, not a folder")
    for name in chosen:  # every destination is checked before any file is copied
        target = to / name
        if target.is_symlink() or (target.exists() and not target.is_file()):
            raise InputError(f"--to {to}: {name} is a folder, a link or a device, not a file")
    clashes = [n for n in chosen if (to / n).exists()]
    if clashes and not force:
        raise InputError(f"--to {to}: {clashes[0]} exists already (add --force to overwrite)")
    try:
        to.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"--to {to}: cannot create the folder ({err.strerror})") from None
    with writing(to, "--to"):
        for name in chosen:
            shutil.copyfile(shipped[name], to / name)
    console.print(f"copied {', '.join(chosen)} to {escape(str(to))}", highlight=False)


def register(app: typer.Typer) -> None:
    app.command("examples")(examples)
