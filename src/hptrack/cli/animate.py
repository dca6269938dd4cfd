"""``hptrack animate``: a saved episode record as a GIF (or MP4 with ffmpeg), with progress of
the drawing and then of the GIF's encoding.

`write_animation` is the same rendering for other commands (``simulate --animate``).
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn

from hptrack.cli.common import check_memory, check_output_path, console, progress_display
from hptrack.interface import InputError
from hptrack.sim.record import EpisodeRecord


def _declared_bytes(archive: zipfile.ZipFile, item: zipfile.ZipInfo) -> int:
    """The bytes that array member ``item`` says it holds (its ``.npy`` header: shape and
    type), refused if the member is smaller than that (a header that lies)."""
    with archive.open(item) as member:
        version = np.lib.format.read_magic(member)
        read = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, _, dtype = read(member)
        header = member.tell()
    need = math.prod(shape) * dtype.itemsize
    if dtype.hasobject or need > item.file_size - header:
        raise ValueError(
            f"{item.filename} declares an array of shape {shape} ({need:,} bytes of "
            f"{dtype}) but holds {item.file_size - header:,} bytes"
        )
    return need


def load_record(path: Path) -> EpisodeRecord:
    """Read an episode record, or raise a one-line `InputError` naming the file."""
    if not path.is_file():
        raise InputError(f"RECORD {str(path)!r}: no such file")
    try:
        with zipfile.ZipFile(path) as archive:  # a zip bomb is refused before it is expanded
            items = archive.infolist()
            check_memory(sum(item.file_size for item in items), f"RECORD {path}")
            for item in items:
                _declared_bytes(archive, item)
        return EpisodeRecord.load(path)
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as err:
        reason = " ".join(str(err).split()) or type(err).__name__
        raise InputError(
            f"RECORD {str(path)!r} is not an hptrack episode record (.npz, "
            f"written by simulate --record): {reason}"
        ) from None


def check_animation_output(path: Path, option: str = "--output") -> None:
    """Refuse, before any work, an animation file that cannot be written: an unknown suffix,
    an MP4 without ffmpeg, a folder or an unwritable place."""
    from hptrack.viz.animation import check_format

    check_format(path, option)
    check_output_path(path, option)


def write_animation(record: EpisodeRecord, path: Path, stride: int = 5, fps: int = 20) -> int:
    """Render ``record`` to ``path`` with a rich progress bar; returns the frames written."""
    from hptrack.viz.animation import animate_mission

    path = Path(path)
    with progress_display(
        "animation",
        "frames",
        TextColumn("[bold]animation"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("frames {task.description}"),
        TimeRemainingColumn(),
        transient=True,
    ) as progress:
        drawing = progress.add_task("drawn", total=None)
        encoding = None

        def encoded(done: int, total: int) -> None:
            nonlocal encoding
            if encoding is None:
                encoding = progress.add_task(f"encoded into {path.suffix[1:].upper()}", total=total)
            progress.update(encoding, completed=done)

        frames = animate_mission(
            record,
            path,
            stride=stride,
            fps=fps,
            progress=lambda done, total: progress.update(drawing, completed=done, total=total),
            encoding=encoded,
        )
    console.print(
        f"animation written to {escape(str(path))} ({frames} frames, "
        f"{frames / fps:.1f} s at {fps} fps)",
        soft_wrap=True,
    )
    return frames


def animate(
    record_path: Annotated[
        Path, typer.Argument(metavar="RECORD", help="Episode record (.npz, simulate --record).")
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Animation file: .gif, or .mp4 (needs ffmpeg).")
    ] = Path("mission.gif"),
    stride: Annotated[int, typer.Option(help="Steps between frames (the last step is drawn).")] = 5,
    fps: Annotated[int, typer.Option(help="Frames per second.")] = 20,
) -> None:
    """Animate a recorded mission: agent, targets, 95 % belief ellipses, detections, sub-task."""
    if stride < 1:
        raise InputError(f"--stride must be a positive number of steps, got {stride}")
    if fps < 1:
        raise InputError(f"--fps must be a positive number of frames per second, got {fps}")
    check_animation_output(output)
    record = load_record(record_path)
    write_animation(record, output, stride=stride, fps=fps)


def register(app: typer.Typer) -> None:
    """Add the ``animate`` command to ``app``."""
    app.command("animate")(animate)
