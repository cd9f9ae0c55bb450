"""The package.xml files of the ROS packages: valid format 3, and their dependencies real.

Every third-party module the installed Python code imports is either an exec_depend (a
rosdep key: the ROS package itself, or python3-*) or one of the few pip-only packages the
file names in a comment; so a new import cannot slip past the system-ROS install. Also:
which tests `colcon test` runs (setup.cfg), and ./compile's own ament index entries.
"""

from __future__ import annotations

import ast
import configparser
import os
import re
import sys
from pathlib import Path

import pytest

catkin_pkg = pytest.importorskip("catkin_pkg.package")

ROOT = Path(__file__).resolve().parents[1]
# Python package folders each ROS package installs (mm_pc/setup.py, mm_beagle/setup.py).
INSTALLS = {"mm_pc": ("mm_pc", "pln2033"), "mm_beagle": ("mm_beagle",)}
ROSDEP_PYTHON = {"numpy": "python3-numpy", "yaml": "python3-yaml", "psutil": "python3-psutil"}
# no rosdep key: ./compile installs them with pip (zstandard comes with mcap)
PIP_ONLY = {"PySide6", "pyqtgraph", "mcap", "zstandard", "spidev", "smbus2", "zenoh"}
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
    # _sha2: the standard library's sha256 module from Python 3.12 on (link_auth's fallback)
    return names - set(sys.stdlib_module_names) - {"__future__", "_sha2"}


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


def _pytest_options(pkg: str) -> dict[str, str]:
    """The [tool:pytest] section of ``pkg``/setup.cfg (what `colcon test` runs)."""
    parser = configparser.ConfigParser(interpolation=None)
    parser.read(ROOT / pkg / "setup.cfg")
    return dict(parser["tool:pytest"])


def test_colcon_test_runs_every_test_folder_with_the_suites_options():
    """Each tests/ folder belongs to the package whose code it tests (tests/pln2033: mm_pc
    installs pln2033); the repository's own tests/test_*.py are ./compile test's."""
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    owners: dict[str, str] = {}
    for pkg in INSTALLS:
        options = _pytest_options(pkg)
        for path in options["testpaths"].split():
            assert path.startswith("../tests/") and path not in owners, path
            owners[path.removeprefix("../tests/")] = pkg
        assert options["pythonpath"].split() == [f"../{p}" for p in project["pythonpath"]]
        assert int(options["timeout"]) == project["timeout"]
        assert options["filterwarnings"].split("\n")[1:] == project["filterwarnings"]
        assert options["markers"].split("\n")[1:] == project["markers"]
    folders = {p.name for p in (ROOT / "tests").iterdir() if any(p.glob("test_*.py"))}  # not data/
    assert set(owners) == folders
    assert owners["beagle"] == "mm_beagle" and owners["pln2033"] == "mm_pc"


def test_compile_registers_the_packages_in_its_ament_index():
    """After ./compile alone both packages are in an ament index on AMENT_PREFIX_PATH (the
    venv's; a colcon install/ros first where ./compile ran colcon): the share folder with
    package.xml, launch/ and config/, and lib/<pkg>/ with the package's executables."""
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    assert "AMENT_PREFIX_PATH" in os.environ, "source install/setup.bash"
    text = (ROOT / "pyproject.toml").read_text()
    scripts = re.search(r"^\[project\.scripts\]\n(.*?)(?=^\[)", text, re.M | re.S).group(1)
    for pkg in INSTALLS:
        share = Path(get_package_share_directory(pkg))
        assert (share / "package.xml").read_bytes() == (ROOT / pkg / "package.xml").read_bytes()
        for sub, pattern in (("launch", "*.launch.py"), ("config", "*.yaml")):
            found = sorted(p.name for p in (share / sub).glob(pattern))
            assert found and found == sorted(p.name for p in (ROOT / pkg / sub).glob(pattern))
        lib = Path(get_package_prefix(pkg)) / "lib" / pkg
        want = sorted(re.findall(rf'^([\w-]+) = "{pkg}\.', scripts, re.M))
        assert want and sorted(p.name for p in lib.iterdir()) == want
        assert all(os.access(lib / exe, os.X_OK) for exe in want)
    robot = Path(get_package_share_directory("mm_beagle")) / "launch" / "robot.launch.py"
    assert robot.read_bytes() == (ROOT / "mm_beagle" / "launch" / "robot.launch.py").read_bytes()
