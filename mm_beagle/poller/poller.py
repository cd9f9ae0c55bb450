"""The 1 kHz poller: its own process, no ROS.

A Python thread sharing the GIL with the rclpy executor was measured at a p99
period of 6 ms under load; a separate process at about 1.1 ms. So the
poller runs in a process of its own (spawned, so it inherits nothing of
rclpy), owns the SPI devices, and publishes into :mod:`shared_state`.

Each device has its chip (``chips``, :mod:`mm_beagle.poller.chip_config`) and its
:class:`~mm_beagle.poller.channel.Channel`: a PLN2033 keeps the hand-tuned hot path there;
any other driver is polled through ``read_motion()`` and the general ``Channel.record``,
which also stores the chip's quality figure per poll and treats a poll below the chip's
threshold like a lift (its counts stay in the measured
totals, as a lifted poll's do; it is a gap poll for the lift estimate).

Per poll and sensor it reads status + delta X + delta Y in one transfer, adds
the counts to monotone totals (counts and metres at the CPI in force), stores
the poll in the ring buffer, and estimates the counts lost to lifts. Between
polls it serves commands from the node over a pipe (settings read, CPI
change), always folding the displacement a command's status read returns
into the totals -- a settings read never eats counts.
"""

from __future__ import annotations

import ctypes
import operator
import os
import signal
import time
import traceback
from collections import Counter
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from itertools import repeat
from typing import TYPE_CHECKING, cast

from mm_beagle.poller import chip_config, commands
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.channel import Bus, Channel, no_clock
from mm_beagle.poller.patches import patch_load_steps, resolve_patch_file
from mm_beagle.poller.sim_backend import SimConfig
from pln2033 import SensorError
from pln2033 import chips as registry
from pln2033.errors import FirmwareError, InvalidCpiError
from pln2033.pln2033 import PLN2033, RegisterMap
from pln2033.sensor import ChipInfo, SensorDriver

if TYPE_CHECKING:  # multiprocessing.connection: 1.1 MB RSS on the agent for annotations
    from multiprocessing.connection import Connection

    from pln2033.bus import SpiBus

ERRORS_BEFORE_DOWN = 3  # consecutive failed polls before a sensor is declared down
HEALTH_CHECK_S = 1.0  # how often the CPI is read back to catch a chip that reset itself


@dataclass
class PollerConfig:
    devices: list[str]
    backend: str = "spidev"  # "spidev" | "sim"
    cpi: int = 1600
    poll_rate: float = 1000.0
    spi_speed_hz: int = 3_000_000
    register_map: str = ""
    patch_file: str = ""  # resolved inside patch_dir (see patches.py), '' = none
    patch_dir: str = ""  # where patch files may come from ('' = patch loading off)
    chips: list[str] = field(default_factory=list)  # one per device, one for all, [] = pln2033
    chip_options: dict[str, object] = field(default_factory=dict)  # see chip_config
    srom_file: str = ""  # SROM for chips whose firmware is "srom", inside patch_dir
    # per-device driver options (the OTOS's scalars and offset from calibration_file);
    # chip_options given explicitly win over them
    device_options: dict[str, dict[str, object]] = field(default_factory=dict)
    realtime_priority: int = 0
    retry_interval: float = 1.0
    ring_size: int = 65536
    sim: SimConfig = field(default_factory=SimConfig)


COMMON_FIELDS = (
    "devices",
    "backend",
    "cpi",
    "poll_rate",
    "spi_speed_hz",
    "register_map",
    "patch_file",
    "patch_dir",
    "realtime_priority",
    "retry_interval",
    "chips",
    "chip_options",
)


def poller_config(values: dict, ring_size: int, sim: SimConfig) -> PollerConfig:
    """A PollerConfig from checked settings named as its fields (the node's, the agent's).

    Raises ValueError (PatchPathError) when patch_file is not a file inside patch_dir."""
    common = {k: values[k] for k in COMMON_FIELDS}
    common["patch_file"] = resolve_patch_file(values["patch_dir"], values["patch_file"])
    common["srom_file"] = resolve_patch_file(values["patch_dir"], values.get("srom_file", ""))
    return PollerConfig(**common, ring_size=ring_size, sim=sim)


