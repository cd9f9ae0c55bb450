"""A poller that stalls (SIGSTOP, what a busy single-core board does) never stops the node.

Real processes: mm-beagle with the sim backend, its spawned poller found as the
node's child, stopped and continued from here.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

import psutil
import pytest
from fakes import scaled, wait_until

rclpy = pytest.importorskip("rclpy")

from mm_beagle.poller.shared_state import BUSY_MESSAGE  # noqa: E402
from mm_beagle.tools.harness import beagle_process  # noqa: E402

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"

pytestmark = pytest.mark.ros


def poller_pid(node_pid: int, timeout: float = 60.0) -> int:
    """The node's poller: its child started by multiprocessing.spawn (not the resource tracker)."""

    def spawned() -> int | None:
        for child in psutil.Process(node_pid).children():
            try:
                if "spawn_main" in " ".join(child.cmdline()):
                    return child.pid
            except psutil.Error:
                continue
        return None

    return wait_until(spawned, timeout, "a poller process under the node", interval=0.1)


def start_node(client, tmp_path, **extra):
    log = tmp_path / "mm_beagle.log"
    params = {"backend": "sim", "sim_trajectory": "figure_eight", "diagnostics_period": 0.5}
    return beagle_process({**params, **extra}, env=dict(os.environ), log_path=str(log)), log


def wait_up(client, log):
    """Until a reply serves both sensors: right after a (re)start of the poller a sensor
    may still be down, and the reply then serves the other alone ("down: ...")."""
    assert client.wait(scaled(60)), f"services did not come up; log:\n{log.read_text()}"

    def both_served() -> bool:
        res = client.call("get_sensor_data", id="", timeout=scaled(30))
        return res.success and {d.id for d in res.data} == {S0, S1}

    try:
        wait_until(both_served, 60, "a reply serving both sensors", interval=0.2)
    except AssertionError as exc:
        raise AssertionError(f"{exc}; log:\n{log.read_text()}") from None


def test_60ms_stop_bursts_never_stop_the_node_and_keep_totals_exact(client, tmp_path):
    ctx, log = start_node(client, tmp_path)
    with ctx as proc:
        wait_up(client, log)
        pid = poller_pid(proc.pid)
        done = threading.Event()
        bursts = [0]

        def stall() -> None:  # stopped 60 ms of every 80 ms
            while not done.is_set():
                os.kill(pid, signal.SIGSTOP)
                time.sleep(0.06)
                os.kill(pid, signal.SIGCONT)
                bursts[0] += 1
                time.sleep(0.02)

        t = threading.Thread(target=stall, daemon=True)
        failures, served = [], 0
        t.start()
        try:
            end = time.monotonic() + 5.0  # 5 s of calls through the bursts
            while time.monotonic() < end:
                res = client.call("get_sensor_data", id="", timeout=scaled(30))
                if res.success:
                    served += 1
                else:
                    failures.append(res.message)
                res = client.call(
                    "get_samples", id=S0, since_seq=0, max_samples=50, timeout=scaled(30)
                )
                if not res.success:
                    failures.append(res.message)
        finally:
            done.set()
            t.join(scaled(10))
            os.kill(pid, signal.SIGCONT)
        assert bursts[0] >= 40
        assert proc.poll() is None, log.read_text()[-3000:]
        assert served > 0
        assert all(m == BUSY_MESSAGE for m in failures), failures
        # the totals are exact: every count the emulators generated was counted
        diag = client.diagnostics(time.monotonic(), timeout=scaled(30))
        for dev in (S0, S1):
            assert int(diag[dev]["sim_generated_x_counts"]) == int(diag[dev]["x_total_counts"])
            assert int(diag[dev]["sim_generated_y_counts"]) == int(diag[dev]["y_total_counts"])
            assert int(diag[dev]["y_total_counts"]) != 0
            assert diag[dev]["poller_restarts"] == "0"  # bursts are stalls, not a stuck poller
        assert proc.poll() is None


