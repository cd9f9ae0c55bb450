"""mm-monitor: the Qt monitor's command line.

    mm-monitor                          window, asks /mm_beagle at 15 Hz
    mm-monitor --sim                    also start mm-beagle on emulated sensors (private domain)
    mm-monitor --sim calibration_run    ... driving the calibration wizard's guided run, the
                                        sensors mounted with a known error (--sim-mounts)
    mm-monitor --headless --duration 10 --screenshot monitor.png
                                        offscreen run, a screenshot of the main window, exit 0
    mm-monitor --replay run.mcap        replay a recording into the monitor (no node needed)
    mm-monitor --headless --duration 60 --record run/
                                        record 60 s (replies, single polls, live topics) into
                                        the rosbag2 folder run/ (or a file: --record run.mcap)

Where there is no display (no $DISPLAY / $WAYLAND_DISPLAY) and --headless was
not given, the monitor says so and runs headless instead, leaving a
screenshot and a one-paragraph summary of what it saw.
"""

from __future__ import annotations

import argparse
import collections
import gc
import math
import os
import signal
import sys
import time
from contextlib import ExitStack
from pathlib import Path

__all__ = ["freeze_startup_objects", "main", "summary"]

DEFAULT_SCREENSHOT = "demo-output/mm-monitor.png"
MAX_DURATION_S = 2_000_000  # QTimer.singleShot's milliseconds are a 32-bit int


def _parser() -> argparse.ArgumentParser:
    from mm_pc.core.odometry import METHODS
    from mm_pc.sim.robot import TRAJECTORIES

    p = argparse.ArgumentParser(prog="mm-monitor", description=__doc__.split("\n\n")[0])
    p.add_argument("--beagle", default="/mm_beagle", help="namespace/name of the mm_beagle node")
    p.add_argument("--rate", type=float, default=None,
                   help="sample rate, 1..500 Hz (default: the last one used, else 15)")
    p.add_argument("--method", default=None, choices=sorted(METHODS),
                   help="pose method (default: the last one used, else exact)")
    p.add_argument("--reset-settings", action="store_true",
                   help="forget the remembered window layout, rate, method and folders")
    p.add_argument("--calibration", type=Path, default=None, help="calibration YAML to load")
    p.add_argument("--headless", action="store_true", help="no window on screen (offscreen)")
    p.add_argument("--duration", type=float, default=0.0, help="seconds, then exit (0 = never)")
    p.add_argument("--screenshot", type=Path, default=None, help="PNG of the window at the end")
    p.add_argument(
        "--sim", nargs="?", const="figure_eight", default=None, metavar="TRAJECTORY",
        help="start mm-beagle on emulated sensors driving TRAJECTORY (default figure_eight; "
        f"one of {', '.join(TRAJECTORIES)} or file:PATH, a CSV t,v,w or t,vx,vy,w); "
        "calibration_run is the calibration wizard's guided run, which the wizard can "
        "drive for you",
    )  # fmt: skip
    p.add_argument(
        "--sim-mounts", default=None, metavar="X,Y,YAW;...",
        help="with --sim: where the emulated sensors sit, per sensor base_link x, y (m) and "
        "yaw (deg); default: as designed, or with --sim calibration_run a known error "
        "(51,-38.5 mm +3 deg; 47,41 mm -2 deg) for the wizard to find",
    )  # fmt: skip
    p.add_argument(
        "--agent", action="store_true",
        help="with --sim: the BBB chain, mm-beagle-agent on emulated sensors and mm-beagle "
        "backend:=remote on its link",
    )  # fmt: skip
    p.add_argument(
        "--sim-chips", default="", metavar="CHIPS",
        help="with --sim: the emulated chip of each sensor, e.g. pmw3360,pmw3360 (one for "
        "all, or one per sensor; default pln2033); ./compile demo takes sim_chips:=CHIPS",
    )  # fmt: skip
    p.add_argument("--replay", type=Path, default=None, help="replay an MCAP recording")
    p.add_argument(
        "--record", type=Path, default=None, metavar="PATH",
        help="record from the start: PATH.mcap = one MCAP file, any other PATH = a new "
        "rosbag2 folder with metadata.yaml (replies, single polls, live topics)",
    )  # fmt: skip
    p.add_argument(
        "--executor", choices=("events", "waitset"), default="events",
        help="rclpy executor of the monitor's ROS thread: events (rclpy's C++ one, the "
        "default: about half the CPU per reply) or waitset (the Python one, to fall back on)",
    )  # fmt: skip
    p.add_argument("--tab", default=None,
                   help="tab to show first (Map, Graphs, Data, ...; default: the last one)")
    return p


