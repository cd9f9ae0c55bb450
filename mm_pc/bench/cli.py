"""mm-bench: benchmarks that print one JSON object.

mm-bench pose --json
    Every odometry method of mm_pc.core.odometry on the same simulated runs
    (figure eight, meander; 1 kHz and 15 Hz requests; noise-free and noisy):
    final/heading/RMS error, calibration error, update/integrate samples/s.
    See mm_pc.bench.pose.

mm-bench maps --json
    Coverage grid update/init times, trilateration fixes/s and error vs
    noise, raw vs fused drift after a simulated 200 m mowing run.
    See mm_pc.bench.maps.

mm-bench gui [--hours H] [--rate HZ] [--frames N] [--stalls ACTIONS] [--no-node] --json
    The real monitor window offscreen with H hours of simulated history at
    HZ, polling a real mm-beagle sim node at HZ: frame time p50/p95 (all
    tabs and per tab), memory, dropped requests. See mm_pc.bench.gui.

mm-bench executors [--rate HZ] [--seconds S] [--rounds N] --json
    A bare get_sensor_data client (asks, counts, nothing else) under rclpy's
    events executor and its wait-set executor, alternating, against a real
    mm-beagle sim node: CPU per reply of each and their ratio.
    See mm_pc.bench.executors.

mm-bench agent [--seconds S] [--drops N] [--drop-seconds D] --json
    The board agent (mm-beagle-agent): CPU per poll with a stub bus (x86, and
    under qemu-arm in the armhf root where it can be had), CPU % at 1 kHz, RSS,
    link bandwidth and latency, counts lost over N forced link drops.
    See mm_beagle.tools.bench_agent.

mm-bench chips [--polls N] --json
    CPU per poll of every installed chip's driver in the real poller, in this
    process: with a constant-reply stub (driver + poller only) and with the
    chip's emulator. See mm_beagle.tools.bench_chips.

mm-bench pipeline [--rates 15,100] [--cpi 1600] [--speed 0.5] [--duration 20] [--lifts 0] --json
    One s-curves path (CSV) integrated in-process and through the real processes
    (mm-beagle sim on the file, one mm-odometry per method and rate): final error per
    10 m and yaw error side by side, against the file's ground truth.
    See mm_pc.bench.pipeline.

mm-bench soak [--minutes N] [--sample-seconds S] --json
    The board chain for N minutes (30): agent on emulated sensors, node in backend:=remote,
    one 100 Hz client; RSS of agent and node every S s (10), their least-squares slope
    after the warm-up (MB/min; flat: |slope| < 0.05), counts served vs generated.
    See mm_pc.bench.soak.

mm-bench poll --seconds S [--clients N] [--rate HZ] [--cursor ack|shared] --json
    mm-beagle on emulated sensors (separate process) while N (2) client
    processes call get_sensor_data at HZ (100; 0 = flat out) each. Reports the
    poll rate and period, the poller's CPU use, count conservation per client
    (totals, and read-and-clear: each client's own with --cursor ack, the sum
    over clients with shared), replies lost (none within 5 s), node exits and
    the service round-trip time. Also a bare sleep loop measured in the same run
    (``baseline_sleep_p99_us``): on a virtual machine the wake-up latency of
    an idle vCPU dominates the period tail, and the ratio tells code from host.
    ``--chip NAME`` (both devices that chip) or ``--chips a,b`` (one per device)
    runs the emulators of those chips behind their real drivers: the poller's
    CPU per poll (``cpu_us_per_poll``, emulator included) and ``counts_lost``
    per device (``counts_lost_per_device``) for each chip.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing as mp
import os
import platform
import sys
import time

import numpy as np
import psutil

from mm_beagle.tools.harness import BeagleClient, beagle_process, use_isolated_ros_env


def sleep_loop_periods(seconds: float, period_s: float = 0.001) -> np.ndarray:
    """Periods (us) of a bare absolute-deadline sleep loop: the host's floor."""
    periods = []
    nxt = last = time.perf_counter_ns()
    end = last + int(seconds * 1e9)
    step = int(period_s * 1e9)
    while last < end:
        nxt += step
        time.sleep(max(0.0, (nxt - time.perf_counter_ns()) / 1e9))
        t = time.perf_counter_ns()
        periods.append(t - last)
        last = t
    return np.array(periods) / 1e3


