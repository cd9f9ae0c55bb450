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

from mm_beagle.link import link, link_auth, link_checks, zenoh_config
from mm_beagle.link.agent import (
    AgentLink,
    AgentPoller,
    StubMotionBus,
    make_state,
    rss_mb,
)
from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.options import (
    OPTIONS,
    Option,
    check_ranges,
    option_bounds,
    poller_config_from,
)
from mm_beagle.poller.poller import PollerConfig, tune_process
from mm_beagle.poller.sim_backend import parse_sim_mounts
from mm_beagle.poller.sim_channel import truth_of
from mm_pc.core.user_file import read_user_text
from mm_pc.core.yaml_text import parse_yaml

EXIT_CONFIG = 2
MIN_RING_S = 60.0
MAX_RING_S = 600.0
#: the poll ring's memory (every sensor's): 20000 s took 776 MB; a BBB has 512 MB in all
MAX_RING_BYTES = 32 << 20
MAX_CONFIG_BYTES = 1 << 20
MAX_SELF_TEST_S = 3600.0
#: glibc malloc arenas: one per thread by default (8 zenoh and agent threads); two keep
#: the agent's RSS under attack 1.5 MB lower (issue 27 item 2). MALLOC_ARENA_MAX overrides.
MALLOC_ARENAS = 2
#: with a real-time poll thread, every other thread of the agent (zenoh's, the workers, the
#: sender) runs SCHED_FIFO at this priority: one holding the GIL is then never preempted by
#: a normal process while the poll thread waits for it (gaps of 50-70 ms at load 9 before)
HELPER_PRIORITY = 1
#: the longest another thread keeps the GIL while the poll thread asks for it (CPython: 5 ms)
SWITCH_INTERVAL_S = 0.001


@dataclass
class AgentConfig:
    """What main needs: the poller's configuration and the zenoh side's."""

    poller: PollerConfig
    name: str = link.DEFAULT_NAME
    listen: list[str] = field(default_factory=lambda: [link.DEFAULT_ENDPOINT])
    credentials: str = ""


#: the agent's own options (the poller's are mm_beagle.poller.options.OPTIONS)
AGENT_OPTIONS = {
    o.name: o
    for o in (
        Option(
            "ring_seconds",
            65.536,
            "single polls kept (s); at least the link's replay window",
            lo=MIN_RING_S,
            hi=MAX_RING_S,
            unit=" s (at least the link's replay window)",
        ),
        Option(
            "name",
            link.DEFAULT_NAME,
            f"key prefix mm/NAME: 1..{link_checks.MAX_NAME} letters, digits, _ . -",
        ),
        Option("listen", [link.DEFAULT_ENDPOINT], "zenoh endpoints to listen on"),
        Option("credentials", "", "user:password file (mode 600) peers must present"),
        Option(
            "sim_mounts",
            "",
            "backend sim: where the emulated sensors sit, 'X,Y,YAW;X,Y,YAW' (m, m, degrees "
            "in base_link, one per device; mm-monitor --sim-mounts); '' = as designed",
        ),
    )
}
ALL_OPTIONS = {**OPTIONS, **AGENT_OPTIONS}
DEFAULTS = {name: o.default for name, o in ALL_OPTIONS.items()}


def _names(text: str) -> list[str]:
    """``"pmw3360,pln2033"`` -> ["pmw3360", "pln2033"]."""
    return chip_config.split_names([text])


def _help(o: Option, text: str = "") -> str:
    """An option's help: ``text`` or its description, with its range and default."""
    extra = [bounds] if (bounds := option_bounds(o)) else []
    if o.default not in ("", []):
        d = o.default
        extra.append(f"default {' '.join(d) if isinstance(d, list) else d}")
    return f"{text or o.description}" + (f" [{', '.join(extra)}]" if extra else "")


def _add(p: argparse.ArgumentParser, name: str, text: str = "", **kw) -> None:
    """``--name`` typed after the option's default, with help from the option table."""
    o = ALL_OPTIONS[name]
    d = o.default
    if isinstance(d, bool):
        kw.setdefault("action", argparse.BooleanOptionalAction)
    elif isinstance(d, list):
        kw.setdefault("nargs", "*")
    elif isinstance(d, (int, float)):
        kw.setdefault("type", type(d))
    if o.choices:
        kw.setdefault("choices", o.choices)
    p.add_argument("--" + name.replace("_", "-"), help=_help(o, text), **kw)


