"""Test modules have unique basenames: the test folders are not packages, so pytest imports each
test module by its basename, and two files of one name in different folders cannot both run."""

from collections import Counter
from pathlib import Path


def test_test_module_names_are_unique():
    tests = Path(__file__).resolve().parents[1]
    names = Counter(p.name for p in tests.rglob("*.py") if p.name != "conftest.py")
    assert [n for n, count in names.items() if count > 1] == []
