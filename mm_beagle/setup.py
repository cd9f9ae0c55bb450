"""colcon (ament_python) build of the ROS package mm_beagle: the Python package mm_beagle.

The ROS package is this folder, so the Python package's own folder is the package root
(``package_dir={"mm_beagle": "."}``). pln2033 and mm_pc.core/sim/ros, which the node
imports, come with the ROS package mm_pc (an exec_depend). Version and console scripts are
read from ../pyproject.toml, the pip install's one source, so both installs offer the same
executables. This file is run only by colcon; pip builds from the repository root.
"""

from __future__ import annotations

import re
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

NAME = "mm_beagle"
HERE = Path(__file__).resolve().parent


def _section(name: str) -> str:
    """The body of one ``[name]`` table of ../pyproject.toml (tomllib is 3.11+ only)."""
    text = (HERE.parent / "pyproject.toml").read_text()
    match = re.search(rf"^\[{re.escape(name)}\]\n(.*?)(?=^\[|\Z)", text, re.M | re.S)
    return match.group(1) if match else ""


def console_scripts(package: str) -> list[str]:
    """pyproject's [project.scripts] whose entry point lies in ``package``."""
    pairs = re.findall(r'^([\w-]+)\s*=\s*"([\w.]+:\w+)"', _section("project.scripts"), re.M)
    return [f"{name} = {target}" for name, target in pairs if target.startswith(package + ".")]


class BuildPy(build_py):
    """build_py that leaves this setup.py out: with the package at '.', setuptools would
    otherwise install it as the module ``mm_beagle.setup``."""

    def find_package_modules(self, package, package_dir):
        found = super().find_package_modules(package, package_dir)
        return [m for m in found if not (m[0] == NAME and m[1] == "setup")]


# pip's wheel (built from ../pyproject.toml) carries this file as the module mm_beagle.setup;
# imported as such it must do nothing. colcon runs it as a script.
if __name__ != "mm_beagle.setup":
    setup(
        name=NAME,
        version=re.search(r'^version = "([^"]+)"', _section("project"), re.M).group(1),
        packages=[NAME, *(f"{NAME}.{p}" for p in find_packages(".", exclude=["launch*"]))],
        package_dir={NAME: "."},
        package_data={NAME: ["config/*.yaml"]},
        data_files=[
            ("share/ament_index/resource_index/packages", [f"resource/{NAME}"]),
            (f"share/{NAME}", ["package.xml"]),
            (f"share/{NAME}/launch", sorted(glob("launch/*.launch.py"))),
            (f"share/{NAME}/config", sorted(glob("config/*.yaml"))),
        ],
        install_requires=["setuptools"],
        zip_safe=True,
        cmdclass={"build_py": BuildPy},
        entry_points={"console_scripts": console_scripts(NAME)},
    )
