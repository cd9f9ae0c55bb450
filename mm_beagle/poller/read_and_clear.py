"""Per-client read-and-clear cursors that survive a lost reply (docs/beagle-node.md §3.1).

A read-and-clear reply is the difference of two snapshots of a sensor's monotone
totals (:class:`~mm_beagle.poller.shared_state.Totals`). With one shared cursor a reply
that DDS drops has still moved the cursor, and its interval is gone for the
client. Here each client (named by a token in the request) has, per sensor, the
start of its interval (``acked``: the end of the last interval it acknowledged)
and the end of the interval it was last served (``served``). The client sends
back the ``seq`` of the last reply it received:

- ``ack == served.seq``: received; the next interval is served.seq -> now.
- ``ack == acked.seq``: the reply was lost; the same interval is served again.
- anything else: refused, nothing changes.

No ROS here: the node (``on_get_sensor_data``) holds one :class:`ClientCursors`
under its lock and turns the intervals into messages.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from mm_beagle.poller.shared_state import Totals

MAX_CLIENTS = 64  # least recently served clients beyond this are forgotten
MAX_TOKEN = 128  # characters of a client token


@dataclass
class _Cursor:
    acked: Totals  # start of the interval: end of the last acknowledged one
    served: Totals | None  # end of the interval last served, until acknowledged


class ClientCursors:
    """The read-and-clear state of up to ``max_clients`` clients of ``n_sensors`` sensors."""

    def __init__(self, n_sensors: int, start: Totals, max_clients: int = MAX_CLIENTS) -> None:
        self.n_sensors = n_sensors
        self.start = start  # what a new client's first interval starts from (node start)
        self.max_clients = max_clients
        self._clients: OrderedDict[str, list[_Cursor]] = OrderedDict()
        self.forgotten = 0  # clients dropped to stay within max_clients

    def __len__(self) -> int:
        return len(self._clients)

    def serve(
        self,
        client: str,
        wanted: Sequence[int],
        acks: Sequence[int],
        snapshot: Callable[[int], Totals],
        one_id: bool = False,
    ) -> tuple[list[tuple[Totals, Totals]], str]:
        """The intervals (start, end) for the sensors ``wanted``, or ([], why not).

        ``acks`` holds one seq per sensor of the node (for an empty id), one for the
        one sensor asked for (``one_id``; ``wanted`` has its index), or none (all 0:
        nothing received yet).
        ``snapshot(i)`` gives sensor i's totals now. A refusal changes nothing.
        """
        if not client or len(client) > MAX_TOKEN or not client.isprintable():
            return [], f"client token must be 1 to {MAX_TOKEN} printable characters"
        if not acks:
            acks = [self.start.seq] * (1 if one_id else self.n_sensors)
        if one_id and len(acks) == 1:
            by_sensor = {wanted[0]: int(acks[0])}
        elif not one_id and len(acks) == self.n_sensors:
            by_sensor = {i: int(acks[i]) for i in wanted}
        else:
            want = "1" if one_id else f"{self.n_sensors} (the order of the devices parameter)"
            return [], f"ack_seq has {len(acks)} entries; this request needs {want}, or none"
        cursors = self._clients.get(client)
        if cursors is None:
            stale = {i: a for i, a in by_sensor.items() if a != self.start.seq}
            if stale:
                return [], (
                    f"unknown client '{client}' with ack_seq {sorted(stale.values())}: "
                    f"never served, or forgotten (only the {self.max_clients} most recent "
                    "clients are kept); start again with ack_seq empty and re-baseline "
                    "on the totals"
                )
            cursors = [_Cursor(self.start, None) for _ in range(self.n_sensors)]
        nows = {i: snapshot(i) for i in by_sensor}
        repeat: dict[int, bool] = {}  # per sensor: serve the same interval again?
        for i, ack in by_sensor.items():
            c = cursors[i]
            if ack > nows[i].seq:
                return [], f"ack_seq {ack} is ahead of the newest poll ({nows[i].seq})"
            if c.served is not None and ack == c.served.seq:
                repeat[i] = False  # received: that interval is done
            elif ack == c.acked.seq:
                repeat[i] = c.served is not None  # lost (or the first request)
            else:
                expected = [c.acked.seq] + ([c.served.seq] if c.served is not None else [])
                return [], (
                    f"ack_seq {ack} is not the seq of a reply this client was served "
                    f"(expected one of {expected})"
                )
        out = []
        for i in wanted:
            c = cursors[i]
            if repeat[i] and c.served is not None:  # (a repeat always has a served interval)
                start, end = c.acked, c.served
            else:
                start, end = (c.served if c.served is not None else c.acked), nows[i]
            c.acked, c.served = start, end
            out.append((start, end))
        self._clients[client] = cursors
        self._clients.move_to_end(client)
        while len(self._clients) > self.max_clients:
            self._clients.popitem(last=False)
            self.forgotten += 1
        return out, ""


class AckedReader:
    """The client side: the request fields of the ack protocol, and what to ack next.

    ``devices``: the node's sensors in the order of its ``devices`` parameter.
    Call :meth:`fields` for each request (the same fields again after a lost
    reply) and :meth:`received` with each reply that arrived.
    """

    def __init__(self, client: str, devices: Sequence[str]) -> None:
        self.client = client
        self.devices = list(devices)
        self.acks = dict.fromkeys(self.devices, 0)  # seq of the last reply received

    def fields(self, sensor_id: str = "") -> dict:
        """Keyword fields of a GetSensorData request for ``sensor_id`` ('' = all)."""
        acks = [self.acks[sensor_id]] if sensor_id else [self.acks[d] for d in self.devices]
        return {"id": sensor_id, "client": self.client, "ack_seq": acks}

    def received(self, res) -> None:
        """Note the seq of every sensor in a successful reply (it is acked next time)."""
        if res.success:
            for d in res.data:
                self.acks[d.id] = int(d.seq)
