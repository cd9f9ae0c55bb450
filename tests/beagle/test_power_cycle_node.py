"""A real mm-beagle (sim backend, and remote on an mm-beagle-agent) whose first sensor is
power-cycled for 2.5 s while the robot drives straight at 0.2 m/s: /diagnostics says ERROR
"sensor reset ..." for one round with the counts lost estimated, then keeps the running
count and sum (issue 27 item 5; the estimate itself against the emulator's truth:
tests/beagle/test_power_cycle.py)."""

from __future__ import annotations

import time

import pytest
from fakes import scaled

pytest.importorskip("rclpy")

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"
SPEED = 0.2  # m/s, straight ahead: every sensor moves at it
_BOARD = {"retry_interval": 0.5, "sim_trajectory": "straight", "sim_speed": SPEED,
          "sim_fail_windows": [f"{S0}@11-13.5"]}  # fmt: skip
#: (late enough that a loaded machine has the node and this test up before the reset)
_NODE = {"diagnostics_period": 0.5}
BEAGLE_NODE = {"sim": {**_BOARD, **_NODE}, "agent": _BOARD, "remote": _NODE}

pytestmark = pytest.mark.ros


def _statuses(client, since: float) -> list:
    """The statuses of the /diagnostics the client received after ``since`` (monotonic s;
    its last few messages may still be the previous backend's node's)."""
    with client._diag_lock:
        return [s for t, m in client._diag if t > since for s in m.status]


def test_power_cycle_is_an_error_with_the_loss_estimated(node, client):
    start = time.monotonic()
    deadline = start + scaled(30)
    reset = None
    while reset is None and time.monotonic() < deadline:
        for s in _statuses(client, start):
            if s.hardware_id == S0 and s.message.startswith("sensor reset"):
                reset = s
        time.sleep(0.05)
    assert reset is not None, "no 'sensor reset' status within 30 s"
    assert reset.level == b"\x02"  # ERROR
    values = {kv.key: kv.value for kv in reset.values}
    outage = float(values["reset_outage_s"])
    assert 2.5 <= outage < 4.0  # the window, then the next retry (every 0.5 s) and bring-up
    # straight at 0.2 m/s: the loss is 0.2 m/s over the outage (less the poll that ends it)
    assert float(values["est_reset_loss_m"]) == pytest.approx(SPEED * outage, rel=0.03)
    assert f"about {max(abs(float(values['est_reset_loss_x_counts'])), abs(float(values['est_reset_loss_y_counts']))):.0f} counts" in reset.message  # noqa: E501
    assert values["sensor_resets"] == "1"
    # the other sensor was never reset
    others = [s for s in _statuses(client, start) if s.hardware_id == S1]
    assert others and all(not s.message.startswith("sensor reset") for s in others)
    # later rounds: no new reset, the running sum stays
    time.sleep(1.2)
    later = [s for s in _statuses(client, start) if s.hardware_id == S0][-1]
    lv = {kv.key: kv.value for kv in later.values}
    assert not later.message.startswith("sensor reset"), (later.message, lv)
    assert lv.get("sensor_resets") == "1", (later.message, lv)
    assert lv["est_reset_loss_total_y_counts"] == values["est_reset_loss_y_counts"]