def _open_bus(dev: str, cfg: PollerConfig, info: ChipInfo) -> Bus:
    """The real bus of one device, in its chip's SPI mode, clock capped to its maximum."""
    if info.bus == "i2c":  # /dev/i2c-N through smbus2's i2c_rdwr (the OTOS)
        from pln2033.i2c import Smbus2Bus

        return Smbus2Bus(dev)
    from pln2033.bus import SpidevBus

    speed, _note = chip_config.spi_speed(info, cfg.spi_speed_hz)
    return SpidevBus(dev, speed, mode=info.spi_mode)


class Poller:
    def __init__(
        self,
        cfg: PollerConfig,
        state: ss.SharedState,
        commands: Connection,
        events: Connection,
    ) -> None:
        self.cfg = cfg
        self.state = state
        self.commands = commands
        self.events = events
        self.regmap = (
            RegisterMap.load(cfg.register_map) if cfg.register_map else RegisterMap.default()
        )
        self.chips, self.notes = chip_config.check_board_config(
            cfg.devices, cfg.chips, cfg.chip_options, cfg.cpi, cfg.register_map
        )
        channel_class = Channel
        if cfg.backend == "sim":  # its channels also keep the emulator's ground truth
            from mm_beagle.poller.sim_channel import SimChannel

            channel_class = SimChannel
        self.channels = [
            channel_class(i, d, state, cfg.ring_size, chip, self._info(chip))
            for i, (d, chip) in enumerate(zip(cfg.devices, self.chips, strict=True))
        ]
        # firmware per chip type: the PLN2033's patch, the PMW33xx's SROM
        self.firmware: dict[str, list[int] | None] = {}
        for chip in sorted(set(self.chips)):
            info = self._info(chip)
            path, note = chip_config.firmware_source(info, cfg.patch_file, cfg.srom_file)
            self.firmware[chip] = chip_config.read_firmware(info, path)
            if note:
                self.notes.append(note)
            if info.bus == "spi":
                _speed, note = chip_config.spi_speed(info, cfg.spi_speed_hz)
                if note and cfg.backend == "spidev":
                    self.notes.append(note)
        self.driver_extra: dict[str, object] = {}  # tests: e.g. sleep on a fake clock
        self.t0 = time.monotonic()
        self.sim_buses: dict[str, Bus] = self._sim_buses() if cfg.backend == "sim" else {}
        self.running = True
        self.commands_seen = 0

    def _info(self, chip: str) -> ChipInfo:
        if chip == registry.DEFAULT_CHIP:
            from pln2033.pln2033 import pln2033_info

            return pln2033_info(self.regmap)
        return registry.chip_info(chip)

    @property
    def patch(self) -> list[int] | None:
        """The PLN2033's patch code (loaded at every bring-up)."""
        return self.firmware.get(registry.DEFAULT_CHIP)

    @patch.setter
    def patch(self, words: list[int] | None) -> None:
        self.firmware[registry.DEFAULT_CHIP] = words

    def make_driver(self, ch: Channel) -> SensorDriver:
        """The driver of ``ch``'s chip on its bus, with the chip options it takes."""
        if ch.fast:  # an SPI chip: its bus is one
            return PLN2033(cast("SpiBus", ch.bus), self.regmap, name=ch.device)
        opts = {
            **self.cfg.device_options.get(ch.device, {}),
            **chip_config.options_for(ch.chip, {**self.cfg.chip_options, **self.driver_extra}),
        }
        return registry.make_driver(ch.chip, ch.bus, ch.device, **opts)

    def _sim_buses(self) -> dict[str, Bus]:
        from mm_beagle.poller.sim_backend import make_sim_buses

        return make_sim_buses(self.cfg, self.t0)

    # --- events to the node ---

    def emit(self, kind: str, *args: object) -> None:
        try:
            self.events.send((kind, *args))
        except (BrokenPipeError, OSError):
            self.running = False

    # --- bring-up and recovery ---

    def try_init(self, ch: Channel, now: float) -> None:
        ch.ints[ss.I_STATE] = ss.STATE_STARTING
        try:
            if ch.bus is None:
                ch.bus = self.sim_buses.get(ch.device) or _open_bus(ch.device, self.cfg, ch.info)
            driver = self.make_driver(ch)
            if ch.info.cpi.fixed:
                ch.cpi_wanted = driver.info.cpi.min
            else:
                ch.cpi_wanted = ch.cpi_wanted or self.cfg.cpi
            driver.initialise(ch.cpi_wanted, self.firmware.get(ch.chip))
            ch.set_cpi_cache(*driver.get_cpi())
            driver.read_motion()  # start-up counts are dropped
        except (SensorError, ValueError, OSError) as exc:
            self.mark_down(ch, now, f"start-up failed: {exc}")
            return
        ch.attach(driver)
        ch.consecutive_errors = 0
        ch.ints[ss.I_REINITS] += 1
        ch.ints[ss.I_STATE] = ss.STATE_UP
        self.emit("up", ch.device, f"{ch.info.title} initialised at {ch.cpi_x} CPI")

    def mark_down(self, ch: Channel, now: float, why: str) -> None:
        changed = ch.driver is not None or why != ch.last_error
        ch.attach(None)
        ch.ints[ss.I_STATE] = ss.STATE_DOWN
        ch.next_retry = now + self.cfg.retry_interval
        if changed:
            self.emit("down", ch.device, f"{why}; retrying every {self.cfg.retry_interval:g} s")
        ch.last_error = why

    # --- polling ---

    def poll(self, ch: Channel, stamp_ns: int, now: float) -> None:
        """Poll one sensor once; count errors, declare it down, or bring it up again.

        After a failed poll the CPI is read back before the next poll's counts are taken
        (:meth:`check_health`): a glitch of one or two polls can be a chip that reset
        itself, whose counts since are at its default CPI; it is re-initialised (its counts
        dropped, the reset reported) instead of those counts being scaled by the old CPI
        until the next periodic check."""
        if ch.driver is None:
            if now >= ch.next_retry:
                self.try_init(ch, now)
            return
        if ch.consecutive_errors:
            driver = ch.driver
            self.check_health(ch, now)
            if ch.driver is not driver:  # it had reset: re-initialised (or down) meanwhile
                return
        try:
            ch.poll(stamp_ns, no_clock)
        except SensorError as exc:
            self.poll_failed(ch, stamp_ns, now, exc)
            return
        ch.consecutive_errors = 0
        ch.ok = True

    def poll_failed(self, ch: Channel, stamp_ns: int, now: float, exc: Exception) -> None:
        """Record a failed poll; the third in a row declares the sensor down."""
        ch.ok = False
        ch.ints[ss.I_SPI_ERRORS] += 1
        ch.consecutive_errors += 1
        ch.record(stamp_ns, None)
        if ch.consecutive_errors >= ERRORS_BEFORE_DOWN:
            if self.cfg.backend == "spidev" and ch.bus is not None:
                ch.bus.close()
                ch.bus = None  # reopen the device on the next try
            self.mark_down(ch, now, f"{ch.consecutive_errors} polls failed: {exc}")

    def _resync_cpi(self, ch: Channel) -> None:
        """After a failed command the chip may be half-changed: take its CPI as it is."""
        if ch.driver is None:
            return
        try:
            ch.set_cpi_cache(*ch.driver.get_cpi())
        except SensorError:
            self.mark_down(ch, time.monotonic(), "CPI unknown after a failed command")

    def check_health(self, ch: Channel, now: float) -> None:
        """Read the CPI back: a chip that lost power mid-run comes back at its default.

        Its counts since the last poll are gone either way; re-initialising at
        once keeps the next counts at the right scale (and reloads the patch).
        """
        if ch.driver is None:
            return
        try:
            x, y = ch.driver.get_cpi()
        except SensorError:
            return  # the polls count SPI errors; they decide about "down"
        if (x, y) != (ch.cpi_x, ch.cpi_y):
            self.mark_down(ch, now, f"the sensor reset itself (CPI reads {x}/{y}, set {ch.cpi_x})")
            self.try_init(ch, now)

    # --- commands from the node ---

    def serve_command(self, msg: tuple) -> tuple[str, object]:
        """One command from the node's pipe, ``(name, sensor index, *args)``
        (:mod:`~mm_beagle.poller.commands`): ``(status, payload)``.

        A malformed tuple (no sensor index, missing arguments) raises: the caller
        answers "error" and logs the traceback."""
        kind = msg[0]
        cmd = commands.COMMANDS.get(kind)
        if cmd is not None and cmd.pipe and not cmd.sensor:
            return self._serve(kind)(*msg[1:])
        ch = self.channels[msg[1]]
        if cmd is None or not cmd.pipe:
            return (commands.ERROR, commands.unknown_command(kind))
        driver = ch.driver
        if driver is None:
            return (commands.ERROR, commands.sensor_down(ch.device, ch.last_error))
        try:
            return self._serve(kind)(ch, driver, *msg[2:])
        except InvalidCpiError as exc:
            return (commands.INVALID, str(exc))
        except SensorError as exc:
            ch.ints[ss.I_SPI_ERRORS] += 1
            self._resync_cpi(ch)
            return (commands.ERROR, f"sensor {ch.device}: {exc}")

    def _serve(self, kind: str) -> Callable[..., tuple[str, object]]:
        """The handler of command ``kind``: the method ``_command_<kind>``."""
        return getattr(self, f"_command_{kind}")

    def _command_stop(self) -> tuple[str, object]:
        self.running = False
        return (commands.OK, None)

    def _command_settings(self, ch: Channel, driver: SensorDriver) -> tuple[str, object]:
        """The register dump; the counts its status read returns go into the totals."""
        motion, regs = driver.read_all_registers()
        ch.record(time.time_ns(), motion, ss.FLAG_COMMAND_READ)
        cpi = ch.info.cpi
        return (
            commands.OK,
            {
                "chip": ch.chip,
                "registers": regs,
                "cpi_x": ch.cpi_x,
                "cpi_y": ch.cpi_y,
                "cpi_range": [cpi.min, cpi.max, cpi.step],
                "lifted": motion.lifted,
                "motion": motion.moved,
            },
        )

    def _command_set_cpi(
        self, ch: Channel, driver: SensorDriver, cpi: object
    ) -> tuple[str, object]:
        problem = driver.cpi_problem(cpi)
        if problem or not isinstance(cpi, int):  # the chip's check refuses a non-integer
            return (commands.INVALID, f"{ch.device} ({ch.chip}): {problem}")
        # The driver drains the counters in the CPI write's own transfer: every count made
        # at the old CPI is recorded at it, none falls between the drain and the write.
        driver.set_cpi(cpi, on_drain=lambda m: ch.record(time.time_ns(), m, ss.FLAG_COMMAND_READ))
        ch.cpi_wanted = cpi
        ch.set_cpi_cache(*driver.get_cpi())
        return (commands.OK, ch.cpi_y)

    def _command_load_patch(
        self, ch: Channel, driver: SensorDriver, words: list[int]
    ) -> tuple[str, object]:
        if ch.info.firmware != "patch":
            return (commands.INVALID, commands.takes_no_patch(ch.device, ch.info.title))
        try:
            driver.check_firmware(words)  # the PLN2033's firmware: its patch code
        except FirmwareError as exc:
            return (commands.INVALID, str(exc))
        driver.load_firmware(words)  # writes, verifies, enables
        self.patch = list(words)  # re-initialisations load it too
        return (commands.OK, len(words))

    def load_patch_steps(
        self, i: int, words: list[int]
    ) -> Generator[None, None, tuple[str, object]]:
        """load_patch on sensor ``i`` in steps (:func:`~mm_beagle.poller.patches.patch_load_steps`):
        the caller polls between two ``next()``; the generator's value is ``(status, payload)``
        as :meth:`serve_command` answers. A sensor re-initialised meanwhile ends it with an
        error (its bring-up loaded the previous patch)."""
        ch = self.channels[i]
        driver = ch.driver
        if driver is None:
            return (commands.ERROR, commands.sensor_down(ch.device, ch.last_error))
        if ch.info.firmware != "patch":
            return (commands.INVALID, commands.takes_no_patch(ch.device, ch.info.title))
        try:
            driver.check_firmware(words)
        except FirmwareError as exc:
            return (commands.INVALID, str(exc))
        try:
            for _ in patch_load_steps(cast(PLN2033, driver), words):
                yield
                if ch.driver is not driver:
                    return (
                        commands.ERROR,
                        f"sensor {ch.device} was re-initialised during the patch load "
                        "(with the previous patch): load it again",
                    )
        except SensorError as exc:  # the bus, or the read-back differs
            ch.ints[ss.I_SPI_ERRORS] += 1
            self._resync_cpi(ch)
            return (commands.ERROR, f"sensor {ch.device}: {exc}")
        self.patch = list(words)  # re-initialisations load it too
        return (commands.OK, len(words))

    def handle_commands(self) -> None:
        conn = self.commands
        while conn.poll():
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                self.running = False  # the node is gone
                return
            try:
                reply = self.serve_command(msg)
            except Exception as exc:  # never let one bad command kill the poller
                reply = ("error", f"poller failed on {msg[0]!r}: {exc!r}")
                self.emit("log", traceback.format_exc())
            conn.send(reply)

    def service(self) -> None:
        """Work between polls every ``service_period`` s: the node's commands here.

        The agent overrides it to serve its link.
        """
        glob = self.state.glob_view
        if glob[ss.G_COMMANDS_SENT] != self.commands_seen:
            self.commands_seen = glob[ss.G_COMMANDS_SENT]
            self.handle_commands()

    service_period = 0.002

    def run(self, max_polls: int = 0, paced: bool = True) -> None:
        """Poll every sensor at ``poll_rate`` until stopped (or ``max_polls``, for benchmarks).

        ``paced=False`` polls flat out (benchmarks: CPU per poll). A late loop
        skips the missed slots instead of bursting. The common case (every sensor up, last
        poll good) costs one attribute test per sensor besides the poll itself, and one
        list append per tick: the ticks' times are turned into the period histogram
        (1 us bins), the late count, the poll count and the period sum at each service
        (:meth:`_flush_ticks`), not per poll.
        """
        cfg = self.cfg
        glob = self.state.glob_view
        wall_ns, sleep = time.time_ns, time.sleep
        period_ns = round(1e9 / cfg.poll_rate)
        now = time.monotonic()
        for ch in self.channels:
            self.try_init(ch, now)
        glob[ss.G_RUNNING] = 1
        clock = time.perf_counter_ns
        next_t = clock()
        health_ns = int(HEALTH_CHECK_S * 1e9)
        service_ns = int(self.service_period * 1e9)
        next_health = next_t + health_ns
        next_service = next_t + service_ns
        channels = self.channels
        poll, failed = self.poll, self.poll_failed
        ticks: list[int] = []  # the ticks' times since the last service
        tick = ticks.append
        last = 0  # the tick before those (0: none yet)
        polls = 0
        # wall-clock stamps as the poll clock plus an offset taken again at every service:
        # one clock read per poll (both clocks are slewed alike by NTP; a step of the wall
        # clock reaches the stamps at the next service)
        wall_off = wall_ns() - clock()
        fast = self._fast_polls()
        while self.running:
            # each sensor stamped at its own transfer (Channel.poll reads the clock right
            # before it): they are read ~20 us apart, and the pose math moves each later one
            # back to the first one's time (mm_pc.core.polls.deskew: 1 us left over is
            # 0.06 mm per 10 m at 0.5 m/s for two-sensor); the tick's time is the first's
            t = 0
            if fast:  # every sensor up, its last poll good: their polls, taken once
                for ch, ch_poll in fast:
                    try:
                        s = ch_poll(wall_off)
                    except SensorError as exc:
                        s = clock()
                        failed(ch, s + wall_off, s / 1e9, exc)
                        fast = ()  # the general case below until all are good again
                    t = t or s
            else:
                for ch in channels:
                    if ch.ok:
                        try:
                            s = ch.poll(wall_off)
                        except SensorError as exc:
                            s = clock()
                            failed(ch, s + wall_off, s / 1e9, exc)
                    else:
                        s = clock()
                        poll(ch, s + wall_off, s / 1e9)
                    t = t or s
                fast = self._fast_polls()
            tick(t)
            polls += 1
            if t >= next_service:
                last = self._flush_ticks(ticks, last, period_ns)
                next_service = t + service_ns
                self.service()
                wall_off = wall_ns() - clock()
                if t >= next_health:
                    next_health = t + health_ns
                    for ch in channels:
                        self.check_health(ch, t / 1e9)
                fast = self._fast_polls()  # a command or check may have re-attached one
            if polls == max_polls:
                break
            if not paced:
                continue
            next_t += period_ns
            t = clock()
            if next_t <= t:  # fell behind: skip the missed slots instead of bursting
                missed = (t - next_t) // period_ns + 1
                glob[ss.G_OVERRUNS] += missed
                next_t += missed * period_ns
            sleep((next_t - t) / 1e9)
        self._flush_ticks(ticks, last, period_ns)
        self.service()
        glob[ss.G_RUNNING] = 0

    def _fast_polls(self) -> tuple[tuple[Channel, Callable[[int], int]], ...]:
        """Each channel with its ``poll`` while every one is up and its last poll was good,
        else (): the run loop's common case without two attribute reads per sensor. A
        channel's ``ok`` and ``poll`` change only in a failed poll, the run loop's general
        case or a service (commands, health checks): the loop takes this again after each."""
        chans = self.channels
        if all(ch.ok for ch in chans):
            return tuple((ch, ch.poll) for ch in chans)
        return ()

    def _flush_ticks(self, ticks: list[int], last: int, period_ns: int) -> int:
        """The ticks' times (perf counter, ns; ``last``: the tick before them, 0 = none)
        into the shared state: G_POLLS, G_PERIOD_SUM_NS, G_LATE (periods over
        LATE_FACTOR x ``period_ns``) and the histogram. Empties ``ticks``; returns the
        newest tick (the next call's ``last``). Each step runs in C (map, Counter)."""
        if not ticks:
            return last
        glob, hist = self.state.glob_view, self.state.hist_view
        glob[ss.G_POLLS] += len(ticks)
        newest = ticks[-1]
        periods = list(map(operator.sub, ticks, [last, *ticks]))
        if not last:
            del periods[0]
        if periods:
            glob[ss.G_PERIOD_SUM_NS] += newest - (last or ticks[0])
            late = sum(map(int(ss.LATE_FACTOR * period_ns).__lt__, periods))
            if late:
                glob[ss.G_LATE] += late
            top = ss.HIST_BINS - 1
            for b, k in Counter(map(operator.floordiv, periods, repeat(1000))).items():
                hist[b if b < top else top] += k
        ticks.clear()
        return newest