def freeze_startup_objects() -> None:
    """Collect once, then move everything alive (modules, Qt wrappers, the built window) to
    the collector's permanent generation: a full pass then walks only what came after, not
    the ~80 000 objects of start-up (a full pass took 20-30 ms at a load of 5.6, 0.0 ms
    after this; passes of 50-90 ms fell anywhere in the GUI thread at a load of 6, issue
    29). Called once the window is built and shown."""
    gc.collect()
    gc.freeze()


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def summary(window, seconds: float) -> str:
    """One paragraph: what the monitor saw in ``seconds`` (for the headless run)."""
    ctx = window.ctx
    s = ctx.session
    bridge = ctx.bridge
    parts = []
    if bridge is not None:
        st = bridge.stats()
        rtt = "n/a" if math.isnan(st.rtt_p50_s) else f"{st.rtt_p50_s * 1e3:.1f} ms"
        link = {"connected": "was connected to", "waiting": "waited for", "lost": "had lost"}
        parts.append(
            f"In {seconds:.1f} s the monitor {link.get(st.state, st.state)} {ctx.config.beagle}: "
            f"{st.replies} replies to {st.requests} requests at {ctx.config.rate_hz:g} Hz "
            f"(round trip p50 {rtt}, {st.dropped_requests} dropped, "
            f"{st.skipped_ticks} ticks skipped while a reply was outstanding)."
        )
    else:
        parts.append(f"In {seconds:.1f} s the monitor processed {s.stats.replies} replies.")
    hist = s.history
    if hist is not None and len(hist):
        x, y = hist.column("x"), hist.column("y")
        import numpy as np

        travelled = float(np.sum(np.hypot(np.diff(x), np.diff(y)))) if len(x) > 1 else 0.0
        p = s.pose
        parts.append(
            f"Sensors {', '.join(s.devices)}; {len(hist)} samples used; the robot "
            f"({s.method}) travelled {travelled:.2f} m and is at x={p.x:.3f} m, y={p.y:.3f} m, "
            f"yaw={math.degrees(p.yaw_wrapped):.1f} deg."
        )
    else:
        parts.append("No sensor data arrived.")
    if s.stats.restarts:
        parts.append(f"The node restarted {s.stats.restarts} time(s); each was re-baselined.")
    if s.stats.polls or s.stats.gaps:
        parts.append(
            f"The pose integrated {s.stats.polls} single polls; {s.stats.gaps} gap(s) without "
            "them were stepped over with the totals (dashed red on the map)."
        )
        if s.gaps:
            why = collections.Counter(g.reason for g in s.gaps)
            parts.append("Gaps: " + "; ".join(f"{r} ({n}x)" for r, n in why.most_common()) + ".")
    if window.frame_ms:
        import numpy as np

        f = np.asarray(window.frame_ms)
        parts.append(
            f"Frames: p50 {np.percentile(f, 50):.1f} ms, p95 {np.percentile(f, 95):.1f} ms."
        )
    return " ".join(parts)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.reset_settings:
        from mm_pc.monitor.settings import settings_path

        settings_path().unlink(missing_ok=True)
    _remembered_defaults(args)
    try:
        from mm_pc.core.calibration import Calibration  # noqa: F401 - fail early on a broken install
        from mm_pc.monitor.ros_bridge import validate_rate

        validate_rate(args.rate)
    except ValueError as e:
        print(f"mm-monitor: {e}", file=sys.stderr)
        return 2
    if not 0 <= args.duration <= MAX_DURATION_S:  # also NaN; Qt's timer takes int32 ms
        print(f"mm-monitor: --duration must be 0..{MAX_DURATION_S} s (0 = never), "
              f"got {args.duration:g}", file=sys.stderr)  # fmt: skip
        return 2
    if args.agent and not args.sim:
        print("mm-monitor: --agent goes with --sim (the emulated sensors behind an agent)",
              file=sys.stderr)
        return 2
    if args.sim:
        from mm_beagle.poller.sim_backend import check_trajectory

        try:
            check_trajectory(args.sim)
        except ValueError as e:
            print(f"mm-monitor: --sim: {e}", file=sys.stderr)
            return 2
    if problem := _sim_mounts_problem(args):
        print(f"mm-monitor: {problem}", file=sys.stderr)
        return 2
    if args.record is not None and (problem := _record_problem(args)):
        print(f"mm-monitor: --record {args.record}: {problem}", file=sys.stderr)
        return 2
    for problem in (_beagle_problem(args.beagle), _calibration_problem(args),
                    _screenshot_problem(args)):  # fmt: skip
        if problem:
            print(f"mm-monitor: {problem}", file=sys.stderr)
            return 2
    headless = args.headless
    if not headless and not _has_display() and os.environ.get("QT_QPA_PLATFORM") != "offscreen":
        duration = args.duration or 20.0
        print(
            f"mm-monitor: no display ($DISPLAY and $WAYLAND_DISPLAY are unset); running headless "
            f"for {duration:g} s instead, leaving a screenshot and a summary.",
            flush=True,
        )
        headless, args.duration = True, duration
        args.screenshot = args.screenshot or Path(DEFAULT_SCREENSHOT)
    if headless:
        os.environ["QT_QPA_PLATFORM"] = "offscreen"
        _quiet_qt_messages()
    else:
        from mm_pc.monitor.qt_platform import check

        if missing := check():  # Qt would abort with no window and a vague message
            print(f"mm-monitor: {missing}", file=sys.stderr)
            return 2
    try:
        code = _run(args, headless)
    except KeyboardInterrupt:  # SIGINT/SIGTERM before the run loop (mm_pc.stop_signals)
        if argv is not None:
            raise
        from mm_pc import stop_signals

        stop_signals.ignore_more()  # cleaned up on the way here: say so as the launcher would
        print(stop_signals.stop_line("mm-monitor", stop_signals.stopped_by()), file=sys.stderr)
        _exit_now(stop_signals.EXIT_STOPPED)
    if argv is None:  # the program itself, not a test calling main()
        _exit_now(code)
    return code


