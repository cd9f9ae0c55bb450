"""The poller's commands: one table of names, arguments, their checks and the refusals.

A command reaches the poller two ways, and both are read through :data:`COMMANDS`:

- over the node's pipe as a tuple ``(name, sensor index, *args)``
  (:meth:`mm_beagle.poller.poller.Poller.serve_command` dispatches by name);
- over the board link as JSON ``{"cmd": name, "sensor": device, <arg>: value}``
  (:mod:`mm_beagle.link.agent` parses it with :func:`from_link`; the node's
  :mod:`mm_beagle.link.remote` builds it with :func:`to_link`).

Every reply is ``(status, payload)``: "ok", "invalid" (refused as asked, nothing
changed) or "error" (the sensor or the poller failed). A link request is checked in
full here before anything reaches a sensor; a refusal raises :class:`CommandRefusedError`.
Pure Python: the board's agent imports this.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

OK, INVALID, ERROR = "ok", "invalid", "error"


class CommandRefusedError(ValueError):
    """A request refused before it reached a sensor (status "invalid"); says why."""


def _cpi(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CommandRefusedError(f"'cpi' must be an integer, got {value!r}")
    return value


def _patch_file(value: object) -> str:
    if not isinstance(value, str) or not value:
        raise CommandRefusedError(
            "load_patch needs 'file': a patch file in the agent's --patch-dir"
        )
    return value


def _same(value: object) -> object:
    return value


@dataclass(frozen=True)
class Arg:
    """One argument: its JSON key on the link, the check of a value received there and
    how a sender puts the value (a patch file goes by name, never as code)."""

    name: str
    check: Callable[[object], object]  # the value as the poller takes it, or CommandRefusedError
    encode: Callable[[object], object] = _same


@dataclass(frozen=True)
class Command:
    """One command: its name, whether it names a sensor, and its arguments (in order)."""

    name: str
    doc: str
    sensor: bool = True
    args: tuple[Arg, ...] = ()
    pipe: bool = True  # the node's pipe to a local poller takes it
    link: bool = True  # the board link takes it
    # keys a link request must not carry, and why (the patch code never travels)
    forbidden: dict[str, str] = field(default_factory=dict)


COMMANDS: dict[str, Command] = {
    c.name: c
    for c in (
        Command("info", "the agent's configuration (devices, ring, chips)", sensor=False,
                pipe=False),
        Command("settings", "the register dump and the CPI in force (the read keeps its counts)"),
        Command("set_cpi", "a new resolution (drains the counts at the old one first)",
                args=(Arg("cpi", _cpi),)),
        Command(
            "load_patch",
            "PLN2033 patch code: over the link a file in the agent's patch_dir, never the code",
            args=(Arg("file", _patch_file, encode=str),),
            forbidden={
                "words": "load_patch takes 'file' (a patch file in the agent's --patch-dir), "
                "not 'words'"
            },
        ),
        Command("stop", "end the poller process", sensor=False, link=False),
    )
}  # fmt: skip

LINK_COMMANDS = tuple(name for name, c in COMMANDS.items() if c.link)
PIPE_COMMANDS = tuple(name for name, c in COMMANDS.items() if c.pipe)


# --- refusals --------------------------------------------------------------------------


def unknown_command(name: object, known: Sequence[str] = ()) -> str:
    text = f"unknown command {name!r}"
    return f"{text}; known: {', '.join(known)}" if known else text


def unknown_sensor(device: object, devices: Sequence[str]) -> str:
    return f"unknown sensor id {device!r}; known: {', '.join(devices)}"


def sensor_down(device: str, last_error: str) -> str:
    return f"sensor {device} is down ({last_error}); retrying"


def takes_no_patch(device: str, title: str) -> str:
    return f"{device} is a {title}: it takes no PLN2033 patch code"


# --- the link's JSON -------------------------------------------------------------------


def _count(what: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**63:
        raise CommandRefusedError(f"history '{what}' must be an integer >= 0, got {value!r}")
    return value


def history_request(msg: dict, n_sensors: int, max_default: int) -> tuple[int, int, int, int]:
    """A history request ``{"id", "sensor", "since", "max"}`` checked: (id, sensor index,
    since, max); ``max`` defaults to ``max_default``. Raises :class:`CommandRefusedError`."""
    rid = _count("id", msg.get("id"))
    i = _count("sensor", msg.get("sensor"))
    since = _count("since", msg.get("since"))
    most = _count("max", msg.get("max", max_default))
    if i >= n_sensors:
        raise CommandRefusedError(f"history 'sensor' {i} is not one of 0..{n_sensors - 1}")
    return rid, i, since, most


def history_ahead(since: int, newest: int) -> str:
    return f"history since {since} is ahead of the newest poll {newest}"


def to_link(name: str, device: str, *args: object) -> dict[str, object]:
    """The JSON object of one command for ``device`` (the node's remote backend)."""
    cmd = COMMANDS[name]
    if not cmd.link:
        raise ValueError(unknown_command(name, LINK_COMMANDS))
    msg: dict[str, object] = {"cmd": name}
    if cmd.sensor:
        msg["sensor"] = device
    for arg, value in zip(cmd.args, args, strict=True):
        msg[arg.name] = arg.encode(value)
    return msg


def from_link(msg: dict, devices: Sequence[str]) -> tuple[Command, int | None, tuple]:
    """A link request checked against the table: (command, sensor index, arguments).

    Raises :class:`CommandRefusedError` with the refusal message; nothing is changed."""
    name = msg.get("cmd")
    cmd = COMMANDS.get(name) if isinstance(name, str) else None
    if cmd is None or not cmd.link:
        raise CommandRefusedError(unknown_command(name, LINK_COMMANDS))
    index = None
    if cmd.sensor:
        device = msg.get("sensor")
        if not isinstance(device, str) or device not in devices:
            raise CommandRefusedError(unknown_sensor(device, devices))
        index = list(devices).index(device)
    for key, why in cmd.forbidden.items():
        if key in msg:
            raise CommandRefusedError(why)
    args = tuple(arg.check(msg.get(arg.name)) for arg in cmd.args)
    return cmd, index, args
