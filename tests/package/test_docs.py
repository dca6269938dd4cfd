"""The documentation reads as Markdown for users: docstrings carry no Sphinx roles (mkdocstrings
would print them raw), the API page documents the main objects, user pages keep to what an
option does, the nav lists each page once and links read as titles, not file names."""

import ast
import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "hptrack"
DOCS = ROOT / "docs"

# reStructuredText that mkdocstrings renders raw: a role such as :func:`plan`, or a paragraph
# ending in "::" to open a literal block
SPHINX = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|obj|exc|ref|const):`|\w::$", re.M)


def sphinx_in_docstrings(source: str) -> list[int]:
    """Line numbers of the docstrings in ``source`` (module, class, function and attribute
    docstrings alike) that use reStructuredText markup."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
            and SPHINX.search(node.value.value)
        ):
            lines.append(node.lineno)
    return lines


def test_no_docstring_uses_sphinx_markup():
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for path in sorted(SRC.rglob("*.py"))
        for line in sphinx_in_docstrings(path.read_text())
    ]
    assert found == []


@pytest.mark.parametrize(
    "text",
    [
        'def f():\n    """Calls :func:`plan`."""\n',
        '"""Module, see :class:`~hptrack.x.Y`\nfor more."""\n',
        'X = 1\n"""Attribute docstring naming :mod:`hptrack.sim`."""\n',
        '"""It prints::\n\n    a table\n"""\n',
    ],
)
def test_sphinx_markup_is_caught(text):
    assert sphinx_in_docstrings(text) != []


def test_markdown_docstrings_pass():
    assert sphinx_in_docstrings('"""Calls `plan` (``-o KEY=VALUE``): see `hptrack.sim`."""') == []


def api_objects() -> set[str]:
    """Every object the API page renders: ``::: module`` with its ``members`` (all its public
    top-level names when none are listed)."""
    objects = set()
    text = (DOCS / "api.md").read_text()
    for block in re.split(r"\n(?=::: )", text):
        match = re.match(r"::: ([\w.]+)", block)
        if not match:
            continue
        module = match.group(1)
        members = re.search(r"members: \[([^\]]*)\]", block)
        if members:
            names = [name.strip() for name in members.group(1).split(",")]
        else:
            path = SRC.parent / (module.replace(".", "/") + ".py")
            tree = ast.parse(path.read_text())
            names = [
                node.name
                for node in tree.body
                if isinstance(node, (ast.ClassDef, ast.FunctionDef)) and not node.name[0] == "_"
            ]
        objects.add(module)
        objects.update(f"{module}.{name}" for name in names)
    return objects


def defined(qualified: str) -> bool:
    """Whether ``module.Name`` is a class or function defined at the top of its module's file."""
    module, name = qualified.rsplit(".", 1)
    path = SRC.parent / (module.replace(".", "/") + ".py")
    tree = ast.parse(path.read_text())
    return any(
        isinstance(node, (ast.ClassDef, ast.FunctionDef)) and node.name == name
        for node in tree.body
    )


REQUIRED = [
    "hptrack.runtime.controller.MissionController",
    "hptrack.runtime.mavsdk_adapter.run_flight",
    "hptrack.runtime.mavsdk_adapter.FlightOptions",
    "hptrack.envs.tracking.TrackingEnv",
    "hptrack.envs.subtask.SubtaskTrackingEnv",
    "hptrack.learning.agent.AdfqAgent",
    "hptrack.learning.train.Trainer",
    "hptrack.learning.sb3.PpoTrainer",
    "hptrack.learning.policy_planner.AdfqPlanner",
    "hptrack.learning.policy_planner.Sb3Planner",
    "hptrack.planning.hierarchical.HierarchicalPlanner",
    "hptrack.baselines.greedy.GreedyPlanner",
    "hptrack.baselines.arvi.ArviPlanner",
    "hptrack.baselines.astar.AStarPlanner",
    "hptrack.baselines.coverage.CoveragePlanner",
    "hptrack.baselines.stationary.StationaryPlanner",
    "hptrack.baselines.clairvoyant.ClairvoyantPlanner",
]


@pytest.mark.parametrize("qualified", REQUIRED)
def test_the_api_page_documents(qualified):
    assert defined(qualified), f"{qualified} is not defined in its module"
    assert qualified in api_objects()


def test_every_object_the_api_page_lists_exists():
    def exists(name: str) -> bool:
        path = SRC.parent / name.replace(".", "/")
        return path.with_suffix(".py").exists() or (path / "__init__.py").exists()

    missing = [name for name in api_objects() if not exists(name) and not defined(name)]
    assert missing == []


USER_PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
NOT_FOR_USERS = re.compile(r"quality goals?|shared with other jobs", re.I)


def test_user_pages_speak_of_options_not_of_project_goals_or_machine_load():
    found = [
        f"{page.relative_to(ROOT)}: {match.group(0)!r}"
        for page in USER_PAGES
        for match in NOT_FOR_USERS.finditer(page.read_text())
    ]
    assert found == []


def nav_pages(nav) -> list[str]:
    """Every page the mkdocs nav lists, in order, repeats included."""
    if isinstance(nav, str):
        return [nav]
    if isinstance(nav, dict):
        return [page for value in nav.values() for page in nav_pages(value)]
    return [page for entry in nav for page in nav_pages(entry)]


def test_nav_lists_every_page_once():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    pages = nav_pages(config["nav"])
    repeated = sorted({page for page in pages if pages.count(page) > 1})
    assert repeated == []
    on_disk = [
        str(path.relative_to(DOCS))
        for path in [*DOCS.glob("*.md"), *(DOCS / "results").glob("*.md")]
    ]
    assert sorted(set(on_disk) - set(pages)) == []


def test_nav_repeats_are_caught():
    assert nav_pages([{"A": [{"x": "a.md"}, {"y": "b.md"}]}, {"B": [{"z": "a.md"}]}]) == [
        "a.md",
        "b.md",
        "a.md",
    ]


# a link whose text is a file or folder name (``[model.md](model.md)``, ``[results/x/](...)``)
# rather than a title; code spans (``[`Scenario`](api.md)``) are names, not file names
LINK = re.compile(r"(?<!!)\[([^\]`]+)\]\(([^)\s]+)\)")
FILE_NAME = re.compile(r"^[\w./-]+\.(?:md|txt|csv|json|yaml|png|gif)$|^[\w.-]+/(?:[\w.-]+/)*$")


def file_name_links(text: str) -> list[str]:
    return [match.group(0) for match in LINK.finditer(text) if FILE_NAME.match(match.group(1))]


def test_links_read_as_titles():
    pages = [*USER_PAGES, *sorted((DOCS / "results").glob("*.md"))]
    found = [
        f"{page.relative_to(ROOT)}: {link}"
        for page in pages
        for link in file_name_links(page.read_text())
    ]
    assert found == []


def test_a_file_name_link_is_caught():
    text = "see [results/speed.md](results/speed.md), [results/x/](x/table.md), [model.md](m.md)"
    assert len(file_name_links(text)) == 3
    assert file_name_links("see [speed results](results/speed.md) and [`Scenario`](api.md)") == []
