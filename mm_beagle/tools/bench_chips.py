"""mm-bench chips: CPU per poll of each chip's driver in the real poller, in this process.

For every installed chip, one :class:`~mm_beagle.poller.channel.Channel` is brought up on the
chip's emulator (the real driver's bring-up), then polled flat out:

- ``stub_us``: after bring-up the motion burst is answered by a constant reply (the
  driver's own transfer list, bytes of the emulator's first answer): what the driver and
  the poller cost per poll, the emulator left out. This is the board's share of a poll
  apart from the kernel's SPI ioctl; on the board the ioctl also holds the bus for the
  burst's ``hold_us`` (the PMW33xx's tSRAD_MOTBR of 35 us inside the chip-select frame,
  the kernel's ``delay_usecs``: the CPU sleeps or spins in the kernel for it, see
  docs/benchmarks.md).
- ``emulated_us``: the same with the emulator answering every poll (what the sim backend
  costs).

The OTOS's stub answers its one I2C read (status + position + velocity) with a constant
reply, so its stub figure leaves out the pose arithmetic of a moving chip (a few µs more).

No ROS; numpy only for the emulator's motion source. Prints one JSON object.
"""

from __future__ import annotations

import os
import platform
import time
from multiprocessing import Pipe

from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig


class ConstantBurst:
    """Answers the driver's own motion-burst list with a constant reply; the rest to the
    emulator. The reply is the emulator's answer to the first burst after arming."""

    def __init__(self, emulator, burst) -> None:
        self.emulator = emulator
        self.burst = burst
        self.reply = None

    def xfer2(self, data):
        if data is self.burst:
            if self.reply is None:
                self.reply = self.emulator.xfer2(data)
            return list(self.reply)
        return self.emulator.xfer2(data)

    def xfer_segments(self, segments):
        if segments is self.burst:
            if self.reply is None:
                self.reply = self.emulator.xfer_segments(segments)
            return [list(r) for r in self.reply]
        return self.emulator.xfer_segments(segments)

    def write_read(self, addr, write, read_len):  # I2C (the OTOS's one motion read)
        if write is self.burst:
            if self.reply is None:
                self.reply = self.emulator.write_read(addr, write, read_len)
            return bytes(self.reply)
        return self.emulator.write_read(addr, write, read_len)

    def write(self, addr, data):
        return self.emulator.write(addr, data)

    def close(self) -> None:
        pass


def _burst_of(driver) -> object:
    """The transfer list the driver sends for each motion read (built once)."""
    for name in ("_burst_tx", "motion_tx", "_motion_ptr"):
        tx = getattr(driver, name, None)
        if tx is not None:
            return tx
    raise RuntimeError(f"{driver.name}: no burst list found")


def chip_cost(chip: str, polls: int = 20000) -> dict:
    """CPU per poll (us) of ``chip``'s driver in the poller: stub and emulated."""
    out: dict[str, object] = {"chip": chip}
    for mode in ("stub", "emulated"):
        ring = 65536
        state = ss.SharedState(bytearray(ss.SharedState.size(1, ring)), 1, ring)
        _a, cmd = Pipe()
        _b, ev = Pipe()
        cfg = PollerConfig(
            devices=["/dev/spidev1.0"], backend="sim", chips=[chip], ring_size=ring,
            sim=SimConfig(trajectory="straight", speed=0.3),
        )  # fmt: skip
        poller = Poller(cfg, state, cmd, ev)
        ch = poller.channels[0]
        poller.try_init(ch, time.monotonic())
        if ch.driver is None:
            raise RuntimeError(f"{chip}: bring-up failed: {ch.last_error}")
        if mode == "stub":
            burst = _burst_of(ch.driver)
            if ch.fast:
                ch.driver.bus = ConstantBurst(ch.bus, burst)
                ch.attach(ch.driver)
            else:
                ch.driver.bus = ConstantBurst(ch.bus, burst)
        stamp = time.time_ns()
        poll = ch.poll
        for _ in range(200):  # warm up (and arm the burst)
            poll(stamp)
        t0 = time.process_time()
        for _ in range(polls):
            poll(stamp)
        us = (time.process_time() - t0) / polls * 1e6
        out[f"{mode}_us"] = round(us, 2)
        if mode == "emulated":
            t = state.snapshot(0)
            out["counts_lost"] = abs(t.gen_x - t.x_total) + abs(t.gen_y - t.y_total)
        out["transfers_per_poll"] = getattr(ch.driver, "transfers_per_poll", 1)
        out["burst_delay_us"] = getattr(ch.driver, "burst_delay_us", 0)
    return out


def bench_chips(polls: int = 20000) -> dict:
    return {
        "benchmark": "chips",
        "polls": polls,
        "chips": [chip_cost(c, polls) for c in chip_config.available_chips()],
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "load_avg_1min": round(os.getloadavg()[0], 2),
        },
    }
