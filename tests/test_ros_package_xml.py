"""The package.xml files of the ROS packages: valid format 3, and their dependencies real.

Every third-party module the installed Python code imports is either an exec_depend (a
rosdep key: the ROS package itself, or python3-*) or one of the few pip-only packages the
file names in a comment; so a new import cannot slip past the system-ROS install.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

catkin_pkg = pytest.importorskip("catkin_pkg.package")

ROOT = Path(__file__).resolve().parents[1]
# Python package folders each ROS package installs (mm_pc/setup.py, mm_beagle/setup.py).
INSTALLS = {"mm_pc": ("mm_pc", "pln2033"), "mm_beagle": ("mm_beagle",)}
ROSDEP_PYTHON = {"numpy": "python3-numpy", "yaml": "python3-yaml", "psutil": "python3-psutil"}
PIP_ONLY = {"PySide6", "pyqtgraph", "mcap", "spidev", "smbus2", "zenoh"}  # no rosdep key: ./compile
OURS = {"mm_pc", "pln2033", "mm_beagle"}


def imports(folders: tuple[str, ...]) -> set[str]:
    """Top-level names imported anywhere in ``folders`` (not the build's setup.py)."""
    names = set()
    for folder in folders:
        for path in (ROOT / folder).rglob("*.py"):
            if path.name == "setup.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names |= {a.name.partition(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names.add(node.module.partition(".")[0])
    return names - set(sys.stdlib_module_names) - {"__future__"}


@pytest.mark.parametrize("pkg", sorted(INSTALLS))
def test_package_xml_is_valid_and_matches_pyproject(pkg):
    manifest = catkin_pkg.parse_package(ROOT / pkg / "package.xml")
    manifest.validate()
    assert manifest.package_format == 3
    assert manifest.name == pkg
    version = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M)
    assert manifest.version == version.group(1)
    assert [e.content for e in manifest.exports if e.tagname == "build_type"] == ["ament_python"]
    assert (ROOT / pkg / "resource" / pkg).is_file()


@pytest.mark.parametrize("pkg", sorted(INSTALLS))
def test_every_import_is_a_declared_dependency(pkg):
    manifest = catkin_pkg.parse_package(ROOT / pkg / "package.xml")
    declared = {d.name for d in manifest.exec_depends}
    text = (ROOT / pkg / "package.xml").read_text()
    missing = []
    for name in sorted(imports(INSTALLS[pkg])):
        if name in INSTALLS[pkg]:
            continue
        if name in PIP_ONLY:
            assert name.lower() in text.lower(), f"{pkg}/package.xml should name pip-only {name}"
            continue
        if pkg == "mm_pc" and name == "mm_beagle":
            continue  # the monitor's import; declared the other way round (no cycle)
        if name in OURS:
            name = next(p for p, folders in INSTALLS.items() if name in folders)
        want = ROSDEP_PYTHON.get(name, name)
        if want not in declared:
            missing.append(want)
    assert not missing, f"{pkg}/package.xml lacks exec_depend {missing}"


def test_the_dependency_walk_sees_the_node_imports():
    assert {"rclpy", "mm_interfaces", "mm_pc", "zenoh"} <= imports(("mm_beagle",))