def _exit_now(code: int) -> None:
    """End the process at once with ``code``, skipping the interpreter's finalisation.

    Everything that must outlive the run is done by then (the node stopped, the recording
    closed, the settings synced, the node's log folder removed). What is left is tearing down
    the window's widgets, the plots and the DDS libraries one object at a time: 2.5 to 7 s
    with three busy loops on two cores (issue 27 item 7: Ctrl-C and SIGTERM end the monitor
    within 3 s). A child still running (a mowing simulation) is ended first, as the console
    script's launcher would.
    """
    import logging

    from mm_pc import stop_signals

    stop_signals.ignore_more()
    stop_signals.end_children()
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _remembered_defaults(args) -> None:
    """Rate and method not given: the ones remembered from the last run (a remembered value
    that is no longer valid is ignored), else 15 Hz and exact."""
    from mm_pc.core.odometry import METHODS
    from mm_pc.monitor.ros_bridge import validate_rate
    from mm_pc.monitor.settings import open_settings

    s = open_settings()
    if args.rate is None:
        try:
            args.rate = validate_rate(s.value("sampling/rate_hz", 15.0))
        except ValueError:
            args.rate = 15.0
    if args.method is None:
        method = s.value("pose/method", "exact")
        args.method = method if method in METHODS else "exact"


