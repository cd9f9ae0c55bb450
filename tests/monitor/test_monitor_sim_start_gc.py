"""Short turns of the GUI thread (issue 29 item 6): what "Simulate mowing run" does comes in
short polls (the result's modules imported one a poll while the child builds, the result
unpickled without a garbage-collection pass), and the start-up objects are frozen out of
the collector's full passes. Functional checks; the timing is ``mm-bench gui``'s."""

from __future__ import annotations

import gc
import pickle
import subprocess
import sys
import time
from dataclasses import dataclass

import pytest

pytest.importorskip("PySide6")

from mm_pc.monitor.app import freeze_startup_objects
from mm_pc.monitor.model import sim_process


@dataclass
class Item:
    k: int
    values: tuple


def test_the_result_is_unpickled_without_a_collection(monkeypatch):
    payload = pickle.dumps([Item(k, (k, [k])) for k in range(30_000)])  # > 700 new objects
    passes, inside = [], []

    def seen(phase, info):
        if phase == "start":
            passes.append(info["generation"])

    class Spy:  # pickle, noting the collector's state as the unpickling ends
        @staticmethod
        def loads(data):
            out = pickle.loads(data)
            inside.append((gc.isenabled(), len(passes)))
            return out

    monkeypatch.setattr(sim_process, "pickle", Spy)
    gc.callbacks.append(seen)
    try:
        gc.collect()  # the counts from 0: a pass now would come from the unpickling
        passes.clear()
        items = sim_process._unpickle(payload)
        assert inside == [(False, 0)]  # off, and no pass inside
        assert gc.isenabled()  # on again afterwards
        assert len(items) == 30_000 and items[-1] == Item(29_999, (29_999, [29_999]))
        garbage = [[] for _ in range(5000)]  # allocations: the collector runs again
        assert len(garbage) == 5000
        assert passes  # the objects are collected from the next automatic pass on
        gc.disable()  # a caller's own setting is kept
        try:
            sim_process._unpickle(payload)
            assert not gc.isenabled()
        finally:
            gc.enable()
    finally:
        gc.callbacks.remove(seen)


def test_the_results_modules_are_imported_one_a_poll_before_it_is_read():
    import stall_children

    job = sim_process.SimJob(2, target=stall_children.send_big)
    n = len(sim_process.WARM_MODULES)
    try:
        for i in range(n):
            assert not job.warmed and job.slices == 0
            assert job.poll() is None
            assert len(job._to_import) == n - 1 - i  # one module a poll
        assert job.warmed
        deadline = time.monotonic() + 30
        result = None
        while result is None and time.monotonic() < deadline:
            result = job.poll()
            time.sleep(0.005)
        assert result == ("ok", bytes(range(256)) * (3_000_000 // 256))
        assert job.slices >= 3_000_000 // sim_process.READ_SLICE
    finally:
        job.cancel()


def test_the_warm_list_holds_what_the_result_module_loads_beyond_the_window():
    # in a fresh interpreter: the window's modules, then the result's module; what that adds
    # of ours is imported ahead, one a poll (a new dependency would land in one poll again)
    code = (
        "import sys, mm_pc.monitor.main_window, mm_pc.monitor.model.maps\n"
        "before = set(sys.modules)\n"
        f"import {sim_process.RESULT_MODULE}\n"
        "print(' '.join(sorted(m for m in set(sys.modules) - before if m.startswith('mm_pc'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout.split()  # fmt: skip
    warm = sim_process.WARM_MODULES
    packages = {w.rsplit(".", k)[0] for w in warm for k in (1, 2)}  # imported on the way
    assert out and set(out) <= set(warm) | packages, out
    assert sim_process.WARM_MODULES[-1] == sim_process.RESULT_MODULE


def test_the_start_up_objects_are_left_out_of_later_full_passes():
    before = [object(), [1, 2]]
    try:
        freeze_startup_objects()
        after = [3, 4]
        tracked = {id(o) for o in gc.get_objects()}  # what a full pass walks
        assert id(before[1]) not in tracked and id(after) in tracked
        assert gc.get_freeze_count() > 1000  # the test process's modules, functions, ...
        assert gc.isenabled()
    finally:
        gc.unfreeze()
    assert id(before[1]) in {id(o) for o in gc.get_objects()}


def test_the_arrived_run_is_shown_from_the_next_tick(qtbot):
    from mm_pc.monitor.context import MonitorContext
    from mm_pc.monitor.model.maps import build_sim_run
    from mm_pc.monitor.model.session import MonitorSession
    from mm_pc.monitor.widgets.maps_view.view import MapsView

    run = build_sim_run(1)

    class Arrived:  # a job whose result has just been unpickled
        seed = 1
        elapsed_s = 5.0

        def poll(self):
            return ("ok", run)

    view = MapsView(MonitorContext(MonitorSession()))
    qtbot.addWidget(view)
    view.speed_box.setCurrentText("all at once")
    view._job = Arrived()
    view._tick()  # the poll that unpickled it: nothing drawn in the same turn
    assert view._job is None and view.run is None and view.sim_button.isEnabled()
    view._tick()
    assert view.run is run and view.source == "sim" and view.sim_k == len(run.sim.t) - 1
    view._tick()
    assert view.run is run  # shown once


def send_then_linger(seed: int, conn) -> None:
    """A child that sends its result, then takes 3 s to end (a slow interpreter shutdown)."""
    conn.send(("ok", seed))
    conn.close()
    time.sleep(3.0)


def test_the_result_is_handed_over_without_waiting_for_the_child_to_end():
    job = sim_process.SimJob(5, target=send_then_linger)
    try:
        deadline = time.monotonic() + 30
        result, longest = None, 0.0
        while result is None and time.monotonic() < deadline:
            t0 = time.perf_counter()
            result = job.poll()
            longest = max(longest, time.perf_counter() - t0)
            time.sleep(0.005)
        assert result == ("ok", 5) and job.done and job.poll() is None
        assert job.process.is_alive()  # still ending: not joined on the GUI thread
        assert longest < 1.0  # no poll waited for its 3 s
    finally:
        job.process.join(10)
    assert job.process.exitcode == 0
