"""Shared memory between the 1 kHz poller process and the ROS node.

The poller is the only writer. Per sensor it keeps monotone totals (counts,
metres, lift estimates) and a ring buffer of single polls. The node reads
without ever blocking the poller: the totals are published under a sequence
lock (a version counter that is odd while a write is in progress; a reader
retries until it sees the same even version before and after its copy).

The memory is a ``multiprocessing`` RawArray made by the node before it
spawns the poller, so both processes map the same pages and nothing needs
to be unlinked afterwards.
"""

from __future__ import annotations

import operator
import time
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

from mm_beagle.poller import ring_layout

# the bits of each poll's ring_flags, defined once in the lowest layer (re-exported here)
from mm_pc.core.poll_flags import FLAG_COMMAND_READ as FLAG_COMMAND_READ
from mm_pc.core.poll_flags import FLAG_LIFT as FLAG_LIFT
from mm_pc.core.poll_flags import FLAG_LOW_QUALITY as FLAG_LOW_QUALITY
from mm_pc.core.poll_flags import FLAG_MOTION as FLAG_MOTION
from mm_pc.core.poll_flags import FLAG_OVERFLOW as FLAG_OVERFLOW
from mm_pc.core.poll_flags import FLAG_SPI_ERROR as FLAG_SPI_ERROR

if TYPE_CHECKING:
    import numpy as np

# int64 fields per sensor. The last four, then the first two floats (the metres), are
# contiguous in memory (see SharedState): the poller's hot path writes them with one pack.
I_VERSION = 0
I_LIFT_TOTAL = 1  # polls that reported the lift bit
I_SPI_ERRORS = 2
I_OVERFLOWS = 3
I_STATE = 4  # see STATE_*
I_CPI_X = 5
I_CPI_Y = 6
I_GEN_X = 7  # emulator ground truth: counts that entered the sensor's counter
I_GEN_Y = 8
I_REINITS = 9  # successful (re)initialisations
I_LIFT_LOST_X = 10  # emulator ground truth: counts cleared by lifts
I_LIFT_LOST_Y = 11
I_LOW_QUALITY = 12  # polls whose quality was below the chip's threshold (treated like a lift)
I_QUALITY = 13  # the newest poll's quality figure (-1: the chip has none)
I_CHIP_POSE_NS = 14  # system time of the newest on-chip pose (the OTOS; 0 = none)
I_RING_FROM = 15  # oldest seq the ring holds (the remote backend starts mid-run)
I_SEQ = 16  # polls done for this sensor
I_X_TOTAL = 17  # measured counts
I_Y_TOTAL = 18
I_STAMP_NS = 19  # system time of the newest poll
N_INT = 20

# int64 fields that only grow: a restarted agent's are added to what came before
MONOTONE_INTS = (
    I_SEQ,
    I_X_TOTAL,
    I_Y_TOTAL,
    I_LIFT_TOTAL,
    I_SPI_ERRORS,
    I_OVERFLOWS,
    I_GEN_X,
    I_GEN_Y,
    I_REINITS,
    I_LIFT_LOST_X,
    I_LIFT_LOST_Y,
    I_LOW_QUALITY,
)

# float64 fields per sensor
F_X_TOTAL_M = 0
F_Y_TOTAL_M = 1
F_X_EST_COUNTS = 2  # lift-gap estimates, counts (not in the measured totals)
F_Y_EST_COUNTS = 3
F_X_EST_M = 4
F_Y_EST_M = 5
F_X_EST_VAR_COUNTS = 6  # variance of those estimates (count^2, m^2): gaps add up independently
F_Y_EST_VAR_COUNTS = 7
F_X_EST_VAR_M = 8
F_Y_EST_VAR_M = 9
N_TOTAL_FLOAT = 10  # the floats above only grow (a restarted agent's are added on)
# the chip's own pose estimate (the OTOS: on-chip fusion), base_link frame (REP 103):
# x, y (m), yaw (rad) in the chip's odometry frame, and the velocity in base_link
F_CHIP_X = 10
F_CHIP_Y = 11
F_CHIP_YAW = 12
F_CHIP_VX = 13  # m/s, base_link
F_CHIP_VY = 14
F_CHIP_WZ = 15  # rad/s
N_FLOAT = 16

