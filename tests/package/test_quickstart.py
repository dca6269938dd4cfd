"""The README's Python quick start runs verbatim and prints the figures it promises."""

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def python_block(path: Path, marker: str) -> str:
    """The first ```python block after ``marker`` in ``path``."""
    text = path.read_text()
    start = text.index(marker)
    match = re.search(r"```python\n(.*?)```", text[start:], re.DOTALL)
    assert match, f"no python block after {marker!r} in {path.name}"
    return match.group(1)


def test_readme_and_docs_show_the_same_quick_start():
    readme = python_block(ROOT / "README.md", "<!-- python quick start -->")
    docs = python_block(ROOT / "docs" / "python.md", "<!-- python quick start -->")
    assert readme == docs
    assert len(readme.strip().splitlines()) <= 12


def test_python_quick_start_runs(tmp_path):
    code = python_block(ROOT / "README.md", "<!-- python quick start -->")
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=600
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("t1 ")  # the first decision: pursue t1
    assert lines[1] == "U = 43.431"  # the same mission as `hptrack simulate --random ...`
    assert lines[2].startswith("{'mcts': ") and "'greedy': " in lines[2]  # in the order asked


def test_ci_runs_the_readme_test_command_exactly():
    command = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert command.startswith('python3 -m pip install -e ".[test]"')
    assert f"```bash\n{command}\n```" in (ROOT / "README.md").read_text()
