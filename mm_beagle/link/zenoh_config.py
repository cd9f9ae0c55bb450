"""The zenoh sessions of the board link: endpoints, access control, configurations.

:func:`zenoh_config` is the one configuration both sides build on (no scouting, only the
endpoints given, user/password with credentials); the agent listens as a peer with
:func:`agent_acl` and the limits of :func:`agent_zenoh_config`, the node connects as a
client (no shared memory, messages up to :data:`mm_beagle.link.link.NODE_RX_MAX_BYTES`).
"""

from __future__ import annotations

import ipaddress
import json
import os
from pathlib import Path

from mm_beagle.link.agent_requests import RX_MAX_MESSAGE_BYTES
from mm_beagle.link.link import DEFAULT_ENDPOINT, NODE_RX_MAX_BYTES, LinkError
from mm_beagle.link.link_auth import load_credentials

TX_BATCH_BYTES = 16384  # the agent's zenoh batches (memory per queued message; zenoh: 65535)
# zenoh's log on the agent: only its lines about peers accepted or refused (credentials)
ZENOH_LOG = "off,zenoh_transport::unicast::establishment::accept=debug"


def endpoint_host(endpoint: str) -> str:
    """``tcp/127.0.0.1:7447`` -> ``127.0.0.1``; LinkError for anything else."""
    proto, _, rest = endpoint.partition("/")
    if proto not in ("tcp", "tls", "quic", "udp") or not rest or ":" not in rest:
        raise LinkError(
            f"endpoint '{endpoint}' is not PROTO/HOST:PORT (e.g. {DEFAULT_ENDPOINT}, "
            "tcp/192.168.7.2:7447)"
        )
    host, _, port = rest.rpartition(":")
    port = port.split("#", 1)[0]
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise LinkError(f"endpoint '{endpoint}' has no valid port")
    return host.strip("[]")


def is_loopback(endpoint: str) -> bool:
    host = endpoint_host(endpoint)
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


AGENT_KEYS = ("polls", "status", "events", "history", "cmd")  # what only the agent sends


def agent_acl() -> dict:
    """zenoh access control for the agent's session: no peer may put on the keys only the
    agent publishes (polls, status, events, history), nor declare a queryable on ``cmd``
    or reply to a query there. Every connected peer is such a subject (zenoh's subject
    with no criteria matches all): nodes only put history requests and query ``cmd``.
    The node is a client of the agent's session, so everything it receives passes here."""
    rule = {
        "id": "only-the-agent-speaks",
        "permission": "deny",
        "flows": ["ingress"],
        "messages": ["put", "delete", "declare_queryable", "reply"],
        "key_exprs": [f"mm/*/{k}" for k in AGENT_KEYS],
    }
    return {
        "enabled": True,
        "default_permission": "allow",
        "rules": [rule],
        "subjects": [{"id": "every-peer"}],
        "policies": [{"rules": [rule["id"]], "subjects": ["every-peer"]}],
    }


def zenoh_config(
    *,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    credentials: str = "",
):
    """A zenoh.Config: no multicast scouting, no gossip, only the endpoints given.

    The agent listens (peer mode, with :func:`agent_acl`); the node connects as a
    client and keeps retrying every 0.1-1 s. With ``credentials`` both sides authenticate with
    zenoh's user/password scheme: a listener then refuses peers without them.
    ``RUST_LOG`` (e.g. ``zenoh=debug``) turns on zenoh's own log on stderr.
    """
    import zenoh

    zenoh.try_init_log_from_env()

    cfg: dict = {
        "mode": "peer" if listen else "client",
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }
    if listen:
        cfg["listen"] = {"endpoints": listen}
    if connect:
        # The node: no shared memory (a local peer's large message maps its 16 MB segment
        # into the node), and no message over NODE_RX_MAX_BYTES is reassembled (a larger
        # live batch is dropped and its polls fetched as a gap, 4096 per history reply).
        cfg["transport"] = {
            "shared_memory": {"enabled": False},
            "link": {"rx": {"max_message_size": NODE_RX_MAX_BYTES}},
        }
        cfg["connect"] = {
            "endpoints": connect,
            "timeout_ms": -1,
            "exit_on_failure": False,
            "retry": {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
        }
    if listen:
        cfg["access_control"] = agent_acl()
    if credentials:
        user, password = load_credentials(credentials)
        auth = {"user": user, "password": password}
        if listen:
            auth["dictionary_file"] = str(Path(credentials).resolve())
        cfg.setdefault("transport", {})["auth"] = {"usrpwd": auth}
    return zenoh.Config.from_json5(json.dumps(cfg))


def agent_zenoh_config(listen: list[str], credentials: str = ""):
    """The agent's zenoh.Config: :func:`zenoh_config` and limits a peer cannot push
    past. Messages over :data:`RX_MAX_MESSAGE_BYTES` are dropped by zenoh before Python
    sees them (a 200 MB command once cost 490 MB of RSS); no shared-memory transport; a
    full transmission queue drops a message after at most 2 ms, fragments included
    (zenoh's default waits 50 ms), and a peer that reads no reply for 1 s is
    disconnected (command replies keep the congestion control of their query). Unless
    ``RUST_LOG`` says otherwise, zenoh logs one line per peer link accepted and per peer
    refused ("UsrPwd extension - Recv OpenSyn. Invalid password."): who was refused is
    known only inside zenoh, before any of the agent's code runs."""
    import zenoh

    if "RUST_LOG" not in os.environ:  # (RUST_LOG: zenoh's own log as asked, zenoh_config)
        zenoh.init_log_from_env_or(ZENOH_LOG)
    cfg = zenoh_config(listen=listen, credentials=credentials)
    cfg.insert_json5("transport/link/rx/max_message_size", str(RX_MAX_MESSAGE_BYTES))
    # 16 KiB batches (zenoh: 64 KiB): what waits in a slow peer's transmission queue is
    # batches, so a stuck reader held up to 0.8 MB more of the agent's RSS; a history
    # reply (<= 78 kB) goes as a few fragments, a poll batch (< 2 kB) as one
    cfg.insert_json5("transport/link/tx/batch_size", str(TX_BATCH_BYTES))
    # No shared memory: a local peer's messages over 3 kB came in its 16 MB zenoh segment,
    # mapped into the agent (+16 MB RSS per peer, and past max_message_size).
    cfg.insert_json5("transport/shared_memory/enabled", "false")
    cfg.insert_json5(
        "transport/link/tx/queue/congestion_control",
        json.dumps(
            {
                "drop": {"wait_before_drop": 1000, "max_wait_before_drop_fragments": 2000},
                # a reply that cannot be queued for 1 s (its peer reads nothing) closes
                # that peer's session: the command worker is free again (zenoh: 5 s)
                "block": {"wait_before_close": 1_000_000},
            }
        ),
    )
    return cfg
