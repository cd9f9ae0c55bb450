"""The one command table (mm_beagle.poller.commands): what the link and the pipe take,
the checks and refusal messages a link request meets before it reaches a sensor."""

from __future__ import annotations

import pytest

from mm_beagle.poller import commands
from mm_beagle.poller.commands import COMMANDS, CommandRefusedError, from_link, to_link

DEVICES = ["/dev/spidev1.0", "/dev/spidev1.1"]


def test_the_table_names_every_command_once_and_where_it_goes():
    assert list(COMMANDS) == ["info", "settings", "set_cpi", "load_patch", "stop"]
    assert commands.LINK_COMMANDS == ("info", "settings", "set_cpi", "load_patch")
    assert commands.PIPE_COMMANDS == ("settings", "set_cpi", "load_patch", "stop")
    assert [a.name for a in COMMANDS["set_cpi"].args] == ["cpi"]
    assert [a.name for a in COMMANDS["load_patch"].args] == ["file"]


@pytest.mark.parametrize(
    ("name", "args", "msg"),
    [
        ("settings", (), {"cmd": "settings", "sensor": DEVICES[1]}),
        ("set_cpi", (3200,), {"cmd": "set_cpi", "sensor": DEVICES[1], "cpi": 3200}),
        ("load_patch", ("a.p",), {"cmd": "load_patch", "sensor": DEVICES[1], "file": "a.p"}),
    ],
)
def test_to_link_and_from_link_agree(name, args, msg):
    assert to_link(name, DEVICES[1], *args) == msg
    cmd, index, got = from_link(msg, DEVICES)
    assert (cmd.name, index, got) == (name, 1, args)


def test_info_names_no_sensor_and_stop_never_travels():
    assert to_link("info", DEVICES[0]) == {"cmd": "info"}
    assert from_link({"cmd": "info"}, DEVICES)[:2] == (COMMANDS["info"], None)
    with pytest.raises(ValueError, match="unknown command 'stop'"):
        to_link("stop", DEVICES[0])
    with pytest.raises(ValueError):  # an argument missing
        to_link("set_cpi", DEVICES[0])


@pytest.mark.parametrize(
    ("msg", "expect"),
    [
        ({"cmd": "format_disk"}, "unknown command 'format_disk'; known: info, settings, set_cpi"),
        ({"cmd": "stop"}, "unknown command 'stop'"),
        ({"cmd": ["settings"]}, "unknown command"),
        ({}, "unknown command None"),
        ({"cmd": "settings", "sensor": "/dev/spidev9.9"}, "unknown sensor id '/dev/spidev9.9'"),
        ({"cmd": "settings"}, "unknown sensor id None; known: /dev/spidev1.0, /dev/spidev1.1"),
        ({"cmd": "set_cpi", "sensor": DEVICES[0], "cpi": "800"}, "'cpi' must be an integer"),
        ({"cmd": "set_cpi", "sensor": DEVICES[0], "cpi": True}, "got True"),
        ({"cmd": "set_cpi", "sensor": DEVICES[0], "cpi": 800.0}, "got 800.0"),
        ({"cmd": "set_cpi", "sensor": DEVICES[0]}, "got None"),
        ({"cmd": "load_patch", "sensor": DEVICES[0], "words": [4660]}, "not 'words'"),
        ({"cmd": "load_patch", "sensor": DEVICES[0], "words": [1], "file": "a"}, "not 'words'"),
        ({"cmd": "load_patch", "sensor": DEVICES[0]}, "needs 'file'"),
        ({"cmd": "load_patch", "sensor": DEVICES[0], "file": 7}, "needs 'file'"),
        ({"cmd": "load_patch", "sensor": DEVICES[0], "file": ""}, "needs 'file'"),
    ],
)
def test_bad_link_requests_are_refused_with_the_tables_message(msg, expect):
    with pytest.raises(CommandRefusedError) as err:
        from_link(msg, DEVICES)
    assert expect in str(err.value)


def test_a_history_request_is_checked_field_by_field():
    assert commands.history_request({"id": 4, "sensor": 1, "since": 9}, 2, 100) == (4, 1, 9, 100)
    assert commands.history_request({"id": 0, "sensor": 0, "since": 0, "max": 5}, 2, 9)[3] == 5


@pytest.mark.parametrize(
    ("msg", "expect"),
    [
        ({"id": 1, "sensor": -1, "since": 0}, "history 'sensor' must be an integer >= 0, got -1"),
        ({"id": 1, "sensor": 2, "since": 0}, "history 'sensor' 2 is not one of 0..1"),
        ({"id": 1, "sensor": 0, "since": 1e99}, "'since' must be an integer"),
        ({"id": -5, "sensor": 0, "since": 0}, "history 'id' must be an integer >= 0, got -5"),
        ({"id": True, "sensor": 0, "since": 0}, "'id'"),
        ({"id": 1, "sensor": 0, "since": 0, "max": 2**63}, "'max'"),
        ({"sensor": 0, "since": 0}, "'id' must be an integer >= 0, got None"),
    ],
)
def test_bad_history_requests_are_refused_with_the_tables_message(msg, expect):
    with pytest.raises(CommandRefusedError) as err:
        commands.history_request(msg, 2, 100)
    assert expect in str(err.value)
