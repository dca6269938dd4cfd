"""Every number the README and docs quote, regenerated from the result files in docs/results/.

A quoted table is a block between two HTML comments (invisible on GitHub and on the docs site)::

    <!-- quoted: benchmark/table.md table=1 rows="mcts|greedy" -->
    | planner | n=2 | ...
    <!-- end quoted -->

that copies table ``table`` (1-based) of ``docs/results/benchmark/table.md``, only the rows whose
first cell is listed in ``rows`` (all rows if absent), in the order listed. A quoted number in
prose is an inline pair::

    <!-- q: benchmark/episodes_summary.csv planner=mcts n_targets=6 mean_U .2f -->86.37<!-- /q -->

that formats column ``mean_U`` of the one CSV row matching every ``column=value`` filter.

``python3 benchmarks/quoted_numbers.py`` checks every quote in README.md and docs/**/*.md against
its file (exit 1 and one line per stale quote); ``--write`` rewrites the quotes from the files.
"""

from __future__ import annotations

import argparse
import csv
import re
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"

BLOCK = re.compile(
    r"(?P<open>(?<!`)<!-- quoted: (?P<spec>.*?) -->\n)(?P<body>.*?)(?P<close><!-- end quoted -->)",
    re.DOTALL,
)
INLINE = re.compile(r"(?P<open>(?<!`)<!-- q: (?P<spec>.*?) -->)(?P<body>.*?)(?P<close><!-- /q -->)")


def _arguments(spec: str) -> tuple[Path, dict[str, str], list[str]]:
    """The result file, the ``key=value`` options and the other words of a quote's spec."""
    words = shlex.split(spec)
    if not words:
        raise ValueError("an empty quote spec")
    path = RESULTS / words[0]
    if not path.is_file():
        raise ValueError(f"{words[0]}: no such result file under docs/results/")
    options = dict(w.split("=", 1) for w in words[1:] if "=" in w)
    return path, options, [w for w in words[1:] if "=" not in w]


def markdown_tables(text: str) -> list[list[str]]:
    """The markdown tables of ``text``, each a list of its lines."""
    tables: list[list[str]] = []
    current: list[str] = []
    for line in text.splitlines():
        if line.startswith("|"):
            current.append(line.rstrip())
        elif current:
            tables.append(current)
            current = []
    if current:
        tables.append(current)
    return tables


def _first_cell(line: str) -> str:
    return line.strip("|").split("|", 1)[0].strip()


def quoted_table(spec: str) -> str:
    """The body of a block quote: the selected table rows, a trailing newline."""
    path, options, _ = _arguments(spec)
    tables = markdown_tables(path.read_text())
    index = int(options.get("table", "1"))
    if not 1 <= index <= len(tables):
        raise ValueError(f"{spec}: {path.name} has {len(tables)} tables, not {index}")
    header, rule, *rows = tables[index - 1]
    if "rows" in options:
        by_name = {_first_cell(r): r for r in rows}
        wanted = options["rows"].split("|")
        missing = [w for w in wanted if w not in by_name]
        if missing:
            raise ValueError(f"{spec}: no rows {missing} in table {index} of {path.name}")
        rows = [by_name[w] for w in wanted]
    return "\n".join([header, rule, *rows]) + "\n"


def quoted_value(spec: str) -> str:
    """The text of an inline quote: one formatted CSV cell."""
    path, filters, (column, fmt) = _arguments(spec)
    with path.open(newline="") as f:
        matches = [r for r in csv.DictReader(f) if all(r.get(k) == v for k, v in filters.items())]
    if len(matches) != 1:
        raise ValueError(f"{spec}: {len(matches)} rows of {path.name} match, not one")
    return format(float(matches[0][column]), fmt)


def documents() -> list[Path]:
    """README.md and every markdown page of the docs (the result folders' files excluded)."""
    pages = [
        p
        for p in sorted((ROOT / "docs").rglob("*.md"))
        if RESULTS not in p.parents or p.parent == RESULTS
    ]
    return [ROOT / "README.md", *pages]


def regenerate(text: str) -> str:
    """``text`` with every quote replaced by what its result file says."""
    text = BLOCK.sub(lambda m: m["open"] + quoted_table(m["spec"]) + m["close"], text)
    return INLINE.sub(lambda m: m["open"] + quoted_value(m["spec"]) + m["close"], text)


def stale_quotes(path: Path) -> list[str]:
    """One line per quote of ``path`` that disagrees with its result file."""
    text = path.read_text()
    stale = []
    for pattern, build in ((BLOCK, quoted_table), (INLINE, quoted_value)):
        for m in pattern.finditer(text):
            expected = build(m["spec"])
            if m["body"] != expected:
                line = text.count("\n", 0, m.start()) + 1
                where = path.relative_to(ROOT) if ROOT in path.parents else path
                stale.append(
                    f"{where}:{line}: quote of {m['spec']!r} is "
                    f"{m['body'].strip()[:60]!r}, the file says {expected.strip()[:60]!r}"
                )
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the quotes from the files")
    args = parser.parse_args(argv)
    if args.write:
        for path in documents():
            text = path.read_text()
            new = regenerate(text)
            if new != text:
                path.write_text(new)
                print(f"rewrote {path.relative_to(ROOT)}")
        return 0
    stale = [line for path in documents() for line in stale_quotes(path)]
    print("\n".join(stale) if stale else "every quoted number agrees with its result file")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
