"""A CPI change in the monitor (issues 28 item 2, 29 item 6): each poll carries its CPI, so
a change is no bridged gap and no red dashed segment on the map, is counted and logged as
a CPI change, is recorded (SensorPolls' poll_cpi) and replays to the live pose; replies and
recordings without poll_cpi behave as before (the interval is a gap step)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from cpi_ring import CpiRing

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.io.mcap_reader import read_replies
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.sim import robot

DEVS = ("/dev/spidev1.0", "/dev/spidev1.1")
N = 5000
CHANGES = {1234: 800, 3773: 3200}
ENDS = [0, *range(100, N + 1, 100)]  # 10 Hz requests: each change inside an interval


@pytest.fixture(scope="module")
def ring():
    v, w = robot.trajectory("s_curves")
    return CpiRing(v[:N], w[:N], 1600, CHANGES)


def _replies(ring, ends=ENDS, per_poll_cpi=True):
    """The replies a bridge gets at the poll counts ``ends``, with the polls since the last."""
    out, cursor = [], None
    for p in ends:
        tot = ring.totals(p)
        readings = tuple(
            Reading(id=d, stamp_ns=t.stamp_ns, seq=t.seq, x_total=t.x_m, y_total=t.y_m,
                    x_total_counts=t.x_counts, y_total_counts=t.y_counts,
                    cpi=int(ring.cpi[i][max(t.seq - 1, 0)]))
            for i, (d, t) in enumerate(zip(DEVS, tot, strict=True))
        )  # fmt: skip
        since = [t.seq for t in tot] if cursor is None else cursor
        polls = {d: ring.samples(i, since[i], tot[i].seq, per_poll_cpi) for i, d in enumerate(DEVS)}
        out.append(Reply(readings, polls=polls))
        cursor = [t.seq for t in tot]
    return out


def _truth_pose(ring):
    odo = Odometry(DEFAULT_MOUNTS, "exact")
    odo.integrate(np.full(N, 0.001), ring.true_m)
    return odo.pose.as_array()


def _session(replies):
    s = MonitorSession(devices=DEVS)
    for r in replies:
        s.process(r)
    return s


def test_a_cpi_change_is_no_gap_and_is_shown_as_a_cpi_change(ring):
    s = _session(_replies(ring))
    assert (s.stats.gaps, len(s.gaps)) == (0, 0)
    assert s.stats.polls == N
    np.testing.assert_allclose(s.pose.as_array(), _truth_pose(ring), rtol=0, atol=1e-9)
    # counted and logged as what it is, where the robot was
    assert s.stats.cpi_changes == 4
    assert [(c.device, c.old, c.new) for c in s.cpi_changes] == [
        (DEVS[0], 1600, 800), (DEVS[1], 1600, 800), (DEVS[0], 800, 3200), (DEVS[1], 800, 3200),
    ]  # fmt: skip
    lines = [text for kind, text in s.stats.events if kind == "cpi"]
    assert lines[0].startswith(f"{DEVS[0]}: CPI 1600 -> 800 at 1.3") and "no data lost" in lines[0]
    assert not [e for e in s.stats.events if e[0] == "gap"]
    s.reset()
    assert len(s.cpi_changes) == 0 and s.stats.cpi_changes == 4


def test_a_new_baseline_at_another_cpi_is_no_cpi_change(ring):
    """Switching sources (live -> a replay, forget_baselines) or a node restart at another
    CPI starts afresh: no CPI change is counted for it."""
    replies = _replies(ring)
    s = _session(replies[:5])  # 1600 CPI
    s.forget_baselines()
    for r in replies[20:25]:  # 800 CPI
        s.process(r)
    assert s.stats.cpi_changes == 0 and s.stats.baselines == 2


def test_batched_replies_give_the_same_as_one_by_one(ring):
    replies = _replies(ring)
    one = _session(replies)
    batched = MonitorSession(devices=DEVS)
    for k in range(0, len(replies), 7):
        batched.process_batch(replies[k : k + 7])
    assert batched.pose == one.pose and batched.stats.gaps == 0
    assert np.array_equal(batched.history.column("x"), one.history.column("x"))


def test_the_headless_summary_names_each_gaps_cause(ring):
    from mm_pc.monitor.app import summary

    s = _session(_replies(ring, per_poll_cpi=False))
    text = summary(SimpleNamespace(ctx=SimpleNamespace(session=s, bridge=None), frame_ms=[]), 5)
    assert f"{len(CHANGES)} gap(s) without them" in text, text
    # one cause, counted: the summary ends on it
    assert text.endswith("Gaps: sensor 0: the CPI changed within the interval (2x)."), text


def test_replies_without_poll_cpi_still_bridge_the_interval_as_a_gap(ring):
    """An old node: the reply's one cpi for all its polls; the interval with the change is
    a gap step from the totals, as before (nothing lost), and the change is still named."""
    s = _session(_replies(ring, per_poll_cpi=False))
    assert s.stats.gaps == len(s.gaps) == len(CHANGES)
    assert all("the CPI changed within the interval" in g.reason for g in s.gaps)
    assert s.stats.cpi_changes == 4
    assert s.stats.polls == N - 100 * len(CHANGES)
    # the pose is near the truth (each gap one straight step over 0.1 s), not exact
    err = np.hypot(*(s.pose.as_array()[:2] - _truth_pose(ring)[:2]))
    assert 1e-9 < err < 1e-3


def test_a_recording_with_a_cpi_change_replays_to_the_live_pose(ring, tmp_path):
    replies = _replies(ring)
    live = _session(replies)
    path = tmp_path / "cpi.mcap"
    rec = McapRecorder(path)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    back = read_replies(path)
    got = back[13].polls[DEVS[0]]  # the reply with the first change
    assert list(got.poll_cpi) == list(ring.samples(0, 1200, got.next_seq).poll_cpi)
    assert {800, 1600} <= set(got.poll_cpi)
    again = _session(back)
    assert again.pose == live.pose
    assert (again.stats.polls, again.stats.gaps, again.stats.cpi_changes) == (N, 0, 4)


def test_a_recording_without_poll_cpi_replays_as_before(ring, tmp_path):
    """Polls recorded without poll_cpi (an old node, or a recording made before it): the
    same gaps and pose as a live session of the same replies."""
    replies = _replies(ring, per_poll_cpi=False)
    live = _session(replies)
    path = tmp_path / "old.mcap"
    rec = McapRecorder(path)
    for r in replies:
        rec.write_reply(r)
    rec.close()
    back = read_replies(path)
    assert all(len(b.polls[d].poll_cpi) == 0 for b in back for d in DEVS)
    again = _session(back)
    assert again.pose == live.pose
    assert (again.stats.gaps, [g.reason for g in again.gaps]) == (
        live.stats.gaps, [g.reason for g in live.gaps]) and live.stats.gaps == 2  # fmt: skip


def test_sensor_polls_bytes_from_before_poll_cpi_decode_with_it_empty():
    from rclpy.serialization import serialize_message

    from mm_interfaces.msg import SensorPolls
    from mm_pc.monitor.io import cdr

    msg = SensorPolls(id="/dev/spidev1.0", first_seq=3, next_seq=5, cpi=800, stamp_ns=[1, 2],
                      dx=[4, 5], dy=[6, 7], status=[0, 0], flags=[2, 2], quality=[40, 41],
                      poll_cpi=[1600, 800])  # fmt: skip
    new = serialize_message(msg)
    assert list(cdr.deserialize_appended(new, SensorPolls).poll_cpi) == [1600, 800]
    # the layout before issue 28 ended with the quality array
    old_bytes = new[: new.rfind((41).to_bytes(2, "little", signed=True)) + 2]
    old = cdr.deserialize_appended(old_bytes, SensorPolls)
    assert (list(old.quality), list(old.poll_cpi), old.cpi) == ([40, 41], [], 800)
    # and the tracker then takes the reply's cpi for both polls
    from mm_pc.core.polls import PollBatch

    assert list(PollBatch.from_reply(old).cpis) == [800, 800]


def test_polls_msg_carries_poll_cpi_and_leaves_it_empty_for_old_replies():
    from mm_pc.monitor.io.cdr import polls_msg

    res = SimpleNamespace(first_seq=0, next_seq=2, dropped=0, cpi=800, stamp_ns=[1, 2],
                          dx=[1, 2], dy=[3, 4], status=[0, 0], flags=[2, 2])  # fmt: skip
    assert list(polls_msg("/dev/spidev1.0", res).poll_cpi) == []
    res.poll_cpi = np.array([1600, 800], np.uint16)
    assert list(polls_msg("/dev/spidev1.0", res).poll_cpi) == [1600, 800]


def test_map_and_health_show_no_gap_for_a_cpi_change(ring, qtbot):
    """Connected, the sensors' CPI changed twice: Health says 0 gaps bridged and 4 CPI
    changes, and the map draws no gap segment; an old node's replies still draw one."""
    from mm_pc.monitor.widgets.health_view import HealthView
    from mm_pc.monitor.widgets.map_view.view import MapView

    for per_poll, gaps in ((True, 0), (False, 2)):
        ctx = MonitorContext(MonitorSession())
        view, health = MapView(ctx), HealthView(ctx)
        for w in (view, health):
            qtbot.addWidget(w)
        view.resize(600, 500)
        view.show()
        for r in _replies(ring, per_poll_cpi=per_poll):
            ctx.on_reply(r)
        view.refresh()
        health.refresh()
        assert len(view.gap_segments()) == gaps
        text = health.session_label.text()
        assert f"{gaps} gaps bridged" in text and "4 CPI changes" in text, text