def test_a_stuck_poller_is_reported_and_restarted(client, tmp_path):
    """Stopped for longer than POLLER_STUCK_S: ERROR on /diagnostics, a new poller, totals go on."""
    ctx, log = start_node(client, tmp_path)
    with ctx as proc:
        wait_up(client, log)
        before = {d.id: d for d in client.call("get_sensor_data", id="").data}
        pid = poller_pid(proc.pid)
        os.kill(pid, signal.SIGSTOP)
        try:

            def stuck_error() -> bool:
                with client._diag_lock:
                    msgs = [m for _, m in client._diag]
                return any(
                    s.level == b"\x02" and "stuck" in s.message for m in msgs for s in m.status
                )

            try:
                wait_until(stuck_error, 60, "an ERROR status saying the poller is stuck",
                           interval=0.1)
            except AssertionError as exc:
                raise AssertionError(f"{exc}; log:\n{log.read_text()[-3000:]}") from None
        finally:
            with contextlib.suppress(ProcessLookupError):  # the node should have killed it
                os.kill(pid, signal.SIGCONT)
        assert proc.poll() is None
        new_pid = poller_pid(proc.pid)
        assert new_pid != pid
        wait_up(client, log)
        after = {d.id: d for d in client.call("get_sensor_data", id="").data}
        for dev in (S0, S1):
            assert after[dev].seq > before[dev].seq  # seq and totals carry on, never go back
        diag = client.diagnostics(time.monotonic(), timeout=scaled(30))
        assert all(v["poller_restarts"] == "1" for v in diag.values())
        assert "restarted" in log.read_text()


def test_a_poller_stopped_mid_write_gets_busy_answers_that_change_nothing():
    """The node in this process; its real poller stopped with the version odd (mid-write)."""
    from rclpy.parameter import Parameter

    from mm_beagle.node.node import BeagleNode
    from mm_beagle.poller import shared_state as ss
    from mm_interfaces.srv import GetSamples, GetSensorData

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = BeagleNode(
        context=ctx, parameter_overrides=[Parameter("backend", value="sim")]
    )
    try:
        ints = node.poller.state.ints
        req = GetSensorData.Request(id=S0)
        first = node.on_get_sensor_data(req, GetSensorData.Response())
        assert first.success, first.message
        pid = node.poller.process.pid
        os.kill(pid, signal.SIGSTOP)
        odd_by_us = not ints[0][ss.I_VERSION] & 1
        if odd_by_us:  # stopped between writes: make it look stopped inside one
            ints[0][ss.I_VERSION] += 1
        try:
            res = node.on_get_sensor_data(req, GetSensorData.Response())
            assert (res.success, res.message, list(res.data)) == (False, BUSY_MESSAGE, [])
            token = GetSensorData.Request(id=S0, client="stall-test")  # the per-client cursors
            res = node.on_get_sensor_data(token, GetSensorData.Response())
            assert (res.success, res.message) == (False, BUSY_MESSAGE)
            res = node.on_get_samples(
                GetSamples.Request(id=S0, since_seq=0), GetSamples.Response()
            )
            assert (res.success, res.message) == (False, BUSY_MESSAGE)
            node.publish_diagnostics()  # skips its round, does not raise
            node.publish_data()
        finally:
            if odd_by_us:
                ints[0][ss.I_VERSION] -= 1
            os.kill(pid, signal.SIGCONT)

        def served():  # the poller finishes its write once continued; until then: busy again
            r = node.on_get_sensor_data(req, GetSensorData.Response())
            return r if r.success else None

        res = wait_until(served, 30, "a reply once the poller is continued")
        (d,) = res.data
        # the refused call moved no cursor: this interval starts where the first one ended
        assert d.samples == d.seq - first.data[0].seq
        assert d.x_counts == d.x_total_counts - first.data[0].x_total_counts
        # the refused client request left no cursor behind: it starts as a new client
        res = node.on_get_sensor_data(token, GetSensorData.Response())
        assert res.success, res.message
    finally:
        node.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def _collect(client, newer_than: float, seen: dict) -> list:
    """Add the client's /diagnostics received after ``newer_than`` to ``seen``; return
    every status in ``seen``, oldest first. The client keeps only its newest 5 messages:
    call this often."""
    with client._diag_lock:
        for t, m in client._diag:
            if t > newer_than:
                seen[id(m)] = (t, m)
    msgs = [m for _, m in sorted(seen.values(), key=lambda tm: tm[0])]
    return [(s.hardware_id, s.level, s.message, {kv.key: kv.value for kv in s.values})
            for m in msgs for s in m.status]  # fmt: skip