def _record_problem(args) -> str:
    """Why ``--record`` cannot take its path ('' when it can); nothing is created."""
    import os.path

    from mm_pc.monitor.io.bag_format import recording_target

    try:
        target, folder = recording_target(args.record)
    except ValueError as e:
        return str(e)
    for name, given in (("--replay", args.replay), ("--calibration", args.calibration)):
        if given is None or not given.exists():
            continue
        for mine in {args.record, target}:
            if mine.exists() and os.path.samefile(mine, given):
                return f"that is the {name} input; record to another path"
    where = folder.parent if folder is not None else target.parent
    if not os.access(where, os.W_OK):
        return f"the folder {where} is not writable"
    return ""


def _beagle_problem(beagle: str) -> str:
    """Why ``--beagle`` is not a node name its services can live under ('' if it is)."""
    from rclpy.exceptions import InvalidServiceNameException, InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    name = "/" + beagle.strip("/") if beagle.strip("/") else "/mm_beagle"
    try:
        validate_full_topic_name(f"{name}/get_sensor_data", is_service=True)
    except (InvalidServiceNameException, InvalidTopicNameException) as e:
        reason = str(e).splitlines()[0].rstrip(":")
        return (
            f"--beagle {beagle!r} is not a ROS node name ({reason}); allowed: letters, digits "
            "and _ in /-separated parts that do not start with a digit, e.g. /robot1/mm_beagle"
        )
    return ""


def _calibration_problem(args) -> str:
    """Why the ``--calibration`` file cannot be loaded ('' if it can, or none was given)."""
    if args.calibration is None:
        return ""
    from mm_pc.core.calibration import Calibration

    try:
        Calibration.load(args.calibration)
    except (OSError, ValueError) as e:
        return f"--calibration: {e}"
    return ""


def _screenshot_problem(args) -> str:
    """Why ``--screenshot`` must not write its path ('' if it may): it is one of the inputs."""
    import os.path

    if args.screenshot is None or not args.screenshot.exists():
        return ""
    inputs = [("--replay", args.replay), ("--calibration", args.calibration)]
    if args.sim and args.sim.startswith("file:"):
        inputs.append(("--sim", Path(args.sim[len("file:") :])))
    if args.replay is not None and args.replay.name == "metadata.yaml":  # a rosbag2 folder
        inputs += [("--replay", f) for f in args.replay.parent.iterdir()]
    for name, given in inputs:
        if given is not None and given.exists() and os.path.samefile(args.screenshot, given):
            return (
                f"--screenshot {args.screenshot}: that is the {name} input; "
                "write the screenshot to another path"
            )
    return ""


def _quiet_qt_messages() -> None:
    """Drop the offscreen plugin's harmless 'propagateSizeHints' warning; keep the rest."""
    from PySide6.QtCore import qInstallMessageHandler

    def handler(_mode, _context, message: str) -> None:
        if "propagateSizeHints" not in message:
            print(message, file=sys.stderr)

    qInstallMessageHandler(handler)


def _sim_mounts_problem(args) -> str:
    """Why --sim-mounts cannot be used ('' = fine)."""
    if args.sim_mounts is None:
        return ""
    if not args.sim:
        return "--sim-mounts goes with --sim"
    from mm_pc.monitor.model.sim_mounts import parse_sim_mounts

    try:
        parse_sim_mounts(args.sim_mounts)
    except ValueError as e:
        return str(e)
    return ""


def _sim_mounts(args):
    """The --sim node's (or --agent: the agent's) sensor mounts: --sim-mounts,
    calibration_run's known error, or None (as designed)."""
    from mm_pc.monitor.model.sim_mounts import CALIBRATION_SIM_MOUNTS, parse_sim_mounts

    if args.sim_mounts is not None:
        return parse_sim_mounts(args.sim_mounts)
    if args.sim == "calibration_run":
        return CALIBRATION_SIM_MOUNTS
    return None


def _sim_mounts_parameter(mounts) -> list[float] | None:
    """The node's sim_mounts parameter for ``mounts`` (said on the console), or None."""
    from mm_pc.monitor.model.sim_mounts import describe_sim_mounts, to_parameter

    if mounts is None:
        return None
    print(f"mm-monitor: the emulated sensors are mounted at {describe_sim_mounts(mounts)}",
          flush=True)  # fmt: skip
    return to_parameter(mounts)