def _client(name: str, seconds: float, rate: float, cursor: str, conn) -> None:
    """One client process: get_sensor_data(id='') at ``rate`` Hz (0: flat out), then a final read.

    ``cursor`` 'ack': its own read-and-clear cursor (mm_beagle.poller.read_and_clear), a
    lost reply asked for again with the same ack; 'shared': the node's one cursor.
    A reply that does not come within 5 s counts as lost.
    """
    import rclpy

    from mm_beagle.poller.read_and_clear import AckedReader

    client = BeagleClient(name)
    client.wait(20)
    reader = AckedReader(name, client.get_parameters("devices")[0]) if cursor == "ack" else None
    rtts, sums, totals, seqs, failures, lost = [], {}, {}, [], 0, 0
    conn.send("ready")
    conn.recv()  # start together
    period = 1.0 / rate if rate > 0 else 0.0
    t_next = time.monotonic()
    end = t_next + seconds

    def one_call() -> None:
        nonlocal failures, lost
        fields = reader.fields("") if reader else {"id": ""}
        t0 = time.perf_counter()
        try:
            res = client.call("get_sensor_data", timeout=5.0, **fields)
        except TimeoutError:
            lost += 1
            return
        rtts.append((time.perf_counter() - t0) * 1e3)
        if not res.success:
            failures += 1
        if reader:
            reader.received(res)
        for d in res.data:
            sx, sy = sums.get(d.id, (0, 0))
            sums[d.id] = (sx + d.x_counts, sy + d.y_counts)
            totals[d.id] = (d.x_total_counts, d.y_total_counts)
        if res.data:
            seqs.append((time.monotonic(), res.data[0].seq))

    while time.monotonic() < end:
        one_call()
        if period:
            t_next += period
            time.sleep(max(0.0, t_next - time.monotonic()))
    (t_a, seq_a), (t_b, seq_b) = seqs[0], seqs[-1]
    conn.send("done")
    conn.recv()  # final read once the robot stands still
    n = len(rtts)
    # ack: the first may repeat a lost interval, the second then ends now
    for _ in range(2 if reader else 1):
        one_call()
    del rtts[n:]
    conn.send(
        {
            "rtts": rtts,
            "sums": sums,
            "totals": totals,
            "failures": failures,
            "replies_lost": lost,
            "rate_hz": (seq_b - seq_a) / (t_b - t_a),
        }
    )
    client.close()
    rclpy.shutdown()


def _echo_server(seconds: float) -> None:
    """A trivial GetSensorData server: the round-trip floor of rclpy on this host."""
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from mm_interfaces.srv import GetSensorData

    def answer(_req, res):
        res.success = True
        return res

    rclpy.init()
    node = rclpy.create_node("mm_beagle", namespace="/mm_bench_echo")
    node.create_service(GetSensorData, "~/get_sensor_data", answer)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    end = time.monotonic() + seconds
    with contextlib.suppress(ExternalShutdownException):  # terminate() ends it early
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.1)
    node.destroy_node()
    if rclpy.ok():
        rclpy.shutdown()


