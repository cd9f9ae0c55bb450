"""A simulated node ring whose CPI changes between polls (issue 28 item 2), no ROS.

Like :class:`fakes.FakeRing` (1 kHz twist script, per-poll counts, monotone totals),
but each poll has its own resolution: the counts are the floor of the cumulative true
motion at the CPI in force (the sub-count remainder carried across a change in metres,
as the chip holds it), and the totals' metres add each entry at its own CPI as the
node's poller does (``x_m += dx * INCH_M / cpi``). Each sensor has its own ring (its own
``seq``). At a change the poller drains the counters at the old CPI first: ``drain``
``"poll"`` records that read as a poll of that sensor alone (flag 2, as the poller's
``set_cpi`` does today), ``"command"`` as a command read (flag 16), ``None`` not at all;
sensor ``i``'s change (and drain) comes ``i * lag`` polls after sensor 0's, as two
``set_resolution`` calls do. ``samples(..., per_poll_cpi=False)`` is a reply of an
old node (no ``poll_cpi``: the reply's ``cpi`` stands for all its polls).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from mm_pc.core.polls import SensorTotals
from mm_pc.sim import robot
from pln2033 import INCH_M

FLAG_MOTION, FLAG_COMMAND_READ = 2, 16


class CpiRing:
    """Ring entries (polls and drain reads) per sensor; see the module doc.

    ``changes``: {poll index: new CPI} for sensor 0 (the poll at that index is its
    first at the new CPI; sensor i's is ``lag * i`` polls later). Poll j of every
    sensor has stamp ``t0_ns + (j + 1) ms``, a drain read 0.5 ms before it.
    ``true_m`` (polls, sensors, 2): each poll's displacement in metres at the CPI it was
    counted with, plus the drain read just before it (the per-poll truth).
    """

    def __init__(self, v, w, cpi0=1600, changes=None, drain="poll", lag=3, mounts=None,
                 t0_ns=1_700_000_000_000_000_000):  # fmt: skip
        self.mounts = tuple(mounts or robot.DEFAULT_MOUNTS)
        n, k = len(v), len(self.mounts)
        self.n_polls, self.t0_ns = n, t0_ns
        self.stamp_ns, self.cpi, self.flags, self.counts = [], [], [], []
        self.cum, self.cum_m, self.entries_after = [], [], []
        self.true_m = np.empty((n, k, 2))
        for i, m in enumerate(self.mounts):
            step_m = np.stack(robot.sensor_displacements(
                np.asarray(v, float), np.asarray(w, float), robot.DT, m), -1)  # fmt: skip
            mine = {j + lag * i: c for j, c in dict(changes or {}).items()}
            rows = []  # (stamp_ns, cpi, flags, is a drain, dx, dy)
            rem = np.zeros(2)  # metres not yet counted
            c = cpi0
            for j in range(n):
                if j in mine:
                    if drain:
                        dc = np.floor(rem * c / INCH_M + 1e-9).astype(np.int64)
                        rem -= dc * INCH_M / c
                        flag = FLAG_COMMAND_READ if drain == "command" else FLAG_MOTION
                        rows.append((t0_ns + j * 1_000_000 + 500_000, c, flag, True, *dc))
                    c = mine[j]
                rem += step_m[j]
                dc = np.floor(rem * c / INCH_M + 1e-9).astype(np.int64)
                rem -= dc * INCH_M / c
                rows.append((t0_ns + (j + 1) * 1_000_000, c, FLAG_MOTION, False, *dc))
            stamp = np.array([r[0] for r in rows], np.int64)
            cpi = np.array([r[1] for r in rows], np.int64)
            counts = np.array([r[4:] for r in rows], np.int64)
            metres = counts * (INCH_M / cpi)[:, None]
            acc, cum_m = np.zeros(2), [np.zeros(2)]
            for e in range(len(rows)):  # the node's float totals: entry after entry
                acc = acc + metres[e]
                cum_m.append(acc)
            polls = np.flatnonzero([not r[3] for r in rows])
            self.stamp_ns.append(stamp)
            self.cpi.append(cpi)
            self.flags.append(np.array([r[2] for r in rows], np.int64))
            self.counts.append(counts)
            self.cum.append(np.concatenate([np.zeros((1, 2), np.int64), np.cumsum(counts, 0)]))
            self.cum_m.append(np.array(cum_m))
            self.entries_after.append(np.r_[0, polls + 1])
            self.true_m[:, i] = np.add.reduceat(metres, np.r_[0, polls[:-1] + 1], axis=0)

    def totals(self, p):
        """The node's totals after ``p`` polls (and the drain reads before them)."""
        out = []
        for i in range(len(self.mounts)):
            e = int(self.entries_after[i][p])
            out.append(SensorTotals(
                seq=e, stamp_ns=self.t0_ns + p * 1_000_000,
                x_counts=int(self.cum[i][e, 0]), y_counts=int(self.cum[i][e, 1]),
                x_m=float(self.cum_m[i][e, 0]), y_m=float(self.cum_m[i][e, 1]),
            ))  # fmt: skip
        return out

    def samples(self, i, since, now, per_poll_cpi=True):
        """get_samples of sensor ``i`` for its ring entries ``since``..``now``."""
        sl = slice(since, now)
        cpi = self.cpi[i][sl]
        return SimpleNamespace(
            success=True, message="", first_seq=since, next_seq=now, dropped=0,
            cpi=int(cpi[-1]) if len(cpi) else int(self.cpi[i][max(now - 1, 0)]),
            stamp_ns=self.stamp_ns[i][sl], dx=self.counts[i][sl, 0], dy=self.counts[i][sl, 1],
            status=np.zeros(now - since, np.int64), flags=self.flags[i][sl],
            quality=(), poll_cpi=cpi if per_poll_cpi else (),
        )  # fmt: skip

    @property
    def final_m(self) -> np.ndarray:
        """(sensors, 2) the node's total metres at the end."""
        return np.array([c[-1] for c in self.cum_m])
