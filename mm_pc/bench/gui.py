"""mm-bench gui: frame times and memory of the real monitor window with an hour of history.

What :func:`bench_gui` does, in order:

Derivations and measurements: docs/benchmarks.md,
section "mm_pc.bench.gui in detail".
"""

from __future__ import annotations

import gc
import math
import os
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

__all__ = ["STALL_ACTIONS", "bench_gui", "cpu_figures", "stall_actions"]

FRAME_HZ = 30.0
GOAL_P95_MS = 16.0
#: sample rates of the live CPU measurement (Hz) and its goals: 500 Hz achieved with
#: the monitor under half of one core
LIVE_RATES_HZ = (100.0, 500.0)
GOAL_LIVE_CPU_PERCENT = 50.0


def _live_cpu(window, bridge, app, rate_hz: float, seconds: float) -> dict:
    """The monitor process's CPU and the achieved reply rate at ``rate_hz``.

    The window runs as it does for a user: the real Qt event loop for ``seconds``
    with its 30 Hz frame timer on the current tab, the bridge polling the node
    (another process, not counted). CPU = user + system time of this process
    (every thread) over the wall time; ``cpu_ms_per_reply`` = CPU time / replies.
    """
    import psutil
    from PySide6.QtCore import QEventLoop, QTimer

    bridge.set_rate(rate_hz)
    loop = QEventLoop()
    QTimer.singleShot(1000, loop.quit)  # the new timer settles
    window.frame_timer.start()
    loop.exec()
    proc = psutil.Process()
    used0 = window.ctx.session.stats.used
    c0, r0, s0, t0 = proc.cpu_times(), bridge.replies, bridge.skipped_ticks, time.perf_counter()
    th0 = _thread_cpu(proc)
    QTimer.singleShot(int(seconds * 1000), loop.quit)
    loop.exec()
    c1, r1, s1, t1 = proc.cpu_times(), bridge.replies, bridge.skipped_ticks, time.perf_counter()
    th1 = _thread_cpu(proc)
    window.frame_timer.stop()
    wall, replies = t1 - t0, r1 - r0
    gui_tid, ros_tid = threading.main_thread().native_id, bridge.thread_native_id
    per_thread = {tid: th1[tid] - th0.get(tid, 0.0) for tid in th1}
    gui, ros = per_thread.pop(gui_tid, 0.0), per_thread.pop(ros_tid, 0.0)
    return {
        **cpu_figures((c1.user + c1.system) - (c0.user + c0.system), wall, replies),
        # the same CPU by thread (100 = one core): Qt and the session, the rclpy executor,
        # and the rest (DDS, Qt's helpers)
        "cpu_percent_gui_thread": round(100.0 * gui / wall, 1),
        "cpu_percent_ros_thread": round(100.0 * ros / wall, 1),
        "cpu_percent_other_threads": round(100.0 * sum(per_thread.values()) / wall, 1),
        "replies": replies,
        # replies the session turned into rows: a slot that raised would make the CPU
        # figures look good while nothing was processed
        "rows": window.ctx.session.stats.used - used0,
        "skipped_ticks": s1 - s0,
        "seconds": round(wall, 2),
    }


def _thread_cpu(proc) -> dict[int, float]:
    """CPU seconds (user + system) of each of ``proc``'s threads, by native thread id."""
    return {t.id: t.user_time + t.system_time for t in proc.threads()}


def cpu_figures(cpu_s: float, wall_s: float, replies: int) -> dict:
    """``achieved_hz``, ``cpu_percent_one_core`` (100 = one core) and ``cpu_ms_per_reply``
    of ``replies`` that took ``cpu_s`` of CPU time in ``wall_s`` seconds."""
    return {
        "achieved_hz": round(replies / wall_s, 1),
        "cpu_percent_one_core": round(100.0 * cpu_s / wall_s, 1),
        "cpu_ms_per_reply": round(1e3 * cpu_s / replies, 3) if replies else math.nan,
    }


