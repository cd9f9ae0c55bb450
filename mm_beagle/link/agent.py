"""mm-beagle-agent: the 1 kHz poller on the board, served over zenoh, without ROS.

A BeagleBone Black cannot run ROS 2 Jazzy, so the board runs only this: the
same :class:`~mm_beagle.poller.poller.Poller` the node spawns locally (same driver,
same conservation rules), writing into a private shared-state buffer, and
every 10 ms (between polls, on the poll thread: no locks, no second thread)
it publishes the new polls with the totals after them and answers queued
queries. ``mm-beagle --ros-args -p backend:=remote`` on any ROS machine turns
that back into the ROS services (:mod:`mm_beagle.link.remote`). Keys and frames:
:mod:`mm_beagle.link.link`. Needs only Debian's python3-spidev and python3-yaml and
the eclipse-zenoh wheel; ``--backend sim`` also needs python3-numpy.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import random
import signal
import sys
import time
import zlib
from dataclasses import dataclass, field

from mm_beagle.link import link
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig, poller_config, tune_process
from mm_beagle.poller.sim_backend import SimConfig, check_trajectory, parse_fail_windows

EXIT_CONFIG = 2
HEARTBEAT_S = 0.1  # an empty batch at least this often: the node's link watchdog
STATUS_S = 1.0
MIN_RING_S = 60.0


@dataclass
class AgentConfig:
    poller: PollerConfig
    name: str = link.DEFAULT_NAME
    listen: list[str] = field(default_factory=lambda: [link.DEFAULT_ENDPOINT])
    credentials: str = ""


class AgentLink:
    """The agent's zenoh side: publishers, and a queryable and a subscriber read with
    ``try_recv`` on the poll thread (no callbacks, no second thread)."""

    def __init__(self, session, name: str, poller: AgentPoller) -> None:
        import zenoh

        self.keys = link.keys(name)
        self.session = session
        self.poller = poller
        self.boot_id = random.getrandbits(63) | 1
        self.number = 0
        self.pub = session.declare_publisher(self.keys["polls"])
        self.status_pub = session.declare_publisher(self.keys["status"])
        self.events_pub = session.declare_publisher(self.keys["events"])
        fifo = zenoh.handlers.FifoChannel
        self.cmd_q = session.declare_queryable(self.keys["cmd"], handler=fifo(64))
        self.history_sub = session.declare_subscriber(self.keys["history_req"], handler=fifo(64))
        self.history_pub = session.declare_publisher(
            self.keys["history"], congestion_control=zenoh.CongestionControl.BLOCK
        )
        n = len(poller.channels)
        self.sent = [0] * n  # next seq to publish, per sensor
        self.ring_bytes = [
            [poller.state.ring_bytes(f, i) for f in ss.SharedState.RING_FIELDS] for i in range(n)
        ]
        self.last_pub = 0.0
        self.next_status = 0.0
        self.t0 = time.monotonic()
        self.cpu_last = (os.times(), time.monotonic())
        self.cpu_percent = float("nan")
        self.bytes_sent = 0

    # --- between polls ---

    def service(self) -> None:
        now = time.monotonic()
        blocks = [self._block(ch, self.sent[ch.i], ch.seq) for ch in self.poller.channels]
        if any(b.count for b in blocks) or now - self.last_pub >= HEARTBEAT_S:
            self.publish_batch(blocks)
            for ch in self.poller.channels:
                self.sent[ch.i] = ch.seq
            self.last_pub = now
        self._answer(self.cmd_q, self.answer_command)
        while (sample := self.history_sub.try_recv()) is not None:
            self.history_pub.put(self.answer_history(sample.payload.to_bytes()))
        if now >= self.next_status:
            self.next_status = now + STATUS_S
            self.publish_status(now)

    def _block(self, ch, first: int, end: int) -> link.Block:
        n = ch.n
        first = max(first, end - n, 0)
        count = end - first
        arrays = []
        a = first % n
        for mv, item in zip(self.ring_bytes[ch.i], link.ARRAY_ITEM, strict=True):
            if a + count <= n:
                arrays.append(mv[a * item : (a + count) * item])
            else:
                arrays.append([mv[a * item :], mv[: (a + count - n) * item]])
        return link.Block(ch.i, first, count, ch.ints.tobytes(), ch.floats.tobytes(), arrays)

    def publish_batch(self, blocks: list[link.Block]) -> None:
        self.number += 1
        frame = link.encode_batch(
            self.boot_id, self.number, self.poller.state.glob_view.tobytes(), blocks
        )
        self.bytes_sent += len(frame)
        self.pub.put(frame)

    def _answer(self, queryable, answer) -> None:
        while True:
            query = queryable.try_recv()
            if query is None:
                return
            payload = query.payload.to_bytes() if query.payload is not None else b""
            try:
                reply = answer(payload)
            except link.LinkError as exc:
                reply = json.dumps({"status": "invalid", "payload": str(exc)}).encode()
            except Exception as exc:  # never let one request stop the polls
                reply = json.dumps({"status": "error", "payload": f"agent failed: {exc!r}"})
                reply = reply.encode()
            query.reply(query.key_expr, reply)
            query.drop()

    def _sensor(self, msg: dict) -> int:
        devices = self.poller.cfg.devices
        dev = msg.get("sensor")
        if dev not in devices:
            raise link.LinkError(f"unknown sensor id {dev!r}; known: {', '.join(devices)}")
        return devices.index(dev)

    def answer_command(self, payload: bytes) -> bytes:
        """One command (JSON) -> {"status", "payload", "seq"}: the poller's own answers."""
        msg = link.parse_request(payload, "command")
        cmd = msg.get("cmd")
        poller = self.poller
        if cmd == "info":
            status, body = "ok", self.info()
        elif cmd == "settings":
            status, body = poller.serve_command(("settings", self._sensor(msg)))
        elif cmd == "set_cpi":
            i, cpi = self._sensor(msg), msg.get("cpi")
            if isinstance(cpi, bool) or not isinstance(cpi, int):
                raise link.LinkError(f"'cpi' must be an integer, got {cpi!r}")
            status, body = poller.serve_command(("set_cpi", i, cpi))
        elif cmd == "load_patch":
            i, words = self._sensor(msg), self._patch_words(msg)
            status, body = poller.serve_command(("load_patch", i, words))
        else:
            known = "info, settings, set_cpi, load_patch"
            raise link.LinkError(f"unknown command {cmd!r}; known: {known}")
        seqs = [ch.seq for ch in poller.channels]
        return json.dumps({"status": status, "payload": body, "seq": seqs}).encode()

    def _patch_words(self, msg: dict) -> list[int]:
        """The words of the patch file ``msg["file"]`` names in this agent's patch_dir.

        A peer names a file; it never sends a path elsewhere or the code itself."""
        from mm_beagle.poller.patches import PatchPathError, resolve_patch_file
        from pln2033.errors import PatchError
        from pln2033.pln2033 import read_patch_file

        if "words" in msg:
            raise link.LinkError(
                "load_patch takes 'file' (a patch file in the agent's --patch-dir), not 'words'"
            )
        name = msg.get("file")
        if not isinstance(name, str) or not name:
            raise link.LinkError("load_patch needs 'file': a patch file in the agent's --patch-dir")
        try:
            return read_patch_file(resolve_patch_file(self.poller.cfg.patch_dir, name))
        except (PatchPathError, PatchError) as exc:
            raise link.LinkError(str(exc)) from None

    def answer_history(self, payload: bytes) -> bytes:
        """Polls ``since`` onwards of one sensor (at most ``max``): a batch frame numbered
        by the request's ``id``, or JSON saying why not."""
        rid = None
        try:
            msg = link.parse_request(payload, "history")
            rid, i, since = msg.get("id"), msg.get("sensor"), msg.get("since")
            most = msg.get("max", link.MAX_HISTORY)
            n = len(self.poller.channels)
            for name, v in (("id", rid), ("sensor", i), ("since", since), ("max", most)):
                if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < 2**63:
                    raise link.LinkError(f"history '{name}' must be an integer >= 0, got {v!r}")
            if i >= n:
                raise link.LinkError(f"history 'sensor' {i} is not one of 0..{n - 1}")
            ch = self.poller.channels[i]
            if since > ch.seq:
                raise link.LinkError(f"history since {since} is ahead of the newest poll {ch.seq}")
        except link.LinkError as exc:
            rid = rid if isinstance(rid, int) and not isinstance(rid, bool) else None
            return json.dumps({"id": rid, "status": "invalid", "payload": str(exc)}).encode()
        end = min(ch.seq, since + min(most, link.MAX_HISTORY))
        block = self._block(ch, since, end)
        return link.encode_batch(self.boot_id, rid, self.poller.state.glob_view.tobytes(), [block])

    def info(self) -> dict:
        cfg = self.poller.cfg
        return {
            "devices": cfg.devices,
            "backend": cfg.backend,
            "boot_id": self.boot_id,
            "ring_size": cfg.ring_size,
            "poll_rate": cfg.poll_rate,
            "cpi": cfg.cpi,
            "cpi_range": [self.poller.regmap.cpi_min, self.poller.regmap.cpi_max],
            "cpi_step": self.poller.regmap.cpi_step,
            "chips": self.poller.chips,
            "chip_cpi": [
                [ch.info.cpi.min, ch.info.cpi.max, ch.info.cpi.step] for ch in self.poller.channels
            ],
        }

    # --- status and events ---

    def publish_status(self, now: float) -> None:
        times, wall = os.times(), time.monotonic()
        last, last_wall = self.cpu_last
        if wall > last_wall:
            busy = (times.user + times.system) - (last.user + last.system)
            self.cpu_percent = 100.0 * busy / (wall - last_wall)
        self.cpu_last = (times, wall)
        hist_z = zlib.compress(self.poller.state.hist_view.tobytes(), 1)
        chans = self.poller.channels
        status = {
            "boot_id": self.boot_id,
            "uptime_s": round(now - self.t0, 3),
            "devices": self.poller.cfg.devices,
            "chips": self.poller.chips,
            "states": [ss.STATE_NAMES.get(ch.ints[ss.I_STATE], "?") for ch in chans],
            "last_errors": [ch.last_error for ch in chans],
            "cpu_percent": round(self.cpu_percent, 2),
            "rss_mb": round(rss_mb(), 2),
            "bytes_sent": self.bytes_sent,
            "hist_z": base64.b64encode(hist_z).decode(),
        }
        self.status_pub.put(json.dumps(status).encode())

    def event(self, kind: str, args: tuple) -> None:
        device = str(args[0]) if kind in ("up", "down") else ""
        text = str(args[-1]) if args else ""
        self.events_pub.put(json.dumps({"kind": kind, "device": device, "text": text}).encode())

    def close(self) -> None:
        for entity in (
            self.cmd_q,
            self.history_sub,
            self.history_pub,
            self.pub,
            self.status_pub,
            self.events_pub,
        ):
            entity.undeclare()


