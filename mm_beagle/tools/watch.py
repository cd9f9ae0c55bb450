"""mm-watch: a live text view of what mm-beagle serves.

Listens to the node's sensor_data topic (so it never takes counts away from
service clients) and /diagnostics, and redraws a small table twice a second:
per sensor the poll rate, speed, distance travelled, CPI, polls that saw the
lift bit ("lifted") and the distance estimated for the lift gaps, state, the
chip and its newest surface-quality figure ("-" where the chip has none).
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from dataclasses import dataclass

from mm_pc.core.sensor_data import Reading


@dataclass
class SensorView:
    """What the view shows of one sensor (SI units; printed in mm and m)."""

    samples: int = 0
    interval: float = 0.0
    x_speed: float = 0.0
    y_speed: float = 0.0
    x_total: float = 0.0
    y_total: float = 0.0
    cpi: int = 0
    lifts: int = 0
    lift_est: float = 0.0
    chip: str = ""
    quality: int = -1

    def update(self, msg) -> None:
        """Add one ``mm_interfaces/SensorData``, read by the one reader (as the monitor and
        mm-odometry read it)."""
        r = Reading.from_msg(msg)
        self.samples += r.samples
        self.interval += r.interval
        self.x_speed, self.y_speed = r.x_speed, r.y_speed
        self.x_total, self.y_total = r.x_total, r.y_total
        self.cpi = r.cpi
        self.lifts = r.lift_events_total
        self.lift_est = math.hypot(r.x_lift_total, r.y_lift_total)
        self.chip = r.chip or "pln2033"  # an older node sends none
        self.quality = r.quality

    def take_rate(self) -> float:
        """Polls per second since the previous call."""
        rate = self.samples / self.interval if self.interval > 0 else float("nan")
        self.samples, self.interval = 0, 0.0
        return rate


HEADER = (
    f"{'sensor':<16}{'state':>7}{'polls/s':>9}{'vx mm/s':>9}{'vy mm/s':>9}"
    f"{'x m':>9}{'y m':>9}{'CPI':>6}{'lifted':>7}{'lift est m':>11}{'chip':>9}{'quality':>8}"
)


def format_row(device: str, view: SensorView, state: str, rate: float) -> str:
    return (
        f"{device:<16}{state:>7}{rate:>9.0f}{view.x_speed * 1e3:>9.1f}{view.y_speed * 1e3:>9.1f}"
        f"{view.x_total:>9.3f}{view.y_total:>9.3f}{view.cpi:>6}{view.lifts:>7}{view.lift_est:>11.4f}"
        f"{view.chip or '?':>9}{view.quality if view.quality >= 0 else '-':>8}"
    )


def run(
    duration: float,
    namespace: str,
    refresh: float,
    out=sys.stdout,
    stop: threading.Event | None = None,
) -> int:
    """Show the view for ``duration`` s (0 = until Ctrl-C or ``stop`` is set). Returns
    messages received. Without ``stop``, rclpy is started with mm_pc.ros.spin's handlers:
    SIGINT and SIGTERM end the loop at its next wake-up (at most ``refresh`` s)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data

    from mm_interfaces.msg import SensorData
    from mm_pc.ros.spin import init, stopping

    if stop is None:
        stop = init(["mm-watch"], "mm-watch") if not rclpy.ok() else threading.Event()
    node = rclpy.create_node("mm_watch")
    views: dict[str, SensorView] = {}
    states: dict[str, str] = {}
    received = 0

    def on_data(msg) -> None:
        nonlocal received
        views.setdefault(msg.id, SensorView()).update(msg)
        received += 1

    def on_diag(msg) -> None:
        for s in msg.status:
            values = {kv.key: kv.value for kv in s.values}
            if "state" in values:
                states[s.hardware_id] = values["state"]

    node.create_subscription(
        SensorData, f"{namespace}/sensor_data", on_data, qos_profile_sensor_data
    )
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    end = time.monotonic() + duration if duration > 0 else math.inf
    tty = out.isatty()
    # Spun here, not on a thread: a daemon thread still inside spin() when the
    # interpreter exits aborts the process ("terminate called without an active exception").
    try:
        while time.monotonic() < end and not stop.is_set():
            redraw = min(end, time.monotonic() + refresh)
            while (left := redraw - time.monotonic()) > 0 and not stop.is_set():
                executor.spin_once(timeout_sec=min(left, 0.1))
            rows = [
                format_row(dev, v, states.get(dev, "?"), v.take_rate())
                for dev, v in sorted(views.items())
            ]
            if tty:
                out.write("\x1b[H\x1b[2J")  # redraw in place on a terminal
            stamp = time.strftime("%H:%M:%S")
            if rows:
                out.write(f"{stamp}  {namespace}/sensor_data\n{HEADER}\n" + "\n".join(rows) + "\n")
            else:
                out.write(f"{stamp}  waiting for {namespace}/sensor_data ...\n")
            out.flush()
    finally:
        stopping()  # a second signal must not cut the clean-up short
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return received


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mm-watch", description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=0.0, help="seconds; 0 = until Ctrl-C")
    parser.add_argument("--namespace", default="/mm_beagle", help="the node's namespace/name")
    parser.add_argument("--refresh", type=float, default=0.5, help="seconds between redraws")
    args = parser.parse_args(argv)
    if not (0 <= args.duration < math.inf and 0 < args.refresh <= 3600):
        parser.error("--duration must be >= 0 and finite, --refresh > 0 and <= 3600 (s)")
    received = run(args.duration, args.namespace, args.refresh)
    return 0 if received or args.duration == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
