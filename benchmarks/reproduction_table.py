"""The honest reproduction table: the paper's search at an effort comparable to the paper's, under
both forms of ``Q``, beside the published 100,000-simulation rows and the paper's Table II.

Reads the ``mcts`` episodes of a benchmark database made with, for each ``n`` and its effort
(``benchmarks/paper_effort.py``) and each ``Q`` form,

    hptrack benchmark --homogeneous --targets N --scenarios 100 --planners mcts \\
        -o mcts.preset=paper --iterations EFFORT --process-noise-form FORM --db results/effort.db

and writes a Markdown table (mean +- std and standard error of U per row and ``n``) and the
per-episode CSV.

    python3 benchmarks/reproduction_table.py --out docs/results/effort-matched
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

PUBLISHED = Path(__file__).resolve().parents[1] / "docs/results/benchmark/episodes.csv"
FORMS = {"homogeneous": "q tau I (continuous)", "homogeneous+paper_text": "q I (printed)"}


def main() -> None:
    from hptrack.experiments.report import PAPER_TABLE, effort_label, write_csv
    from hptrack.experiments.store import ResultStore

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, default=Path("results/effort.db"))
    parser.add_argument("--out", type=Path, default=Path("results/effort-matched"))
    args = parser.parse_args()
    store = ResultStore(args.db)
    rows = [r for r in store.rows() if r.key.planner == "mcts" and r.key.setting in FORMS]
    store.close()
    cells = defaultdict(list)  # (form, n) -> U
    efforts = defaultdict(set)  # form -> {(n, effort)}
    for r in rows:
        cells[(r.key.setting, r.key.n_targets)].append(r.uncertainty)
        efforts[r.key.setting].add((r.key.n_targets, effort_label(r.key)))
    with PUBLISHED.open(newline="") as fh:
        for r in csv.DictReader(fh):
            if r["planner"] == "mcts":
                cells[("published", int(r["n_targets"]))].append(float(r["U"]))
    ns = sorted({n for (_, n) in cells})

    def cell(values) -> str:
        a = np.asarray(values)
        return (
            f"{a.mean():.2f} +- {a.std():.2f} (se {a.std(ddof=1) / math.sqrt(a.size):.2f}, "
            f"{a.size})"
        )

    lines = [
        "Mean +- std of U (standard error of the mean, episodes), homogeneous scenarios "
        "0..99 per n, the paper's search (`-o mcts.preset=paper`).",
        "",
        "| search effort, Q | " + " | ".join(f"n={n}" for n in ns) + " |",
        "|---|" + "---|" * len(ns),
    ]
    for form, name in FORMS.items():
        if any((form, n) in cells for n in ns):
            lines.append(
                f"| paper-comparable effort, {name} | "
                + " | ".join(cell(cells[(form, n)]) if (form, n) in cells else "" for n in ns)
                + " |"
            )
    lines.append(
        "| 100,000 simulations, q tau I (continuous) | "
        + " | ".join(cell(cells[("published", n)]) if ("published", n) in cells else "" for n in ns)
        + " |"
    )
    paper = PAPER_TABLE["hierarchical, homogeneous (paper)"]
    lines.append(
        "| paper (30 s of Python per search, q I printed) | "
        + " | ".join(f"{paper[n][0]:.2f} +- {paper[n][1]:.2f}" if n in paper else "" for n in ns)
        + " |"
    )
    lines += [
        "",
        "Effort (simulations per search) per n: "
        + "; ".join(
            f"{FORMS[f]}: " + ", ".join(f"n={n} {e}" for n, e in sorted(v))
            for f, v in sorted(efforts.items())
        )
        + ".",
    ]
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(text)
    write_csv(rows, args.out / "episodes.csv")
    print(text)


if __name__ == "__main__":
    main()
