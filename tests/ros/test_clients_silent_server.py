"""No client of ours waits forever on a server that takes requests and never answers.

A stand-in ``/mm_silent/mm_beagle`` offers mm-beagle's four services, takes every request
and sends no response (as mm-beagle's "failed to send response (timeout)", for every
request). mm-odometry against such a server: tests/ros/test_odometry_lost_replies.py. Here
the harness's BeagleClient (mm-bench's clients, the demo, the tests) and the monitor's
bridge: each call is given up at its deadline, rclpy forgets it, and the next goes out
(issue 25 item 1).
"""

from __future__ import annotations

import threading
import time

import pytest
from fakes import scaled, wait_until

pytest.importorskip("rclpy")

from mm_pc.ros.services import service_types

NAMESPACE = "/mm_silent"


@pytest.fixture
def silent_beagle():
    """``/mm_silent/mm_beagle`` whose services count requests and answer none."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("mm_beagle", namespace=NAMESPACE, context=ctx)
    taken: dict[str, int] = {}
    lock = threading.Lock()
    for name, srv_type in service_types().items():

        def take(request, response, name=name):
            with lock:
                taken[name] = taken.get(name, 0) + 1
            return response

        srv = node.create_service(srv_type, f"~/{name}", take)
        srv.send_response = lambda response, header: None  # taken, never answered
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield taken
    finally:
        stop.set()
        thread.join(5)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        ctx.try_shutdown()


@pytest.mark.ros
def test_beagle_client_gives_up_each_call_and_asks_again(silent_beagle):
    from mm_beagle.tools.harness import BeagleClient

    client = BeagleClient("mm_silent_client", namespace=f"{NAMESPACE}/mm_beagle")
    try:
        assert client.wait(scaled(20)), "the stand-in's services were not discovered"
        for n in (1, 2):
            t0 = time.monotonic()
            with pytest.raises(TimeoutError, match=r"get_sensor_data did not answer within 0\.5 s"):
                client.call("get_sensor_data", timeout=0.5, id="")
            assert 0.5 <= time.monotonic() - t0 < scaled(3.0)
            wait_until(lambda n=n: silent_beagle.get("get_sensor_data") == n, 5,
                       f"request {n} at the server")  # fmt: skip
            assert not client.clients["get_sensor_data"]._pending_requests  # forgotten
        with pytest.raises(TimeoutError, match=r"get_samples did not answer within 0\.3 s"):
            client.call("get_samples", timeout=0.3, retries=1, id="/dev/spidev1.0")
        wait_until(lambda: silent_beagle.get("get_samples") == 2, 5, "the retried get_samples")
    finally:
        client.close()


@pytest.mark.ros
def test_monitor_bridge_keeps_asking_a_server_that_never_answers(qapp, silent_beagle):
    """Each data request is dropped at ``timeout_s`` and the next one goes out: the
    bridge says 'no reply within', goes to 'lost' and never stops asking."""
    pytest.importorskip("PySide6")
    from mm_pc.monitor.ros_bridge import LOST, RosBridge

    bridge = RosBridge(beagle=f"{NAMESPACE}/mm_beagle", rate_hz=20.0, timeout_s=0.3,
                       node_name="mm_silent_monitor", fetch_polls=False)  # fmt: skip
    failures: list[str] = []
    bridge.data_failed.connect(failures.append)
    bridge.start()
    try:
        wait_until(lambda: bridge.dropped_requests >= 3, 20, "three requests given up",
                   pump=qapp.processEvents)  # fmt: skip
        assert bridge.replies == 0 and bridge.requests >= 3
        # at most max_in_flight (2) still out: a second request goes out while one waits
        assert bridge.requests - bridge.dropped_requests <= bridge.max_in_flight
        wait_until(lambda: silent_beagle.get("get_sensor_data", 0) >= 3, 5, "3 at the server")
        wait_until(lambda: "no reply within 0.3 s" in failures, 5, "the failure's message",
                   pump=qapp.processEvents)  # fmt: skip
        assert bridge.state == LOST
    finally:
        bridge.stop()