#: the heartbeat's period (ms) and the gap that counts as a stall (ms): a GUI thread busy
#: for longer than this is a freeze the user sees (issue 29 item 6)
HEARTBEAT_MS = 10
STALL_MS = 100.0
#: the actions of the stall phase, in order (see :func:`_stalls`)
STALL_ACTIONS = ("tabs_500hz", "data_tab_500hz", "simulate_mowing_run", "csv_export",
                 "png_export", "replay", "replay_seek")


def stall_actions(text: str) -> tuple[str, ...]:
    """``--stalls``: 'all', 'none' or a comma list of :data:`STALL_ACTIONS` (ValueError
    naming them otherwise)."""
    if text.strip() == "all":
        return STALL_ACTIONS
    if text.strip() == "none":
        return ()
    names = tuple(n.strip() for n in text.split(","))
    if not all(names) or any(n not in STALL_ACTIONS for n in names):
        raise ValueError(
            f"--stalls {text!r}: give 'all', 'none' or a comma list of {', '.join(STALL_ACTIONS)}"
        )
    return names


#: how long the ``data_tab_500hz`` action keeps the Data tab open (s)
DATA_TAB_S = 5.0


class _Heartbeat:
    """A 10 ms QTimer on the GUI thread: the gap between two ticks is how long the thread
    could not run it (a stall). ``gaps_ms``: every gap since :meth:`start`."""

    def __init__(self) -> None:
        from PySide6.QtCore import Qt, QTimer

        self.timer = QTimer()
        self.timer.setTimerType(Qt.PreciseTimer)
        self.timer.setInterval(HEARTBEAT_MS)
        self.timer.timeout.connect(self._tick)
        self.gaps_ms: list[float] = []
        self._last = 0.0

    def start(self) -> None:
        self.gaps_ms = []
        self._last = time.perf_counter()
        self.timer.start()

    def _tick(self) -> None:
        now = time.perf_counter()
        self.gaps_ms.append((now - self._last) * 1e3)
        self._last = now

    def stop(self) -> dict:
        """Stop; {"longest_ms", "count_over_100ms", "ticks"} of the gaps since start."""
        self.timer.stop()
        self._tick()  # the time since the last tick counts as well
        return stall_figures(self.gaps_ms)


def stall_figures(gaps_ms) -> dict:
    """The longest gap (ms) and how many gaps exceed :data:`STALL_MS`."""
    gaps = list(gaps_ms)
    return {
        "longest_ms": round(max(gaps), 1) if gaps else 0.0,
        "count_over_100ms": sum(1 for g in gaps if g > STALL_MS),
        "ticks": len(gaps),
    }


def _run_loop(app, seconds: float, done=None) -> bool:
    """The real Qt event loop for at most ``seconds`` (ends early once ``done()`` holds);
    True if ``done`` held (or there is none)."""
    from PySide6.QtCore import QEventLoop, QTimer

    loop = QEventLoop()
    deadline = time.perf_counter() + seconds
    check = QTimer()
    check.setInterval(20)

    def poll() -> None:
        if (done is not None and done()) or time.perf_counter() >= deadline:
            loop.quit()

    check.timeout.connect(poll)
    check.start()
    loop.exec()
    check.stop()
    return done is None or bool(done())


