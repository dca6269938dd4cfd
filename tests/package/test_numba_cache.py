"""Numba's disk cache is keyed by the kernels' sources (``hptrack._numba_cache``): an edit in any
kernel module reaches every kernel that uses it in the next process, with no file deleted."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

import hptrack
from hptrack import _numba_cache

INNER = "import numba\n\n\n@numba.njit(cache=True)\ndef inner():\n    return {value}\n"
OUTER = (
    "import numba\n\nfrom hptrack.models._probe_inner import inner\n\n\n"
    "@numba.njit(cache=True)\ndef outer():\n    return inner() + 10.0\n"
)
RUN = (
    "import hptrack, numba\n"
    "from hptrack.planning._probe_outer import outer\n"
    "print(outer(), sum(outer.stats.cache_hits.values()), hptrack.__file__, "
    "numba.config.CACHE_DIR)\n"
)


@pytest.fixture
def scratch(tmp_path) -> Path:
    """A copy of the package's sources with a kernel in ``models`` that a kernel in
    ``planning`` calls."""
    package = tmp_path / "src" / "hptrack"
    shutil.copytree(
        Path(hptrack.__file__).parent,
        package,
        ignore=shutil.ignore_patterns("__pycache__", "*.pt", "*.zip"),
    )
    (package / "models" / "_probe_inner.py").write_text(INNER.format(value="1.0"))
    (package / "planning" / "_probe_outer.py").write_text(OUTER)
    return package


def _run(package: Path, cache: Path) -> tuple[float, int, str, str]:
    env = {**os.environ, "PYTHONPATH": str(package.parent), "HPTRACK_CACHE_DIR": str(cache)}
    out = subprocess.run(
        [sys.executable, "-c", RUN], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    return float(out[0]), int(out[1]), out[2], out[3]


def test_an_edit_of_a_called_kernel_reaches_the_caller_in_a_new_process(scratch, tmp_path):
    cache = tmp_path / "cache"
    value, hits, source, directory = _run(scratch, cache)
    assert (value, hits) == (11.0, 0)
    assert Path(source).parent == scratch  # the scratch copy, not the installed package
    assert Path(directory).parent == cache and list(Path(directory).rglob("*.nbi"))
    assert _run(scratch, cache)[:2] == (11.0, 1)  # the next process loads it from disk
    (scratch / "models" / "_probe_inner.py").write_text(INNER.format(value="2.0"))
    value, hits, _, edited = _run(scratch, cache)
    assert (value, hits) == (12.0, 0)  # numba's own cache would load 11 (outer's file is old)
    assert edited != directory


def test_checkouts_of_the_same_sources_share_one_cache_and_others_do_not(scratch, tmp_path):
    cache = tmp_path / "cache"
    clone = tmp_path / "clone" / "src" / "hptrack"  # the same sources at another path
    shutil.copytree(scratch, clone)
    assert _run(scratch, cache)[:2] == (11.0, 0)  # compiled
    value, hits, source, directory = _run(clone, cache)
    assert Path(source).parent == clone
    assert (value, hits) == (11.0, 1)  # loaded: numba's own locator would compile again
    nbi = {p.relative_to(directory) for p in Path(directory).rglob("*.nbi")}
    assert {p.parent for p in nbi} == {Path("hptrack/models"), Path("hptrack/planning")}
    (clone / "models" / "_probe_inner.py").write_text(INNER.format(value="2.0"))
    value, hits, _, edited = _run(clone, cache)  # an edited clone: its own directory
    assert (value, hits) == (12.0, 0) and edited != directory
    assert _run(scratch, cache)[:2] == (11.0, 1)  # and the original still loads its own


def test_kernels_outside_the_package_keep_numbas_own_locator(tmp_path):
    from numba.core.caching import UserProvidedCacheLocator

    def kernel():
        return 1

    outside = tmp_path / "elsewhere.py"
    outside.write_text("")
    assert _numba_cache.PackageLocator.from_function(kernel, str(outside)) is None
    assert _numba_cache.PackageLocator.from_function(kernel, "<ipython-input-1>") is None
    inside = Path(hptrack.__file__).parent / "models" / "motion.py"
    locator = _numba_cache.PackageLocator.from_function(kernel, str(inside))
    assert Path(locator.get_cache_path()).parts[-2:] == ("hptrack", "models")
    assert UserProvidedCacheLocator.from_function(kernel, str(outside)) is not None


def test_the_key_covers_the_kernel_modules_and_what_they_import_only(scratch):
    before = _numba_cache.sources_digest(scratch)
    app = scratch / "cli" / "app.py"
    app.write_text(app.read_text() + "\n# a comment\n")
    assert _numba_cache.sources_digest(scratch) == before  # no kernel reads the CLI
    interface = scratch / "interface.py"  # no numba in it, but kernel modules import it
    assert b"numba" not in interface.read_bytes()
    interface.write_text(interface.read_text() + "\nLIMIT = 3\n")
    assert _numba_cache.sources_digest(scratch) != before


def test_where_the_cache_lives(scratch, tmp_path, monkeypatch):
    name = f"numba-{_numba_cache.sources_digest(scratch)}"
    monkeypatch.delenv("HPTRACK_CACHE_DIR", raising=False)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    assert _numba_cache.cache_directory(scratch) == tmp_path / "numba" / "hptrack" / name
    base = tmp_path / "mine"
    old, recent = base / "numba-0000000000000000", base / "numba-1111111111111111"
    for other in (old, recent):
        other.mkdir(parents=True)
    month = time.time() - 31 * 86400.0
    os.utime(old, (month, month))
    monkeypatch.setenv("HPTRACK_CACHE_DIR", str(base))
    assert _numba_cache.cache_directory(scratch) == base / name
    assert not old.exists() and recent.exists()  # unused for a month: removed
    blocked = tmp_path / "a-file"  # a base that cannot be written: the temporary directory
    blocked.write_text("")
    monkeypatch.setenv("HPTRACK_CACHE_DIR", str(blocked / "cache"))
    monkeypatch.setenv("USER", "someone")
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))
    assert _numba_cache.cache_directory(scratch) == tmp_path / "tmp" / "hptrack-someone" / name


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="POSIX owners and modes")
@pytest.mark.parametrize("planted", ["base", "directory"])
def test_a_cache_another_user_owns_or_can_write_is_never_used(
    scratch, tmp_path, monkeypatch, caplog, planted
):
    name = f"numba-{_numba_cache.sources_digest(scratch)}"
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setenv("USER", "someone")
    mine = tmp_path / "mine"
    monkeypatch.setenv("HPTRACK_CACHE_DIR", str(mine))
    shared = tmp_path / "tmp" / "hptrack-someone"  # the fallback another user created first
    for base in (mine, shared):
        target = base if planted == "base" else base / name
        target.mkdir(parents=True)
        target.chmod(0o777)
    if os.getuid() == 0:
        os.chown(shared if planted == "base" else shared / name, 65534, 65534)
    with caplog.at_level("WARNING", logger="hptrack"):
        directory = _numba_cache.cache_directory(scratch)
    assert directory.name == name and directory.parent not in (mine, shared)
    assert directory.parent.parent == tmp_path / "tmp"
    assert _numba_cache.unsafe_reason(directory) is None
    assert _numba_cache.unsafe_reason(directory.parent) is None
    (line,) = caplog.messages
    assert "writable by others (mode 777)" in line and str(mine) in line
    if os.getuid() == 0:
        assert "owned by user id 65534" in line
    if planted == "base":  # nothing was made inside a folder others can write
        assert not (mine / name).exists() and not (shared / name).exists()
    for path in (mine, mine / name):
        if path.exists():
            path.chmod(0o755)
    assert _numba_cache.cache_directory(scratch) == mine / name  # made private: used again


def test_the_directories_it_creates_are_private(scratch, tmp_path, monkeypatch):
    monkeypatch.setenv("HPTRACK_CACHE_DIR", str(tmp_path / "a" / "b"))
    old = os.umask(0)  # even where new folders would be writable by everyone
    try:
        directory = _numba_cache.cache_directory(scratch)
    finally:
        os.umask(old)
    for path in (tmp_path / "a", tmp_path / "a" / "b", directory):
        assert (path.stat().st_mode & 0o777) == 0o700, path
