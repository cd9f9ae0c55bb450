"""``mm-bench pipeline``: one path integrated in-process and through the real processes.

The s-curves path (``mm_pc.sim.robot.s_curves`` at ``speed`` m/s for ``duration`` s:
speed and curvature change all the time) is written to a CSV (100 Hz rows, the
sim backend's ``file:PATH`` format). The ground truth is the file as the sim reads it:
``load_trajectory_file`` then ``integrate_pose`` (exact per 1 ms step).

* in-process: the file's 1 kHz steps, counts floored at ``cpi`` like the emulator, read
  at each request rate through :class:`mm_pc.core.polls.PollTracker`, integrated per
  poll (what ``mm-bench pose``'s ``per_poll_15hz_*`` keys measure);
* through the processes: ``mm-beagle`` (sim backend, the file, ``cpi``, no loop, a start
  delay so every client has its baseline before the robot moves) and one ``mm-odometry``
  per (method, rate), and mm-beagle's own odometry (``two-sensor``, every poll of its
  ring, :data:`ONBOARD`); the final pose each publishes once the robot stands.

Errors: final position (mm per 10 m travelled) and yaw (rad) against the ground truth,
with each process's gap count from /diagnostics and the published final covariance
(``sigma_xy_mm``, ``sigma_yaw_rad``). ``lifts`` (lifts per second per sensor, 10 ms
each, the sim's ``sim_lift_rate``) lifts the emulated sensors through the processes
only (the in-process rows stay unlifted): each mm-odometry row then also gives its
``lifted_steps``, ``switched_steps`` (``exact`` on the other sensor) and
``lift_fill_sigma_m`` (the fill variance it added, docs/pose-math.md "Covariance").
The speed-up: the path at ``speed`` is the same shape at any speed (s_curves scales
its speed, not its curvature), so the default 0.5 m/s keeps the run at ~20 s of motion
for ~10 m.
"""

from __future__ import annotations

import math
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from mm_pc.bench.per_poll import _counts, _through_tracker
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.sim import robot as sim

__all__ = [
    "FinalPoses",
    "in_process",
    "pipeline",
    "pose_of",
    "start_pipeline",
    "through_processes",
    "write_path",
]

METHODS = ("exact", "two-sensor")
#: mm-beagle's onboard odometry's key in the results (two-sensor, published at 15 Hz)
ONBOARD = "mm-beagle onboard two-sensor@15Hz"
ROW_S = 0.01  # CSV row interval (s): 100 Hz, the file format's slowest


def write_path(path: Path, speed: float = 0.5, duration: float = 20.0) -> None:
    """The s-curves at ``speed`` m/s (mean) for ``duration`` s as a ``t,v,w`` CSV."""
    v, w = sim.s_curves(speed=speed, duration=duration)
    step = round(ROW_S / sim.DT)
    idx = np.arange(0, len(v) + 1, step)
    idx[-1] = min(idx[-1], len(v) - 1)
    with open(path, "w") as f:
        f.write("t,v,w\n")
        for k in idx:
            f.write(f"{k * sim.DT:.6f},{v[k]:.9f},{w[k]:.9f}\n")