def _stalls(window, bridge, app, tmp: Path, actions=STALL_ACTIONS, sim_timeout_s=180.0) -> dict:
    """The longest GUI-thread stall during each action, as a user does them.

    The window runs its real event loop with its 30 Hz frame timer (the bridge at 500 Hz
    when there is one) and a :class:`_Heartbeat`; each action is started from the event
    loop and the loop runs until it is over:

    * ``tabs_500hz``: every tab in turn, 0.3 s each, twice;
    * ``data_tab_500hz``: the Data tab left open for :data:`DATA_TAB_S` (its table follows);
    * ``simulate_mowing_run``: Maps tab, "Simulate mowing run" clicked, until the run is
      shown (``sim_build_s``: how long the user waits);
    * ``csv_export``: the Data tab's Export CSV of the first sensor (every row);
    * ``png_export``: File > Export view as PNG of every tab;
    * ``replay``: a 30 s recording at 100 Hz read in the background and replayed at 10x,
      then Back to live;
    * ``replay_seek``: that recording paused, a seek to 29 s, then back to 17 s
      (``seek_back_s``, ``seek_back_replies``: from the keyframe before 17 s).

    Returns {"longest_ms", "count_over_100ms", "by_action": {action: figures}, ...}.
    """
    from PySide6.QtCore import QTimer

    heart = _Heartbeat()
    by_action: dict[str, dict] = {}
    extra: dict = {}
    if bridge is not None:
        bridge.set_rate(500.0)
    window.frame_timer.start()
    _run_loop(app, 1.0)  # settle at the new rate

    def measure(name: str, start, done, timeout_s: float) -> None:
        heart.start()
        t0 = time.perf_counter()
        QTimer.singleShot(0, start)
        ok = _run_loop(app, timeout_s, done)
        _run_loop(app, 0.3)  # what the action leaves behind (a last repaint)
        by_action[name] = {**heart.stop(), "seconds": round(time.perf_counter() - t0, 2)}
        if not ok:
            by_action[name]["error"] = f"not done within {timeout_s:g} s"

    for name in actions:
        prepare = _ACTIONS.get(name)
        if prepare is None:
            raise ValueError(f"unknown stall action {name!r}")
        start, done, timeout_s, after = prepare(window, app, tmp, extra)
        if start is None:
            by_action[name] = {"error": "nothing to do"}
            continue
        measure(name, start, done, timeout_s)
        after()
    window.frame_timer.stop()
    every = [a for a in by_action.values() if "longest_ms" in a]
    return {
        "longest_ms": max((a["longest_ms"] for a in every), default=0.0),
        "count_over_100ms": sum(a["count_over_100ms"] for a in every),
        "heartbeat_ms": HEARTBEAT_MS,
        "stall_ms": STALL_MS,
        "by_action": by_action,
        **extra,
        "load_avg_1min": round(os.getloadavg()[0], 2),
    }


def _tab_switches(window, app, tmp, extra):
    """Every tab in turn, 0.3 s each, twice."""
    from PySide6.QtCore import QTimer

    tabs, n, total = window.tabs, [0], 2 * window.tabs.count()
    timer = QTimer()
    timer.setInterval(300)

    def switch() -> None:
        tabs.setCurrentIndex(n[0] % tabs.count())
        n[0] += 1
        if n[0] >= total:
            timer.stop()

    timer.timeout.connect(switch)
    return timer.start, lambda: n[0] >= total, 0.3 * total + 5, lambda: extra.update(
        tab_switches=n[0]
    )


def _data_tab(window, app, tmp, extra):
    """The Data tab left open for :data:`DATA_TAB_S` at 500 Hz (its table takes the newest
    rows as they come)."""
    view, until = window.views["Data"], [math.inf]

    def start() -> None:
        window.tabs.setCurrentIndex(window.tabs.indexOf(view.parentWidget().parentWidget()))
        until[0] = time.perf_counter() + DATA_TAB_S

    return start, lambda: time.perf_counter() >= until[0], DATA_TAB_S + 5.0, lambda: None


def _show_tab(window, app, title: str):
    view = window.views[title]
    window.tabs.setCurrentIndex(window.tabs.indexOf(view.parentWidget().parentWidget()))
    _run_loop(app, 0.3)
    return view


def _simulate(window, app, tmp, extra):
    """Maps tab, "Simulate mowing run" clicked, until the run is shown."""
    maps = _show_tab(window, app, "Maps")
    t0 = [0.0]

    def start() -> None:
        t0[0] = time.perf_counter()
        maps.sim_button.click()

    def after() -> None:
        extra["sim_build_s"] = round(time.perf_counter() - t0[0] - 0.3, 1)

    return start, lambda: maps._job is None and maps.run is not None, 180.0, after


def _csv_export(window, app, tmp, extra):
    """The Data tab's Export CSV of the first sensor (every row), as its button does it
    (:meth:`~mm_pc.monitor.widgets.data_list.SensorTable.export_in_background` where the
    table has it, else at once)."""
    data = _show_tab(window, app, "Data")
    if not data.tables:
        return None, None, 0.0, None
    table, out, started = data.tables[0], tmp / "export.csv", [False]

    def start() -> None:
        getattr(table, "export_in_background", table.export_to)(out)
        started[0] = True

    return (start, lambda: started[0] and _export_done(table), 120.0,
            lambda: extra.update(csv_rows=_csv_rows(out)))  # fmt: skip


