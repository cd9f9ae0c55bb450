"""The link's credentials and the MAC on every message of the agent (issue 27).

The credentials file holds one ``user:password`` line, mode 600 (:func:`load_credentials`,
:func:`make_credentials`); zenoh's user/password scheme lets only peers with it connect
(:mod:`mm_beagle.link.zenoh_config`), and :class:`FrameAuth` tags each message the agent
sends with an HMAC keyed by it, which the node checks (:func:`attachment_bytes`).
"""

from __future__ import annotations

import os
import stat
from _operator import _compare_digest as compare_digest  # hmac.compare_digest, without hmac
from pathlib import Path

from mm_beagle.link.link import LinkError

CREDENTIALS_HELP = "see docs/hardware-setup.md, 'Credentials'"
TAG_BYTES = 16  # HMAC-SHA256 truncated: 128 bits

# CPython's own SHA-256: hashlib and hmac load OpenSSL's libcrypto (+3.7 MB of the agent's RSS)
try:
    from _sha256 import sha256 as _sha256
except ImportError:  # Python >= 3.12 (_sha2), or another interpreter
    try:
        from _sha2 import sha256 as _sha256  # type: ignore[no-redef]
    except ImportError:
        from hashlib import sha256 as _sha256  # type: ignore[no-redef]


MAC_SLICE = 4096  # bytes hashed per call: CPython's sha256 holds the GIL (~35 us per slice on x86)
_IPAD = bytes(x ^ 0x36 for x in range(256))
_OPAD = bytes(x ^ 0x5C for x in range(256))


def hmac_pads(key: bytes) -> tuple:
    """The two SHA-256 states HMAC starts from for ``key`` (inner, outer): copy, then update."""
    if len(key) > 64:
        key = _sha256(key).digest()
    key = key.ljust(64, b"\0")
    return _sha256(key.translate(_IPAD)), _sha256(key.translate(_OPAD))


def hmac_sha256(key: bytes | tuple, *parts: bytes) -> bytes:
    """HMAC-SHA256 (RFC 2104) of the concatenated ``parts``, as hmac.new(key, msg, sha256);
    ``key`` may be its :func:`hmac_pads`."""
    inner, outer = hmac_pads(key) if isinstance(key, bytes) else key
    inner, outer = inner.copy(), outer.copy()
    for part in parts:
        view = memoryview(part)
        for j in range(0, len(view), MAC_SLICE):  # the GIL is free between slices
            inner.update(view[j : j + MAC_SLICE])
    outer.update(inner.digest())
    return outer.digest()


class FrameAuth:
    """A MAC over every message the agent sends, keyed by the shared credential.

    Without credentials (``key`` None) there is no tag and :meth:`check` passes. With them
    the agent sends ``TAG_BYTES`` of HMAC-SHA256(key, kind | body) as the zenoh
    attachment of each message (the payload is unchanged) and the node refuses anything
    without a valid tag. ``kind`` (polls, status, events, history, reply) is in the MAC, so
    one kind cannot be replayed as another; the boot id and sequence numbers are inside
    the body, and the node's boot and sequence rules refuse replays. The key is
    HMAC-SHA256(password, "mm-link-v1/" + user + "/" + agent name).
    """

    def __init__(self, key: bytes | None) -> None:
        self.key = key
        self.pads = hmac_pads(key) if key is not None else None

    @classmethod
    def from_credentials(cls, path: str, name: str) -> FrameAuth:
        if not path:
            return cls(None)
        user, password = load_credentials(path)
        info = f"mm-link-v1/{user}/{name}".encode()
        return cls(hmac_sha256(password.encode(), info))

    def tag(self, kind: str, body: bytes) -> bytes | None:
        """The attachment to send with ``body`` on ``kind`` (None without credentials)."""
        if self.pads is None:
            return None
        return hmac_sha256(self.pads, kind.encode(), b"|", body)[:TAG_BYTES]

    def check(self, kind: str, body: bytes, attachment: bytes | None) -> None:
        """LinkError unless ``attachment`` is the tag of ``body`` (always fine without a key)."""
        if self.key is None:
            return
        if attachment is None or len(attachment) != TAG_BYTES:
            raise LinkError(f"{kind} message has no authentication tag (forged, or an old agent)")
        if not compare_digest(attachment, self.tag(kind, body) or b""):
            raise LinkError(f"{kind} message fails authentication (forged, or other credentials)")


def attachment_bytes(sample) -> bytes | None:
    """A zenoh sample's attachment as bytes (None: none, or longer than a tag could be)."""
    att = getattr(sample, "attachment", None)
    if att is None:
        return None
    data = att.to_bytes()
    return data if len(data) <= 64 else None


def load_credentials(path: str) -> tuple[str, str]:
    """(user, password) from a ``user:password`` file only its owner can read."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise LinkError(f"cannot read credentials file {p}: {exc.strerror or exc}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise LinkError(
            f"credentials file {p} can be read by others (mode {stat.filemode(mode)}); "
            f"run: chmod 600 {p}"
        )
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if len(lines) != 1 or ":" not in lines[0]:
        raise LinkError(f"credentials file {p} must hold one line 'user:password'")
    user, password = lines[0].split(":", 1)
    if not user or len(password) < 12:
        raise LinkError(f"credentials file {p}: needs a user and a password of 12+ characters")
    return user, password


def make_credentials(path: str, user: str = "mm") -> str:
    """Write a new ``user:password`` file (mode 600); refuses to overwrite one."""
    p = Path(path)
    if p.exists():
        raise LinkError(f"{p} exists; remove it first to make new credentials")
    import secrets  # (imports hmac, hence libcrypto: only here)

    p.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"{user}:{secrets.token_urlsafe(24)}\n")
    return str(p)
