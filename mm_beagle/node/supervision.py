"""The node watching its poller: first bring-up, events, a stuck poller restarted.

Every 0.2 s the node logs what the poller reported (sensor up/down, fatal), restarts a
local poller whose poll count stood still for :data:`POLLER_STUCK_S`, and stops itself
(exit 1) once the poller is gone: without it the node has nothing to serve.
"""

from __future__ import annotations

import time

from mm_beagle.link.remote import RemoteAgent
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller_client import PollerClient

# A local poller whose poll count has not moved for this long (s) while its
# process lives is stuck (stopped, or hung mid-write): reported on /diagnostics
# as ERROR and restarted. Longer than any stall the diagnostics should report
# as a stall (a 4 s stop still gets its counter-wrap ERROR first).
POLLER_STUCK_S = 5.0


class StartupError(RuntimeError):
    """The poller could not start (its message says why)."""


class PollerSupervisor:
    """Watches the poller of ``node`` (a BeagleNode) and keeps ``node.last_errors``,
    ``node.fatal`` and ``node.stuck`` up to date."""

    def __init__(self, node) -> None:
        self.node = node
        self.progress = (-1, time.monotonic())  # (G_POLLS, when it last changed)

    def start_timer(self) -> None:
        self.node.create_timer(0.2, self.relay_poller_events)

    def wait_for_first_bring_up(self, timeout: float, stop=None) -> None:
        """Return once every sensor is up or has failed once (the services come after).

        With the remote backend an unreachable agent does not stop the node:
        the services say so until the link comes up.
        """
        node, poller = self.node, self.node.poller
        ints = poller.state.ints
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and poller.alive:
            if stop is not None and stop.is_set():  # SIGINT/SIGTERM while it waits
                return
            if all(int(ints[i][ss.I_STATE]) != ss.STATE_STARTING for i in range(len(node.devices))):
                break
            time.sleep(0.02)
        if isinstance(poller, RemoteAgent) and poller.unavailable():
            node.get_logger().warning(f"{poller.unavailable()}; serving that until it is")
        for event in poller.drain_events():
            if event[0] == "fatal":  # e.g. an unreadable patch file or register map
                poller.stop()
                raise StartupError(str(event[1]))
            self.relay(event)
        if not poller.alive:
            raise StartupError("the poller process died while starting")

    def relay_poller_events(self) -> None:
        """Log what the poller reported; restart a stuck one; stop the node if it is gone."""
        node = self.node
        for event in node.poller.drain_events():
            self.relay(event)
        self.check_progress()
        if not node.poller.alive:
            node.fatal = node.fatal or "the poller process is gone"
            node.get_logger().fatal(f"{node.fatal}; shutting down")
            node.context.try_shutdown()

    def check_progress(self) -> None:
        """Restart a local poller whose poll count stood still for POLLER_STUCK_S."""
        node, poller = self.node, self.node.poller
        if not isinstance(poller, PollerClient) or not poller.alive:
            return
        polls, now = int(poller.state.glob[ss.G_POLLS]), time.monotonic()
        if polls != self.progress[0]:
            self.progress = (polls, now)
            return
        if now - self.progress[1] < POLLER_STUCK_S:
            return
        node.stuck = (
            f"poller stuck: no poll for {now - self.progress[1]:.1f} s "
            f"(limit {POLLER_STUCK_S:g} s); restarted it"
        )
        node.get_logger().error(node.stuck)
        node.diagnostics.publish()  # the ERROR goes out before the restart
        poller.restart()
        self.progress = (-1, time.monotonic())

    def relay(self, event: tuple) -> None:
        """Log one poller event and keep what the services need from it."""
        node = self.node
        log = node.get_logger()
        kind = event[0]
        if kind == "up":
            i = node.poller.index(event[1])
            if i is not None:
                node.last_errors[i] = ""
            log.info(f"sensor {event[1]} up: {event[2]}")
        elif kind == "down":
            i = node.poller.index(event[1])
            if i is not None:
                node.last_errors[i] = event[2]
            log.error(f"sensor {event[1]} down: {event[2]}")
        elif kind == "fatal":
            log.fatal(f"poller stopped: {event[1]}")
            node.fatal = str(event[1])
        else:
            log.info(str(event[1]))
