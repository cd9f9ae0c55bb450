"""colcon (ament_python) build of the ROS packages mm_pc and mm_beagle (one recipe).

Each ROS package is its Python package's own folder, so that folder is the package
root. mm_pc brings pln2033, which lives beside it, since mm_pc.core uses its units;
mm_beagle's node imports mm_pc (an exec_depend). Version and console scripts are read
from ../pyproject.toml, the pip install's one source, so both installs offer the same
executables. mm_beagle/setup.py loads this file and calls :func:`ros_package_setup`.
Only colcon runs these files; pip builds from the repository root and carries them as
inert modules (``mm_pc.setup``, ``mm_beagle.setup``); ./compile imports
:func:`console_scripts` to register the packages in its own ament index.

``colcon build --symlink-install`` links every top-level package that colcon's dry run
of this file names into the package's build folder, by its ``package_dir`` entry; an
entry "this folder itself" (``.``) cannot be linked (``build/mm_pc/.``: OSError EINVAL).
So the dry run (it stops after reading the configuration) sees no packages: they are
declared when a command runs (:func:`_distribution`), and ``develop``, which colcon runs
from the build folder it then puts on PYTHONPATH, makes the links colcon would have made.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from setuptools import Distribution, find_packages, setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent.parent  # also when colcon runs it through a link


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


def _distribution(home: Path, folders: dict[str, Path]) -> type:
    """A Distribution that declares the packages of ``folders`` (top-level name -> source
    folder) only when its commands run, so colcon's dry run sees none; ``home`` is the
    ROS package's folder."""
    packages = [
        p for top, src in folders.items()
        for p in (top, *(f"{top}.{sub}" for sub in find_packages(str(src), exclude=["launch*"])))
    ]  # fmt: skip

    class Dist(Distribution):
        def run_commands(self):
            self.packages = packages
            cwd = Path.cwd().resolve()
            if "develop" in self.commands and cwd != home:
                # colcon --symlink-install: run from its build folder; link the packages
                # there (that folder is on the install's PYTHONPATH) and build from the links
                for top, src in folders.items():
                    link = cwd / top
                    if link.is_symlink() and link.resolve() != src:
                        link.unlink()
                    if not link.is_symlink():
                        link.symlink_to(src, target_is_directory=True)
                self.package_dir = {}
            else:  # colcon's install, run from this folder
                self.package_dir = {top: os.path.relpath(src, cwd) for top, src in folders.items()}
            super().run_commands()

    return Dist


def _files(home: Path, pattern: str) -> list[str]:
    """``pattern``'s files relative to ``home``, wherever setup.py runs (colcon's develop
    runs it from the build folder, where it linked these files)."""
    return sorted(str(p.relative_to(home)) for p in home.glob(pattern))


def ros_package_setup(name: str, with_pln2033: bool = False) -> None:
    """setup() for the ROS package ``name``, run from its folder (colcon's working directory)."""
    home = ROOT / name
    folders = {name: home}
    package_data = {name: ["config/*.yaml"]}
    if with_pln2033:
        folders["pln2033"] = ROOT / "pln2033"
        package_data["pln2033.pln2033"] = ["*.yaml"]
    setup(
        name=name,
        version=re.search(r'^version = "([^"]+)"', _section("project"), re.M).group(1),
        distclass=_distribution(home, folders),
        package_data=package_data,
        data_files=[
            ("share/ament_index/resource_index/packages", [f"resource/{name}"]),
            (f"share/{name}", ["package.xml"]),
            (f"share/{name}/launch", _files(home, "launch/*.launch.py")),
            (f"share/{name}/config", _files(home, "config/*.yaml")),
        ],
        install_requires=["setuptools"],
        # `colcon test` runs pytest in this folder: setup.cfg [tool:pytest] names the tests
        extras_require={"test": ["pytest"]},
        zip_safe=True,
        cmdclass={"build_py": _build_py_without_setup(name)},
        entry_points={"console_scripts": console_scripts(name)},
    )


# Imported (pip's wheel: mm_pc.setup; mm_beagle/setup.py; ./compile) it must do nothing.
if __name__ == "__main__":
    ros_package_setup("mm_pc", with_pln2033=True)