def _run(args, headless: bool) -> int:
    from mm_pc import stop_signals

    with stop_signals.at_once("mm-monitor"):  # nothing started yet: a signal ends it here
        from PySide6.QtCore import QTimer
        from PySide6.QtWidgets import QApplication

        from mm_beagle.tools.harness import emulated_sensors, use_isolated_ros_env
        from mm_pc.monitor.context import MonitorConfig, MonitorContext
        from mm_pc.monitor.main_window import MainWindow
        from mm_pc.monitor.model.session import MonitorSession
        from mm_pc.monitor.settings import open_settings

        if args.replay is None:
            from mm_pc.monitor.ros_bridge import RosBridge

    config = MonitorConfig(beagle=args.beagle, rate_hz=args.rate, method=args.method)
    config.sim, config.sim_mounts = args.sim, _sim_mounts(args)
    if args.calibration is not None:
        config.calibration_file = args.calibration
    node_exit: list[str] = []
    with ExitStack() as stack:
        node = None
        if args.sim:
            import tempfile

            env = use_isolated_ros_env()
            folder = Path(tempfile.mkdtemp(prefix="mm-monitor-"))  # mode 700
            log = folder / "sim_beagle.log"
            # registered first, so it runs after the node has stopped (also on Ctrl-C)
            stack.push(_remove_unless_failed(folder, node_exit))
            chain = "mm-beagle-agent + mm-beagle backend:=remote" if args.agent else "mm-beagle"
            print(
                f"mm-monitor: starting {chain} on emulated sensors ({args.sim}, "
                f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}); node log: {log}",
                flush=True,
            )
            mounts = _sim_mounts_parameter(config.sim_mounts)
            node = stack.enter_context(
                emulated_sensors(args.sim, env, str(log), args.agent, args.sim_chips, mounts)
            )
        app = QApplication.instance() or QApplication([sys.argv[0]])
        app.setApplicationName("Mouse Monitor")
        bridge = None
        if args.replay is None:
            bridge = RosBridge(args.beagle, args.rate, executor=args.executor)
        session = MonitorSession(method=args.method)
        ctx = MonitorContext(session, bridge, config)
        window = MainWindow(ctx, open_settings())
        for i in range(window.tabs.count()):
            if args.tab is not None and window.tabs.tabText(i).lower() == args.tab.lower():
                window.tabs.setCurrentIndex(i)
        ctx.load_calibration()
        if ctx.calibration_error:  # checked in main(); changed since
            print(f"mm-monitor: {ctx.calibration_error}", file=sys.stderr)
            window.close()
            return 2
        window.show()
        if bridge is not None:
            bridge.start()
            stack.callback(bridge.stop)
        if args.record is not None:
            from mm_pc.monitor.recording import start_recording, stop_recording

            if not start_recording(window, args.record):
                print(f"mm-monitor: {window.statusBar().currentMessage()}", file=sys.stderr)
                window.close()
                return 2
            print(f"mm-monitor: recording to {args.record}", flush=True)
            recorder = ctx.recorder
            stack.callback(_report_recording, window, recorder, stop_recording)
        if args.replay is not None:
            from mm_pc.monitor.replay import start_replay

            replayer = start_replay(window, args.replay)
            if replayer is None:  # the status bar says why
                print(f"mm-monitor: --replay {args.replay}: "
                      f"{window.statusBar().currentMessage().removeprefix('replay: ')}",
                      file=sys.stderr)  # fmt: skip
                window.close()
                return 2
            if headless and not args.duration:  # nothing else would end the run
                _quit_after(replayer, app)
        stopped_by = quit_on_signals(app)
        # Python signal handlers run only between bytecodes: wake the interpreter regularly.
        tick = QTimer()
        tick.timeout.connect(lambda: None)
        tick.start(200)
        started = time.monotonic()
        if args.duration:
            QTimer.singleShot(int(args.duration * 1000), app.quit)
        if node is not None:
            tick.timeout.connect(lambda: _check_node(node, log, node_exit, app))
        freeze_startup_objects()
        app.exec()
        seconds = time.monotonic() - started
        if stopped_by:
            print(stop_signals.stop_line("mm-monitor", stopped_by[0]), file=sys.stderr)
        # the summary and the screenshot show the run as it ended: taken before the --sim
        # node is stopped (a slow PC's bridge saw it go first and the summary said "lost")
        ended = summary(window, seconds) if headless or args.duration else ""
        code = 0
        if args.screenshot is not None and not node_exit:
            code = _screenshot(window, args.screenshot)
        if node is not None and node.poll() is None:
            node.send_signal(signal.SIGINT)  # it stops while the window and bridge close
        if node_exit:
            print(f"mm-monitor: --sim: {node_exit[0]}", file=sys.stderr)
            window.close()
            return 2
        if ended:
            print(ended, flush=True)
        window.close()
    return code


