"""The Beagle node's own odometry: every 1 kHz poll, integrated on the robot.

The seed's improvement "move more to the BBB": instead of the PC's request
rate, the pose is integrated over the single polls in the ring buffer with
the same pose math (:mod:`mm_pc.core.odometry`, vectorised) and published as the
same nav_msgs/Odometry as mm-odometry's. ``calibration_file`` is the wizard's
file (:mod:`mm_pc.core.calibration`, version 1 or 2): its angles and scales
correct every poll, its fitted sensor positions replace the configured mounts.
Counts lost to lifts are not added here (the gap estimate is a sum, not per
poll), but the polls' lift flags go to the odometry: ``two-sensor`` drops a
lifted sensor's equations for them.
"""

from __future__ import annotations

import numpy as np

from mm_beagle.node.params import OdometrySettings
from mm_beagle.poller.shared_state import SharedState
from mm_pc.core.calibration import Calibration
from mm_pc.core.geometry import SensorMount
from mm_pc.core.odometry import Odometry, Pose2D
from mm_pc.core.polls import MAX_READ_SKEW_NS, deskew, unseen_bits
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
        self.last_stamp = [0] * len(devices)
        # the later sensors' reads moved back to sensor 0's (mm_pc.core.polls.deskew)
        self._carry = np.zeros((len(devices), 2))
        self._delay = np.zeros(len(devices))

    def reset(self) -> None:
        """Pose back to the origin; the polls from here on are integrated (the past is not)."""
        self.odometry.reset()

    def step(self) -> tuple[Pose2D, Pose2D, float, int, int] | None:
        """Integrate the new polls: (before, after, seconds, last stamp ns, cpi), or None."""
        batches = [self.state.samples(i, self.next_seq[i], 0) for i in range(len(self.devices))]
        n = min(len(arr["dx"]) for _, _, _, arr in batches)
        if n == 0:
            return None
        d = np.empty((n, len(self.devices), 2))
        lifted = np.empty((n, len(self.devices)), dtype=bool)
        for i, (first, _next, _dropped, arr) in enumerate(batches):
            # a poll below the chip's quality threshold counts as a lift (issue 15), unless
            # the chip's own fallback carried the motion (the OTOS's warning: issue 26)
            lifted[:, i] = (arr["flags"][:n] & self.gap_bits[i]) != 0
            scale = INCH_M / np.maximum(arr["cpi"][:n].astype(float), 1.0)
            dx = arr["dx"][:n] * scale
            dy = arr["dy"][:n] * scale
            dx, dy = self.calibration.apply(self.devices[i], dx, dy)
            d[:, i, 0], d[:, i, 1] = dx, dy
            self.next_seq[i] = first + n
        stamps = batches[self.sensor][3]["stamp_ns"][:n].astype(np.int64)
        prev = self.last_stamp[self.sensor] or int(stamps[0]) - 1_000_000
        dt = np.diff(np.concatenate([[prev], stamps])) / 1e9
        dt = np.maximum(dt, 1e-6)  # a command's read shares its poll's stamp
        self.last_stamp[self.sensor] = int(stamps[-1])
        first = batches[0][3]["stamp_ns"][:n].astype(np.int64)
        delay = np.stack([b[3]["stamp_ns"][:n].astype(np.int64) - first for b in batches], 1)
        delay[(delay < 0) | (delay >= MAX_READ_SKEW_NS)] = 0  # not the same tick: as read
        d = deskew(d, delay, dt, self._carry, self._delay)
        before = self.odometry.pose
        self.odometry.integrate(dt, d, lifted=lifted)  # advances the pose
        after = self.odometry.pose
        cpi = int(batches[self.sensor][3]["cpi"][n - 1])
        return before, after, float(dt.sum()), int(stamps[-1]), cpi