def _init_rclpy() -> None:
    """rclpy without its own signal handlers: they would shut the context down under the
    client's spin thread (a traceback); SIGINT/SIGTERM reach this process as the
    KeyboardInterrupt of mm_pc.stop_signals, and the ``finally`` blocks close the clients."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    if not rclpy.ok():
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)


def baseline_rtt(n: int = 300, rate: float = 100.0) -> np.ndarray:
    """Round trips (ms) to the trivial server, same client pattern as the bench; a request
    unanswered within 2 s is left out (the next one goes out), not the end of the run."""
    ctx = mp.get_context("spawn")
    server = ctx.Process(target=_echo_server, args=(n / rate + 30.0,), daemon=True)
    server.start()
    _init_rclpy()
    try:
        client = BeagleClient("mm_bench_echo_client", namespace="/mm_bench_echo/mm_beagle")
    except BaseException:
        server.terminate()
        raise
    try:
        if not client.clients["get_sensor_data"].wait_for_service(timeout_sec=30):
            raise RuntimeError("the echo server did not come up")
        rtts = []
        for _ in range(n):
            t0 = time.perf_counter()
            with contextlib.suppress(TimeoutError):
                client.call("get_sensor_data", timeout=2.0, id="")
                rtts.append((time.perf_counter() - t0) * 1e3)
            time.sleep(1.0 / rate)
    finally:
        client.close()
        server.terminate()
        server.join(5)
    return np.array(rtts)


def _poller_process(node_pid: int) -> psutil.Process:
    for child in psutil.Process(node_pid).children():
        if any("spawn_main" in part for part in child.cmdline()):
            return child
    raise RuntimeError("the poller process of mm_beagle was not found")


@contextlib.contextmanager
def _client_side():
    """The bench's own client and the list of its client processes: closed, and the
    processes ended, however the run ends (a SIGTERM is a KeyboardInterrupt here)."""
    import rclpy

    _init_rclpy()
    client = BeagleClient("mm_bench")
    procs: list = []
    try:
        yield client, procs
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(3)
        client.close()
        if rclpy.ok():
            rclpy.shutdown()


def bench_poll(
    seconds: float, rate: float, n_clients: int, cursor: str = "ack", chips: list[str] | None = None
) -> dict:

    baseline = sleep_loop_periods(2.0)
    use_isolated_ros_env()
    echo = baseline_rtt()
    motion_s = max(1.0, seconds - 2.0)
    params: dict[str, object] = {
        "backend": "sim",
        "sim_trajectory": "figure_eight",
        "sim_duration": motion_s,
    }
    if chips:
        devices = [f"/dev/spidev1.{i}" for i in range(max(2, len(chips)))]
        params.update(devices=devices, chips=chips)
    ctx = mp.get_context("spawn")
    pipes = []
    with beagle_process(params, env=dict(os.environ)) as proc, _client_side() as (client, procs):
        if not client.wait(30):
            raise RuntimeError("mm_beagle did not come up")
        for k in range(n_clients):
            a, b = ctx.Pipe()
            p = ctx.Process(target=_client, args=(f"mm_bench_client_{k}", seconds, rate, cursor, b))
            p.start()
            pipes.append(a)
            procs.append(p)
        for a in pipes:
            a.recv()
        poller = _poller_process(proc.pid)
        cpu0, wall0 = poller.cpu_times(), time.monotonic()
        for a in pipes:
            a.send("go")
        for a in pipes:
            a.recv()
        cpu1, wall1 = poller.cpu_times(), time.monotonic()
        time.sleep(max(0.0, motion_s + 1.5 - seconds))  # the robot stands still by now
        for a in pipes:
            a.send("final")
        results = [a.recv() for a in pipes]
        for p in procs:
            p.join(10)
        final = client.diagnostics(newer_than=time.monotonic())
        node_exits = 0 if proc.poll() is None else 1

    devices = sorted(final)
    generated = {
        d: (int(final[d]["sim_generated_x_counts"]), int(final[d]["sim_generated_y_counts"]))
        for d in devices
    }

    def served_by(r: dict) -> dict:
        return {d: tuple(r["totals"].get(d, (0, 0))) for d in devices}

    def lost(served: dict) -> int:
        return sum(abs(generated[d][k] - served[d][k]) for d in devices for k in (0, 1))

    if cursor == "ack":  # each client's own read-and-clear sum must match what was generated
        rc_lost = sum(lost({d: tuple(r["sums"].get(d, (0, 0))) for d in devices}) for r in results)
    else:  # one shared cursor: only the sum over all clients can
        rc_lost = lost(
            {
                d: tuple(sum(r["sums"].get(d, (0, 0))[k] for r in results) for k in (0, 1))
                for d in devices
            }
        )
    rtts = np.array([x for r in results for x in r["rtts"]])
    base_p50, base_p99 = np.percentile(baseline, [50, 99])
    cpu_percent = 100 * ((cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)) / (wall1 - wall0)
    rate_hz = min(r["rate_hz"] for r in results)
    return {
        "benchmark": "poll",
        "chips": {d: final[d].get("chip", "pln2033") for d in devices},
        "cpu_us_per_poll": round(cpu_percent / 100 / rate_hz * 1e6, 1) if rate_hz else None,
        "counts_lost_per_device": {
            d: max(
                sum(abs(generated[d][k] - served_by(r)[d][k]) for k in (0, 1)) for r in results
            )
            for d in devices
        },
        "seconds": seconds,
        "clients": n_clients,
        "client_rate_hz": rate if rate > 0 else "flat out",
        "cursor": cursor,
        "rate_hz": round(min(r["rate_hz"] for r in results), 1),
        "period_p50_us": float(final[devices[0]]["period_p50_us"]),
        "period_p99_us": float(final[devices[0]]["period_p99_us"]),
        "late_polls": int(final[devices[0]]["late_polls"]),
        "polls": int(final[devices[0]]["polls"]),
        "cpu_percent": round(cpu_percent, 2),
        "counts_generated": sum(abs(v) for g in generated.values() for v in g),
        "counts_served": [sum(abs(v) for s in served_by(r).values() for v in s) for r in results],
        "counts_lost": max(lost(served_by(r)) for r in results),
        "counts_lost_read_and_clear": rc_lost,
        "replies_lost": sum(r["replies_lost"] for r in results),
        "node_exits": node_exits,
        "failed_requests": sum(r["failures"] for r in results),
        "requests": len(rtts),
        "service_rtt_p50_ms": round(float(np.percentile(rtts, 50)), 3),
        "service_rtt_p99_ms": round(float(np.percentile(rtts, 99)), 3),
        "baseline_rtt_p50_ms": round(float(np.percentile(echo, 50)), 3),
        "baseline_rtt_p99_ms": round(float(np.percentile(echo, 99)), 3),
        "baseline_sleep_p50_us": round(float(base_p50), 1),
        "baseline_sleep_p99_us": round(float(base_p99), 1),
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "load_avg_1min": round(os.getloadavg()[0], 2),
        },
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="mm-bench", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    poll = sub.add_parser("poll", help="the 1 kHz poller under two 100 Hz clients")
    poll.add_argument("--seconds", type=float, default=10.0)
    poll.add_argument(
        "--rate", type=float, default=100.0, help="requests per second per client (0: flat out)"
    )
    poll.add_argument("--clients", type=int, default=2)
    poll.add_argument(
        "--cursor",
        choices=("ack", "shared"),
        default="ack",
        help="read-and-clear per client with ack_seq (default), or the node's shared cursor",
    )
    poll.add_argument("--chip", help="the chip of both emulated sensors (default pln2033)")
    poll.add_argument("--chips", help="one chip per emulated sensor, comma-separated")
    poll.add_argument("--json", action="store_true", help="print JSON only (the default)")
    pose = sub.add_parser("pose", help="accuracy and speed of every odometry method (simulated)")
    pose.add_argument("--json", action="store_true", help="print JSON only (the default)")
    maps = sub.add_parser("maps", help="grid map, trilateration and fusion (simulated)")
    maps.add_argument("--json", action="store_true", help="print JSON only (the default)")
    from mm_pc.bench.gui import STALL_ACTIONS

    gui = sub.add_parser("gui", help="monitor frame times and memory with an hour of history")
    gui.add_argument("--hours", type=float, default=1.0, help="simulated history (h)")
    gui.add_argument("--rate", type=float, default=100.0, help="sample rate (Hz)")
    gui.add_argument("--frames", type=int, default=300, help="frames measured per tab")
    gui.add_argument(
        "--live-seconds", type=float, default=10.0,
        help="seconds of each live CPU measurement at 100 and 500 Hz (0: none)",
    )
    gui.add_argument(
        "--polls", choices=("reply", "get_samples"), default="reply",
        help="single polls inside the get_sensor_data reply (default), or one get_samples "
        "per sensor and reply (the fallback for older nodes; for before/after comparisons)",
    )
    gui.add_argument(
        "--executor", choices=("events", "waitset"), default="events",
        help="the monitor's rclpy executor: the C++ events executor (default) or the Python "
        "wait-set one (for before/after comparisons)",
    )
    gui.add_argument(
        "--stalls", default="all", metavar="ACTIONS",
        help="the heavy actions whose GUI-thread stalls are measured: 'all' (default), "
        "'none' or a comma list of " + ", ".join(STALL_ACTIONS),
    )
    gui.add_argument(
        "--no-node", action="store_true",
        help="no live mm-beagle: the history only, the stalls without live data (an "
        "action's own cost, to compare with a run that has the node)",
    )
    gui.add_argument("--json", action="store_true", help="print JSON only (the default)")
    execs = sub.add_parser("executors", help="CPU per reply of a bare client, per executor")
    execs.add_argument("--rate", type=float, default=500.0, help="request rate (Hz)")
    execs.add_argument("--seconds", type=float, default=8.0, help="per measurement")
    execs.add_argument("--rounds", type=int, default=2, help="measurements per executor")
    execs.add_argument("--json", action="store_true", help="print JSON only (the default)")
    agent = sub.add_parser("agent", help="the board agent: CPU per poll, RSS, link, drops")
    agent.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    agent.add_argument("--drops", type=int, default=5, help="forced link drops")
    agent.add_argument("--drop-seconds", type=float, default=3.0, help="length of each drop")
    agent.add_argument("--json", action="store_true", help="print JSON only (the default)")
    chips = sub.add_parser("chips", help="CPU per poll of each chip's driver in the poller")
    chips.add_argument("--polls", type=int, default=20000)
    chips.add_argument("--json", action="store_true", help="print JSON only (the default)")
    soak = sub.add_parser("soak", help="agent + remote node + a 100 Hz client: RSS slope")
    soak.add_argument("--minutes", type=float, default=30.0, help="length of the run (min)")
    soak.add_argument("--sample-seconds", type=float, default=10.0, help="RSS sample period")
    soak.add_argument("--json", action="store_true", help="print JSON only (the default)")
    from mm_pc.bench.pipeline import main_args as pipeline_args

    pipeline_args(sub.add_parser("pipeline", help="one path in-process and through the nodes"))
    args = parser.parse_args(argv)
    if args.what == "chips":
        from mm_beagle.tools.bench_chips import bench_chips

        if args.polls < 1000:
            parser.error("need --polls >= 1000")
        result = bench_chips(args.polls)
    elif args.what == "agent":
        from mm_beagle.tools.bench_agent import bench_agent

        if not args.seconds >= 1 or args.drops < 0 or not args.drop_seconds > 0:
            parser.error("need --seconds >= 1, --drops >= 0, --drop-seconds > 0")
        result = bench_agent(args.seconds, args.drops, args.drop_seconds)
    elif args.what == "soak":
        from mm_pc.bench.soak import bench_soak

        if not 0.1 <= args.minutes <= 1440 or not 0.5 <= args.sample_seconds <= 600:
            parser.error("need 0.1 <= --minutes <= 1440 and 0.5 <= --sample-seconds <= 600")
        result = bench_soak(args.minutes, args.sample_seconds)
    elif args.what == "gui":
        from mm_pc.bench.gui import bench_gui, stall_actions

        try:
            result = bench_gui(
                hours=args.hours, rate_hz=args.rate, frames=args.frames,
                live_seconds=args.live_seconds, polls=args.polls,
                executor=args.executor, node=not args.no_node,
                stalls=stall_actions(args.stalls),
            )
        except ValueError as e:
            parser.error(str(e))
    elif args.what == "executors":
        from mm_pc.bench.executors import bench_executors

        try:
            result = bench_executors(args.rate, args.seconds, args.rounds)
        except ValueError as e:
            parser.error(str(e))
    elif args.what == "pipeline":
        from mm_pc.bench.pipeline import run as bench_pipeline

        try:
            result = bench_pipeline(args)
        except ValueError as e:
            parser.error(str(e))
    elif args.what == "maps":
        from mm_pc.bench.maps import bench_maps

        result = bench_maps()
    elif args.what == "pose":
        from mm_pc.bench.pose import bench_pose

        result = bench_pose()
    elif args.what == "poll":
        if not args.seconds >= 3 or not args.rate >= 0 or not 1 <= args.clients <= 64:
            parser.error("need --seconds >= 3, --rate >= 0 (0: flat out), 1 <= --clients <= 64")
        chips = [c.strip() for c in (args.chips or args.chip or "").split(",") if c.strip()]
        if args.chip and args.chips:
            parser.error("give --chip or --chips, not both")
        if chips:
            from mm_beagle.poller.chip_config import resolve_chips

            try:
                resolve_chips(chips, ["a", "b"] if len(chips) == 1 else chips)
            except ValueError as e:
                parser.error(str(e))
        result = bench_poll(args.seconds, args.rate, args.clients, args.cursor, chips)
    print(json.dumps(result, indent=None if args.json else 2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
