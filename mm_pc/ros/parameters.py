"""ROS parameters the way every node of ours declares them.

A node keeps a table ``{name: (default, ParameterDescriptor)}`` built with
:func:`read_only` (plus :func:`float_range` / :func:`int_range` for numbers), marks
the ones ``ros2 param set`` may change with :func:`mark_live`, and declares and
reads them all at once with :func:`declare_all`. Ranges in a descriptor are
enforced by rclpy at declaration and at every set.
"""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

#: a table of parameters: name -> (default, descriptor)
Table = dict[str, tuple[object, ParameterDescriptor]]

LIVE_NOTE = " (live: ros2 param set)"


def read_only(desc: str, **kw) -> ParameterDescriptor:
    """A read-only parameter's descriptor; ``kw`` as from :func:`float_range`/:func:`int_range`."""
    return ParameterDescriptor(description=desc, read_only=True, **kw)


def float_range(lo: float, hi: float) -> dict:
    """Descriptor keywords bounding a float parameter to [lo, hi]."""
    return {"floating_point_range": [FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]}


def int_range(lo: int, hi: int, step: int = 0) -> dict:
    """Descriptor keywords bounding an integer parameter to lo..hi (step 0: any integer)."""
    return {"integer_range": [IntegerRange(from_value=lo, to_value=hi, step=step)]}


def ranged(desc: str, default: object, lo: float | None, hi: float | None, step: int = 0):
    """A read-only descriptor with the range [lo, hi] typed after ``default`` (none if
    either bound is None or the default is not a number)."""
    if lo is None or hi is None or isinstance(default, bool):
        return read_only(desc)
    if isinstance(default, int):
        return read_only(desc, **int_range(int(lo), int(hi), step))
    if isinstance(default, float):
        return read_only(desc, **float_range(float(lo), float(hi)))
    return read_only(desc)


def mark_live(table: Table, live: tuple[str, ...]) -> None:
    """Make the ``live`` parameters writable while the node runs, and say so."""
    for name in live:
        desc = table[name][1]
        desc.read_only = False
        desc.description += LIVE_NOTE


def declare_all(node: Node, table: Table) -> dict:
    """Declare every parameter of ``table`` on ``node`` and return {name: value}."""
    for name, (default, desc) in table.items():
        node.declare_parameter(name, default, desc)
    return {name: node.get_parameter(name).value for name in table}