class AgentPoller(Poller):
    """The poller with its link served every 10 ms instead of a pipe to a node."""

    service_period = 0.01

    def __init__(self, cfg: PollerConfig, state: ss.SharedState) -> None:
        super().__init__(cfg, state, None, None)  # type: ignore[arg-type]
        self.link: AgentLink | None = None

    def emit(self, kind: str, *args: object) -> None:
        text = " ".join(str(a) for a in args)
        print(f"mm-beagle-agent: {kind}: {text}", file=sys.stderr, flush=True)
        if self.link is not None:
            self.link.event(kind, args)

    def service(self) -> None:
        if self.link is not None:
            self.link.service()


class StubMotionBus:
    """Benchmarks: an emulated sensor whose motion bursts get a constant reply.

    Bring-up and commands reach the emulator; the 1 kHz motion burst costs
    nothing but the Python around it (3 and 5 counts of motion, every poll).
    """

    def __init__(self, emulator, regmap) -> None:
        a = regmap.addresses
        self.emulator = emulator
        self.status_addr, self.dx_addr = a["status"], a["delta_x_disp"]
        m = regmap.status_motion
        self.reply = [0, m >> 8, m & 0xFF, 0, 0, 3, 0, 0, 5]
        self.burst: list[int] | None = None

    def xfer2(self, data: list[int]) -> list[int]:
        if data is self.burst:  # the driver's own motion-burst list, once it is known
            return self.reply[:]  # a new list each time, as spidev returns
        if len(data) == 9 and data[0] == self.status_addr and data[3] == self.dx_addr:
            self.burst = data
            return self.reply[:]
        return self.emulator.xfer2(data)

    def close(self) -> None:
        self.emulator.close()


