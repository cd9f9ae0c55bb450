"""The node's /diagnostics: one DiagnosticStatus per sensor every ``diagnostics_period`` s.

This module reads the shared state and keeps what a round needs from the previous
one (poll counts, stamps, error counters); what each status says is
:func:`mm_beagle.node.health.sensor_status`, which takes plain values.
"""

from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from mm_beagle.node import health, messages
from mm_beagle.poller import shared_state as ss

LEVELS = {"OK": DiagnosticStatus.OK, "WARN": DiagnosticStatus.WARN, "ERROR": DiagnosticStatus.ERROR}


class Diagnostics:
    """Publishes the rounds for ``node`` (a BeagleNode: its poller, devices, chips)."""

    def __init__(self, node) -> None:
        self.node = node
        n = len(node.devices)
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.timer = node.create_timer(node.settings.diagnostics_period, self.publish)
        self.last: tuple[float, list[int], int] | None = None  # (wall s, seqs, G_POLLS)
        self.errors = [(0, 0)] * n  # (spi_errors, overflows) at the last round
        self.stamps = [0] * n  # newest poll seen by the last round (ns)
        self.overruns = 0
        # re-initialisations seen (None: not yet) and the sum of reset-loss estimates
        self.reinits: list[int | None] = [None] * n
        self.reset_seq = [0] * n  # a ring seq before the outage being looked for
        self.resets = [0] * n
        self.reset_loss = [(0.0, 0.0)] * n  # counts x, y

    def set_period(self, seconds: float) -> None:
        """A new ``diagnostics_period`` (live parameter)."""
        self.node.destroy_timer(self.timer)
        self.timer = self.node.create_timer(seconds, self.publish)

    def _status_name(self, dev: str) -> str:
        return f"{self.node.get_fully_qualified_name()}: {dev}"  # unique per robot namespace

    def publish(self) -> None:
        """One round: a status per sensor (state, rates, errors, totals, and the link)."""
        node = self.node
        poller, state = node.poller, node.poller.state
        glob = state.glob
        try:
            snaps = [state.snapshot(i) for i in range(len(node.devices))]
        except ss.PollerBusyError:
            if node.stuck:
                self.publish_stuck()
            return  # a brief stall mid-write: this round skipped
        wall = time.monotonic()
        seqs = [t.seq for t in snaps]
        last, self.last = self.last, (wall, seqs, int(glob[ss.G_POLLS]))
        overruns = int(glob[ss.G_OVERRUNS])
        overruns_grew = overruns - self.overruns if last else 0
        self.overruns = overruns
        now_ns = time.time_ns()
        p50, p99 = state.period_percentiles(0.5, 0.99)
        r = health.PollerRound(
            p50,
            p99,
            int(glob[ss.G_LATE]),
            overruns,
            poller.cpu_percent(),
            getattr(poller, "restarts", 0),
            poller.link_values(),
            stuck=node.stuck,
            unavailable=poller.unavailable(),
            sim=node.settings.poller.backend == "sim",
        )
        arr = DiagnosticArray()
        arr.header.stamp = node.get_clock().now().to_msg()
        for i, (dev, t) in enumerate(zip(node.devices, snaps, strict=True)):
            rate = (
                (seqs[i] - last[1][i]) / (wall - last[0])
                if last and wall > last[0]
                else float("nan")
            )
            reset = self._reset(i, t, last)
            seen = self.reinits[i]
            outage = bool(reset[0]) or (seen is not None and t.reinits > seen)
            assessed = self._assess(i, t, last, rate, overruns_grew, now_ns, outage)
            level, text, values = health.sensor_status(
                r,
                node.chips[i],
                t,
                rate,
                node.last_errors[i],
                assessed,
                node.down_message(i),
                self.errors[i],
                reset,
            )
            self.errors[i] = (t.spi_errors, t.overflows)
            status = messages.diagnostic(self._status_name(dev), dev, LEVELS[level], text, values)
            arr.status.append(status)
        self.pub.publish(arr)
        node.stuck = ""  # reported (the restart's own round and this one)

    def _assess(self, i, t, last, rate, overruns_grew, now_ns, outage=False):
        """health.assess for sensor ``i`` over the polls since the previous round
        (``outage``: a reset's outage is in them; its report says what was lost, not the
        wrap estimate of a gap that long)."""
        node = self.node
        prev_seq = last[1][i] if last else t.seq
        dropped = 0
        try:
            _f, _n, dropped, arr = node.poller.state.samples(i, prev_seq, 0)
        except ss.PollerBusyError:
            arr = None
        stamps = arr["stamp_ns"] if arr is not None else []
        cfg = node.settings.poller
        remote = cfg.backend == "remote"
        if arr is not None and len(stamps):
            self.stamps[i], prev_ns = int(stamps[-1]), self.stamps[i]
            # remote: only the gaps between the agent's polls (the link's delay is no stall)
            end_ns = int(stamps[-1]) if remote else now_ns
            gap = health.longest_gap(stamps, arr["dx"], arr["dy"], prev_ns, end_ns)
        else:
            gap = health.longest_gap([], [], [], self.stamps[i] or t.stamp_ns, now_ns)
        if outage or t.state != ss.STATE_UP or (remote and (not len(stamps) or dropped)):
            gap = health.Gap(0.0, 0.0, 0.0)  # the link's own values say what is late there
        return health.assess(rate, cfg.poll_rate, overruns_grew, gap, t.cpi_y)

    def _reset(self, i, t, last) -> tuple[str, dict[str, object]]:
        """health.reset_report of a re-initialisation of sensor ``i`` since the previous
        round (text ''), once OUTAGE_WINDOW good polls after it are in the ring; the running
        count and sum of the estimates as values either way.

        The first bring-up is no reset; a sensor up again after a power cycle, a glitch
        the health check caught or lost contact is. Its outage is the longest time
        between good polls from a little before the previous round's newest poll."""
        seen = self.reinits[i]
        text, values = "", {}
        if seen is None or (seen == 0 and t.reinits):  # the first bring-up
            self.reinits[i] = t.reinits
        elif t.reinits > seen and t.state == ss.STATE_UP:
            try:
                _f, _n, _d, arr = self.node.poller.state.samples(i, self.reset_seq[i], 0)
            except ss.PollerBusyError:
                arr = None
            out = None
            if arr is not None:
                out = health.outage_estimate(arr["stamp_ns"], arr["dx"], arr["dy"], arr["flags"])
            if out is not None and out.n_after >= health.OUTAGE_WINDOW:
                self.reinits[i] = t.reinits
                self.resets[i] += t.reinits - seen
                x, y = self.reset_loss[i]
                self.reset_loss[i] = (x + out.x, y + out.y)
                text, values = health.reset_report(out, t.cpi_y, self.resets[i])
        if self.reinits[i] == t.reinits or t.state != ss.STATE_UP:
            # the next outage is looked for from here (with the window before it)
            self.reset_seq[i] = max(0, t.seq - health.OUTAGE_WINDOW - 8)
        if self.resets[i]:
            x, y = self.reset_loss[i]
            values["sensor_resets"] = self.resets[i]
            values["est_reset_loss_total_x_counts"] = f"{x:.0f}"
            values["est_reset_loss_total_y_counts"] = f"{y:.0f}"
        return text, values

    def publish_stuck(self) -> None:
        """ERROR per sensor when no snapshot can be had (the poller stopped mid-write)."""
        node = self.node
        arr = DiagnosticArray()
        arr.header.stamp = node.get_clock().now().to_msg()
        values = {"state": "stuck", "poller_restarts": getattr(node.poller, "restarts", 0)}
        for dev in node.devices:
            arr.status.append(
                messages.diagnostic(
                    self._status_name(dev), dev, DiagnosticStatus.ERROR, node.stuck, values
                )
            )
        self.pub.publish(arr)
