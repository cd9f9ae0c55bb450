"""The import rules between the layers (docs/architecture.md), checked by walking the source.

Every ``import`` statement counts, also those inside functions: a lazy import still pulls the
package in when it runs. Rules on a layer hold over the transitive closure of the project's own
modules, so a core module cannot reach rclpy through a helper either. Nothing is imported here;
the files are parsed with :mod:`ast`.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = ("mm_pc", "mm_beagle", "pln2033")

ROS = (
    "rclpy",
    "rcl_interfaces",
    "rosidl_runtime_py",
    "builtin_interfaces",
    "std_msgs",
    "geometry_msgs",
    "nav_msgs",
    "sensor_msgs",
    "diagnostic_msgs",
    "mm_interfaces",
    "tf2_msgs",
    "ament_index_python",
)
QT = ("PySide6", "shiboken6", "pyqtgraph")


def module_files() -> dict[str, Path]:
    """Every module of the project packages by dotted name."""
    out = {}
    for pkg in PROJECT:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


MODULES = module_files()


@cache
def direct_imports(module: str) -> frozenset[str]:
    """The dotted names ``module`` imports (relative imports resolved; ``from a import b`` gives
    ``a.b`` when that is one of our modules, else ``a``)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names.add(target)
            for a in node.names:
                if f"{target}.{a.name}" in MODULES:
                    names.add(f"{target}.{a.name}")
    return frozenset(names)


def _ours(name: str) -> str | None:
    """The project module ``name`` refers to (a name inside a module maps to that module)."""
    while name:
        if name in MODULES:
            return name
        name = name.rpartition(".")[0]
    return None


@cache
def closure(module: str) -> dict[str, tuple[str, ...]]:
    """Every name reachable from ``module`` with one import chain that reaches it."""
    seen: dict[str, tuple[str, ...]] = {}
    todo = [(module, (module,))]
    while todo:
        mod, chain = todo.pop()
        for name in direct_imports(mod):
            if name in seen:
                continue
            seen[name] = (*chain, name)
            ours = _ours(name)
            if ours and ours not in chain:
                # importing a.b.c runs a/__init__ and a/b/__init__ too
                parts = ours.split(".")
                for i in range(1, len(parts) + 1):
                    step = ".".join(parts[:i])
                    if step in MODULES and step not in seen:
                        seen[step] = (*chain, step)
                    if step in MODULES:
                        todo.append((step, (*chain, step)))
    return seen


def _hits(names, forbidden: tuple[str, ...]) -> list[str]:
    return sorted(n for n in names if any(n == f or n.startswith(f + ".") for f in forbidden))


def in_layer(prefix: str) -> list[str]:
    return [m for m in MODULES if m == prefix or m.startswith(prefix + ".")]


def broken(modules, forbidden, transitive=True) -> list[str]:
    """One line per module that reaches a forbidden name, with the chain that does it."""
    out = []
    for m in modules:
        if transitive:
            reach = closure(m)
            out += [f"{m}: {' -> '.join(reach[h])}" for h in _hits(reach, forbidden)]
        else:
            out += [f"{m} imports {h}" for h in _hits(direct_imports(m), forbidden)]
    return out


#: what runs on a board without ROS (docs/architecture.md); absent ones are skipped, but the
#: rule fails if none is there
BOARD_SIDE = (
    "mm_beagle.poller.poller",
    "mm_beagle.poller.shared_state",
    "mm_beagle.poller.lift_gap",
    "mm_beagle.poller.sim_backend",
    "mm_beagle.link.link",
    "mm_beagle.link.agent",
)

RULES = {
    "core is pure: no ROS, no Qt": (in_layer("mm_pc.core"), ROS + QT, True),
    "core imports nothing from sim, ros, bench, monitor or the board side": (
        in_layer("mm_pc.core"),
        ("mm_pc.sim", "mm_pc.ros", "mm_pc.bench", "mm_pc.monitor", "mm_beagle"),
        True,
    ),
    "sim imports no ROS and no Qt": (in_layer("mm_pc.sim"), ROS + QT, True),
    "sim imports nothing from ros, bench or monitor": (
        in_layer("mm_pc.sim"),
        ("mm_pc.ros", "mm_pc.bench", "mm_pc.monitor"),
        True,
    ),
    "monitor/model imports no ROS and no Qt": (in_layer("mm_pc.monitor.model"), ROS + QT, True),
    "ros adapters never import Qt": (in_layer("mm_pc.ros"), QT, True),
    "widgets never import rclpy (nor the bridge that does)": (
        in_layer("mm_pc.monitor.widgets"),
        (*ROS, "mm_pc.monitor.ros_bridge", "mm_pc.monitor.recording"),
        True,
    ),
    "pln2033 imports no ROS, no Qt and nothing of ours above it": (
        in_layer("pln2033"),
        (*ROS, *QT, "mm_pc", "mm_beagle"),
        True,
    ),
    "the board side of mm_beagle (poller, agent, link, sim backend) imports no ROS": (
        [m for m in BOARD_SIDE if m in MODULES],
        ROS,
        True,
    ),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_import_rule(rule):
    modules, forbidden, transitive = RULES[rule]
    assert modules, f"{rule}: no module in this layer (was it renamed?)"
    out = broken(modules, forbidden, transitive)
    assert not out, "\n".join(out)


def _widget(module: str) -> str:
    """The widget a module belongs to: mm_pc.monitor.widgets.<name>[.<part>] -> <name>."""
    return module.split(".")[3] if module.count(".") >= 3 else ""


def test_widgets_do_not_import_each_other():
    """Shared colours and styles live in widgets.style; anything else shared goes to model.
    A widget made of several files is a package (map_view/): its parts may import each other."""
    widgets = in_layer("mm_pc.monitor.widgets")
    shared = ("mm_pc.monitor.widgets", "mm_pc.monitor.widgets.style")
    out = []
    for w in widgets:
        if w in shared:
            continue
        others = tuple(o for o in widgets if _widget(o) != _widget(w) and o not in shared)
        out += broken([w], others, transitive=False)
    assert not out, "\n".join(out)


def test_the_walk_sees_lazy_and_relative_imports():
    """The checker itself: a function-level relative import is found and resolved."""
    assert "mm_pc.ros.spin" in closure("mm_beagle.node.node")
    assert "rclpy" in closure("mm_pc.ros.odometry_node")
    # mm_beagle.poller.sim_backend imports the simulator inside its functions
    assert "mm_pc.sim.robot" in direct_imports("mm_beagle.poller.sim_backend")
    assert broken(["mm_pc.ros.odometry_node"], ("rclpy",)) != []
