"""The package layout is a picture of the pipeline: a module imports only from its own package
or from packages below it (imports inside ``if TYPE_CHECKING:`` are not dependencies)."""

import ast
from pathlib import Path

import hptrack

LAYERS = [
    "_numba_cache",
    "jsonout",
    "_dispatch",
    "models",
    "subtasks",
    "interface",
    "settings",
    "scenario",
    "coverage",
    "planning",
    "baselines",
    "teams",
    "sim",
    "viz",
    "envs",
    "learning",
    "registry",
    "decision",
    "runtime",
    "integrations",
    "experiments",
    "cli",
    "examples",
    "__main__",
]
"""Bottom to top."""
ROOT = Path(hptrack.__file__).parent


def _package(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "hptrack" and len(parts) > 1 else None


def _imports(tree: ast.AST):
    """``(line, module)`` of every import outside ``if TYPE_CHECKING:`` blocks."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for child in node.body for n in ast.walk(child))
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.lineno, node.module
            for alias in node.names:  # ``from hptrack import x``
                if node.module == "hptrack":
                    yield node.lineno, f"hptrack.{alias.name}"


def test_every_module_imports_only_from_its_layer_or_below():
    rank = {name: i for i, name in enumerate(LAYERS)}
    bad = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if rel.parts[0] == "__init__.py":
            continue
        own = rel.parts[0].removesuffix(".py")
        assert own in rank, f"{rel}: package {own!r} is not in LAYERS"
        for line, module in _imports(ast.parse(path.read_text())):
            other = _package(module)
            if other is not None and other != own and rank.get(other, -1) > rank[own]:
                bad.append(f"{rel}:{line} ({own}) imports {module} ({other})")
    assert not bad, "\n".join(bad)
