"""The Beagle node's own odometry: every 1 kHz poll, integrated on the robot.

The seed's improvement "move more to the BBB": instead of the PC's request
rate, the pose is integrated over the single polls in the ring buffer with
the same pose math (:mod:`mm_pc.core.odometry`, vectorised) and published as the
same nav_msgs/Odometry as mm-odometry's. ``calibration_file`` is the wizard's
file (:mod:`mm_pc.core.calibration`, version 1 or 2): its angles and scales
correct every poll, its fitted sensor positions replace the configured mounts.
Counts lost to lifts are not added here (the gap estimate is a sum, not per
poll), but the polls' lift flags go to the odometry: ``two-sensor`` drops a
lifted sensor's equations for them, ``exact`` takes the other sensor's split
while its own is lifted and goes back after (:class:`mm_pc.core.odometry.Odometry`,
``switched_samples``); with every sensor lifted the pose holds.
"""

from __future__ import annotations

import numpy as np

from mm_beagle.node.params import OdometrySettings
from mm_beagle.poller.shared_state import SharedState
from mm_pc.core.calibration import Calibration
from mm_pc.core.geometry import SensorMount
from mm_pc.core.odometry import Odometry, Pose2D
from mm_pc.core.polls import FLAG_COMMAND_READ, deskew, snap_to_ticks, unseen_bits
from pln2033 import INCH_M


class OnboardOdometry:
    """Integrates the polls each sensor made since the previous call."""

    def __init__(
        self,
        settings: OdometrySettings,
        devices: list[str],
        state: SharedState,
        chips: list[str] | None = None,
    ) -> None:
        """``chips``: each device's chip name; it says which poll flags make a lift
        (:func:`mm_pc.core.polls.unseen_bits`: an OTOS's warning polls carry motion)."""
        self.devices = devices
        self.gap_bits = [unseen_bits(c) for c in (chips or [""] * len(devices))]
        self.state = state
        self.sensor = settings.sensor
        if not 0 <= settings.sensor < len(devices):
            raise ValueError(f"'odometry_sensor' must be 0..{len(devices) - 1}")
        mounts = [SensorMount(*m) for m in settings.mounts]
        # a bad file: OSError/ValueError naming it (the node exits 2)
        self.calibration = (
            Calibration.load(settings.calibration_file)
            if settings.calibration_file
            else Calibration()
        )
        mounts = self.calibration.mounts(devices, mounts)  # the fitted sensor positions
        self.odometry = Odometry(mounts, method=settings.method, sensor=settings.sensor)
        # start from now: the past is not integrated
        self.next_seq = [int(state.snapshot(i).seq) for i in range(len(devices))]
        self.last_stamp = 0  # the newest tick integrated (sensor 0's poll stamp, ns)
        # the later sensors' reads moved back to sensor 0's (mm_pc.core.polls.deskew)
        self._carry = np.zeros((len(devices), 2))
        self._delay = np.zeros(len(devices))

    def reset(self) -> None:
        """Pose back to the origin; the polls from here on are integrated (the past is not)."""
        self.odometry.reset()

    def step(self) -> tuple[Pose2D, Pose2D, float, int, int] | None:
        """Integrate the new polls: (before, after, seconds, last stamp ns, cpi), or None.

        The sensors' polls are paired by tick as mm-odometry pairs them
        (:func:`mm_pc.core.polls.snap_to_ticks` onto sensor 0's polls, not by ring
        position: a command read, e.g. the drain before a CPI change, is one entry more in
        one sensor's ring); each read, command reads too, is summed into the tick at or
        after it at its own CPI. Polls after the newest tick every sensor has wait."""
        batches = [self.state.samples(i, self.next_seq[i], 0) for i in range(len(self.devices))]
        arrs = [b[3] for b in batches]
        if any(len(a["dx"]) == 0 for a in arrs):
            return None
        flags = [a["flags"].astype(np.int64) for a in arrs]
        raw = [a["stamp_ns"].astype(np.int64) for a in arrs]
        real = [(f & FLAG_COMMAND_READ) == 0 for f in flags]
        ticks = raw[0][real[0]]
        later = zip(raw[1:], flags[1:], strict=True)
        stamps = [raw[0], *(snap_to_ticks(ticks, r, f) for r, f in later)]
        for st, ok in zip(stamps[1:], real[1:], strict=True):
            ticks = np.intersect1d(ticks, st[ok])
        if not len(ticks):
            return None
        k, n_dev = len(ticks), len(self.devices)
        d = np.zeros((k, n_dev, 2))
        lifted = np.zeros((k, n_dev), dtype=bool)
        delay = np.zeros((k, n_dev), dtype=np.int64)
        cpi = 0
        for i, ((first, _next, _dropped, arr), st) in enumerate(zip(batches, stamps, strict=True)):
            m = int(np.searchsorted(st, ticks[-1], side="right"))
            idx = np.searchsorted(ticks, st[:m], side="left")  # the tick at or after
            own = st[:m] == ticks[idx]
            # a poll below the chip's quality threshold counts as a lift (issue 15), unless
            # the chip's own fallback carried the motion (the OTOS's warning: issue 26)
            lifted[idx[own], i] = (flags[i][:m][own] & self.gap_bits[i]) != 0
            delay[idx[own], i] = raw[i][:m][own] - ticks[idx[own]]
            scale = INCH_M / np.maximum(arr["cpi"][:m].astype(float), 1.0)
            dx, dy = self.calibration.apply(
                self.devices[i], arr["dx"][:m] * scale, arr["dy"][:m] * scale
            )
            np.add.at(d[:, i, 0], idx, dx)
            np.add.at(d[:, i, 1], idx, dy)
            self.next_seq[i] = first + m
            if i == self.sensor:
                cpi = int(arr["cpi"][m - 1])
        prev = self.last_stamp or int(ticks[0]) - 1_000_000
        dt = np.maximum(np.diff(np.concatenate([[prev], ticks])) / 1e9, 1e-6)
        self.last_stamp = int(ticks[-1])
        d = deskew(d, delay, dt, self._carry, self._delay)
        before = self.odometry.pose
        self.odometry.integrate(dt, d, lifted=lifted)  # advances the pose
        after = self.odometry.pose
        return before, after, float(dt.sum()), int(ticks[-1]), cpi