def tune_process(priority: int, parent_death: bool = True) -> str:
    """Tighter timer slack and, if allowed, SCHED_FIFO. Returns a note for the log.

    ``parent_death``: SIGTERM when the parent dies (the node's spawned poller).
    """
    note = []
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(29, 1000, 0, 0, 0) == 0:  # PR_SET_TIMERSLACK = 1 us
            note.append("timer slack 1 us")
        if parent_death:  # PR_SET_PDEATHSIG: a SIGTERM when the node dies, even by SIGKILL
            libc.prctl(1, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            note.append(f"SCHED_FIFO priority {priority}")
        except (PermissionError, OSError, AttributeError) as exc:
            note.append(
                f"no real-time priority ({exc}); "
                "run as root or grant CAP_SYS_NICE for steadier polls"
            )
    return ", ".join(note)


def run_poller(cfg: PollerConfig, buffer: object, commands: Connection, events: Connection) -> None:
    """Entry point of the poller process."""
    # Ctrl-C goes to the whole process group; the node decides when we stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    state = ss.SharedState(buffer, len(cfg.devices), cfg.ring_size)
    parent_pid = os.getppid()
    try:
        poller = Poller(cfg, state, commands, events)
    except Exception as exc:  # configuration errors: tell the node, then stop
        events.send(("fatal", f"{exc}"))
        return
    events.send(("log", f"poller pid {os.getpid()}: {tune_process(cfg.realtime_priority)}"))
    for note in poller.notes:
        events.send(("log", note))
    signal.signal(signal.SIGTERM, lambda *_: setattr(poller, "running", False))
    if os.getppid() != parent_pid:  # the node died before the death signal was armed
        return
    try:
        poller.run()
    except Exception:
        events.send(("fatal", traceback.format_exc()))
