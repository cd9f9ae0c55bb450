"""``--help`` of the ROS node commands (mm-beagle, mm-odometry, mm-fusion, mm-field-sim).

A node takes ROS arguments only (``--ros-args -p NAME:=VALUE``, ``--params-file FILE``);
rclpy passes anything else through and the node ignored it, so ``mm-beagle --help``
started the node and ``mm-beagle backend:=sim`` (``--ros-args -p`` forgotten) started it
with the defaults. The console-script launchers (``mm_pc.commands``, ``mm_beagle.commands``)
call :func:`check` first: ``-h``/``--help`` prints a short usage and exits 0, any other
argument outside ``--ros-args`` is refused with one line and exit 2; in both cases before
rclpy is imported. Imports nothing but ``sys`` (it runs in the launcher).
"""

from __future__ import annotations

import sys

#: program -> (node name, what it does, example parameters, where the parameters are
#: described, the file with every one and its default ('' if none))
NODES = {
    "mm-beagle": (
        "mm_beagle",
        "The sensor node: polls the mouse sensors (backend spidev or sim) or reads an\n"
        "mm-beagle-agent on the board (backend remote), and serves their counts.",
        "-p backend:=sim -p cpi:=3200",
        "docs/beagle-node.md section 2",
        "mm_beagle/config/mm_beagle.yaml",
    ),
    "mm-odometry": (
        "mm_odometry",
        "Robot pose from the sensor node's samples: ~/odom, ~/path, /tf.",
        "-p rate:=20.0 -p method:=exact",
        "docs/ros-integration.md 'Parameters'",
        "mm_pc/config/mm_odometry.yaml",
    ),
    "mm-fusion": (
        "mm_fusion",
        "One pose estimate from the mouse odometry and absolute fixes (an EKF).",
        "-p publish_rate:=10.0 -p gps_topic:=/gps/fix",
        "docs/maps-and-fixes.md 'Fusion'",
        "mm_pc/config/mm_fusion.yaml",
    ),
    "mm-field-sim": (
        "field_sim",
        "The simulated mowing run published on ROS topics, then exit 0.",
        "-p speed:=20.0 -p seed:=1",
        "docs/maps-and-fixes.md 'Fusion' and mm_pc/ros/field_sim_node.py",
        "",
    ),
}

HELP = ("-h", "--help")
EXIT_USAGE = 0
EXIT_BAD_ARGUMENT = 2


def usage(program: str) -> str:
    """The short usage of ``program`` (a key of :data:`NODES`)."""
    node, what, example, doc, file = NODES[program]
    every = f", every one with its default in\n  {file}" if file else ""
    return f"""\
usage: {program} [--ros-args [-p NAME:=VALUE]... [--params-file FILE]... [OTHER...]]

{what}

It takes ROS arguments only, after --ros-args:
  -p NAME:=VALUE       set a parameter (floating-point ones need a decimal point: 10.0)
  --params-file FILE   parameters from a YAML file ({node}: {{ros__parameters: {{...}}}})
  -r __ns:=/robot      run in a namespace (-r __node:=NAME: another node name)
  --log-level LEVEL    debug, info, warn, error or fatal
Example: {program} --ros-args {example}

Parameters: {doc}{every};
  on a running node: ros2 param list /{node}, ros2 param describe /{node} NAME.
Ctrl-C or SIGTERM stops it cleanly (exit 0); bad configuration: one line, exit 2.
"""


def outside_ros_args(args: list[str]) -> list[str]:
    """The arguments of ``args`` (without the program) that are not ROS arguments: those
    before the first ``--ros-args`` and after a ``--`` that ends a ``--ros-args`` section."""
    out, in_ros = [], False
    for arg in args:
        if arg == "--ros-args":
            in_ros = True
        elif in_ros and arg == "--":
            in_ros = False
        elif not in_ros:
            out.append(arg)
    return out


def refusal(program: str, arg: str) -> str:
    """The one line for an argument ``arg`` that a node does not take."""
    hint = f"--ros-args -p {arg}" if ":=" in arg else "--ros-args -p NAME:=VALUE"
    return (
        f"{program}: unexpected argument {arg!r}: a node takes ROS arguments only "
        f"({program} {hint}); {program} --help says more"
    )


def check(program: str, args: list[str] | None = None) -> int | None:
    """Print the usage (exit status 0) or refuse a non-ROS argument (2) of ``program``'s
    ``args`` (default: the command line); None: nothing to say, start the node."""
    extra = outside_ros_args(sys.argv[1:] if args is None else args)
    if not extra:
        return None
    if any(arg in HELP for arg in extra):
        sys.stdout.write(usage(program))
        sys.stdout.flush()
        return EXIT_USAGE
    print(refusal(program, extra[0]), file=sys.stderr, flush=True)
    return EXIT_BAD_ARGUMENT