def _png_export(window, app, tmp, extra):
    """File > Export view as PNG of every tab, each looked at first."""
    from mm_pc.monitor.export import export_current_view

    tabs, n = window.tabs, [0]

    def start() -> None:
        for i in range(tabs.count()):
            tabs.setCurrentIndex(i)
            app.processEvents()
            export_current_view(window, str(tmp / f"tab{i}.png"))
            n[0] += 1

    return start, lambda: n[0] >= tabs.count(), 60.0, lambda: None


def _replay(window, app, tmp, extra):
    """A 30 s recording at 100 Hz read in the background, replayed at 10x, Back to live."""
    from mm_pc.monitor.io.mcap_writer import McapRecorder
    from mm_pc.monitor.model.sim_feed import sim_replies
    from mm_pc.monitor.replay import leave_replay, load_in_background

    path = tmp / "replay.mcap"
    recorder = McapRecorder(path, rate_hz=100.0)
    for r in sim_replies("figure_eight", 100.0, 30.0):
        recorder.write_reply(r)
    recorder.close()
    window.tabs.setCurrentIndex(0)

    def over() -> bool:
        rep = getattr(window, "replayer", None)
        return rep is not None and rep.done

    return (lambda: load_in_background(window, path, 10.0, dialog=False), over, 60.0,
            lambda: leave_replay(window))  # fmt: skip


def _replay_seek(window, app, tmp, extra):
    """The replay's recording (30 s at 100 Hz, read before) paused, a seek to 29 s (fed by
    the timer), then a seek back to 17 s: ``seek_back_s`` (how long the seek back took,
    to the 20 ms of the loop's check) and ``seek_back_replies`` (replies it fed: from the
    keyframe at or before 17 s)."""
    from mm_pc.monitor.replay import begin_replay, leave_replay, load_recording

    path = tmp / "replay.mcap"
    if not path.exists():
        _replay(window, app, tmp, extra)
    _, replies, _ = load_recording(path)
    st: dict = {}

    def start() -> None:
        rep = begin_replay(window, path, replies, 1.0)
        rep.pause()
        rep.seek(29.0)
        st.update(rep=rep, phase="forward")

    def done() -> bool:
        rep = st.get("rep")
        if rep is None or rep.seeking:
            return False
        if st["phase"] == "forward":
            st.update(phase="back", t0=time.perf_counter(), p0=rep.position)
            rep.seek(17.0)
            base = rep.keyframes.frames[-1].position if rep.keyframes.frames else 0
            st["base"] = base
            if rep.seeking:
                return False
        st.setdefault("back_s", time.perf_counter() - st["t0"])
        return True

    def after() -> None:
        rep = st.get("rep")
        extra["seek_back_s"] = round(st.get("back_s", math.nan), 3)
        extra["seek_back_replies"] = rep.position - st.get("base", 0) if rep else -1
        extra["seek_keyframes"] = len(rep.keyframes) if rep else 0
        leave_replay(window)

    return start, done, 60.0, after


_ACTIONS = {
    "tabs_500hz": _tab_switches,
    "data_tab_500hz": _data_tab,
    "simulate_mowing_run": _simulate,
    "csv_export": _csv_export,
    "png_export": _png_export,
    "replay": _replay,
    "replay_seek": _replay_seek,
}


def _export_done(table) -> bool:
    """The export said its result beside the button (a background export when it is done)."""
    return bool(table.message.text()) and "writing" not in table.message.text()


def _csv_rows(path: Path) -> int:
    try:
        with open(path, "rb") as f:
            return sum(1 for _ in f) - 1
    except OSError:
        return -1


def _rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 1e6


def _pct(values, q: float) -> float:
    return round(float(np.percentile(values, q)), 3) if len(values) else math.nan


