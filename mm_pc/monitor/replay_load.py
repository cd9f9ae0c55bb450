"""Reading a recording for a replay: at once (the command line, tests) or in slices.

File > Replay reads on the GUI thread in slices from a 0 ms timer (:class:`SlicedRead`,
at most SLICE_S a slice), so paints, the bridge's replies and every other timer run
between two slices. A worker thread did it before: decoding in Python, it held the GIL
for most of the read and the GUI thread got no turn for 0.2-0.4 s at the start of every
replay (docs/benchmarks.md, "stalls"); and a Python thread can run the garbage collector
over Qt objects (a PySide6 deadlock seen with the CSV export).
"""

from __future__ import annotations

import concurrent.futures
import gc
import time
from pathlib import Path

from PySide6.QtCore import QObject, QTimer

from mm_pc.monitor.io.mcap_reader import read_replies_up_to_cut_steps, run_steps
from mm_pc.monitor.replayer import parse_speed

__all__ = ["SLICE_S", "SlicedRead", "load_recording", "load_recording_steps"]

#: GUI time one slice of reading may take (s)
SLICE_S = 0.012


def load_recording_steps(path: str | Path, speed=1.0):
    """:func:`load_recording` as a generator of steps (:mod:`~.io.mcap_reader`)."""
    speed = parse_speed(speed)
    replies, warning = yield from read_replies_up_to_cut_steps(Path(path))
    return speed, replies, warning


def load_recording(path: str | Path, speed=1.0) -> tuple[float, list, str]:
    """(speed, replies, warning) of a recording; ValueError saying what is wrong with either.

    A file cut short (a crash, a full disk) gives the replies of its whole messages and a
    warning saying how much was read; "" for a whole file."""
    return run_steps(load_recording_steps(path, speed))


class SlicedRead(QObject):
    """Runs a generator of steps from a 0 ms timer, SLICE_S of GUI time a tick.

    ``future`` (a :class:`concurrent.futures.Future`) gets the generator's result or its
    exception; ``on_done(future)`` runs on the GUI thread once it has one. :meth:`cancel`
    stops the reading (the generator is closed, the future cancelled).

    Within a slice Python's automatic garbage collection is off and the slice ends with a
    collection of the youngest generation (~1 ms): the read allocates ~10 objects a message,
    which set off full collections of the whole process (46-89 ms each at load 6,
    measured with ``gc.callbacks``) in the middle of a slice. (Collecting generation 1
    each slice instead made a full collection due every 10 slices, between two of them.)
    """

    def __init__(self, steps, on_done, parent=None, slice_s: float = SLICE_S) -> None:
        super().__init__(parent)
        self.steps = steps
        self.on_done = on_done
        self.slice_s = slice_s
        self.future: concurrent.futures.Future = concurrent.futures.Future()
        self.slices = 0
        self.timer = QTimer(self)
        self.timer.setInterval(0)
        self.timer.timeout.connect(self._slice)
        self.timer.start()

    def _slice(self) -> None:
        deadline = time.perf_counter() + self.slice_s
        self.slices += 1
        automatic = gc.isenabled()
        gc.disable()  # see the class doc
        try:
            while time.perf_counter() < deadline:
                next(self.steps)
            return
        except StopIteration as done:
            self.future.set_result(done.value)
        except Exception as e:  # the caller decides (a ValueError is a bad file)
            self.future.set_exception(e)
        finally:
            gc.collect(0)
            if automatic:
                gc.enable()
        self.timer.stop()
        # from the event loop, not at the end of this slice: entering replay mode is
        # 20-30 ms of work of its own
        QTimer.singleShot(0, self, lambda: self.on_done(self.future))

    def cancel(self) -> None:
        if self.future.done():
            return
        self.timer.stop()
        self.steps.close()
        self.future.cancel()
