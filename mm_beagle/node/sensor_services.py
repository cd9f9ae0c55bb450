"""The node's four services (:data:`mm_pc.ros.services.SERVICES`), answered from the
shared state the poller (or the board's agent) writes.

  get_sensor_data      read-and-clear sums since this service's previous call (empty id:
                       every sensor that is up), or since a client's acknowledged seq
                       (:mod:`mm_beagle.poller.read_and_clear`), with the single polls
                       when asked (polls_ids)
  get_sensor_settings  all registers of one sensor, without losing counts
  set_resolution       CPI of one sensor (X and Y)
  get_samples          single polls from the ring buffer

A request the poller cannot answer right now (busy mid-write, the agent unreachable)
is refused with a message and moves no cursor.
"""

from __future__ import annotations

from mm_beagle.node import messages
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller_client import PollerError
from mm_beagle.poller.read_and_clear import ClientCursors
from mm_pc.ros.clock import node_stamp
from mm_pc.ros.services import service_types


class SensorServices:
    """The services of ``node`` (a BeagleNode), with their read-and-clear cursors from
    the totals snapshot ``start`` on: one shared by plain calls, one per ``client``."""

    def __init__(self, node, start: ss.Totals) -> None:
        self.node = node
        n = len(node.devices)
        self._served = [start] * n
        self._client_cursors = ClientCursors(n, start)  # request.client
        #: SensorData.header.frame_id of each device
        self.frames = messages.counts_frames(node.devices, node.settings.odometry)
        handlers = {
            "get_sensor_data": self.on_get_sensor_data,
            "get_sensor_settings": self.on_get_settings,
            "set_resolution": self.on_set_resolution,
            "get_samples": self.on_get_samples,
        }
        for name, srv_type in service_types().items():
            node.create_service(srv_type, f"~/{name}", handlers[name])

    def _unavailable(self, res) -> bool:
        """True (and ``res`` says why) while the remote agent cannot be reached."""
        problem = self.node.poller.unavailable()
        if problem:
            res.success, res.message = False, problem
        return bool(problem)

    def on_get_sensor_data(self, req, res):
        """Read-and-clear sums since this service's previous call, per sensor.

        With ``req.client`` set: since that client's acknowledged ``ack_seq``
        (:mod:`mm_beagle.poller.read_and_clear`; a repeated ack gets the same interval).
        """
        if self._unavailable(res):
            return res
        if req.id:
            i = self.node.poller.index(req.id)
            if i is None:
                res.success, res.message = False, self.node.unknown_id(req.id)
                return res
            if not self.node.is_up(i):
                res.success, res.message = False, self.node.down_message(i)
                return res
            wanted = [i]
        else:
            wanted = [i for i in range(len(self.node.devices)) if self.node.is_up(i)]
            down = [self.node.devices[i] for i in range(len(self.node.devices)) if i not in wanted]
            if not wanted:
                res.success, res.message = (
                    False,
                    "no sensor is up: "
                    + "; ".join(self.node.down_message(i) for i in range(len(self.node.devices))),
                )
                return res
            res.message = f"down: {', '.join(down)}" if down else ""
        polls_wanted, problem = self._polls_request(req, wanted)
        if problem:
            res.success, res.message = False, problem
            return res
        data = []
        ends: dict[int, int] = {}
        with self.node.lock:
            # every snapshot before any cursor moves: a busy poller changes nothing
            # (ClientCursors.serve also takes its snapshots before it changes a cursor)
            try:
                if req.client or len(req.ack_seq):
                    intervals, problem = self._client_cursors.serve(
                        req.client,
                        wanted,
                        list(req.ack_seq),
                        self.node.poller.state.snapshot,
                        one_id=bool(req.id),
                    )
                    if problem:
                        res.success, res.message = False, problem
                        return res
                else:
                    nows = [self.node.poller.state.snapshot(i) for i in wanted]
                    intervals = []
                    for i, now in zip(wanted, nows, strict=True):
                        intervals.append((self._served[i], now))
                        self._served[i] = now
            except ss.PollerBusyError:
                res.success, res.message = False, ss.BUSY_MESSAGE
                return res
            for i, (prev, now) in zip(wanted, intervals, strict=True):
                node = self.node
                msg = messages.sensor_data(
                    node.devices[i], prev, now, node.instance_id, node.chips[i],
                    self.frames[i], node_stamp(node, now.stamp_ns),
                )  # fmt: skip
                data.append(msg)
                ends[i] = now.seq
        res.data = data
        res.polls, busy = self._polls_for(polls_wanted, ends)
        if busy:
            note = f"no polls for {', '.join(busy)}: {ss.BUSY_MESSAGE} (ask get_samples)"
            res.message = f"{res.message}; {note}" if res.message else note
        res.success = True
        return res

    def _polls_request(self, req, wanted: list[int]) -> tuple[list[tuple[int, int]], str]:
        """``req.polls_ids``/``polls_since_seq`` checked: ([(index, since_seq)], '') for the
        sensors of ``wanted`` (a down sensor named there is left out: it has no data either),
        or ([], why not) -- checked before any cursor moves, so a bad request changes nothing."""
        ids, sinces = list(req.polls_ids), [int(s) for s in req.polls_since_seq]
        if len(ids) != len(sinces):
            return [], (
                f"polls_ids has {len(ids)} entries and polls_since_seq {len(sinces)}; "
                "give one since_seq per sensor id (both empty for no polls)"
            )
        out: list[tuple[int, int]] = []
        seen: set[int] = set()
        for dev, since in zip(ids, sinces, strict=True):
            i = self.node.poller.index(dev)
            if i is None:
                return [], f"polls_ids: {self.node.unknown_id(dev)}"
            if i in seen:
                return [], f"polls_ids names {dev} twice; name each sensor at most once"
            seen.add(i)
            if req.id and dev != req.id:
                return [], (
                    f"polls_ids names {dev}, but this request reads only {req.id}; "
                    "ask for the polls of the sensors you read"
                )
            seq_now = int(self.node.poller.state.ints[i][ss.I_SEQ])
            if since > seq_now:
                return [], (
                    f"polls_since_seq {since} for {dev} is ahead of the newest poll "
                    f"({seq_now}); ask with the next_seq of the previous polls "
                    "(or 0 for the oldest stored), and after a node restart without polls once"
                )
            if i in wanted:
                out.append((i, since))
        return out, ""

    def _polls_for(self, wanted: list[tuple[int, int]], ends: dict[int, int]):
        """([SensorPolls], [devices whose ring was busy]): each sensor's polls from its
        since_seq up to ``ends[i]``, the seq of its SensorData in this reply."""
        polls, busy = [], []
        state = self.node.poller.state
        for i, since in wanted:
            end = ends[i]
            cpi_now = int(state.ints[i][ss.I_CPI_Y])
            if end <= since:  # nothing new (or an interval served again after a lost reply)
                fields = ("stamp_ns", "dx", "dy", "status", "cpi", "flags", "quality")
                empty = {k: () for k in fields}
                dev = self.node.devices[i]
                polls.append(messages.sensor_polls(dev, since, since, 0, empty, cpi_now))
                continue
            try:
                first, nxt, dropped, arr = state.samples(i, since, end - since)
            except ss.PollerBusyError:
                busy.append(self.node.devices[i])
                continue
            if nxt > end:  # since_seq had left the ring: stop at this reply's seq all the same
                keep = max(0, end - first)
                arr, nxt = {k: v[:keep] for k, v in arr.items()}, first + keep
            polls.append(
                messages.sensor_polls(self.node.devices[i], first, nxt, dropped, arr, cpi_now)
            )
        return polls, busy

    def _poller_command(self, res, sensor_id: str, kind: str, *args) -> tuple[int, object]:
        """Run a poller command for one sensor id: (index, payload), or (-1, None) on failure.

        On failure ``res`` already carries success=false and the reason.
        """
        i = self.node.poller.index(sensor_id)
        if i is None:
            res.success, res.message = False, self.node.unknown_id(sensor_id)
            return -1, None
        try:
            status, payload = self.node.poller.command(kind, i, *args)
        except PollerError as exc:
            res.success, res.message = False, str(exc)
            return -1, None
        if status != "ok":
            res.success, res.message = False, str(payload)
            return -1, None
        return i, payload

    def on_get_settings(self, req, res):
        """All registers of one sensor; the displacement that read cleared is kept."""
        i, payload = self._poller_command(res, req.id, "settings")
        if i >= 0:
            res.settings = messages.sensor_settings(self.node.devices[i], payload)
            res.success = True
        return res

    def on_set_resolution(self, req, res):
        """Set one sensor's CPI (X and Y); ``res.cpi`` is the CPI in force afterwards."""
        i, _ = self._poller_command(res, req.id, "set_cpi", int(req.cpi))
        known = self.node.poller.index(req.id)
        if known is not None:  # the CPI in force, whether or not the request succeeded
            res.cpi = int(self.node.poller.state.ints[known][ss.I_CPI_Y])
        if i >= 0:
            res.success = True
            res.message = f"{self.node.devices[i]} set to {res.cpi} CPI"
            self.node.get_logger().info(res.message)
        return res

    def on_get_samples(self, req, res):
        """Single polls from the ring, since ``since_seq`` (chained by ``next_seq``)."""
        if self._unavailable(res):
            return res
        i = self.node.poller.index(req.id)
        if i is None:
            res.success, res.message = False, self.node.unknown_id(req.id)
            return res
        seq_now = int(self.node.poller.state.ints[i][ss.I_SEQ])
        if req.since_seq > seq_now:
            res.success = False
            res.message = f"since_seq {req.since_seq} is ahead of the newest poll ({seq_now})"
            return res
        try:
            first, nxt, dropped, arr = self.node.poller.state.samples(
                i, req.since_seq, req.max_samples
            )
        except ss.PollerBusyError:
            res.success, res.message = False, ss.BUSY_MESSAGE
            return res
        messages.fill_polls(
            res, first, nxt, dropped, arr, int(self.node.poller.state.ints[i][ss.I_CPI_Y])
        )
        res.instance_id = self.node.instance_id
        res.success = True
        if dropped:
            res.message = f"{dropped} polls had already left the ring buffer"
        return res