class _Pump:
    """Processes Qt events until a deadline (or until ``predicate()`` holds)."""

    def __init__(self, app) -> None:
        self.app = app

    def until(self, deadline: float, predicate=None) -> bool:
        while True:
            self.app.processEvents()
            if predicate is not None and predicate():
                return True
            if time.perf_counter() >= deadline:
                return predicate is None
            time.sleep(0.001)


def _fast_forward(ctx, hours: float, rate_hz: float, trajectory: str) -> int:
    """Feed ``hours`` of simulated replies through the session; returns replies fed."""
    from mm_pc.monitor.model.sim_feed import sim_replies

    seconds = hours * 3600.0
    start_ns = time.time_ns() - int(seconds * 1e9) - 1_000_000_000
    replies = sim_replies(trajectory, rate_hz, seconds, start_ns=start_ns)
    first = next(replies)
    ctx.on_reply(first)  # the views learn the sensors as they would live
    process = ctx.session.process
    last, n = first, 1
    for r in replies:
        process(r)
        last, n = r, n + 1
    ctx.reply_processed.emit(last)
    return n


class _Frames:
    """Paced frames of the current tab: ``window.frame()`` then the paint (``processEvents``)."""

    def __init__(self, window, pump: _Pump) -> None:
        self.window, self.pump = window, pump
        self.period = 1.0 / FRAME_HZ
        self.next = time.perf_counter()

    def one(self) -> tuple[float, float]:
        """(frame ms, refresh ms) of the next frame, ~1/30 s after the previous one."""
        self.next = max(self.next + self.period, time.perf_counter())
        self.pump.until(self.next)
        t0 = time.perf_counter()
        self.window.frame()
        t1 = time.perf_counter()
        self.pump.app.processEvents()
        t2 = time.perf_counter()
        return (t2 - t0) * 1e3, (t1 - t0) * 1e3


def _measure_tab(window, pump: _Pump, frames: int, max_catch_up: int) -> dict:
    """Catch-up, then ``frames`` measured frames of the current tab at ~30 Hz.

    Catch-up: unmeasured frames until three in a row are within the goal
    (at most ``max_catch_up``): a view first shown after the hour takes its
    history in then (this is what a user waits for on the first visit of a
    tab). Returns {"frames", "refresh", "catch_up_frames", "catch_up_s", "error"}.
    """
    out = {"frames": [], "refresh": [], "catch_up_frames": 0, "catch_up_s": 0.0, "error": ""}
    paced = _Frames(window, pump)
    try:
        fast = 0
        while fast < 3 and out["catch_up_frames"] < max_catch_up:
            ms, _ = paced.one()
            fast = fast + 1 if ms <= GOAL_P95_MS else 0
            out["catch_up_frames"] += 1
            out["catch_up_s"] += ms / 1e3
        for _ in range(frames):
            ms, refresh_ms = paced.one()
            out["frames"].append(ms)
            out["refresh"].append(refresh_ms)
    except Exception as e:  # a view under construction may raise anything
        out["error"] = f"{type(e).__name__}: {e}"
    return out


