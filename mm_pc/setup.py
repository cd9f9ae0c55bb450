"""colcon (ament_python) build of the ROS packages mm_pc and mm_beagle (one recipe).

Each ROS package is its Python package's own folder, so that folder is the package
root (``package_dir={"mm_pc": "."}``). mm_pc brings pln2033, which lives beside it,
since mm_pc.core uses its units; mm_beagle's node imports mm_pc (an exec_depend).
Version and console scripts are read from ../pyproject.toml, the pip install's one
source, so both installs offer the same executables. mm_beagle/setup.py loads this
file and calls :func:`ros_package_setup`. Only colcon runs these files; pip builds from
the repository root and carries them as inert modules (``mm_pc.setup``, ``mm_beagle.setup``).
"""

from __future__ import annotations

import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent.parent


def _section(name: str) -> str:
    """The body of one ``[name]`` table of ../pyproject.toml (tomllib is 3.11+ only)."""
    text = (ROOT / "pyproject.toml").read_text()
    match = re.search(rf"^\[{re.escape(name)}\]\n(.*?)(?=^\[|\Z)", text, re.M | re.S)
    return match.group(1) if match else ""


def console_scripts(package: str) -> list[str]:
    """pyproject's [project.scripts] whose entry point lies in ``package``."""
    pairs = re.findall(r'^([\w-]+)\s*=\s*"([\w.]+:\w+)"', _section("project.scripts"), re.M)
    return [f"{name} = {target}" for name, target in pairs if target.startswith(package + ".")]


def _build_py_without_setup(name: str) -> type:
    """build_py that leaves ``<name>/setup.py`` out: with the package at '.', setuptools
    would otherwise install it as the module ``<name>.setup``."""

    class BuildPy(build_py):
        def find_package_modules(self, package, package_dir):
            found = super().find_package_modules(package, package_dir)
            return [m for m in found if not (m[0] == name and m[1] == "setup")]

    return BuildPy


def ros_package_setup(name: str, with_pln2033: bool = False) -> None:
    """setup() for the ROS package ``name``, run from its folder (colcon's working directory)."""
    packages = [name, *(f"{name}.{p}" for p in find_packages(".", exclude=["launch*"]))]
    package_dir = {name: "."}
    package_data = {name: ["config/*.yaml"]}
    if with_pln2033:
        packages += ["pln2033", *(f"pln2033.{p}" for p in find_packages("../pln2033"))]
        package_dir["pln2033"] = "../pln2033"
        package_data["pln2033.pln2033"] = ["*.yaml"]
    setup(
        name=name,
        version=re.search(r'^version = "([^"]+)"', _section("project"), re.M).group(1),
        packages=packages,
        package_dir=package_dir,
        package_data=package_data,
        data_files=[
            ("share/ament_index/resource_index/packages", [f"resource/{name}"]),
            (f"share/{name}", ["package.xml"]),
            (f"share/{name}/launch", sorted(glob("launch/*.launch.py"))),
            (f"share/{name}/config", sorted(glob("config/*.yaml"))),
        ],
        install_requires=["setuptools"],
        zip_safe=True,
        cmdclass={"build_py": _build_py_without_setup(name)},
        entry_points={"console_scripts": console_scripts(name)},
    )


# Imported (from pip's wheel as mm_pc.setup, or by mm_beagle/setup.py) it must do nothing.
if __name__ == "__main__":
    ros_package_setup("mm_pc", with_pln2033=True)