# poller-wide int64 fields
G_POLLS = 0
G_LATE = 1  # poll periods longer than LATE_FACTOR x the nominal period
G_OVERRUNS = 2  # poll slots skipped because the poller fell behind
G_RUNNING = 3
G_PERIOD_SUM_NS = 5
G_COMMANDS_SENT = 6  # the one field the node writes: bumped after each command it sends
N_GLOBAL = 8

HIST_BINS = 20_000  # period histogram, 1 us bins; the last bin takes everything longer

STATE_DOWN = 0
STATE_UP = 1
STATE_STARTING = 2
STATE_NAMES = {STATE_DOWN: "down", STATE_UP: "up", STATE_STARTING: "starting"}


LATE_FACTOR = 1.5

# How long a reader keeps retrying while the poller is mid-write (s). The poller's
# write takes microseconds; only a stopped or descheduled poller (a busy single-core
# board: 60 ms stalls) holds the lock longer. The budget bounds how long a service
# callback can block the executor.
READ_BUDGET_S = 0.2
BUSY_MESSAGE = "poller busy (stalled mid-write), try again"


class PollerBusyError(RuntimeError):
    """The poller stayed mid-write for the whole read budget (not a configuration error).

    Deliberately not a TimeoutError: that is an OSError, which the node's
    ``main`` reports as bad configuration (exit 2).
    """


@dataclass(frozen=True, slots=True)
class Totals:
    """A consistent snapshot of one sensor's monotone totals."""

    seq: int
    x_total: int
    y_total: int
    lift_total: int
    spi_errors: int
    overflows: int
    state: int
    cpi_x: int
    cpi_y: int
    stamp_ns: int
    gen_x: int
    gen_y: int
    reinits: int
    lift_lost_x: int
    lift_lost_y: int
    low_quality_total: int  # polls below the chip's quality threshold
    quality: int  # the newest poll's quality figure (-1: none)
    chip_pose_ns: int  # when the chip's own pose below was read (0: the chip has none)
    x_total_m: float
    y_total_m: float
    x_est_counts: float
    y_est_counts: float
    x_est_m: float
    y_est_m: float
    x_est_var_counts: float  # 1-sigma^2 of x_est_counts (count^2), see pln2033.lift_fill
    y_est_var_counts: float
    x_est_var_m: float  # m^2
    y_est_var_m: float
    chip_x: float  # the chip's own pose (F_CHIP_*), m, m, rad, m/s, m/s, rad/s
    chip_y: float
    chip_yaw: float
    chip_vx: float
    chip_vy: float
    chip_wz: float

    @classmethod
    def zero(cls, stamp_ns: int = 0) -> Totals:
        values: dict[str, Any] = {f.name: 0.0 if f.type == "float" else 0 for f in fields(cls)}
        return cls(**{**values, "stamp_ns": stamp_ns})