def bench_gui(
    hours: float = 1.0,
    rate_hz: float = 100.0,
    frames: int = 300,
    node: bool = True,
    trajectory: str = "figure_eight",
    max_catch_up: int = 300,
    live_seconds: float = 10.0,
    polls: str = "reply",
    executor: str = "events",
    stalls: bool | tuple[str, ...] = True,
    gc_freeze: bool = True,
) -> dict:
    """Run the GUI benchmark (see the module doc); a JSON-ready dict.

    ``hours``: simulated history fed before measuring (> 0); ``rate_hz``:
    replies per second of the history and of the live bridge (1..500);
    ``frames``: frames measured per tab (>= 1); ``node``: poll a real
    mm-beagle sim node while measuring; ``max_catch_up``: most unmeasured
    frames a tab gets to take in the history first (0 = measure from the
    first frame); ``live_seconds``: length of each live CPU measurement
    (:data:`LIVE_RATES_HZ`, with the node; 0 = none); ``polls``: how the bridge gets
    the single polls, ``reply`` (inside the get_sensor_data reply, one round trip) or
    ``get_samples`` (one more call per sensor, the fallback for an older node);
    ``executor``: the bridge's rclpy executor (:data:`~mm_pc.monitor.ros_bridge.EXECUTORS`);
    ``stalls``: then the longest GUI-thread stalls during the user's heavy actions
    (:func:`_stalls`, ``stalls`` in the JSON; True = every one of :data:`STALL_ACTIONS`, a
    tuple = those, in that order; with ``node`` False they run without live data, to tell
    an action's own cost from the live work it shares the GUI thread with); ``gc_freeze``:
    freeze the start-up objects once the window is shown, as mm-monitor does
    (:func:`~mm_pc.monitor.app.freeze_startup_objects`; False to compare).
    """
    from mm_pc.monitor.ros_bridge import EXECUTORS, validate_rate

    if not (isinstance(hours, (int, float)) and 0 < hours <= 24):
        raise ValueError(f"hours must be in (0, 24], got {hours!r}")
    rate_hz = validate_rate(rate_hz)
    if not (isinstance(frames, int) and frames >= 1):
        raise ValueError(f"frames must be an integer >= 1, got {frames!r}")
    if not (isinstance(max_catch_up, int) and max_catch_up >= 0):
        raise ValueError(f"max_catch_up must be an integer >= 0, got {max_catch_up!r}")
    if not (isinstance(live_seconds, (int, float)) and 0 <= live_seconds <= 600):
        raise ValueError(f"live_seconds must be in [0, 600], got {live_seconds!r}")
    if polls not in ("reply", "get_samples"):
        raise ValueError(f"polls must be 'reply' or 'get_samples', got {polls!r}")
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    actions = STALL_ACTIONS if stalls is True else tuple(stalls or ())
    unknown = [a for a in actions if a not in STALL_ACTIONS]
    if unknown or len(set(actions)) != len(actions):
        raise ValueError(
            f"stalls must be True, False or distinct actions of {', '.join(STALL_ACTIONS)}; "
            f"got {stalls!r}"
        )
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(["mm-bench"])
    pump = _Pump(app)
    with ExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="mm_bench_gui_")))
        if node:
            from mm_beagle.tools.harness import beagle_process, use_isolated_ros_env

            env = use_isolated_ros_env()
            params = {"backend": "sim", "sim_trajectory": trajectory}
            stack.enter_context(beagle_process(params, env, str(tmp / "beagle.log")))
        window, bridge = _build_window(tmp, rate_hz, node, executor)
        if gc_freeze:
            from mm_pc.monitor.app import freeze_startup_objects

            freeze_startup_objects()
            stack.callback(gc.unfreeze)
        if bridge is not None:
            bridge.polls_in_reply = polls == "reply"
        stack.callback(window.close)
        if bridge is not None:
            stack.callback(bridge.stop)
        result = _run(window, bridge, pump, hours, rate_hz, frames, trajectory, max_catch_up)
        if bridge is not None and live_seconds > 0:
            window.tabs.setCurrentIndex(0)
            result["live"] = {
                f"{hz:g}": _live_cpu(window, bridge, app, hz, live_seconds)
                for hz in LIVE_RATES_HZ
            }
            result["live_tab"] = window.tabs.tabText(0)
            result["live_polls"] = polls
            result["live_executor"] = bridge.executor
            result["live_poll_fetches"] = bridge.poll_fetches  # get_samples calls, whole run
            result["goal_live_cpu_percent"] = GOAL_LIVE_CPU_PERCENT
        if actions:
            result["stalls"] = _stalls(window, bridge, app, tmp, actions)
            result["stalls"]["gc_freeze"] = gc_freeze
            result["stalls"]["live_node"] = node
    return result


