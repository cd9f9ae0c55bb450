"""mm-beagle-agent's command line: options, the YAML config file, their checks, and main.

Defaults <- ``--config`` file <- command line, checked before anything opens: a bad
option is one line on stderr and exit 2, never a traceback. The server itself
(:class:`~mm_beagle.link.agent.AgentLink`, the poller on the board) is
:mod:`mm_beagle.link.agent`.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field

from mm_beagle.link import link
from mm_beagle.link.agent import AgentLink, AgentPoller, StubMotionBus, make_state, rss_mb
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import PollerConfig, poller_config, tune_process
from mm_beagle.poller.sim_backend import SimConfig, check_trajectory, parse_fail_windows
from mm_beagle.poller.sim_channel import truth_of

EXIT_CONFIG = 2
MIN_RING_S = 60.0


@dataclass
class AgentConfig:
    """What main needs: the poller's configuration and the zenoh side's."""

    poller: PollerConfig
    name: str = link.DEFAULT_NAME
    listen: list[str] = field(default_factory=lambda: [link.DEFAULT_ENDPOINT])
    credentials: str = ""


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
    if any(truth_of(ch) is None for ch in poller.channels):
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
