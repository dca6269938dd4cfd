"""Estimator accuracy with a detector that misses: the absolute error of ``P_find`` per case.

Reads the ``cases.csv`` of ``validate-coverage`` runs made with ``--detection-probability`` or
``--detection-table`` (and ``--detection-correlation-time``; one folder each) and writes
``table.md``: per run and delay, the mean and largest ``|estimate - simulated|`` of ``P_find``
for the paper's estimator and the sharp one, and the share of cases within 0.03::

    python3 benchmarks/detection_accuracy.py docs/results/coverage-validation-detection/pd-0.9 \\
        docs/results/coverage-validation-detection/pd-0.7 ... --out table.md
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path


def rows_of(folder: Path) -> tuple[str, list[str]]:
    """The detector of a run (its ``config.json``) and its table rows."""
    config = json.loads((folder / "config.json").read_text())
    detector = config.get("detection_probability", 1.0)
    label = str(detector if isinstance(detector, float | int) else json.dumps(detector))
    if config.get("detection_correlation_time"):  # draws held over consecutive looks
        label += f", held {config['detection_correlation_time']:g} s"
    with (folder / "cases.csv").open() as f:
        cases = list(csv.DictReader(f))
    lines = []
    for delay in sorted({float(c["delay"]) for c in cases}):
        at = [c for c in cases if float(c["delay"]) == delay]
        cells = []
        for column in ("est_p_find", "sharp_p_find"):
            errors = [abs(float(c[column]) - float(c["emp_p_find"])) for c in at]
            within = sum(e <= 0.03 for e in errors) / len(errors)
            mean = sum(errors) / len(errors)
            cells.append(f"{mean:.4f} | {max(errors):.4f} | {100 * within:.1f} %")
        mean_emp = sum(float(c["emp_p_find"]) for c in at) / len(at)
        head = f"| {label} | {delay:g} | {len(at)} | {mean_emp:.3f} | "
        lines.append(head + " | ".join(cells) + " |")
    return label, lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    header = [
        "| Pd | t_d (s) | cases | simulated P_find, mean | paper's: mean error | largest | "
        "within 0.03 | sharp: mean error | largest | within 0.03 |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    body = [line for folder in args.folders for line in rows_of(folder)[1]]
    args.out.write_text("\n".join(header + body) + "\n")
    print(f"{len(body)} rows written to {args.out}")


if __name__ == "__main__":
    main()