def build_parser() -> argparse.ArgumentParser:
    """The agent's options: every one of the option tables, and the actions."""
    p = argparse.ArgumentParser(
        prog="mm-beagle-agent",
        description="Poll the mouse sensors (PLN2033, PMW3360, ...) at 1 kHz and serve them "
        "over zenoh (no ROS). "
        "On the ROS machine: mm-beagle --ros-args -p backend:=remote -p agent:=ENDPOINT",
    )
    p.add_argument("--config", help="YAML file with any of these options (dashes as _)")
    special = {
        "devices": dict(nargs="+"),
        "chips": dict(
            type=_names,
            nargs=None,
            text="chip of each device, comma-separated, or one for all (default pln2033); "
            f"allowed: {chip_config.chips_help()}",
        ),
        "sim_chips": dict(
            type=_names, nargs=None, text="emulated chip per device (default --chips)"
        ),
        "patch_file": dict(text="vendor patch code loaded at every bring-up (in --patch-dir)"),
        "patch_dir": dict(
            text="the only directory patch files are loaded from, at start or by a peer's "
            "load_patch command ('' = patch loading off)"
        ),
        "srom_file": dict(
            text="SROM for PMW3360/PMW3389 devices, loaded at every bring-up (in --patch-dir)"
        ),
        "listen": dict(
            action="append",
            nargs=None,
            text="zenoh endpoint to listen on (repeatable); anything but loopback needs "
            "--credentials",
        ),
    }
    for name in ALL_OPTIONS:
        _add(p, name, **special.get(name, {}))
    p.add_argument("--make-credentials", metavar="FILE", help="write a new credentials file")
    p.add_argument("--self-test", type=float, metavar="SECONDS", help="run, print one JSON line")
    # mm-bench agent: the motion burst answered by a constant stub, flat out unless paced
    p.add_argument("--bench-stub", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--bench-paced", action="store_true", help=argparse.SUPPRESS)
    return p


def _load_yaml(path: str) -> dict:
    """The config file's options: a regular file of at most 1 MiB (a FIFO would block the
    start, /dev/zero never end), YAML in one line's message (what, line, column)."""
    try:
        text = read_user_text(path, MAX_CONFIG_BYTES)
    except OSError as exc:
        raise ValueError(f"cannot read config file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ValueError(f"config file {path} is not a text file (UTF-8 YAML)") from None
    try:
        data = parse_yaml(text) or {}
    except ValueError as exc:
        raise ValueError(f"config file {path}: {exc}") from None
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
        raise ValueError(f"'{name}' must be {want.__name__}, got {_short(value)}")
    return value


def _short(value: object) -> str:
    """A value for a one-line message: at most 60 characters of its repr."""
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:40]}... ({len(text)} characters)"


def ring_problem(ring_seconds: float, poll_rate: float, sensors: int) -> str:
    """Why a poll ring of ``ring_seconds`` at ``poll_rate`` Hz for ``sensors`` does not fit
    :data:`MAX_RING_BYTES` ('' if it does)."""
    polls = round(ring_seconds * poll_rate)
    need = ss.SharedState.size(sensors, polls)
    if need <= MAX_RING_BYTES:
        return ""
    return (
        f"'ring_seconds' {ring_seconds:g} s at {poll_rate:g} Hz for {sensors} sensors needs "
        f"{need / 2**20:.0f} MiB of poll ring; at most {MAX_RING_BYTES >> 20} MiB "
        "(lower ring_seconds or poll_rate)"
    )


