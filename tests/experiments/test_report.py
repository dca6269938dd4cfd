"""The benchmark report: planners in the order asked, reductions of the first planner only, and
the paper's rows only beside a run that follows the paper's protocol."""

from hptrack.experiments.benchmark import BenchmarkConfig
from hptrack.experiments.report import (
    PAPER_SCENARIOS,
    benchmark_report,
    markdown_tables,
    paper_protocol_gaps,
)
from hptrack.experiments.store import EpisodeKey, EpisodeRow
from hptrack.registry import planner_settings

PLANNERS = ("stationary", "greedy", "arvi")
U = {"stationary": 40.0, "greedy": 30.0, "arvi": 50.0}


def _config(scenarios: int, counts=(2,), homogeneous=True) -> BenchmarkConfig:
    settings = {p: planner_settings(p, None) for p in PLANNERS}
    return BenchmarkConfig(
        planners=PLANNERS,
        settings=settings,
        target_counts=counts,
        scenarios=scenarios,
        homogeneous=homogeneous,
    )


def _rows(config: BenchmarkConfig) -> list[EpisodeRow]:
    # stored alphabetically, as a database might return them; U is the same on every seed
    return [
        EpisodeRow(EpisodeKey(p, n, s, config.setting, "{}"), U[p], 51.3, 0, 1.0, {})
        for p in sorted(config.planners)
        for n in config.target_counts
        for s in range(config.scenarios)
    ]


def test_planners_keep_the_order_asked_and_only_the_first_is_compared():
    config = _config(3)
    text = markdown_tables(_rows(config), planners=config.planners)
    table_rows = [line.split(" |")[0] for line in text.splitlines() if line.startswith("| ")]
    assert table_rows[1:4] == ["| stationary", "| greedy", "| arvi"]
    assert text.startswith("Mean ± std of U") and "| stationary | 40.00 ± 0.00 (3) |" in text
    assert "+-" not in text
    # stationary 40 against greedy 30: -33.33 %; against arvi 50: +20 %
    assert "| stationary vs greedy | -33.33 |" in text
    assert "| stationary vs arvi | 20.00 |" in text
    assert "greedy vs" not in text and "arvi vs" not in text


def test_paper_rows_only_with_the_papers_protocol():
    short = _config(3)
    assert paper_protocol_gaps(short, _rows(short)) == [f"3 scenarios per n, not {PAPER_SCENARIOS}"]
    text = benchmark_report(short, _rows(short))
    assert "(paper)" not in text and "The paper's rows are left out: 3 scenarios" in text

    full = _config(PAPER_SCENARIOS, counts=(2, 3))
    assert paper_protocol_gaps(full, _rows(full)) == []
    text = benchmark_report(full, _rows(full))
    assert "| ARVI (paper) | 40.64 ± 11.58 | 62.84 ± 12.69 |" in text
    assert "ADFQ (paper)" not in text and "left out" not in text
    # an unfinished run, or an n the paper has not, is not the protocol either
    assert paper_protocol_gaps(full, _rows(full)[:-1]) == ["1 planner-n cells are not complete"]
    odd = _config(PAPER_SCENARIOS, counts=(2, 8))
    assert paper_protocol_gaps(odd, _rows(odd)) == ["n = 8 is not in the paper"]
    hetero = _config(PAPER_SCENARIOS, homogeneous=False)
    text = benchmark_report(hetero, _rows(hetero))
    assert "ADFQ (paper)" in text and "ARVI (paper)" not in text
