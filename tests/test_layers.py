"""The import rules between the layers (docs/architecture.md): import-linter's contracts in
pyproject.toml, run as ``lint-imports`` (``./compile test`` runs it before pytest too).

import-linter reads every ``import`` statement, also those inside functions, and a contract
on a module holds over the chains through our own modules: a core module cannot reach
rclpy through a helper either.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(config: Path | None = None) -> subprocess.CompletedProcess:
    cmd = [str(LINT), "--no-cache", *(["--config", str(config)] if config else [])]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_every_contract_is_kept():
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    out = _lint()
    assert out.returncode == 0, out.stdout + out.stderr
    n = len(contracts["contracts"])
    assert re.search(rf"Contracts: {n} kept, 0 broken", out.stdout), out.stdout


def test_a_broken_rule_is_caught_with_its_chain(tmp_path):
    """The checker itself: the ROS adapters do import rclpy, so forbidding it must fail and
    name the line; a lazy import (the sim backend's, inside a function) is seen too."""
    config = tmp_path / "contracts.toml"
    config.write_text(
        "[tool.importlinter]\n"
        'root_packages = ["pln2033", "mm_beagle", "mm_pc"]\n'
        "include_external_packages = true\n"
        "[[tool.importlinter.contracts]]\n"
        'name = "ros without rclpy"\ntype = "forbidden"\n'
        'source_modules = ["mm_pc.ros.odometry_node"]\nforbidden_modules = ["rclpy"]\n'
        "[[tool.importlinter.contracts]]\n"
        'name = "sim backend without the simulator"\ntype = "forbidden"\n'
        'source_modules = ["mm_beagle.poller.sim_backend"]\nforbidden_modules = ["mm_pc.sim"]\n'
    )
    out = _lint(config)
    assert out.returncode == 1, out.stdout
    assert "Contracts: 0 kept, 2 broken" in out.stdout, out.stdout
    assert "mm_pc.ros.odometry_node -> rclpy" in out.stdout, out.stdout