def self_test_problem(seconds: float | None) -> str:
    """Why ``--self-test SECONDS`` cannot run ('' if it can, or was not given)."""
    if seconds is None or 0 < seconds <= MAX_SELF_TEST_S:  # NaN fails both
        return ""
    return f"--self-test must be more than 0 and at most {MAX_SELF_TEST_S:g} s, got {seconds:g}"


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
    check_ranges(ALL_OPTIONS, values)
    if problem := ring_problem(
        values["ring_seconds"], values["poll_rate"], max(1, len(values["devices"]))
    ):
        raise ValueError(problem)
    link_checks.check_link_settings(
        values["name"], values["listen"], "listen", values["credentials"]
    )
    ring = round(values["ring_seconds"] * values["poll_rate"])
    mounts = parse_sim_mounts(values["sim_mounts"], list(values["devices"]))
    if mounts and values["backend"] != "sim":
        raise ValueError("'sim_mounts' goes with backend sim (it mounts emulated sensors)")
    cfg = poller_config_from(values, ring, mounts)
    if problem := link_checks.patch_dir_problem(values["patch_dir"]):  # no patch_file named
        raise ValueError(problem)
    link.keys(values["name"])
    for ep in values["listen"]:
        if not zenoh_config.is_loopback(ep) and not values["credentials"]:
            raise ValueError(
                f"listening on {ep} (not loopback) needs credentials: make them with "
                "mm-beagle-agent --make-credentials FILE and pass --credentials FILE "
                f"({link_auth.CREDENTIALS_HELP})"
            )
    if values["credentials"]:
        link_auth.load_credentials(values["credentials"])
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
        "cpu_us_per_poll_poll_thread": round(poller.run_thread_cpu_s / polls * 1e6, 2)
        if polls
        else None,
        "counts_generated": generated,
        "counts_lost": lost,
        "rss_mb": round(rss_mb(), 2),
        "sensors": len(poller.channels),
        "backend": poller.cfg.backend,
        "link_bytes_sent": poller.link.bytes_sent if poller.link else 0,
        "imports_numpy": "numpy" in sys.modules,
        "machine": os.uname().machine,
    }


def limit_malloc_arenas(arenas: int = MALLOC_ARENAS) -> bool:
    """mallopt(M_ARENA_MAX, ``arenas``) before any thread starts, unless MALLOC_ARENA_MAX
    is set; False where there is no glibc mallopt."""
    if "MALLOC_ARENA_MAX" in os.environ:
        return False
    import ctypes

    try:
        return ctypes.CDLL(None).mallopt(-8, arenas) == 1  # M_ARENA_MAX (malloc.h)
    except (OSError, AttributeError):
        return False


def realtime_helpers(priority: int) -> bool:
    """Before any thread starts: this thread SCHED_FIFO at :data:`HELPER_PRIORITY` (below the
    poll thread's ``priority``), inherited by every thread started after it; the poll
    thread is raised to ``priority`` by tune_process. False if not allowed or not asked."""
    if priority <= HELPER_PRIORITY:
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(HELPER_PRIORITY))
    except (PermissionError, OSError, AttributeError):
        return False
    return True


def _joined(argv: list[str]) -> list[str]:
    """``--sim-mounts VALUE`` as ``--sim-mounts=VALUE``: argparse takes a value starting with
    '-' (a mount behind base_link, "-0.05,0,0") for an option otherwise."""
    out = list(argv)
    for k, arg in enumerate(out[:-1]):
        if arg == "--sim-mounts":
            out[k : k + 2] = [f"--sim-mounts={out[k + 1]}"]
            break
    return out


def main(argv: list[str] | None = None) -> int:
    limit_malloc_arenas()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    parser = build_parser()
    args = parser.parse_args(_joined(sys.argv[1:] if argv is None else argv))
    if problem := self_test_problem(args.self_test):
        print(f"mm-beagle-agent: error: {problem}", file=sys.stderr)
        return EXIT_CONFIG
    if args.make_credentials:
        try:
            path = link_auth.make_credentials(args.make_credentials)
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
    helpers_rt = realtime_helpers(cfg.poller.realtime_priority)
    try:
        import zenoh

        session = zenoh.open(zenoh_config.agent_zenoh_config(cfg.listen, cfg.credentials))
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
    poller.link = AgentLink(session, cfg.name, poller, credentials=cfg.credentials)
    if args.bench_stub:
        for dev, bus in list(poller.sim_buses.items()):
            poller.sim_buses[dev] = StubMotionBus(bus, poller.regmap)
    stop = lambda *_: setattr(poller, "running", False)  # noqa: E731
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    note = tune_process(cfg.poller.realtime_priority, parent_death=False)
    if helpers_rt:
        note += f", other threads SCHED_FIFO priority {HELPER_PRIORITY}"
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
