"""``--help`` of every console script prints a usage and exits 0 without starting anything;
a node command refuses an argument that is not a ROS argument (mm_pc/node_usage.py,
issue 27 item 7)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from fakes import console_script, scaled

from mm_pc import node_usage

NODES = list(node_usage.NODES)
#: every console script but the nodes: argparse's usage
OTHERS = ["mm-beagle-agent", "mm-watch", "mm-security", "mm-bench", "mm-monitor",
          "mm-otos-settings"]  # fmt: skip
#: runs a launcher as pip's script does, then says whether rclpy was imported
PROBE = (
    "import sys\n"
    "from {module} import {func}\n"
    "sys.argv = {argv!r}\n"
    "code = {func}()\n"
    "print('rclpy imported:', 'rclpy' in sys.modules, file=sys.stderr)\n"
    "sys.exit(code)\n"
)
LAUNCHERS = {
    "mm-beagle": ("mm_beagle.commands", "mm_beagle"),
    "mm-odometry": ("mm_pc.commands", "mm_odometry"),
    "mm-fusion": ("mm_pc.commands", "mm_fusion"),
    "mm-field-sim": ("mm_pc.commands", "mm_field_sim"),
}


def _probe(tmp_path, program: str, *args: str) -> subprocess.CompletedProcess:
    module, func = LAUNCHERS[program]
    code = PROBE.format(module=module, func=func, argv=[program, *args])
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
        timeout=scaled(30),
    )  # fmt: skip


@pytest.mark.parametrize("program", NODES)
def test_a_node_command_prints_its_usage_without_starting_ros(tmp_path, program):
    out = _probe(tmp_path, program, "--help")
    assert out.returncode == 0, out.stderr
    node = node_usage.NODES[program][0]
    assert out.stdout.startswith(f"usage: {program} [--ros-args [-p NAME:=VALUE]... ")
    assert "-p NAME:=VALUE" in out.stdout and "--params-file FILE" in out.stdout
    assert f"ros2 param describe /{node} NAME" in out.stdout
    assert f"Example: {program} --ros-args -p " in out.stdout
    assert out.stderr.strip() == "rclpy imported: False"


@pytest.mark.parametrize("args", [["-h"], ["--ros-args", "-p", "backend:=sim", "--", "--help"]])
def test_help_also_short_or_after_a_ros_args_section(tmp_path, args):
    out = _probe(tmp_path, "mm-beagle", *args)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage: mm-beagle ")
    assert out.stderr.strip() == "rclpy imported: False"


@pytest.mark.parametrize(
    ("program", "arg", "hint"),
    [
        ("mm-beagle", "backend:=sim", "(mm-beagle --ros-args -p backend:=sim)"),
        ("mm-odometry", "--rate", "(mm-odometry --ros-args -p NAME:=VALUE)"),
        ("mm-fusion", "fusion.yaml", "(mm-fusion --ros-args -p NAME:=VALUE)"),
    ],
)
def test_an_argument_outside_ros_args_is_refused_with_one_line(tmp_path, program, arg, hint):
    """Before: ignored by rclpy, so the node started with its defaults (a forgotten
    ``--ros-args -p`` started mm-beagle on spidev instead of sim)."""
    out = _probe(tmp_path, program, arg)
    assert out.returncode == 2
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert lines == [
        f"{program}: unexpected argument {arg!r}: a node takes ROS arguments only {hint}; "
        f"{program} --help says more",
        "rclpy imported: False",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written


@pytest.mark.parametrize("program", NODES + OTHERS)
def test_every_console_script_help_exits_0_quickly(tmp_path, program):
    """As a user's shell starts it (pip's script): usage on stdout, exit 0, no traceback;
    a node command that started its node instead would not end (timeout)."""
    if program == "mm-monitor":
        pytest.importorskip("PySide6")
    script = console_script(program, tmp_path)
    started = time.monotonic()
    out = subprocess.run(
        [sys.executable, script, "--help"], capture_output=True, text=True, cwd=tmp_path,
        timeout=scaled(60),
    )  # fmt: skip
    took = time.monotonic() - started
    assert out.returncode == 0, out.stderr[-800:]
    assert out.stdout.startswith(f"usage: {program} "), out.stdout[:200]
    assert "Traceback" not in out.stderr
    if program in NODES:  # the launcher's own imports only
        assert took < scaled(10), took
        assert out.stderr == ""


@pytest.mark.parametrize(
    "args",
    [
        [],
        ["--ros-args", "-p", "backend:=sim"],
        ["--ros-args", "-r", "__node:=beagle", "--params-file", "/tmp/p.yaml", "--"],
        ["--ros-args", "--log-level", "debug", "--", "--ros-args", "-p", "cpi:=800"],
    ],
)
def test_ros_arguments_alone_start_the_node(args):
    """What ros2 launch and ros2 run pass: nothing to say, the node starts."""
    assert node_usage.outside_ros_args(args) == []
    assert node_usage.check("mm-beagle", args) is None


def test_outside_ros_args():
    args = ["a", "--ros-args", "-p", "x:=1", "--", "b", "--ros-args", "--", "--"]
    assert node_usage.outside_ros_args(args) == ["a", "b", "--"]


def _parameters(program: str) -> dict:
    pytest.importorskip("rclpy")
    if program == "mm-beagle":
        from mm_beagle.node.params import PARAMETERS
    elif program == "mm-odometry":
        from mm_pc.ros.odometry_node import PARAMETERS
    elif program == "mm-fusion":
        from mm_pc.ros.fusion_params import PARAMETERS
    else:
        from mm_pc.ros.field_sim_node import PARAMETERS
    return PARAMETERS


@pytest.mark.parametrize("program", NODES)
def test_the_usage_example_names_parameters_of_that_node_with_their_type(program):
    """The example would start the node: every name is declared, every value has the
    declared default's type (a float with a decimal point, as rcl needs)."""
    example = node_usage.NODES[program][2].split()
    assert example[::2] == ["-p"] * (len(example) // 2)
    table = _parameters(program)
    for pair in example[1::2]:
        name, _, value = pair.partition(":=")
        assert name in table, name
        default = table[name][0]
        if isinstance(default, float):
            assert "." in value and float(value) == float(value), pair
        elif isinstance(default, int):
            assert int(value) == int(value), pair
        else:
            assert isinstance(default, str), pair