class SharedState:
    """Views onto one shared buffer; built identically in every process that maps it.

    The writer (:class:`mm_beagle.poller.channel.Channel`) uses the plain memoryviews of
    :meth:`sensor_views`, :attr:`glob_view` and :attr:`hist_view`, so the board's
    agent needs no numpy; readers use the numpy arrays (``ints``, ``floats``,
    ``glob``, ``hist``, ``ring_*``), made on first use.
    """

    # (name, struct code, item size, per sensor?, length); per sensor its ints then its
    # floats (one row: the hot path's seq, counts, stamp and metres are contiguous); the
    # ring: one record per poll (ring_layout.RECORD), ring_size records per sensor, as bytes
    _LAYOUT = (
        ("sensor", "q", 8, True, N_INT + N_FLOAT),
        ("glob", "q", 8, False, N_GLOBAL),
        ("hist", "q", 8, False, HIST_BINS),
        ("ring", "B", ring_layout.POLL_BYTES, True, 0),
    )
    RING_FIELDS = ring_layout.ATTRS

    def __init__(self, buffer: object, n_sensors: int, ring_size: int) -> None:
        self.n_sensors = n_sensors
        self.ring_size = ring_size
        self.buffer = buffer
        # a bytearray or a multiprocessing RawArray: both export the buffer protocol, which
        # Python 3.11's typing cannot name (collections.abc.Buffer is 3.12)
        self.mem = memoryview(buffer).cast("B")  # type: ignore[arg-type]
        # name -> (offset, code, item size, rows, row length, bytes from row to row)
        self._where: dict[str, tuple[int, str, int, int, int, int]] = {}
        offset = 0
        for name, code, size, per_sensor, length in self._LAYOUT:
            offset = (offset + 7) & ~7
            rows, cols = (n_sensors if per_sensor else 1), (length or ring_size)
            self._where[name] = (offset, code, size, rows, cols, cols * size)
            offset += rows * cols * size
        self.nbytes = offset
        at, _code, _size, rows, _cols, row = self._where.pop("sensor")
        self._where["ints"] = (at, "q", 8, rows, N_INT, row)
        self._where["floats"] = (at + 8 * N_INT, "d", 8, rows, N_FLOAT, row)
        if offset > len(self.mem):
            raise ValueError(f"shared buffer of {len(self.mem)} bytes; the layout needs {offset}")
        self.glob_view = self._view("glob", 0)
        self.hist_view = self._view("hist", 0)
        self._ints_v = [self._view("ints", i) for i in range(n_sensors)]
        self._floats_v = [self._view("floats", i) for i in range(n_sensors)]
        self._arrays: dict[str, object] = {}

    def _view(self, name: str, row: int) -> memoryview[Any]:
        offset, code, size, _rows, cols, stride = self._where[name]
        start = offset + row * stride
        # typeshed types cast() per literal format code; this one comes from _LAYOUT
        return self.mem[start : start + cols * size].cast(code)  # type: ignore[call-overload]

    def sensor_views(self, i: int) -> tuple[memoryview[int], memoryview[float], memoryview]:
        """Sensor ``i``'s ints, floats and ring (its records' bytes) as memoryviews."""
        return self._view("ints", i), self._view("floats", i), self.ring_bytes(i)

    def sensor_bytes(self, i: int) -> memoryview:
        """Sensor ``i``'s ints then floats as one run of bytes (int ``k`` at ``8 k``, float
        ``k`` at ``8 (N_INT + k)``): I_SEQ .. I_STAMP_NS, F_X_TOTAL_M, F_Y_TOTAL_M in one pack."""
        offset, _code, _size, _rows, _cols, stride = self._where["ints"]
        return self.mem[offset + i * stride : offset + (i + 1) * stride]

    def ring_bytes(self, i: int) -> memoryview:
        """Sensor ``i``'s ring: ``ring_size`` records (ring_layout.RECORD) as raw bytes;
        poll ``seq`` is at byte ``(seq % ring_size) * POLL_BYTES``."""
        offset, _code, size, _rows, cols, stride = self._where["ring"]
        start = offset + i * stride
        return self.mem[start : start + cols * size]

    def __getattr__(self, name: str):
        """The numpy views (readers only: the writer never needs numpy): ``ints``,
        ``floats`` (sensors x fields), ``glob``, ``hist``, ``ring`` (sensors x slots, the
        record's structured dtype) and ``ring_stamp`` ... ``ring_quality`` (one field of
        ``ring``: strided views, writable)."""
        where = self.__dict__.get("_where")
        if where is None or (name not in where and name not in self.RING_FIELDS):
            raise AttributeError(name)
        import numpy as np

        if name in self.RING_FIELDS:
            arr = self.ring[ring_layout.NAMES[self.RING_FIELDS.index(name)]]
        else:
            offset, code, size, rows, cols, stride = where[name]
            dtype = np.dtype(ring_layout.DTYPE) if name == "ring" else np.dtype(code)
            flat = name in ("glob", "hist")
            shape = (cols,) if flat else (rows, cols)
            strides = (size,) if flat else (stride, size)
            arr = np.ndarray(shape, dtype, buffer=self.mem, offset=offset, strides=strides)
        self._arrays[name] = arr
        setattr(self, name, arr)
        return arr

    @staticmethod
    def size(n_sensors: int, ring_size: int) -> int:
        """Bytes needed for the layout (with alignment slack)."""
        per_ring = ring_layout.POLL_BYTES
        return (
            8 * n_sensors * (N_INT + N_FLOAT)
            + 8 * (N_GLOBAL + HIST_BINS)
            + n_sensors * ring_size * per_ring
            + 8 * 16
        )

    # --- reader side (the node) --------------------------------------------------------

    def snapshot(self, i: int, timeout_s: float = READ_BUDGET_S) -> Totals:
        """Consistent totals of sensor ``i``; retries while the poller writes.

        Raises :class:`PollerBusyError` when no consistent copy was possible within
        ``timeout_s`` seconds (the poller stopped mid-write); nothing is changed.
        """
        ints, floats = self._ints_v[i], self._floats_v[i]
        deadline = time.monotonic() + timeout_s
        tries = 0
        while True:
            v1 = ints[I_VERSION]
            if not v1 & 1:
                iv = ints.tolist()
                fv = floats.tolist()
                if ints[I_VERSION] == v1:
                    return Totals(*_totals_ints(iv), *fv)
            if time.monotonic() > deadline:
                raise PollerBusyError(f"{BUSY_MESSAGE} (sensor {i}, {timeout_s * 1e3:.0f} ms)")
            tries += 1
            # a writer in this process (tests) finishes at once; a stopped one takes
            # milliseconds: stop spinning then
            time.sleep(0 if tries < 100 else 0.001)

    def samples(
        self, i: int, since_seq: int, max_samples: int
    ) -> tuple[int, int, int, dict[str, np.ndarray]]:
        """Polls ``since_seq`` onwards from the ring: (first_seq, next_seq, dropped, arrays)."""
        import numpy as np

        n = self.ring_size
        seq_now = self.snapshot(i).seq
        first = max(since_seq, seq_now - n, int(self.ints[i][I_RING_FROM]))
        limit = n if max_samples <= 0 else min(max_samples, n)
        end = min(seq_now, first + limit)
        idx = np.arange(first, end, dtype=np.int64) % n
        records = self.ring[i][idx]  # one copy of the records, then each field contiguous
        arrays = {name: np.ascontiguousarray(records[name]) for name in ring_layout.NAMES}
        # Slots the poller overwrote while we copied are not trustworthy.
        oldest_valid = self.snapshot(i).seq - n
        if oldest_valid > first:
            cut = min(oldest_valid - first, end - first)
            arrays = {k: v[cut:] for k, v in arrays.items()}
            first += cut
        dropped = max(0, first - since_seq) if since_seq < first else 0
        return first, end, dropped, arrays

    def period_percentiles(self, *quantiles: float) -> list[float]:
        """Poll period quantiles in microseconds from the histogram."""
        import numpy as np

        hist = self.hist.copy()
        total = int(hist.sum())
        if total == 0:
            return [float("nan")] * len(quantiles)
        cum = np.cumsum(hist)
        # the first bin holding the ceil(q * total)-th period (at least the first one)
        return [
            float(np.searchsorted(cum, max(1.0, np.ceil(q * total)), side="left"))
            for q in quantiles
        ]