def _truth(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(v, w) per 1 ms step as the sim reads the file, its exact final pose, length (m)."""
    v, w, vy = sim.load_trajectory_file(path)
    assert vy is None
    return v, w, sim.integrate_pose(v, w, sim.DT)[-1], float(np.sum(np.abs(v)) * sim.DT)


def _row(pose, truth, length: float) -> dict:
    err = math.hypot(pose[0] - truth[0], pose[1] - truth[1])
    return {
        "error_mm_per_10m": round(err * 1e4 / length, 4),
        "yaw_error_rad": float(f"{math.remainder(pose[2] - truth[2], 2 * math.pi):.3g}"),
    }


def in_process(path: Path, rates, cpi: int) -> dict:
    """Per method and rate: the error of per-poll integration of the file's floored counts."""
    v, w, truth, length = _truth(path)
    d = _counts(v, w, DEFAULT_MOUNTS, cpi)
    out: dict = {}
    for hz in rates:
        steps = _through_tracker(d, sim.request_boundaries(len(v), hz), cpi)
        for m in METHODS:
            odo = Odometry(DEFAULT_MOUNTS, m)
            odo.integrate(steps.dt, steps.d)
            out[f"{m}@{hz:g}Hz"] = _row(odo.pose.as_array(), truth, length)
    return out


def read_delay_in_process(
    path: Path, delay_us: float, cpi: int, hz: float = 15.0, equal_stamps: bool = False,
    jitter_us: float = 0.0, seed: int = 1,
) -> dict:  # fmt: skip
    """The poller's read order in-process: sensor 0 read at each 1 ms tick, sensor 1
    ``delay_us`` later (plus uniform jitter up to ``jitter_us``), counts floored at those
    times, each poll stamped with its own read time (``equal_stamps``: all with the
    tick's, as the poller did before) and read at ``hz`` through the tracker. Per method:
    the error of per-poll integration."""
    from mm_pc.core.polls import PollBatch, PollSteps, PollTracker, SensorTotals
    from pln2033 import INCH_M

    v, w, truth, length = _truth(path)
    n = len(v)
    t = np.arange(n + 1) * sim.DT
    rng = np.random.default_rng(seed)
    delay = delay_us * 1e-6 + rng.uniform(0, jitter_us * 1e-6, n + 1)
    delay[0] = 0.0
    reads = [t, np.minimum(t + delay, t[-1])]
    counts, stamps = [], []
    for m, at in zip(DEFAULT_MOUNTS, reads, strict=True):
        cx, cy = sim.cumulative_sensor_path(v, w, sim.DT, m)
        c = np.floor(np.stack([np.interp(at, t, cx), np.interp(at, t, cy)], -1) * cpi / INCH_M)
        counts.append(np.diff(c, axis=0).astype(np.int64))
        stamps.append(np.round((t if equal_stamps else at)[1:] * 1e9).astype(np.int64) + 10**18)
    k = len(counts)
    cum = [np.concatenate([np.zeros((1, 2), np.int64), np.cumsum(c, axis=0)]) for c in counts]
    scale = INCH_M / cpi

    def totals(j: int) -> list:
        return [SensorTotals(j, int(stamps[i][j - 1]) if j else 10**18, int(cum[i][j, 0]),
                             int(cum[i][j, 1]), float(cum[i][j, 0]) * scale,
                             float(cum[i][j, 1]) * scale) for i in range(k)]  # fmt: skip

    tr = PollTracker(k)
    tr.baseline(totals(0))
    parts, prev = [], 0
    for e in sim.request_boundaries(n, hz):
        e = int(e)
        batches = [
            PollBatch(prev, e, 0, cpi, stamps[i][prev:e], counts[i][prev:e, 0],
                      counts[i][prev:e, 1], np.full(e - prev, 2))
            for i in range(k)
        ]  # fmt: skip
        parts.append(tr.step(totals(e), batches))
        prev = e
    steps = PollSteps.concat(parts, k)
    out: dict = {"gaps": tr.gaps}
    for m in METHODS:
        odo = Odometry(DEFAULT_MOUNTS, m)
        odo.integrate(steps.dt, steps.d)
        out[m] = _row(odo.pose.as_array(), truth, length)
    return out


def _odometry_command(namespace: str, params: dict) -> list[str]:
    from mm_beagle.tools.harness import node_command

    cmd = node_command(params, namespace)
    cmd[2] = "mm_pc.ros.odometry_node"
    return cmd


def through_processes(
    path: Path, rates, cpi: int, start_delay: float = 8.0, timeout: float = 120.0,
    log_dir: Path | None = None, lifts: float = 0.0,
) -> dict:  # fmt: skip
    """mm-beagle (sim, the file; ``lifts`` per second per sensor) and one mm-odometry per
    method and rate: final errors."""
    from mm_beagle.tools.harness import use_isolated_ros_env

    v, _w, truth, length = _truth(path)
    motion_s = len(v) * sim.DT
    env = use_isolated_ros_env()
    log_dir = Path(log_dir or tempfile.mkdtemp(prefix="mm_pipeline_"))
    nodes = {f"{m}@{hz:g}Hz": (m, hz) for hz in rates for m in METHODS}
    ns = {k: "/pl_" + k.replace("-", "_").replace("@", "_").replace(".", "_") for k in nodes}
    beagle = {
        "backend": "sim", "sim_trajectory": f"file:{path}", "sim_loop": False,
        "sim_start_delay": start_delay, "cpi": cpi,
        # mm-beagle's own odometry too (every poll of the ring, on the board)
        "odometry_rate": 15.0, "odometry_method": "two-sensor",
        "sim_lift_rate": float(lifts),
    }  # fmt: skip
    odometry = {
        k: (ns[k], {"beagle": "/mm_beagle", "rate": hz, "method": m, "publish_tf": False})
        for k, (m, hz) in nodes.items()
    }
    with _Stack() as stack:
        client, t_start = start_pipeline(stack, odometry, beagle, env, log_dir, "mm_bench_pipeline")
        watch = FinalPoses(client, {**{k: f"{ns[k]}/mm_odometry/odom" for k in nodes},
                                    ONBOARD: "/mm_beagle/odom"})  # fmt: skip
        deadline = t_start + start_delay + motion_s + timeout
        while time.monotonic() < deadline and not watch.done:
            time.sleep(0.5)
            if time.monotonic() >= t_start + start_delay + motion_s:
                watch.note_finals()
        time.sleep(1.5)  # one more /diagnostics round after the last polls
    out: dict = {}
    for k in watch.topics:
        msg = watch.finals.get(k)
        if msg is None:
            out[k] = {"error": f"no final pose within the time allowed (logs: {log_dir})"}
            continue
        row = _row(pose_of(msg), truth, length)
        cov = msg.pose.covariance
        row["sigma_xy_mm"] = round(math.sqrt(cov[0] + cov[7]) * 1e3, 3)
        row["sigma_yaw_rad"] = float(f"{math.sqrt(cov[35]):.3g}")
        if k in ns:  # mm-odometry's /diagnostics
            d = watch.diagnostics(ns[k])
            row["gaps"] = int(d.get("gaps", -1))
            row["polls_integrated"] = int(d.get("polls_integrated", -1))
            if lifts:
                row["lifted_steps"] = int(d.get("lifted_steps", -1))
                row["switched_steps"] = int(d.get("switched_steps", -1))
                row["lift_fill_sigma_m"] = float(d.get("lift_fill_sigma_m", "nan"))
        out[k] = row
    out["logs"] = str(log_dir)
    return out


def start_pipeline(stack, odometry: dict, beagle: dict, env: dict, log_dir: Path, name: str):
    """Start one mm-odometry per key of ``odometry`` (key -> (namespace, parameters), log
    ``log_dir/KEY.log``) first, so each baselines on mm-beagle's first reply, then mm-beagle
    (``beagle``'s parameters, ``beagle.log``), all stopped by ``stack``. Returns a
    :class:`~mm_beagle.tools.harness.BeagleClient` called ``name`` once mm-beagle answers,
    and the ``time.monotonic()`` at mm-beagle's start (its ``sim_start_delay`` counts from
    there, not from the client's first answer)."""
    from mm_beagle.tools.harness import BeagleClient, _child, beagle_process

    for k, (namespace, params) in odometry.items():
        stack.enter(_child(_odometry_command(namespace, params), env, str(log_dir / f"{k}.log")))
    stack.enter(beagle_process(beagle, env, str(log_dir / "beagle.log")))
    started = time.monotonic()
    client = BeagleClient(name)
    stack.callback(client.close)
    if not client.wait(30):
        raise RuntimeError(f"mm-beagle did not come up (log: {log_dir / 'beagle.log'})")
    return client, started


def pose_of(msg) -> tuple[float, float, float]:
    """x, y (m) and yaw (rad) of a nav_msgs/Odometry's planar pose."""
    p = msg.pose.pose
    return p.position.x, p.position.y, 2 * math.atan2(p.orientation.z, p.orientation.w)


class FinalPoses:
    """``client``'s subscriptions to each key's odometry topic (``topics``: key -> topic;
    the last 30 messages kept) and to mm-odometry's /diagnostics (the last values of each
    "NODE: pose" status). :meth:`note_finals` takes each key's final pose once the robot
    stands: 10 messages in a row with no speed, away from the origin."""

    KEEP = 30
    STILL = 10

    def __init__(self, client, topics: dict[str, str]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry as OdometryMsg

        self.topics = dict(topics)
        self.finals: dict[str, object] = {}
        self._got: dict[str, list] = {k: [] for k in topics}
        self._diags: dict[str, dict] = {}
        self._lock = threading.Lock()
        for k, topic in topics.items():
            client.node.create_subscription(OdometryMsg, topic, self._keeper(k), 10)
        client.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 50)

    def _keeper(self, k: str):
        def on(msg) -> None:
            with self._lock:
                self._got[k].append(msg)
                del self._got[k][: -self.KEEP]

        return on

    def _on_diag(self, msg) -> None:
        for s in msg.status:
            if s.name.endswith("mm_odometry: pose"):
                with self._lock:
                    self._diags[s.name] = {kv.key: kv.value for kv in s.values}

    @property
    def done(self) -> bool:
        return len(self.finals) == len(self.topics)

    def note_finals(self) -> None:
        with self._lock:
            for k, got in self._got.items():
                recent = got[-self.STILL :]
                still = len(recent) == self.STILL and all(
                    r.twist.twist.linear.x == 0 and r.twist.twist.angular.z == 0 for r in recent
                )
                if still and abs(recent[-1].pose.pose.position.x) > 0.05:
                    self.finals[k] = recent[-1]

    def diagnostics(self, namespace: str) -> dict:
        """The last pose status of the mm-odometry in ``namespace`` ({} before any)."""
        with self._lock:
            return next(
                (d for n, d in self._diags.items() if n.startswith(namespace + "/")), {}
            )


class _Stack:
    """contextlib.ExitStack with ``enter``/``callback`` (children stop in reverse order)."""

    def __enter__(self):
        import contextlib

        self._s = contextlib.ExitStack().__enter__()
        return self

    def enter(self, cm):
        return self._s.enter_context(cm)

    def callback(self, fn):
        self._s.callback(fn)

    def __exit__(self, *exc):
        return self._s.__exit__(*exc)


def pipeline(
    rates=(15.0, 100.0), cpi: int = 1600, speed: float = 0.5, duration: float = 20.0,
    path_file: str = "", processes: bool = True, lifts: float = 0.0,
) -> dict:  # fmt: skip
    """The whole comparison as one JSON-ready dict (``lifts``: through the processes)."""
    with tempfile.TemporaryDirectory(prefix="mm_pipeline_path_") as tmp:
        path = Path(path_file) if path_file else Path(tmp) / "s_curves.csv"
        if not path_file:
            write_path(path, speed, duration)
        v, _w, _truth_pose, length = _truth(path)
        res: dict = {
            "setup": {
                "path": path_file
                or f"s_curves at {speed:g} m/s for {duration:g} s (CSV, 100 Hz rows)",
                "length_m": round(length, 3),
                "motion_s": round(len(v) * sim.DT, 3),
                "cpi": cpi,
                "request_hz": list(rates),
                "lifts_per_s_per_sensor": lifts,
                "mounts": [[m.x, m.y, m.yaw] for m in DEFAULT_MOUNTS],
                "ground_truth": "the CSV as the sim reads it: mm_pc.sim.robot."
                "load_trajectory_file then integrate_pose (exact per 1 ms step)",
            },
            "in_process": in_process(path, rates, cpi),
            # the poller's read order in-process: sensor 1 read 20 us after sensor 0
            "in_process_read_delay_20us": {
                "own_stamps_deskewed": read_delay_in_process(path, 20.0, cpi),
                "one_stamp_per_tick": read_delay_in_process(path, 20.0, cpi, equal_stamps=True),
            },
        }
        if processes:
            res["processes"] = through_processes(path, rates, cpi, lifts=lifts)
            res["side_by_side_mm_per_10m"] = {
                k: [v["error_mm_per_10m"], res["processes"][k].get("error_mm_per_10m")]
                for k, v in res["in_process"].items()
            }
        return res


def main_args(parser) -> None:
    """The subcommand's options (``mm-bench pipeline``)."""
    parser.add_argument("--rates", default="15,100", help="request rates (Hz), comma separated")
    parser.add_argument("--cpi", type=int, default=1600, help="the sim's CPI")
    parser.add_argument("--speed", type=float, default=0.5, help="mean speed (m/s): the speed-up")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds of motion")
    parser.add_argument("--path-file", default="", help="a t,v,w CSV instead of the s-curves")
    parser.add_argument("--in-process-only", action="store_true", help="skip the processes")
    parser.add_argument(
        "--lifts", type=float, default=0.0,
        help="lifts per second per sensor (10 ms each) in the sim, through the processes only",
    )  # fmt: skip
    parser.add_argument("--json", action="store_true", help="print JSON only (the default)")


def run(args) -> dict:
    """``mm-bench pipeline`` from its parsed options."""
    try:
        rates = tuple(float(r) for r in args.rates.split(","))
    except ValueError:
        raise ValueError(f"--rates '{args.rates}' is not a list of numbers (Hz)") from None
    if not all(0 < r <= 500 for r in rates):
        raise ValueError(f"--rates '{args.rates}': each in (0, 500] Hz")
    if not 100 <= args.cpi <= 25600:
        raise ValueError(f"--cpi {args.cpi}: the sim's CPI, 100..25600")
    if not (args.speed > 0 and args.duration > 0):
        raise ValueError("--speed and --duration must be > 0")
    if not 0 <= args.lifts <= 100:
        raise ValueError(f"--lifts {args.lifts:g}: lifts per second per sensor, 0..100")
    if args.path_file:
        sim.load_trajectory_file(args.path_file)  # a bad file: ValueError naming its line
    return pipeline(
        rates, args.cpi, args.speed, args.duration, args.path_file, not args.in_process_only,
        args.lifts,
    )  # fmt: skip