def _screenshot(window, path) -> int:
    """The window as a PNG at ``path``; 0, or 1 with the reason on stderr."""
    from mm_pc.monitor.export import grab_png

    window.tabs.setCurrentIndex(window.tabs.currentIndex())
    window.frame()
    try:
        print(f"mm-monitor: screenshot {grab_png(window, path)}", flush=True)
    except OSError as e:
        print(f"mm-monitor: {e}", file=sys.stderr)
        return 1
    return 0


def quit_on_signals(app) -> list[int]:
    """SIGINT/SIGTERM quit the Qt loop of ``app``; returns the list the signals received
    are appended to. The quit is queued, not called: a signal that lands before
    ``app.exec()`` (one put off by stop_signals comes 20 ms later) would otherwise be lost
    and the window run on. A signal stop_signals saw before (put off, or swallowed by a
    callback) quits too."""
    from PySide6.QtCore import QTimer

    from mm_pc import stop_signals

    stopped_by: list[int] = []

    def stop(signum, _frame) -> None:
        stopped_by.append(signum)
        QTimer.singleShot(0, app.quit)

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    if stop_signals.seen():
        stop(stop_signals.seen(), None)
    return stopped_by


def _remove_unless_failed(folder: Path, node_exit: list[str]):
    """An ExitStack exit callback: delete the --sim node's log folder when the run ends,
    unless the node died or the monitor failed (then the messages name the log in it)."""

    def exit_(exc_type, _exc, _tb) -> bool:
        from mm_pc import stop_signals

        failed = bool(node_exit) or (
            exc_type is not None
            and not issubclass(exc_type, KeyboardInterrupt)
            and not stop_signals.raised()  # an error a stop's KeyboardInterrupt became
        )
        if not failed:
            import shutil

            shutil.rmtree(folder, ignore_errors=True)
        return False

    return exit_


def _quit_after(replayer, app) -> None:
    """Quit ``app`` once ``replayer`` has fed its last reply (after its own on_end)."""
    ended = replayer.on_end

    def then_quit() -> None:
        if ended is not None:
            ended()
        app.quit()

    replayer.on_end = then_quit


def _check_node(node, log: Path, node_exit: list[str], app) -> None:
    """If the --sim node has exited, keep its reason (the log's last line) and quit."""
    if node_exit or node.poll() is None:
        return
    try:
        lines = [ln for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        lines = []
    said = [ln for ln in lines if ln.startswith("mm-beagle: ") and "shutting down" not in ln]
    reason = (said or lines or ["no output"])[0]
    node_exit.append(
        f"the emulated mm-beagle exited (code {node.returncode}): {reason} (log {log})"
    )
    app.quit()


def _report_recording(window, recorder, stop_recording) -> None:
    """Stop the --record recording (if the window has not) and say what is in it."""
    if window.ctx.recorder is recorder:
        stop_recording(window)
    recorder.close()
    counts = recorder.topic_counts()
    if recorder.error:
        print(f"mm-monitor: {recorder.error}", file=sys.stderr)
    print(
        f"mm-monitor: recorded {recorder.replies} replies and {recorder.live_messages} live "
        f"messages ({sum(counts.values())} messages on {sum(1 for n in counts.values() if n)} "
        f"topics) to {recorder.path}",
        flush=True,
    )


if __name__ == "__main__":
    sys.exit(main())
