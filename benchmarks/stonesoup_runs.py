"""Run the Stone Soup example with the argument sets quoted in docs/stonesoup.md and write what it
prints to docs/results/stonesoup/ (outputs.txt verbatim, table.md the scores).

    python3 benchmarks/stonesoup_runs.py
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "src" / "hptrack" / "examples" / "stonesoup_tracking.py"
OUT = ROOT / "docs" / "results" / "stonesoup"
RUNS = [
    "",
    "-o preset=paper",
    "--planner greedy",
    "--planner stationary",
    "-o iterations=3000 --steps 240",
    "--planner greedy --steps 240",
    "--seed 3",
    "--seed 3 --planner greedy",
]
SCORE = re.compile(r"^\s+(hptrack \S+|hover|hptrack - hover)\s+(-?\d+\.\d+)", re.M)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    outputs, rows = [], []
    for args in RUNS:
        command = f"python3 examples/stonesoup_tracking.py {args}".strip()
        printed = subprocess.run(
            [sys.executable, str(EXAMPLE), *shlex.split(args)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        outputs.append(f"$ {command}\n{printed}")
        scores = dict(SCORE.findall(printed))
        mine = next(k for k in scores if k.startswith("hptrack ") and k != "hptrack - hover")
        rows.append(
            f"| `{args or '(defaults)'}` | {mine.split()[1]} | {scores[mine]} | "
            f"{scores['hover']} | {scores['hptrack - hover']} |"
        )
    (OUT / "outputs.txt").write_text("\n".join(outputs))
    table = [
        "Mean over tracks of the final log det Sigma_xy (log m^4, lower is tighter), "
        "`python3 examples/stonesoup_tracking.py ARGUMENTS`.",
        "",
        "| arguments | planner | hptrack | hover | difference |",
        "|---|---|---|---|---|",
        *rows,
    ]
    (OUT / "table.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))


if __name__ == "__main__":
    main()
