"""How healthy the polling was over one diagnostics period: the /diagnostics level (no ROS).

Thresholds (docs/beagle-node.md section 4.2):

* WARN when the achieved poll rate over the period is below
  ``RATE_WARN_FRACTION`` (95 %) of ``poll_rate``, when the poller's overrun
  count grew, or when a stall happened: two consecutive polls (or the newest
  poll and now) more than ``STALL_S`` (50 ms) apart.
* ERROR when a counter may have wrapped: at the speed measured over the
  period (counts/s, outside the longest gap) the sensor's 16-bit counter
  collects more than ``COUNTER_LIMIT`` (32 767) counts in the longest gap.
  Each wrap loses 65 536 counts; the estimate is in the values (counts and
  metres at the CPI in force).
* ERROR for the round in which a sensor was re-initialised after it had been up (a
  power cycle: the chip came back at its defaults, or stopped answering and came
  back): :func:`outage_estimate` puts the counts lost between the last good poll
  before and the first after at the lift-gap rule's value (:func:`pln2033.lift_fill.fill_gap`:
  the mean speed of the good polls on each side, a straight line between them; here
  ``OUTAGE_WINDOW`` = 200 polls a side, not a lift's 20).

:func:`sensor_status` builds one sensor's status (level, message, values) from
plain values: the node only reads the snapshots and publishes what it returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mm_beagle.poller.shared_state import (
    FLAG_COMMAND_READ,
    FLAG_SPI_ERROR,
    STATE_NAMES,
    STATE_UP,
    Totals,
)
from pln2033 import INCH_M
from pln2033.lift_fill import fill_gap

STALL_S = 0.05
RATE_WARN_FRACTION = 0.95
COUNTER_LIMIT = 32_767  # int16: a poll gap collecting more than this wraps the counter
WRAP_COUNTS = 65_536
#: good polls averaged on each side of an outage (0.2 s at 1 kHz): a lift's 20 would
#: multiply one poll's rounding by thousands of polls (the OTOS's counts come in steps of
#: 12-36 every 2.4 ms: 20 polls put a 2.5 s outage's estimate 1.8 % off, 200 polls 0.x %)
OUTAGE_WINDOW = 200


@dataclass(frozen=True)
class Gap:
    """The longest time without a poll in a period (s) and the speed outside it (counts/s)."""

    seconds: float
    speed_x: float
    speed_y: float


def longest_gap(stamps_ns: np.ndarray, dx: np.ndarray, dy: np.ndarray, prev_ns: int,
                now_ns: int) -> Gap:  # fmt: skip
    """The longest gap among the polls ``stamps_ns`` (with their counts ``dx``, ``dy``).

    ``prev_ns``: the newest poll before them (0: none); ``now_ns``: now, so that a
    stall still going on counts. The speed leaves out the gap and the poll that
    ends it (whose counts may have wrapped).
    """
    t = np.asarray(stamps_ns, dtype=np.int64)
    head = np.array([prev_ns] if prev_ns else [], dtype=np.int64)  # int64: ns since 1970
    edges = np.concatenate([head, t, np.array([now_ns], dtype=np.int64)])
    if len(edges) < 2:
        return Gap(0.0, 0.0, 0.0)
    diffs = np.diff(edges)
    k = int(np.argmax(diffs))
    gap_s = max(0.0, float(diffs[k]) / 1e9)
    # the poll ending the gap is edges[k + 1]: t[k] after a prev stamp, else t[k + 1]
    # (none when the gap runs up to now)
    end = k if prev_ns else k + 1
    keep = np.ones(len(t), dtype=bool)
    if 0 <= end < len(t):
        keep[end] = False
    span_s = max(0.0, float(edges[-1] - edges[0]) / 1e9 - gap_s)
    if span_s <= 0 or not keep.any():
        return Gap(gap_s, 0.0, 0.0)
    sx = float(np.abs(np.asarray(dx)[keep].sum()))
    sy = float(np.abs(np.asarray(dy)[keep].sum()))
    return Gap(gap_s, sx / span_s, sy / span_s)


def assess(rate_hz: float, poll_rate: float, overruns_grew: int, gap: Gap,
           cpi: int) -> tuple[str, str, dict[str, object]]:  # fmt: skip
    """('OK'|'WARN'|'ERROR', message, values for /diagnostics) for one sensor's period.

    ``rate_hz``: achieved polls per second (nan: no previous period, not judged);
    ``overruns_grew``: skipped poll slots since the previous period.
    """
    est_x, est_y = gap.speed_x * gap.seconds, gap.speed_y * gap.seconds
    wraps = int((max(est_x, est_y) + WRAP_COUNTS / 2) // WRAP_COUNTS)
    values: dict[str, object] = {
        "longest_poll_gap_ms": f"{gap.seconds * 1e3:.1f}",
        "gap_est_counts": f"{max(est_x, est_y):.0f}",
    }
    if max(est_x, est_y) > COUNTER_LIMIT:
        wraps = max(wraps, 1)
        loss = wraps * WRAP_COUNTS
        metres = loss * INCH_M / cpi if cpi > 0 else float("nan")
        values["est_wrap_loss_counts"] = loss
        values["est_wrap_loss_m"] = f"{metres:.3f}"
        return (
            "ERROR",
            f"counter may have wrapped: no poll for {gap.seconds:.2f} s at "
            f"{max(gap.speed_x, gap.speed_y):.0f} counts/s, about {loss} counts "
            f"({metres:.2f} m) lost",
            values,
        )
    why = []
    if rate_hz == rate_hz and rate_hz < RATE_WARN_FRACTION * poll_rate:
        why.append(f"achieved {rate_hz:.0f} Hz < {RATE_WARN_FRACTION:.0%} of {poll_rate:g} Hz")
    if overruns_grew > 0:
        why.append(f"{overruns_grew} overruns")
    if gap.seconds > STALL_S:
        why.append(f"stall: no poll for {gap.seconds * 1e3:.0f} ms (> {STALL_S * 1e3:.0f} ms)")
    if why:
        return "WARN", "; ".join(why), values
    return "OK", "up", values


@dataclass(frozen=True)
class Outage:
    """The longest time between two good polls and the counts estimated lost in it.

    ``seconds``: last good poll before -> first good poll after; ``polls``: the poll
    slots between them (the first poll after carries its own period's counts);
    ``x``/``y`` and ``sigma_x``/``sigma_y``: the estimate and its 1 sigma (counts);
    ``n_after``: good polls after it that the estimate used (at most OUTAGE_WINDOW).
    """

    seconds: float
    polls: int
    x: float
    y: float
    sigma_x: float
    sigma_y: float
    n_after: int


def outage_estimate(stamps_ns, dx, dy, flags, window: int = OUTAGE_WINDOW) -> Outage | None:
    """The outage among ring polls (oldest first): their longest time between good polls.

    Good polls are those that read the chip (no SPI error, no command's read). The poll
    period is the median between good polls of the two windows; each window counts as
    the time its counts cover, in periods (a late loop's poll carries more than one), and
    the gap as its time less the period of the poll that ends it; the estimate is
    :func:`pln2033.lift_fill.fill_gap`'s, as for a lift gap. None: fewer than two good polls.
    """
    f = np.asarray(flags)
    idx = np.flatnonzero((f & (FLAG_SPI_ERROR | FLAG_COMMAND_READ)) == 0)
    if len(idx) < 2:
        return None
    t = np.asarray(stamps_ns, dtype=np.int64)[idx]
    diffs = np.diff(t)
    k = int(np.argmax(diffs))
    b0, a1 = max(0, k + 1 - window), min(len(idx), k + 1 + window)
    before, after = idx[b0 : k + 1], idx[k + 1 : a1]
    steps = np.concatenate([np.diff(t[b0 : k + 1]), np.diff(t[k + 1 : a1])])
    period = float(np.median(steps)) if len(steps) else float(diffs[k])
    if period <= 0:
        return None
    # the before-window's counts run from the good poll before it (or one period before
    # its first); the after-window's from the bring-up's read, one period before its first
    start = float(t[b0 - 1]) if b0 > 0 else float(t[b0]) - period
    n_before = (float(t[k]) - start) / period
    n_after = (float(t[a1 - 1]) - float(t[k + 1])) / period + 1.0
    gap = max(0.0, float(diffs[k]) / period - 1.0)
    ax, ay = np.asarray(dx, dtype=float), np.asarray(dy, dtype=float)
    fx = fill_gap(ax[before].sum(), n_before, gap, ax[after].sum(), n_after)
    fy = fill_gap(ay[before].sum(), n_before, gap, ay[after].sum(), n_after)
    return Outage(float(diffs[k]) / 1e9, round(gap), fx.total, fy.total, fx.sigma, fy.sigma,
                  len(after))  # fmt: skip


def reset_report(outage: Outage, cpi: int, resets: int) -> tuple[str, dict[str, object]]:
    """The ERROR text and values of a round in which the sensor was re-initialised
    (``resets``: re-initialisations after the first bring-up, this one included)."""
    loss = max(abs(outage.x), abs(outage.y))
    metres = float(np.hypot(outage.x, outage.y)) * INCH_M / cpi if cpi > 0 else float("nan")
    values: dict[str, object] = {
        "reset_outage_s": f"{outage.seconds:.3f}",
        "est_reset_loss_x_counts": f"{outage.x:.0f}",
        "est_reset_loss_y_counts": f"{outage.y:.0f}",
        "est_reset_loss_sigma_counts": f"{max(outage.sigma_x, outage.sigma_y):.0f}",
        "est_reset_loss_m": f"{metres:.3f}",
    }
    text = (
        f"sensor reset: re-initialised after {outage.seconds:.2f} s without a good poll "
        f"(power cycle, lost contact or poller restart; {resets} so far), about {loss:.0f} "
        f"counts ({metres:.2f} m) lost, estimated from the speed before and after"
    )
    return text, values


@dataclass(frozen=True)
class PollerRound:
    """What one diagnostics round measured of the whole poller (the same for every sensor).

    ``period_p50_us``/``period_p99_us``: poll period percentiles (µs); ``late_polls``,
    ``overruns``: the poller's totals; ``cpu_percent``: its CPU; ``link``: the remote
    link's values ({} locally); ``stuck``/``unavailable``: why the poller counts as
    stuck or the agent cannot be reached ('' = it polls, it can); ``sim``: the sim
    backend, whose emulators' ground truth is reported too.
    """

    period_p50_us: float
    period_p99_us: float
    late_polls: int
    overruns: int
    cpu_percent: float
    restarts: int
    link: dict[str, object]
    stuck: str = ""
    unavailable: str = ""
    sim: bool = False


def sensor_status(
    r: PollerRound,
    chip: str,
    t: Totals,
    rate_hz: float,
    last_error: str,
    assessed: tuple[str, str, dict[str, object]],
    down_message: str,
    errors_before: tuple[int, int],
    reset: tuple[str, dict[str, object]] = ("", {}),
) -> tuple[str, str, dict[str, object]]:
    """('OK'|'WARN'|'ERROR', message, values) of one sensor's /diagnostics status.

    ``t``: the sensor's snapshot; ``rate_hz``: polls per second over the round (nan:
    the first round); ``assessed``: :func:`assess` of its polls; ``down_message``: what
    to say while it is not up; ``errors_before``: its (spi_errors, overflows) at the
    previous round (a change is a WARN); ``reset``: :func:`reset_report` of a
    re-initialisation found this round (text '' = none; its values are shown anyway).
    The level goes by the worst of: stuck poller, unreachable agent, sensor down, a
    reset, ``assessed`` ERROR, new SPI errors or overflows, ``assessed`` WARN.
    """
    values: dict[str, object] = {
        "chip": chip,
        "state": STATE_NAMES.get(t.state, "?"),
        "polls": t.seq,
        "achieved_rate_hz": f"{rate_hz:.1f}",
        "period_p50_us": f"{r.period_p50_us:.0f}",
        "period_p99_us": f"{r.period_p99_us:.0f}",
        "late_polls": r.late_polls,
        "overruns": r.overruns,
        "spi_errors": t.spi_errors,
        "lift_events": t.lift_total,
        "quality": t.quality,  # the newest poll's (SQUAL; -1: the chip has none)
        "low_quality_events": t.low_quality_total,
        # counts lost to lifts, estimated (pln2033.lift_fill), and its 1 sigma
        "lift_est_x_counts": f"{t.x_est_counts:.1f}",
        "lift_est_y_counts": f"{t.y_est_counts:.1f}",
        "lift_est_sigma_x_counts": f"{t.x_est_var_counts**0.5:.1f}",
        "lift_est_sigma_y_counts": f"{t.y_est_var_counts**0.5:.1f}",
        "overflows": t.overflows,
        "cpi": t.cpi_y,
        "x_total_counts": t.x_total,
        "y_total_counts": t.y_total,
        "reinits": t.reinits,
        "poller_cpu_percent": f"{r.cpu_percent:.1f}",
        "poller_restarts": r.restarts,
        "last_error": last_error,
    }
    values.update(r.link)
    level_name, health_text, health_values = assessed
    values.update(health_values)
    reset_text, reset_values = reset
    values.update(reset_values)
    if r.sim or t.gen_x or t.gen_y:
        values["sim_generated_x_counts"] = t.gen_x
        values["sim_generated_y_counts"] = t.gen_y
        values["sim_lift_lost_x_counts"] = t.lift_lost_x
        values["sim_lift_lost_y_counts"] = t.lift_lost_y
    if r.stuck:
        return "ERROR", r.stuck, values
    if r.unavailable:
        return "ERROR", r.unavailable, values
    if t.state != STATE_UP:
        return "ERROR", down_message, values
    if reset_text:
        return "ERROR", reset_text, values
    if level_name == "ERROR":
        return "ERROR", health_text, values
    if (t.spi_errors, t.overflows) != errors_before:
        text = "SPI errors or counter overflows since last report"
        return "WARN", text + (f"; {health_text}" if level_name == "WARN" else ""), values
    if level_name == "WARN":
        return "WARN", health_text, values
    return "OK", "up", values