def rss_mb() -> float:
    """Resident memory of this process (MB): /proc, or the peak where /proc is absent."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        import resource  # a chroot without /proc (the armhf check): the peak instead

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def make_state(cfg: PollerConfig) -> ss.SharedState:
    """A private shared-state buffer for the agent's poller (nobody else maps it)."""
    n = len(cfg.devices)
    return ss.SharedState(bytearray(ss.SharedState.size(n, cfg.ring_size)), n, cfg.ring_size)


# --- command line -------------------------------------------------------------------------


def _names(text: str) -> list[str]:
    """``"pmw3360,pln2033"`` -> ["pmw3360", "pln2033"]."""
    return chip_config.split_names([text])


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="mm-beagle-agent",
        description="Poll the mouse sensors (PLN2033, PMW3360, ...) at 1 kHz and serve them "
        "over zenoh (no ROS). "
        "On the ROS machine: mm-beagle --ros-args -p backend:=remote -p agent:=ENDPOINT",
    )
    p.add_argument("--config", help="YAML file with any of these options (dashes as _)")
    p.add_argument("--backend", choices=("spidev", "sim"), default=None)
    p.add_argument("--devices", nargs="+", help="spidev paths (default /dev/spidev1.0 1.1)")
    p.add_argument("--cpi", type=int)
    p.add_argument("--poll-rate", type=float, help="polls per second (10..2000, default 1000)")
    p.add_argument("--spi-speed-hz", type=int)
    p.add_argument("--register-map", help="YAML overriding the assumed register map")
    p.add_argument(
        "--patch-file", help="vendor patch code loaded at every bring-up (in --patch-dir)"
    )
    p.add_argument(
        "--patch-dir",
        help="the only directory patch files are loaded from, at start or by a peer's "
        "load_patch command (default '': patch loading off)",
    )
    p.add_argument(
        "--srom-file",
        help="SROM for PMW3360/PMW3389 devices, loaded at every bring-up (in --patch-dir)",
    )
    p.add_argument(
        "--chips",
        type=_names,
        help=f"chip of each device, comma-separated, or one for all (default pln2033); "
        f"allowed: {chip_config.chips_help()}",
    )
    p.add_argument(
        "--chip-options",
        nargs="*",
        help="driver options key=value or CHIP.key=value (e.g. height_m=0.08)",
    )
    p.add_argument("--realtime-priority", type=int, help="SCHED_FIFO priority (0 = off)")
    p.add_argument("--retry-interval", type=float)
    p.add_argument("--ring-seconds", type=float, help="single polls kept (s, >= 60)")
    p.add_argument("--name", help=f"key prefix mm/NAME (default {link.DEFAULT_NAME})")
    p.add_argument(
        "--listen",
        action="append",
        help=f"zenoh endpoint to listen on (repeatable; default {link.DEFAULT_ENDPOINT}); "
        "anything but loopback needs --credentials",
    )
    p.add_argument("--credentials", help="user:password file (mode 600) peers must present")
    p.add_argument("--make-credentials", metavar="FILE", help="write a new credentials file")
    p.add_argument("--sim-trajectory")
    p.add_argument("--sim-speed", type=float)
    p.add_argument("--sim-noise-counts", type=float)
    p.add_argument("--sim-lift-rate", type=float)
    p.add_argument("--sim-chips", type=_names, help="emulated chip per device (default --chips)")
    p.add_argument("--sim-low-quality-rate", type=float, help="poor-surface windows per second")
    p.add_argument("--sim-fail-windows", nargs="*", help="DEVICE@START-END (s) failure windows")
    p.add_argument("--sim-start-delay", type=float, help="s standing still before the path")
    p.add_argument("--sim-duration", type=float, help="s of motion, then still (0 = the path)")
    p.add_argument("--sim-loop", action=argparse.BooleanOptionalAction, help="repeat the path")
    p.add_argument("--self-test", type=float, metavar="SECONDS", help="run, print one JSON line")
    # mm-bench agent: the motion burst answered by a constant stub, flat out unless paced
    p.add_argument("--bench-stub", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--bench-paced", action="store_true", help=argparse.SUPPRESS)
    return p


DEFAULTS = {
    "backend": "spidev",
    "devices": ["/dev/spidev1.0", "/dev/spidev1.1"],
    "cpi": 1600,
    "poll_rate": 1000.0,
    "spi_speed_hz": 3_000_000,
    "register_map": "",
    "patch_file": "",
    "patch_dir": "",
    "srom_file": "",
    "chips": [],
    "chip_options": [],
    "realtime_priority": 50,
    "retry_interval": 1.0,
    "ring_seconds": 65.536,
    "name": link.DEFAULT_NAME,
    "listen": [link.DEFAULT_ENDPOINT],
    "credentials": "",
    "sim_trajectory": "figure_eight",
    "sim_speed": 0.2,
    "sim_noise_counts": 0.0,
    "sim_lift_rate": 0.0,
    "sim_chips": [],
    "sim_low_quality_rate": 0.0,
    "sim_fail_windows": [],
    "sim_start_delay": 0.0,
    "sim_duration": 0.0,
    "sim_loop": True,
}


def _load_yaml(path: str) -> dict:
    import yaml

    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f) or {}
    except OSError as exc:
        raise ValueError(f"cannot read config file {path}: {exc.strerror or exc}") from None
    except (yaml.YAMLError, RecursionError) as exc:
        raise ValueError(f"config file {path} is not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"config file {path} must be a mapping of option: value")
    unknown = sorted(set(data) - set(DEFAULTS))
    if unknown:
        known = ", ".join(sorted(DEFAULTS))
        raise ValueError(f"config file {path}: unknown options {unknown}; known: {known}")
    return data


def _check_type(name: str, value: object) -> object:
    want = type(DEFAULTS[name])
    if want is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if want is list:
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise ValueError(f"'{name}' must be a list of strings, got {value!r}")
    elif not isinstance(value, want) or isinstance(value, bool) != (want is bool):
        raise ValueError(f"'{name}' must be {want.__name__}, got {value!r}")
    return value


def config_from_args(args: argparse.Namespace) -> AgentConfig:
    """Defaults <- config file <- command line; ValueError says what is wrong."""
    values = dict(DEFAULTS)
    if args.config:
        values.update(_load_yaml(args.config))
    for name in DEFAULTS:
        v = getattr(args, name, None)
        if v is not None:
            values[name] = v
    values = {k: _check_type(k, v) for k, v in values.items()}
    devices = values["devices"]
    if len(set(devices)) != len(devices):
        raise ValueError(f"'devices' must name distinct devices, got {devices}")
    if not 10.0 <= values["poll_rate"] <= 2000.0:
        raise ValueError(f"'poll_rate' {values['poll_rate']} is outside 10..2000 Hz")
    if not 0 <= values["realtime_priority"] <= 99:
        raise ValueError("'realtime_priority' must be 0..99")
    if not 0.1 <= values["retry_interval"] <= 60:
        raise ValueError("'retry_interval' must be 0.1..60 s")
    if values["ring_seconds"] < MIN_RING_S:
        raise ValueError(f"'ring_seconds' must be >= {MIN_RING_S:g} (the link's replay window)")
    for name in ("chips", "sim_chips"):  # a config file may write "a,b" too
        values[name] = chip_config.split_names(values[name])
    options = chip_config.parse_chip_options(values["chip_options"])
    chip_config.check_board_config(
        devices, values["chips"], options, values["cpi"], values["register_map"]
    )
    values["chip_options"] = options
    link.keys(values["name"])
    for ep in values["listen"]:
        if not link.is_loopback(ep) and not values["credentials"]:
            raise ValueError(
                f"listening on {ep} (not loopback) needs credentials: make them with "
                "mm-beagle-agent --make-credentials FILE and pass --credentials FILE "
                f"({link.CREDENTIALS_HELP})"
            )
    if values["credentials"]:
        link.load_credentials(values["credentials"])
    sim = SimConfig(
        trajectory=values["sim_trajectory"],
        speed=values["sim_speed"],
        noise_counts=values["sim_noise_counts"],
        lift_rate=values["sim_lift_rate"],
        fail_windows=list(values["sim_fail_windows"]),
        start_delay=values["sim_start_delay"],
        duration=values["sim_duration"],
        loop=values["sim_loop"],
        chips=list(values["sim_chips"]),
        low_quality_rate=values["sim_low_quality_rate"],
    )
    if not (0 <= sim.start_delay <= 3600 and 0 <= sim.duration <= 1e6):
        raise ValueError("'sim_start_delay' must be 0..3600 s and 'sim_duration' 0..1e6 s")
    parse_fail_windows(sim.fail_windows, devices)
    if values["backend"] == "sim":
        check_trajectory(sim.trajectory)
    ring = round(values["ring_seconds"] * values["poll_rate"])
    cfg = poller_config(values, ring, sim)
    if values["backend"] == "sim":
        from mm_beagle.poller.sim_backend import sim_chips

        sim_chips(cfg)
    return AgentConfig(cfg, values["name"], values["listen"], values["credentials"])


def self_test_report(poller: AgentPoller, seconds: float, cpu_s: float) -> dict:
    """The self-test's one JSON object: rate, CPU per poll, conservation, memory."""
    polls = int(poller.state.glob_view[ss.G_POLLS])
    generated: int | None = 0
    lost: int | None = 0
    for ch in poller.channels:
        t = poller.state.snapshot(ch.i)
        generated += abs(t.gen_x) + abs(t.gen_y)
        lost += abs(t.gen_x - t.x_total) + abs(t.gen_y - t.y_total)
    if any(ch.sim_stats is None for ch in poller.channels):
        generated = lost = None  # no emulator ground truth (spidev, the benchmark's stub)
    return {
        "polls": polls,
        "seconds": round(seconds, 3),
        "rate_hz": round(polls / seconds, 1) if seconds > 0 else 0.0,
        "cpu_us_per_poll": round(cpu_s / polls * 1e6, 2) if polls else None,
        "counts_generated": generated,
        "counts_lost": lost,
        "rss_mb": round(rss_mb(), 2),
        "sensors": len(poller.channels),
        "backend": poller.cfg.backend,
        "link_bytes_sent": poller.link.bytes_sent if poller.link else 0,
        "imports_numpy": "numpy" in sys.modules,
        "machine": os.uname().machine,
    }


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.make_credentials:
        try:
            path = link.make_credentials(args.make_credentials)
        except (link.LinkError, OSError) as exc:
            print(f"mm-beagle-agent: error: {exc}", file=sys.stderr)
            return EXIT_CONFIG
        print(f"wrote {path} (mode 600); copy it to the ROS machine for agent_credentials")
        return 0
    try:
        cfg = config_from_args(args)
        state = make_state(cfg.poller)
        poller = AgentPoller(cfg.poller, state)
    except Exception as exc:  # configuration: a message and exit 2, never a traceback
        print(f"mm-beagle-agent: error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    try:
        import zenoh

        session = zenoh.open(link.zenoh_config(listen=cfg.listen, credentials=cfg.credentials))
    except ImportError:
        print(
            "mm-beagle-agent: error: the eclipse-zenoh package is missing; "
            "install it with: pip install 'eclipse-zenoh>=1.5,<2'",
            file=sys.stderr,
        )
        return EXIT_CONFIG
    except Exception as exc:
        print(f"mm-beagle-agent: error: cannot listen on {cfg.listen}: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    poller.link = AgentLink(session, cfg.name, poller)
    if args.bench_stub:
        for dev, bus in list(poller.sim_buses.items()):
            poller.sim_buses[dev] = StubMotionBus(bus, poller.regmap)
    stop = lambda *_: setattr(poller, "running", False)  # noqa: E731
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    note = tune_process(cfg.poller.realtime_priority, parent_death=False)
    print(
        f"mm-beagle-agent: polling {', '.join(cfg.poller.devices)} at "
        f"{cfg.poller.poll_rate:g} Hz (backend {cfg.poller.backend}); serving mm/{cfg.name} "
        f"on {', '.join(cfg.listen)}{' with credentials' if cfg.credentials else ''}; {note}",
        file=sys.stderr,
        flush=True,
    )
    t0, c0 = time.monotonic(), time.process_time()
    try:
        if args.self_test:
            signal.signal(signal.SIGALRM, stop)
            signal.setitimer(signal.ITIMER_REAL, args.self_test)
        poller.run(paced=not args.bench_stub or args.bench_paced)
    finally:
        seconds, cpu = time.monotonic() - t0, time.process_time() - c0
        poller.link.close()
        session.close()
    if args.self_test:
        print(json.dumps(self_test_report(poller, seconds, cpu)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
