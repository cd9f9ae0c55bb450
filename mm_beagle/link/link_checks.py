"""The link's settings checked before anything opens, by the agent and the node alike.

An agent name becomes a zenoh key chunk (``mm/NAME/polls``): letters, digits, ``_ . -``,
at most :data:`MAX_NAME` characters. An endpoint is ``PROTO/HOST:PORT[#key=value;...]``
(zenoh's endpoint configuration after ``#``): ``tls/`` and ``quic/`` need their
certificates there (a listener its certificate and private key, a connector the root CA
that signed the agent's), every ``*_file`` named must be a regular file, and
``iface=NAME`` must name an interface of this machine. Without these zenoh starts, then
fails on every connection and the node waits for ever. Every refusal is a
:class:`~mm_beagle.link.link.LinkError` (a ValueError) with one line.
"""

from __future__ import annotations

import os
import re
import socket

from mm_beagle.link.link import LinkError
from mm_beagle.link.zenoh_config import endpoint_host
from mm_pc.core.user_file import check_user_file

MAX_NAME = 64
_NAME = re.compile(rf"[A-Za-z0-9_.-]{{1,{MAX_NAME}}}")
MAX_CERT_BYTES = 1 << 16  # a certificate, key or credentials file
_SECURE = ("tls", "quic")
#: endpoint configuration keys that carry each piece (``_file``: a path; else the data)
_NEEDS = {
    "listen": (("listen_certificate", "certificate"), ("listen_private_key", "private key")),
    "connect": (("root_ca_certificate", "root CA certificate"),),
}


def name_problem(name: object) -> str:
    """Why ``name`` is no agent name ('' if it is one)."""
    if isinstance(name, str) and _NAME.fullmatch(name):
        return ""
    text = name if isinstance(name, str) else repr(name)
    shown = repr(text) if len(text) <= 40 else f"{text[:20]!r}... ({len(text)} characters)"
    return (
        f"agent name {shown} must be 1..{MAX_NAME} letters, digits, '_', '.' or '-' "
        "(one key chunk: no / * $ ? #)"
    )


def endpoint_config(endpoint: str) -> dict[str, str]:
    """The ``key=value;...`` after an endpoint's ``#``."""
    _, _, config = endpoint.partition("#")
    out = {}
    for item in filter(None, config.split(";")):
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise LinkError(f"endpoint '{endpoint}': '{item}' after '#' is not key=value")
        out[key] = value
    return out


def endpoint_problem(endpoint: str, role: str) -> str:
    """Why ``endpoint`` cannot be used to ``role`` ('listen' or 'connect'); '' if it can."""
    try:
        endpoint_host(endpoint)
        config = endpoint_config(endpoint)
    except LinkError as exc:
        return str(exc)
    if (iface := config.get("iface")) is not None:
        try:
            socket.if_nametoindex(iface)
        except OSError:
            return f"endpoint '{endpoint}': this machine has no network interface '{iface}'"
    for key, value in config.items():
        if key.endswith("_file"):
            try:
                check_user_file(value, MAX_CERT_BYTES)
            except OSError as exc:
                return f"endpoint '{endpoint}': {key} {value}: {exc.strerror or exc}"
    proto = endpoint.partition("/")[0]
    if proto in _SECURE:
        for key, what in _NEEDS[role]:
            if not any(k in config for k in (f"{key}_file", f"{key}_base64", f"{key}_raw")):
                return (
                    f"endpoint '{endpoint}': {proto}/ needs its {what} to {role}: add "
                    f"#{key}_file=PATH (zenoh's endpoint configuration), or use tcp/ with "
                    "credentials"
                )
    return ""


def patch_dir_problem(patch_dir: str) -> str:
    """Why ``patch_dir`` cannot hold patch files ('' if it is a directory, or '': off). Checked
    at start: otherwise a peer's or a user's load_patch is the first to find out."""
    if not patch_dir or os.path.isdir(os.path.expanduser(patch_dir)):
        return ""
    what = "does not exist" if not os.path.lexists(patch_dir) else "is not a directory"
    return f"'patch_dir' {patch_dir!r} {what} (give the directory of the patch files, or '')"


def credentials_file_problem(path: str) -> str:
    """Why the credentials file at ``path`` is not read ('' if it is a small regular file)."""
    try:
        check_user_file(path, MAX_CERT_BYTES)
    except OSError as exc:
        return f"cannot read credentials file {path}: {exc.strerror or exc}"
    return ""


def check_link_settings(name: str, endpoints: list[str], role: str, credentials: str) -> None:
    """LinkError for the first problem of an agent's (``role`` 'listen') or node's
    ('connect') link settings."""
    problem = name_problem(name) or next(
        (p for ep in endpoints if (p := endpoint_problem(ep, role))), ""
    )
    if not problem and credentials:
        problem = credentials_file_problem(credentials)
    if problem:
        raise LinkError(problem)
