"""Numba's on-disk cache of the compiled kernels, in a directory named by their sources' hash.

Numba's own cache (``cache=True``) checks only the file of the kernel it loads: a kernel that
calls or inlines a kernel of another module, or reads a constant from one, keeps its old machine
code after an edit there. Here the kernel modules of the package (those that use numba) and every
hptrack module they import are hashed, and numba caches in ``<base>/numba-<hash>``: an edit in
any of them gives a new directory, so nothing stale is ever loaded and nobody deletes files. The
base is ``$HPTRACK_CACHE_DIR``, else ``$NUMBA_CACHE_DIR/hptrack``, else the user's cache directory
(``~/.cache/hptrack`` on Linux), else, if that cannot be written (a read-only home), one in the
system's temporary directory. Directories of other hashes unused for `KEEP_DAYS` are removed.

Inside it, each kernel is cached under its module's folder relative to the package
(`PackageLocator`), not under numba's hash of the folder's absolute path: every checkout or
install of the same sources shares one cache, so a fresh clone loads what another compiled. The
same hash means the same kernel sources (and what they import), so what one loads is what it
would compile; numba still checks each kernel's own file by its content.

``hptrack/__init__.py`` imports this module first: numba chooses a kernel's cache directory when
the kernel is defined. It imports no numerics: it sets ``NUMBA_CACHE_DIR`` (and
``HPTRACK_CACHE_DIR`` to the base, so that child processes key their own sources under the same
base) for numba to read when it is imported, and numba's configuration if numba already is.

Numba's cache holds pickled code, which it runs when it loads a kernel: a directory that another
user owns or can write (a ``/tmp/hptrack-$USER`` that someone else created with mode 777, say)
is never used. The directories created here are private (mode 700); if no candidate is safe,
the kernels are cached in a fresh private temporary directory, removed at exit, and a warning
says why (the kernels then compile again in the next process).
"""

from __future__ import annotations

import atexit
import hashlib
import importlib.machinery
import logging
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

PACKAGE = Path(__file__).parent
KEEP_DAYS = 30.0
"""A cache directory of other sources that no process has used for this long is removed."""

_IMPORT = re.compile(
    r"^[ \t]*(?:from[ \t]+(hptrack[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)"
    r"|import[ \t]+(hptrack[\w.]*))",
    re.MULTILINE,
)


def _module_files(name: str, root: Path) -> list[Path]:
    """The files that importing module ``name`` (``hptrack.a.b``) runs: ``b`` and its packages'
    ``__init__.py``."""
    parts = name.split(".")[1:]
    files = [root / Path(*parts[:i]) / "__init__.py" for i in range(len(parts))]
    path = root / Path(*parts) if parts else root
    files += [path.with_suffix(".py"), path / "__init__.py"]
    return [f for f in files if f.is_file()]


def _imported_files(source: str, root: Path) -> set[Path]:
    """The hptrack files a module's source imports (anywhere in it, also inside functions)."""
    out = set()
    for module, names, plain in _IMPORT.findall(source):
        out.update(_module_files(module or plain, root))
        for name in names.strip("()").split(","):  # ``from hptrack.a import b`` may be a module
            name = name.split(" as ")[0].strip()
            if name.isidentifier():
                out.update(_module_files(f"{module}.{name}", root))
    return out


def sources_digest(root: Path = PACKAGE) -> str:
    """A hash of the package's kernel modules and of every hptrack module they import
    (transitively), by path and content."""
    sources = {p: p.read_bytes() for p in root.rglob("*.py")}
    todo = [p for p, text in sources.items() if b"numba" in text]
    seen: set[Path] = set()
    while todo:
        path = todo.pop()
        if path in seen or path not in sources:
            continue
        seen.add(path)
        todo.extend(_imported_files(sources[path].decode(), root))
    digest = hashlib.sha256()
    for path in sorted(seen):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + sources[path] + b"\0")
    return digest.hexdigest()[:16]


def _user_cache_base() -> Path:
    if sys.platform == "win32":
        return Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local")) / "hptrack"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "hptrack"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "hptrack"


def _bases() -> list[Path]:
    """Where the cache may live, first choice first."""
    if os.environ.get("HPTRACK_CACHE_DIR"):
        first = Path(os.environ["HPTRACK_CACHE_DIR"])
    elif os.environ.get("NUMBA_CACHE_DIR"):
        first = Path(os.environ["NUMBA_CACHE_DIR"]) / "hptrack"
    else:
        first = _user_cache_base()
    user = os.environ.get("USER") or os.environ.get("USERNAME") or "user"
    return [first, Path(tempfile.gettempdir()) / f"hptrack-{user}"]


def _make_private(directory: Path) -> None:
    """Create ``directory`` and its missing parents, each with mode 700."""
    missing = []
    while not directory.exists() and directory.parent != directory:
        missing.append(directory)
        directory = directory.parent
    for path in reversed(missing):
        path.mkdir(mode=0o700, exist_ok=True)


