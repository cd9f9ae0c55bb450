"""Keyframes of a replay: a seek backwards restores the newest keyframe before its target
and feeds at most one interval; the state it reaches is the state a replay to that point
reaches (every history column, the map's path, pose, counters, log, gaps), also on the
map view; a keyframe void after a settings change is not used."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_pc.core.filters import SensorMedianFilter
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.history import History
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES as DEVICES
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.replay import start_replay
from mm_pc.monitor.replay_keyframes import KEYFRAME_S, Keyframes

RATE_HZ = 50.0


@pytest.fixture(scope="module")
def run30(tmp_path_factory):
    """30 s of a figure eight at 50 Hz (1501 replies)."""
    path = tmp_path_factory.mktemp("keyframes") / "run30.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("figure_eight", RATE_HZ, 30.0):
        rec.write_reply(r)
    rec.close()
    return path


def make_window(qtbot, tmp_path) -> MainWindow:
    config = MonitorConfig(rate_hz=RATE_HZ, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config))
    qtbot.addWidget(window)
    return window


def paused_replay(qtbot, window, path, filters: bool = True):
    """A replay of ``path``, paused at its start; median filters on (state to restore)."""
    if filters:  # the session takes them when the first reply names its sensors
        window.ctx.session.filters = {d: SensorMedianFilter(5, True, True) for d in DEVICES}
    replayer = start_replay(window, path, 1.0)
    replayer.pause()
    return replayer


def seek(qtbot, replayer, target_s: float) -> int:
    """Seek and wait until done; the replies fed by the seek."""
    fed = []
    ctx = replayer.ctx
    original = ctx.on_replies

    def counting(replies):
        fed.append(len(replies))
        original(replies)

    ctx.on_replies = counting
    try:
        replayer.seek(target_s)
        qtbot.waitUntil(lambda: not replayer.seeking, timeout=30_000)
    finally:
        del ctx.on_replies  # the bound method again
    return sum(fed)


def state(session: MonitorSession) -> dict:
    """Everything a replay to a point leaves behind, as plain values."""
    hist, path = session.history, session.map_history
    stats = dataclasses.asdict(session.stats)
    stats["events"] = list(session.stats.events)
    return {
        "history": {c: hist.column(c).copy() for c in hist.columns},
        "map": {c: path.column(c).copy() for c in path.columns},
        "pose": (session.pose.x, session.pose.y, session.pose.yaw),
        "stats": stats,
        "log": list(session.log),
        "gaps": list(session.gaps),
    }


def assert_same(a: dict, b: dict) -> None:
    assert a["history"].keys() == b["history"].keys()
    for c in a["history"]:
        np.testing.assert_array_equal(a["history"][c], b["history"][c], err_msg=c)
    for c in a["map"]:
        np.testing.assert_array_equal(a["map"][c], b["map"][c], err_msg=c)
    assert a["pose"] == b["pose"]
    assert a["stats"] == b["stats"]
    assert a["log"] == b["log"] and a["gaps"] == b["gaps"]


def test_a_seek_back_reaches_the_state_of_a_replay_to_there_and_feeds_one_interval(
    qtbot, tmp_path, run30
):
    played = make_window(qtbot, tmp_path)
    to_there = paused_replay(qtbot, played, run30)
    seek(qtbot, to_there, 12.3)
    assert to_there.played_s == pytest.approx(12.3, abs=0.03)
    want = state(played.ctx.session)
    assert len(want["history"]["t"]) == to_there.position - 1 > 600  # the first: a baseline

    window = make_window(qtbot, tmp_path)
    replayer = paused_replay(qtbot, window, run30)
    seek(qtbot, replayer, 25.0)
    far = state(window.ctx.session)
    assert far["pose"] != want["pose"]
    # a keyframe every KEYFRAME_S of recorded time, the first after the first reply
    times = [f.t_s for f in replayer.keyframes.frames]
    assert times[0] == 0.0 and replayer.keyframes.frames[0].position == 1
    assert np.diff(times) == pytest.approx(KEYFRAME_S, abs=1.5 / RATE_HZ)
    fed = seek(qtbot, replayer, 12.3)
    assert replayer.position == to_there.position and not replayer.running
    # back to the keyframe at 10 s, then 2.3 s fed (not 12.3 s from the start)
    assert fed == round(2.3 * RATE_HZ)
    assert fed <= KEYFRAME_S * RATE_HZ
    assert_same(state(window.ctx.session), want)
    # the views draw the restored path: the map shows what the replay to there shows
    for w in (played, window):
        w.tabs.setCurrentIndex(w.tabs.indexOf(w.views["Map"].parentWidget().parentWidget()))
        w.views["Map"].refresh()
        w.views["Map"].finish_drawing()
    for key in ("robot", 0, 1):
        for a, b in zip(window.views["Map"].path_data(key), played.views["Map"].path_data(key),
                        strict=True):
            np.testing.assert_array_equal(a, b)
    # played on from there: the same as a replay that never went back
    seek(qtbot, replayer, 30.0)
    seek(qtbot, to_there, 30.0)
    assert replayer.done and to_there.done
    assert_same(state(window.ctx.session), state(played.ctx.session))


def test_a_seek_back_before_the_second_keyframe_and_to_the_start(qtbot, tmp_path, run30):
    window = make_window(qtbot, tmp_path)
    replayer = paused_replay(qtbot, window, run30)
    seek(qtbot, replayer, 8.0)
    fed = seek(qtbot, replayer, 1.0)
    assert fed == round(1.0 * RATE_HZ)  # from the keyframe after the first reply
    assert replayer.position == round(1.0 * RATE_HZ) + 1
    assert window.ctx.session.history.column("t")[-1] == pytest.approx(1.0)
    seek(qtbot, replayer, 0.0)
    assert replayer.position == 1 and len(window.ctx.session.history) == 0  # the baseline
    assert window.ctx.session.pose.x == 0.0 and window.ctx.session.stats.replies == 1


def test_a_changed_setting_voids_the_keyframes_and_the_seek_starts_over(qtbot, tmp_path, run30):
    """After the pose method changes, the keyframes (made with the old one) are not used:
    the seek back feeds from the first reply, as before keyframes."""
    window = make_window(qtbot, tmp_path)
    replayer = paused_replay(qtbot, window, run30, filters=False)
    seek(qtbot, replayer, 20.0)
    assert len(replayer.keyframes) == 5
    window.ctx.session.configure_odometry(method="seed-approach1")
    fed = seek(qtbot, replayer, 12.0)
    assert fed == round(12.0 * RATE_HZ) + 1  # every reply from the first
    fresh = MonitorSession(method="seed-approach1")
    for r in replayer.replies[: replayer.position]:
        fresh.process(r)
    np.testing.assert_array_equal(window.ctx.session.history.column("x"),
                                  fresh.history.column("x"))
    assert window.ctx.session.pose == pytest.approx(fresh.pose)
    # so are filters changed after the keyframes were made
    seek(qtbot, replayer, 20.0)
    window.ctx.session.filters[window.ctx.session.devices[0]].window = 7
    assert seek(qtbot, replayer, 15.0) == round(15.0 * RATE_HZ) + 1


def test_keyframes_refuse_a_bad_interval_and_history_truncate_checks_its_bound():
    with pytest.raises(ValueError, match="keyframe interval must be > 0 s"):
        Keyframes(0.0)
    h = History(["a"], max_rows=10)
    for v in range(5):
        h.append([float(v)])
    version = h.version
    with pytest.raises(ValueError, match="cannot keep 6 of 5 rows"):
        h.truncate(6)
    assert len(h) == 5 and h.version == version  # nothing changed
    h.truncate(2)
    assert list(h.column("a")) == [0.0, 1.0] and h.version == version + 1
    h.append([9.0])
    assert list(h.column("a")) == [0.0, 1.0, 9.0]


def test_a_session_without_sensors_yet_takes_no_keyframe():
    session = MonitorSession()
    frames = Keyframes()
    assert frames.take(session, 0, 0.0) is None and len(frames) == 0
