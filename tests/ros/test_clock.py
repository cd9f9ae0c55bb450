"""Header stamps under ``use_sim_time`` (mm_pc.ros.clock.node_stamp): ROS time minus
the poll's wall-clock age, never going back for a newer poll while /clock stands still."""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")

from mm_pc.ros import clock as clock_mod  # noqa: E402

S = 1_000_000_000
MS = 1_000_000


@pytest.fixture
def sim_node():
    """A node on ROS time, /clock held at 1000 s (what rclpy's TimeSource sets)."""
    from rclpy.parameter import Parameter
    from rclpy.time import Time

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(
        "mm_clock_test", context=ctx,
        parameter_overrides=[Parameter("use_sim_time", value=True)],
    )  # fmt: skip
    node.get_clock().set_ros_time_override(Time(nanoseconds=1000 * S))
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def stamps(node, monkeypatch, calls) -> list[int]:
    """node_stamp for each (wall now, poll), both in ns, as integer ns."""
    out = []
    for wall, poll in calls:
        monkeypatch.setattr(clock_mod.time, "time_ns", lambda wall=wall: wall)
        t = clock_mod.node_stamp(node, poll)
        out.append(t.sec * S + t.nanosec)
    return out


def test_the_stamp_is_ros_time_minus_the_polls_age(sim_node, monkeypatch):
    wall = 50_000 * S
    assert stamps(sim_node, monkeypatch, [(wall, wall - 5 * MS)]) == [1000 * S - 5 * MS]


def test_a_newer_poll_that_waited_longer_is_not_stamped_earlier(sim_node, monkeypatch):
    """The CI case: /clock had not ticked, the second reply waited 4.5 ms, the first 1 ms."""
    wall = 50_000 * S
    got = stamps(sim_node, monkeypatch, [
        (wall, wall - 1 * MS),                # 1000 s - 1 ms
        (wall + 5 * MS, wall + MS // 2),      # computed 1000 s - 4.5 ms: held after the first
        (wall + 6 * MS, wall + MS // 2),      # the same poll again: the same stamp
        (wall + 7 * MS, wall + 6 * MS),       # 1000 s - 1 ms again: held
        (wall + 8 * MS, wall - 3 * MS),       # an older poll (another stream): not held
    ])  # fmt: skip
    assert got[0] == 1000 * S - 1 * MS
    assert got[1] == got[0] + 1
    assert got[2] == got[1]
    assert got[3] == got[1] + 1
    assert got[4] == 1000 * S - 11 * MS


def test_a_clock_that_jumps_back_is_followed(sim_node, monkeypatch):
    """A bag played in a loop: ROS time steps back by more than MAX_HOLD_NS."""
    from rclpy.time import Time

    wall = 50_000 * S
    first = stamps(sim_node, monkeypatch, [(wall, wall)])
    sim_node.get_clock().set_ros_time_override(Time(nanoseconds=10 * S))
    again = stamps(sim_node, monkeypatch, [(wall + MS, wall + MS), (wall + 2 * MS, wall + MS * 2)])
    assert first == [1000 * S]
    assert again == [10 * S, 10 * S + 1]  # then in order again on the new time line
