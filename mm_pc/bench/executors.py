"""mm-bench executors: CPU per reply of a bare get_sensor_data client under each executor.

A client that only asks (one request out at a time, at ``rate_hz``; one unanswered
for 2 s is given up and asked again: mm_pc.ros.deadline_client) and counts the
replies, against a real ``mm-beagle`` on emulated sensors in another process: what each
rclpy executor the monitor can spin costs per reply before the monitor does anything
with it. Both executors are measured in the same run, alternating, so their ratio
holds on a shared machine. The figures: docs/benchmarks.md, the gui section.
"""

from __future__ import annotations

import os
import threading
import time

__all__ = ["bench_executors"]


def _measure(executor_name: str, rate_hz: float, seconds: float) -> dict:
    """Replies per second and CPU (this process, every thread) of the bare client."""
    import rclpy
    from rclpy.context import Context

    from mm_pc.bench.gui import cpu_figures
    from mm_pc.ros.deadline_client import DeadlineClient
    from mm_pc.ros.services import service_types

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("mm_bench_executor", context=ctx, start_parameter_services=False)
    srv = service_types()["get_sensor_data"]
    client = DeadlineClient(node.create_client(srv, "/mm_beagle/get_sensor_data"), 2.0)
    state = {"replies": 0}

    def done(res) -> None:
        state["replies"] += res is not None  # None: given up, asked again at the next tick

    def tick() -> None:
        client.expire()
        if not client.busy:
            client.call(srv.Request(id=""), done)

    node.create_timer(1.0 / rate_hz, tick)
    if executor_name == "events":
        from rclpy.experimental import EventsExecutor

        executor = EventsExecutor(context=ctx)
    else:
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(0.1)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 30.0
        while state["replies"] < 20 and time.monotonic() < deadline:
            time.sleep(0.05)
        if state["replies"] < 20:
            raise RuntimeError("the mm-beagle sim node did not answer within 30 s")
        time.sleep(1.0)
        r0, c0, t0 = state["replies"], os.times(), time.perf_counter()
        time.sleep(seconds)
        r1, c1, t1 = state["replies"], os.times(), time.perf_counter()
    finally:
        stop.set()
        thread.join(3.0)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        ctx.try_shutdown()
    cpu_s = (c1.user + c1.system) - (c0.user + c0.system)
    return {**cpu_figures(cpu_s, t1 - t0, r1 - r0), "requests_unanswered": client.abandoned}


def bench_executors(rate_hz: float = 500.0, seconds: float = 8.0, rounds: int = 2) -> dict:
    """Each executor ``rounds`` times, alternating; a JSON-ready dict with every run and
    the ratio of the medians of ``cpu_ms_per_reply`` (events / waitset)."""
    import statistics

    from mm_beagle.tools.harness import beagle_process, use_isolated_ros_env
    from mm_pc.monitor.ros_bridge import EXECUTORS, validate_rate

    rate_hz = validate_rate(rate_hz)
    if not (isinstance(seconds, (int, float)) and 1 <= seconds <= 600):
        raise ValueError(f"seconds must be in [1, 600], got {seconds!r}")
    if not (isinstance(rounds, int) and 1 <= rounds <= 20):
        raise ValueError(f"rounds must be an integer in 1..20, got {rounds!r}")
    env = use_isolated_ros_env()
    runs: dict[str, list[dict]] = {e: [] for e in EXECUTORS}
    with beagle_process({"backend": "sim"}, env):
        for _ in range(rounds):
            for name in EXECUTORS:
                runs[name].append(_measure(name, rate_hz, seconds))
    med = {e: statistics.median(r["cpu_ms_per_reply"] for r in runs[e]) for e in EXECUTORS}
    return {
        "benchmark": "executors",
        "rate_hz": rate_hz,
        "seconds": seconds,
        "runs": runs,
        "median_cpu_ms_per_reply": med,
        "events_over_waitset": round(med["events"] / med["waitset"], 3),
        "machine": {"cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2)},
    }
