"""``ros2 param set`` on the node's live parameters (:data:`mm_beagle.node.params.LIVE`).

rclpy has already checked read-only flags and ranges. A refused value keeps the old
one: frame ids are checked as at start, and a new ``cpi`` goes to every sensor like
``set_resolution`` (same checks, counts drained at the old CPI), refused as a whole if
a sensor is down or refuses it.
"""

from __future__ import annotations

import contextlib

from rcl_interfaces.msg import SetParametersResult

from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller_client import PollerError
from mm_pc.ros.tf import frame_ids_problem, prefixed


class LiveParameters:
    """The set-parameters callback of ``node`` (a BeagleNode)."""

    def __init__(self, node) -> None:
        self.node = node
        node.add_on_set_parameters_callback(self.on_set_parameters)

    def on_set_parameters(self, params) -> SetParametersResult:
        """Apply the changes, or refuse them all and keep the old values."""
        node, log = self.node, self.node.get_logger()
        changes = {p.name: p.value for p in params}
        if problem := frame_ids_problem(changes, ("odom_frame", "base_frame")):
            log.warning(f"parameters not changed: {problem}")
            return SetParametersResult(successful=False, reason=problem)
        if "cpi" in changes:
            problem = self.set_cpi_everywhere(int(changes["cpi"]))
            if problem:
                log.warning(f"parameter cpi not changed: {problem}")
                return SetParametersResult(successful=False, reason=problem)
        if "publish_rate" in changes:
            node.data_topic.set_rate(float(changes["publish_rate"]))
        if "diagnostics_period" in changes:
            node.settings.diagnostics_period = float(changes["diagnostics_period"])
            node.diagnostics.set_period(node.settings.diagnostics_period)
        o = node.settings.odometry
        for frame in ("odom_frame", "base_frame"):
            if frame in changes:
                setattr(o, frame, prefixed(o.frame_prefix, str(changes[frame])))
        if "base_frame" in changes and node.onboard is not None:
            node.onboard.send_static_frames()
        for name, value in changes.items():
            if name != "cpi":  # set_cpi logs its own line per sensor
                log.info(f"parameter {name} set to {value}")
        return SetParametersResult(successful=True)

    def set_cpi_everywhere(self, cpi: int) -> str:
        """Set every sensor to ``cpi``; '' on success, else why nothing changed."""
        node, log = self.node, self.node.get_logger()
        poller, devices, chips = node.poller, node.devices, node.chips
        problem = poller.unavailable()
        if problem:
            return problem
        down = [node.down_message(i) for i in range(len(devices)) if not node.is_up(i)]
        if down:
            return "; ".join(down)
        before = [int(poller.state.ints[i][ss.I_CPI_Y]) for i in range(len(devices))]
        fixed = [chip_config.chip_info_for(c).cpi.fixed for c in chips]
        for i, dev in enumerate(devices):
            if fixed[i]:  # optical flow: its resolution follows its height
                log.info(f"{dev} ({chips[i]}) keeps its fixed {before[i]} CPI (parameter cpi)")
                continue
            try:
                status, payload = poller.command("set_cpi", i, cpi)
            except PollerError as exc:
                status, payload = "error", str(exc)
            if status != "ok":
                for k in range(i):  # put back the sensors already changed
                    if fixed[k]:
                        continue
                    with contextlib.suppress(PollerError):
                        poller.command("set_cpi", k, before[k])
                return f"{dev}: {payload}"
            log.info(f"{dev} set to {cpi} CPI (parameter cpi)")
        return ""
