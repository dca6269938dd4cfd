"""Every number the README and the docs quote agrees with its result file in docs/results/
(``python3 benchmarks/quoted_numbers.py --write`` regenerates them)."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location(
    "quoted_numbers", ROOT / "benchmarks" / "quoted_numbers.py"
)
quoted_numbers = importlib.util.module_from_spec(spec)
spec.loader.exec_module(quoted_numbers)


def test_every_quote_agrees_with_its_result_file():
    stale = [
        line for path in quoted_numbers.documents() for line in quoted_numbers.stale_quotes(path)
    ]
    assert stale == []


def test_the_readme_and_the_results_pages_quote_their_tables():
    readme = (ROOT / "README.md").read_text()
    assert len(quoted_numbers.BLOCK.findall(readme)) >= 1
    for page in ("paper-tables", "estimator-accuracy", "planner-comparisons", "speed"):
        text = (ROOT / "docs" / "results" / f"{page}.md").read_text()
        assert quoted_numbers.BLOCK.search(text), page


def test_a_changed_number_is_caught(tmp_path):
    readme = (ROOT / "README.md").read_text()
    changed = readme.replace("| 11.91 +- 3.33 (100) |", "| 11.90 +- 3.33 (100) |", 1)
    assert changed != readme
    page = tmp_path / "page.md"
    page.write_text(changed)
    (stale,) = quoted_numbers.stale_quotes(page)
    assert "benchmark/table.md" in stale
    assert quoted_numbers.regenerate(changed) == readme


def test_inline_quotes_format_one_csv_cell(tmp_path):
    text = (
        "mcts at n = 6: <!-- q: benchmark/episodes_summary.csv planner=mcts n_targets=6 "
        "mean_U .2f -->86.37<!-- /q --> on average.\n"
    )
    page = tmp_path / "page.md"
    page.write_text(text)
    assert quoted_numbers.stale_quotes(page) == []
    page.write_text(text.replace("86.37", "86.4"))
    assert len(quoted_numbers.stale_quotes(page)) == 1


def test_a_quote_of_a_missing_row_or_file_is_an_error():
    with pytest.raises(ValueError, match="no rows"):
        quoted_numbers.quoted_table('benchmark/table.md rows="nope"')
    with pytest.raises(ValueError, match="no such result file"):
        quoted_numbers.quoted_table("nope/table.md")
    with pytest.raises(ValueError, match="5 rows of episodes_summary.csv match, not one"):
        quoted_numbers.quoted_value("benchmark/episodes_summary.csv planner=mcts mean_U .2f")