def _build_window(tmp: Path, rate_hz: float, node: bool, executor: str):
    from mm_pc.monitor.context import MonitorConfig, MonitorContext
    from mm_pc.monitor.main_window import MainWindow
    from mm_pc.monitor.model.session import MonitorSession

    bridge = None
    if node:
        from mm_pc.monitor.ros_bridge import RosBridge

        bridge = RosBridge("/mm_beagle", rate_hz, node_name="mm_bench_gui", executor=executor)
        bridge.set_polling(False)  # until the history is in
    config = MonitorConfig(rate_hz=rate_hz, calibration_file=tmp / "calibration.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), bridge, config))
    window.frame_timer.stop()
    window.show()
    return window, bridge


def _run(window, bridge, pump: _Pump, hours, rate_hz, frames, trajectory, max_catch_up) -> dict:
    ctx = window.ctx
    pump.until(time.perf_counter() + 0.2)
    rss_start = _rss_mb()
    t0 = time.perf_counter()
    fed = _fast_forward(ctx, hours, rate_hz, trajectory)
    fill_s = time.perf_counter() - t0
    pump.until(time.perf_counter() + 0.2)
    rss_filled = _rss_mb()
    rows_filled = len(ctx.session.history)
    live_replies0 = 0
    if bridge is not None:
        bridge.start()
        bridge.set_polling(True)
        if not pump.until(time.perf_counter() + 30.0, lambda: bridge.replies >= 5):
            raise RuntimeError("the mm-beagle sim node did not answer within 30 s")
        live_replies0 = bridge.replies
    t_frames = time.perf_counter()
    per_tab, all_frames, all_refresh, errors, tab_mb = {}, [], [], {}, {}
    catch_up_frames, catch_up_s = {}, {}
    for i in range(window.tabs.count()):
        name = window.tabs.tabText(i)
        window.tabs.setCurrentIndex(i)
        m = _measure_tab(window, pump, frames, max_catch_up)
        tab_mb[name] = round(_rss_mb(), 1)
        catch_up_frames[name] = m["catch_up_frames"]
        catch_up_s[name] = round(m["catch_up_s"], 3)
        if m["error"]:
            errors[name] = m["error"]
        if m["frames"]:
            per_tab[name] = _pct(m["frames"], 95)
            all_frames += m["frames"]
            all_refresh += m["refresh"]
    frames_s = time.perf_counter() - t_frames
    rss_end = _rss_mb()
    hist = ctx.session.history
    out = {
        "benchmark": "gui",
        "hours": hours,
        "rate_hz": rate_hz,
        "frames_per_tab": frames,
        "frame_ms_p50": _pct(all_frames, 50),
        "frame_ms_p95": _pct(all_frames, 95),
        "frame_ms_max": round(max(all_frames), 3) if all_frames else math.nan,
        "refresh_ms_p50": _pct(all_refresh, 50),
        "refresh_ms_p95": _pct(all_refresh, 95),
        "tab_p95_ms": per_tab,
        "tab_catch_up_frames": catch_up_frames,
        "tab_catch_up_s": catch_up_s,
        "goal_p95_ms": GOAL_P95_MS,
        "memory_mb": round(rss_end, 1),
        "memory_before_mb": round(rss_start, 1),
        "memory_after_history_mb": round(rss_filled, 1),
        "memory_growth_mb_during_frames": round(rss_end - rss_filled, 1),
        "memory_after_tab_mb": tab_mb,
        "history_mb": round(hist.nbytes / 1e6, 1),
        "history_rows_fed": fed,
        "rows_after_history": rows_filled,
        "rows": len(hist),
        "fill_s": round(fill_s, 1),
        "frames_s": round(frames_s, 1),
        "errors": errors,
        "machine": {
            "cpus": os.cpu_count(),
            "python": sys.version.split()[0],
            "load_avg_1min": round(os.getloadavg()[0], 2),
        },
    }
    if bridge is not None:
        st = bridge.stats()
        replies = bridge.replies - live_replies0
        out.update(
            replies=replies,
            live_rate_hz=round(replies / frames_s, 1) if frames_s > 0 else 0.0,
            dropped_requests=st.dropped_requests,
            skipped_ticks=st.skipped_ticks,
            rtt_ms_p50=round(st.rtt_p50_s * 1e3, 3),
            rtt_ms_max=round(st.rtt_max_s * 1e3, 3),
        )
    else:
        out.update(replies=0, dropped_requests=0, rtt_ms_p50=math.nan)
    return out