def unsafe_reason(directory: Path) -> str | None:
    """Why numba must not load code from ``directory`` (another owner, writable by others), or
    ``None`` if it is the current user's own."""
    if not hasattr(os, "getuid"):  # Windows: no owner and mode bits to check
        return None
    link, target = os.lstat(directory), os.stat(directory)
    if link.st_uid != os.getuid() or target.st_uid != os.getuid():
        return f"owned by user id {target.st_uid if link.st_uid == os.getuid() else link.st_uid}"
    if target.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"writable by others (mode {stat.S_IMODE(target.st_mode):o})"
    return None


def _usable(directory: Path) -> str | None:
    """Create ``directory`` (private) if needed; ``None`` if the cache may live there, else why
    not."""
    try:
        for path in (directory.parent, directory):  # nothing is made in a folder not safe
            _make_private(path)
            reason = unsafe_reason(path)
            if reason:
                return f"{path}: {reason}"
        with tempfile.TemporaryFile(dir=directory):
            return None
    except OSError as err:
        return f"{directory}: {err.strerror or err}"


def _remove_unused(base: Path, keep: Path) -> None:
    limit = time.time() - KEEP_DAYS * 86400.0
    for other in base.glob("numba-*"):
        try:
            if other != keep and other.stat().st_mtime < limit:
                shutil.rmtree(other, ignore_errors=True)
        except OSError:
            continue


def cache_directory(root: Path = PACKAGE) -> Path | None:
    """The cache directory for the sources under ``root`` (created and marked as used now): the
    first of the candidates that is safe (`unsafe_reason`), else a fresh private temporary
    one; ``None`` if no place can be written."""
    name = f"numba-{sources_digest(root)}"
    reasons = []
    for base in _bases():
        directory = base / name
        reason = _usable(directory)
        if reason is None:
            os.utime(directory)
            _remove_unused(base, directory)
            return directory
        reasons.append(reason)
    try:
        base = Path(tempfile.mkdtemp(prefix="hptrack-cache-"))
    except OSError:
        return None
    atexit.register(shutil.rmtree, base, ignore_errors=True)
    logging.getLogger("hptrack").warning(
        "hptrack: compiled kernels are cached in %s for this run only, since no safe cache "
        "directory was found (%s); set HPTRACK_CACHE_DIR to a folder only you can write",
        base,
        "; ".join(reasons),
    )
    (base / name).mkdir(mode=0o700)
    return base / name


class PackageLocator:
    """Numba's cache locator for the package's own kernels: ``NUMBA_CACHE_DIR/<the module's
    folder relative to the package>`` (module docstring); numba asks it first (`configure`), and
    falls back to its own locators for any other file."""

    def __init__(self, py_func: object, py_file: str, directory: Path) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno  # type: ignore[attr-defined]
        self._directory = directory

    @classmethod
    def from_function(cls, py_func: object, py_file: str) -> PackageLocator | None:
        """A locator for ``py_func`` if it is defined in a file of this package and numba
        caches in a directory, else ``None`` (numba's next locator)."""
        base = os.environ.get("NUMBA_CACHE_DIR")
        numba = sys.modules.get("numba")
        if numba is not None:
            base = numba.config.CACHE_DIR or None
        try:
            folder = Path(py_file).resolve().parent.relative_to(PACKAGE.resolve())
        except (OSError, ValueError):  # not one of ours (a test's kernel, a notebook's)
            return None
        if not base or not Path(py_file).is_file():
            return None
        locator = cls(py_func, py_file, Path(base, "hptrack", *folder.parts))
        try:
            locator.ensure_cache_path()
        except OSError:
            return None
        return locator

    def ensure_cache_path(self) -> None:
        """Create the folder (private) and check that it can be written."""
        _make_private(self._directory)
        with tempfile.TemporaryFile(dir=self._directory):
            pass

    def get_cache_path(self) -> str:
        return str(self._directory)

    def get_source_stamp(self) -> str:
        """The kernel's file by content (numba's own stamp, which a copy keeps)."""
        return hashlib.sha256(Path(self._py_file).read_bytes()).hexdigest()

    def get_disambiguator(self) -> str:
        return str(self._lineno)


def _use_package_locator(caching: object) -> None:
    """Put `PackageLocator` first among numba's cache locators (module
    ``numba.core.caching``)."""
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl  # type: ignore[attr-defined]
    if PackageLocator not in impl._locator_classes:
        impl._locator_classes.insert(0, PackageLocator)


class _AfterCachingImport:
    """An import hook that hands ``numba.core.caching`` to `_use_package_locator` as soon as
    numba imports it, so that ``import hptrack`` itself imports no numerics."""

    name = "numba.core.caching"

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname != self.name:
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module: ModuleType) -> None:
            run(module)
            _use_package_locator(module)

        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


def configure() -> None:
    """Point numba's cache at `cache_directory` (kernels defined from now on), each kernel under
    its folder in the package (`PackageLocator`)."""
    directory = cache_directory()
    if directory is None:
        return
    os.environ["HPTRACK_CACHE_DIR"] = str(directory.parent)
    os.environ["NUMBA_CACHE_DIR"] = str(directory)
    if "numba" in sys.modules:
        sys.modules["numba"].config.CACHE_DIR = str(directory)
    if "numba.core.caching" in sys.modules:
        _use_package_locator(sys.modules["numba.core.caching"])
    elif not any(isinstance(finder, _AfterCachingImport) for finder in sys.meta_path):
        sys.meta_path.insert(0, _AfterCachingImport())


configure()