def _statuses(client, newer_than: float, duration: float):
    """Every /diagnostics status received after ``newer_than``, collected for ``duration`` s."""
    seen: dict[int, object] = {}
    end = time.monotonic() + duration
    while time.monotonic() < end:
        _collect(client, newer_than, seen)
        time.sleep(0.05)
    return _collect(client, newer_than, seen)


def _wait_status(client, newer_than: float, wanted, what: str, timeout: float = 30.0) -> list:
    """The statuses received after ``newer_than`` for which ``wanted(status)``, once any came."""
    seen: dict[int, object] = {}
    return wait_until(
        lambda: [s for s in _collect(client, newer_than, seen) if wanted(s)], timeout, what,
        interval=0.05,
    )


def _wait_clear(client, timeout: float = 60.0):
    """The first round (0.6 s of statuses) in which none reports a stall or a wrap (and none
    is ERROR). A loaded machine may still WARN for overruns: that is not what these tests watch.
    """

    def clear_round():
        got = _statuses(client, time.monotonic(), 0.6)
        if got and all(s[1] != b"\x02" and "stall" not in s[2] and "wrapped" not in s[2]
                       for s in got):  # fmt: skip
            return got
        return None

    return wait_until(clear_round, timeout, "a round of statuses without a stall or a wrap",
                      interval=0)


def test_diagnostics_warn_on_a_stall_error_on_a_wrap_and_back_to_ok(client, tmp_path):
    ctx, log = start_node(client, tmp_path, diagnostics_period=0.25)
    with ctx as proc:
        wait_up(client, log)
        pid = poller_pid(proc.pid)
        _wait_clear(client)
        t0 = time.monotonic()
        os.kill(pid, signal.SIGSTOP)
        time.sleep(0.3)  # the stall
        os.kill(pid, signal.SIGCONT)
        warned = _wait_status(client, t0, lambda s: s[1] == b"\x01" and "stall" in s[2],
                              "a WARN status for the stall")
        assert float(warned[0][3]["longest_poll_gap_ms"]) > 50
        _wait_clear(client)
        # 4 s without a poll while the robot drives: the 16-bit counter may have wrapped
        t0 = time.monotonic()
        os.kill(pid, signal.SIGSTOP)
        try:
            during = _statuses(client, t0, 4.0)  # the 4-s stop
        finally:
            os.kill(pid, signal.SIGCONT)

        def wrapped(s) -> bool:
            return s[1] == b"\x02" and "wrapped" in s[2]

        errors = [s for s in during if wrapped(s)] or _wait_status(
            client, time.monotonic(), wrapped, "an ERROR status for the wrapped counter"
        )
        assert int(errors[0][3]["est_wrap_loss_counts"]) >= 65_536
        assert float(errors[0][3]["est_wrap_loss_m"]) > 0.5
        _wait_clear(client)
        assert proc.poll() is None


EXIT_CODE_SCRIPT = """
import sys
from mm_beagle.node import node
from mm_pc.ros import spin

class Fake:
    fatal = ""
    def __init__(self, *a, **k):
        if sys.argv[1] == "config":
            raise ValueError("'backend' is 'foo'; allowed: spidev, sim")
    def shutdown(self): pass
    def destroy_node(self): pass

def spin_until(n, stop):
    raise TimeoutError("the poller process holds the shared state")

node.BeagleNode = Fake
spin.spin_until = spin_until
sys.exit(node.main([]))
"""


@pytest.mark.parametrize(("case", "code", "text"), [
    ("config", 2, "mm-beagle: 'backend' is 'foo'"),
    ("runtime", 1, "stopped by an error at run time: TimeoutError"),
])  # fmt: skip
def test_exit_code_2_only_for_bad_configuration(case, code, text):
    """A TimeoutError (an OSError) at run time is not reported as bad configuration."""
    import subprocess
    import sys

    r = subprocess.run(
        [sys.executable, "-c", EXIT_CODE_SCRIPT, case],
        capture_output=True, text=True, timeout=scaled(120), env=dict(os.environ),
    )  # fmt: skip
    assert r.returncode == code, r.stderr
    assert text in r.stderr
    assert "Traceback" not in r.stderr
