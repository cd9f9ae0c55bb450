"""A CPI change while the monitor is connected to mm-beagle (sim, moving), recorded and
replayed (issues 28 item 2, 29 item 6): no bridged gap, the changes counted as CPI
changes, and the recording replays to the live history and pose."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from test_monitor_recording import (
    DEVICES,
    assert_same_history,
    make_window,
    run_replay,
)

from mm_pc.monitor.io.mcap_reader import read_replies
from mm_pc.monitor.recording import start_recording, stop_recording
from mm_pc.monitor.ros_bridge import RosBridge

pytestmark = pytest.mark.ros

BEAGLE_PARAMS = {"backend": "sim", "sim_trajectory": "figure_eight"}


def _cpis(session) -> set[int]:
    return {int(session._prev[d].cpi) for d in DEVICES if d in session._prev}


def test_set_resolution_while_connected_is_no_gap_and_replays_the_same(
    qtbot, tmp_path, beagle_node
):
    bridge = RosBridge("/mm_beagle", 15.0, node_name="mm_monitor_cpi_live_test")
    bridge.set_polling(False)
    window = make_window(qtbot, tmp_path, bridge)
    session = window.ctx.session
    path = tmp_path / "cpi.mcap"
    try:
        bridge.start()
        assert start_recording(window, path)
        bridge.set_polling(True)
        qtbot.waitUntil(lambda: session.stats.polls > 1000, timeout=25_000)
        for cpi in (800, 3200):
            for d in DEVICES:
                bridge.set_resolution(d, cpi)
            qtbot.waitUntil(lambda cpi=cpi: _cpis(session) == {cpi}, timeout=15_000)
            n = session.stats.replies
            qtbot.waitUntil(lambda n=n: session.stats.replies >= n + 8, timeout=15_000)
        bridge.set_polling(False)
        qtbot.wait(400)  # the last request in flight is answered
        stop_recording(window)
    finally:
        bridge.stop()
    s = session.stats
    assert (s.gaps, len(session.gaps)) == (0, 0), list(session.gaps)
    assert s.cpi_changes == 4, [c for c in session.cpi_changes]
    assert [(c.old, c.new) for c in session.cpi_changes] == [(1600, 800)] * 2 + [(800, 3200)] * 2
    assert s.polls > 1000
    back = read_replies(path)
    seen = {int(v) for r in back for p in (r.polls or {}).values() if p is not None
            for v in p.poll_cpi}  # fmt: skip
    assert seen == {800, 1600, 3200}
    fresh = make_window(qtbot, tmp_path)
    run_replay(qtbot, fresh, path, "max")
    assert_same_history(session, fresh.ctx.session)
    assert (fresh.ctx.session.stats.gaps, fresh.ctx.session.stats.cpi_changes) == (0, 4)
