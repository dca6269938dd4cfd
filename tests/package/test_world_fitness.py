"""The world is asked, not spelled: code above `hptrack.models` reads a target state through
`hptrack.models.state`, asks the mission's sensor part whether a look measures a target
(`hptrack.models.sensor`) and the vehicle part how soon it meets one (`hptrack.models.vehicle`,
`hptrack.models.mission.intercept_flight`). An AST scan of every module above the models fails
on code that

* indexes a state's velocity (``mean[2]``, ``means[:, 2:]``, ``truth[i, 3]``, ``state[axis + 2]``
  on a value named as a target state: ``mean(s)``, ``truth``, ``states``, ``m``, ...),
* tests a footprint (a comparison that involves a footprint's radius or diameter), or
* computes an intercept itself (the closed form's squared speed, or the vehicle's raw kernels
  imported instead of the dispatched ones).

The coverage formulas of the paper's footprint (the shifting spiral, the estimators, the pass
probability) are geometry of that footprint and of the holonomic vehicle: they read the
footprint's radius by design and are exempt from the footprint rule only (`FOOTPRINT_GEOMETRY`);
the coverage sub-task and its intercept flight are scanned like every other layer.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from test_layers import LAYERS  # noqa: I001 - the sibling test module (tests are not packages)

import hptrack

ROOT = Path(hptrack.__file__).parent
ABOVE_MODELS = set(LAYERS[LAYERS.index("models") + 1 :])
"""The packages and modules scanned."""
FOOTPRINT_GEOMETRY = {
    "coverage/spiral.py",
    "coverage/estimator.py",
    "coverage/sharp_estimator.py",
    "coverage/passes.py",
}
"""The footprint's own coverage formulas (module docstring)."""
STATE_NAME = re.compile(
    r"^(m|mean|means|state_mean|truth|truths|true_state|true_states|states|moved)$"
    r"|_means?$|_truths?$|_states$"
)
"""Names of values that hold target states ``[x, y, vx, vy]``."""
FOOTPRINT_NAME = re.compile(r"^(radius2?|r2)$|footprint_radius|sensor_radius|diameter$")
"""Names of a footprint's size."""
SPEED_NAME = re.compile(r"speed")
RAW_VEHICLE_KERNELS = {"intercept_time", "approach_step", "move_agent"}
"""Kernels of `hptrack.models.vehicle` that hold the holonomic closed forms: code above the
models calls the dispatched ``vehicle_*`` ones or the mission record's."""


def _name(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _is_velocity_index(index: ast.AST) -> bool:
    last = index.elts[-1] if isinstance(index, ast.Tuple) and index.elts else index
    if isinstance(last, ast.Constant):
        return last.value in (2, 3)
    if isinstance(last, ast.Slice) and isinstance(last.lower, ast.Constant):
        return last.lower.value in (2, 3)
    if isinstance(last, ast.BinOp) and isinstance(last.op, ast.Add):
        return any(isinstance(s, ast.Constant) and s.value == 2 for s in (last.left, last.right))
    return False


def _mentions(node: ast.AST, pattern: re.Pattern) -> bool:
    return any((name := _name(n)) is not None and pattern.search(name) for n in ast.walk(node))


def _is_footprint_test(node: ast.Compare) -> bool:
    """An ordering of a footprint's size against something that is not a number (a distance):
    ``d2 <= radius2``, ``hypot(...) <= 0.5 * w``; ``w > 0.0`` validates, it tests nothing."""
    if not all(isinstance(op, (ast.Lt, ast.LtE, ast.Gt, ast.GtE)) for op in node.ops):
        return False
    sides = [node.left, *node.comparators]
    sized = [s for s in sides if _mentions(s, FOOTPRINT_NAME)]
    return bool(sized) and any(s not in sized and not isinstance(s, ast.Constant) for s in sides)


def violations(source: str, footprint_geometry: bool = False) -> list[str]:
    """``"line: what"`` for every place in ``source`` that spells the world (module docstring);
    ``footprint_geometry``: a coverage formula of the footprint (the footprint rule is off)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Subscript):
            name = _name(node.value)
            if name is not None and STATE_NAME.search(name) and _is_velocity_index(node.slice):
                found.append(f"{line}: indexes the velocity of state {name!r}")
        elif isinstance(node, ast.Compare) and not footprint_geometry:
            if _is_footprint_test(node):
                found.append(f"{line}: tests a footprint")
        elif isinstance(node, ast.BinOp):
            left, right = _name(node.left), _name(node.right)
            squared = (isinstance(node.op, ast.Mult) and left is not None and left == right) or (
                isinstance(node.op, ast.Pow)
                and left is not None
                and isinstance(node.right, ast.Constant)
                and node.right.value == 2
            )
            if squared and SPEED_NAME.search(left):
                found.append(f"{line}: squares a speed (an intercept's closed form)")
        elif isinstance(node, ast.ImportFrom) and node.module == "hptrack.models.vehicle":
            for alias in node.names:
                if alias.name in RAW_VEHICLE_KERNELS:
                    found.append(f"{line}: imports the vehicle's raw kernel {alias.name}")
    return found


def test_no_layer_above_the_models_spells_the_world():
    bad = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if rel.parts[0].removesuffix(".py") not in ABOVE_MODELS:
            continue
        geometry = rel.as_posix() in FOOTPRINT_GEOMETRY
        bad += [f"{rel}:{v}" for v in violations(path.read_text(), geometry)]
    assert not bad, "\n".join(bad)


def test_the_scan_finds_each_planted_example_and_passes_its_fix():
    planted = {
        "velocity": "speed = math.hypot(mean[2], mean[3])",
        "stacked velocity": "v = obs.means[:, 2:]",
        "velocity by offset": "end = state_mean[axis] + truth[axis + 2] * budget",
        "footprint": "inside = dx * dx + dy * dy <= mission.sensor_radius ** 2",
        "footprint by diameter": "inside = np.hypot(*d) <= 0.5 * spec.sensor_diameter",
        "footprint reversed": "outside = radius2 < dx * dx + dy * dy",
        "intercept": "closing = agent_speed * agent_speed - (vx * vx + vy * vy)",
        "raw kernel": "from hptrack.models.vehicle import intercept_time",
    }
    for what, source in planted.items():
        assert violations(source), what
    fixed = [
        "vx, vy = velocity_of(mean)",
        "v = velocities(obs.means)",
        "p = positions(obs.means)[:, :2]",
        "inside = sensor_measures(mission.sensor, ax, ay, x, y)",
        "steps = intercept_steps_to(mission, ax, ay, mean)",
        "from hptrack.models.vehicle import vehicle_intercept_time, move_towards",
        "base_cov, base_step = state[2], state[3]",  # a search state, not a target's
    ]
    for source in fixed:
        assert violations(source) == [], source
    assert violations("ok = gap <= radius", footprint_geometry=True) == []
    assert violations("valid = diameter > 0.0 and diameter is not None") == []
