"""Fixtures the tests of mm_pc's nodes share: the command line of a node."""

from __future__ import annotations

import pytest


@pytest.fixture
def ros_command():
    """``ros_command(module, params, namespace="", params_file=None)``: the command line of
    ``python -m module --ros-args [--params-file F] [-r __ns:=ns] -p name:=value ...``,
    built by mm_beagle.tools.harness.node_command (one way to spell a parameter)."""
    from mm_beagle.tools.harness import node_command

    def build(module: str, params: dict, namespace: str = "", params_file=None) -> list[str]:
        cmd = node_command(params, namespace)
        assert cmd[1:4] == ["-m", "mm_beagle.node", "--ros-args"], cmd
        cmd[2] = module
        if params_file:
            cmd[4:4] = ["--params-file", str(params_file)]
        return cmd

    return build