# Totals' int fields, in its order
_totals_ints = operator.itemgetter(
    I_SEQ, I_X_TOTAL, I_Y_TOTAL, I_LIFT_TOTAL, I_SPI_ERRORS, I_OVERFLOWS, I_STATE, I_CPI_X,
    I_CPI_Y, I_STAMP_NS, I_GEN_X, I_GEN_Y, I_REINITS, I_LIFT_LOST_X, I_LIFT_LOST_Y,
    I_LOW_QUALITY, I_QUALITY, I_CHIP_POSE_NS,
)  # fmt: skip
assert len(_totals_ints(range(N_INT))) + N_FLOAT == len(fields(Totals))

# The poller's hot path (channel.Channel.poll) writes these by literal index and packs
# I_SEQ .. I_STAMP_NS and the two metres as one run (they end the ints, start the floats).
assert (I_VERSION, I_SEQ, I_X_TOTAL, I_Y_TOTAL, I_STAMP_NS, N_INT) == (0, 16, 17, 18, 19, 20)
# ... and packs the ring record's fields in this order (channel.Channel.poll/record)
assert ring_layout.NAMES == ("stamp_ns", "dx", "dy", "status", "cpi", "flags", "quality")
assert (F_X_TOTAL_M, F_Y_TOTAL_M, FLAG_MOTION) == (0, 1, 2)
