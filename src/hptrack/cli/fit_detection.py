"""``hptrack fit-detection``: a scenario's ``sensor.detection_probability`` fitted from a
detector's logged looks (`hptrack.models.detection_fit`)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
import yaml
from rich.table import Table

from hptrack.cli.common import check_output_path, console, write_json, writing
from hptrack.interface import InputError
from hptrack.models.detection_fit import MAX_BINS, DetectionFit, fit_detection_probability

TRUE = {"1", "true", "yes"}
FALSE = {"0", "false", "no"}
COLUMNS = ("distance_m", "detected")


def read_looks(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(distances_m, detected)`` of a CSV file with a header holding ``distance_m`` and
    ``detected`` (1/0, true/false, yes/no); other columns are ignored.

    Raises:
        InputError: the file cannot be read, or a column or a value is wrong (naming the line).
    """
    try:
        with path.open(newline="") as stream:
            reader = csv.DictReader(stream)
            missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise InputError(
                    f"{path}: the header must name the columns {', '.join(COLUMNS)}; "
                    f"missing {', '.join(missing)} (header {reader.fieldnames})"
                )
            distances, detected = [], []
            for row in reader:
                line = reader.line_num
                try:
                    distance = float(row["distance_m"])
                except (TypeError, ValueError):
                    raise InputError(
                        f"{path} line {line}: distance_m must be a number, value "
                        f"{row['distance_m']!r}"
                    ) from None
                if not (math.isfinite(distance) and distance >= 0):
                    raise InputError(
                        f"{path} line {line}: distance_m must be finite and >= 0, value {distance}"
                    )
                flag = (row["detected"] or "").strip().lower()
                if flag not in TRUE | FALSE:
                    raise InputError(
                        f"{path} line {line}: detected must be 1/0, true/false or yes/no, "
                        f"value {row['detected']!r}"
                    )
                distances.append(distance)
                detected.append(flag in TRUE)
    except OSError as err:
        raise InputError(f"{path}: cannot be read ({err.strerror})") from None
    except (UnicodeDecodeError, csv.Error) as err:
        raise InputError(f"{path}: not a CSV text file ({err})") from None
    if not distances:
        raise InputError(f"{path}: holds no looks (a header and one row per look)")
    return np.array(distances), np.array(detected)


def fit_json(fit: DetectionFit) -> dict:
    """The fit as JSON: the table, the constant and each bin's counts and interval."""
    return {
        "detection_probability": fit.rows(),
        "constant": {"Pd": fit.constant, "low": fit.constant_low, "high": fit.constant_high},
        "bins": [
            {
                "low_m": float(lo),
                "high_m": float(hi),
                "looks": int(n),
                "hits": int(h),
                "share": float(h / n),
                "fitted": float(p),
                "interval": [float(a), float(b)],
            }
            for lo, hi, n, h, p, a, b in zip(
                fit.low_m,
                fit.high_m,
                fit.looks,
                fit.hits,
                fit.fitted,
                fit.interval_low,
                fit.interval_high,
                strict=True,
            )
        ],
    }


def fit_detection(
    looks: Annotated[
        Path,
        typer.Argument(
            help="CSV of looks at targets inside the footprint: columns distance_m (from the "
            "footprint's centre, m) and detected (1/0)."
        ),
    ],
    bin_width: Annotated[
        float, typer.Option("--bin-width", help="Width of the distance bins, m.")
    ] = 10.0,
    monotone: Annotated[
        bool,
        typer.Option(help="Fit a Pd that does not grow with the distance (isotonic)."),
    ] = True,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help="Write a scenario fragment (sensor: block) here."),
    ] = None,
    json_path: Annotated[Path | None, typer.Option("--json", help="Write the fit as JSON.")] = None,
) -> None:
    """Fit sensor.detection_probability (a table by distance) from a detector's logged looks."""
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise InputError(f"--bin-width must be a positive number of metres, got {bin_width}")
    check_output_path(output, "--output")
    check_output_path(json_path, "--json")
    distances, detected = read_looks(looks)
    if distances.max() / bin_width >= MAX_BINS:
        raise InputError(
            f"--bin-width {bin_width:g} m gives more than {MAX_BINS} bins up to "
            f"{distances.max():g} m ({looks})"
        )
    fit = fit_detection_probability(distances, detected, bin_width_m=bin_width, monotone=monotone)
    table = Table(title=f"detections by distance from the footprint's centre ({looks})")
    for column in ("distance (m)", "looks", "hits", "share", "95 % interval", "fitted Pd"):
        table.add_column(column, justify="right")
    for row in fit_json(fit)["bins"]:
        low, high = row["interval"]
        table.add_row(
            f"{row['low_m']:g}-{row['high_m']:g}",
            str(row["looks"]),
            str(row["hits"]),
            f"{row['share']:.3f}",
            f"{low:.3f}-{high:.3f}",
            f"{row['fitted']:.3f}",
        )
    console.print(table)
    console.print(
        f"constant Pd = {fit.constant:.3f} (95 % {fit.constant_low:.3f}-{fit.constant_high:.3f},"
        f" {int(fit.looks.sum())} looks)",
        highlight=False,
    )
    fragment = {
        "sensor": {"detection_probability": [[round(d, 3), round(p, 4)] for d, p in fit.rows()]}
    }
    text = yaml.safe_dump(fragment, default_flow_style=None, sort_keys=False)
    console.print(text.rstrip(), highlight=False, markup=False)
    if output is not None:
        with writing(output, "--output"):
            output.write_text(text)
    if json_path is not None:
        write_json(json_path, fit_json(fit))


def register(app: typer.Typer) -> None:
    app.command("fit-detection")(fit_detection)
