"""The firmware files users supply (PLN2033 patch code, PixArt SROM): hex text or raw bytes."""

from __future__ import annotations

import re
from pathlib import Path

from .errors import FirmwareError

_HEX_TOKEN = re.compile(r"(?:0x)?([0-9a-fA-F]{1,2})\b")
# Control characters no hex text file holds: a file with any is raw binary,
# even when all its bytes are below 0x80 (and so decode as ASCII).
_BINARY_CHARS = re.compile(r"[\x00-\x08\x0e-\x1f\x7f]")


def read_firmware_bytes(
    path: str | Path, what: str = "firmware file", error: type[Exception] = FirmwareError
) -> bytes:
    """The bytes of a firmware file the user supplies (PLN2033 patch code, PixArt SROM).

    Two formats: a text file of bytes in hex (``0x12, 0x34 ...``; ``//`` and ``#``
    comments allowed), or a raw binary file. Problems raise ``error`` naming ``what``.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from exc
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        text = None
    if text is None or _BINARY_CHARS.search(text):
        data = raw
    else:
        lines = [re.split(r"//|#", line, maxsplit=1)[0] for line in text.splitlines()]
        body = " ".join(lines)
        tokens = [t for t in re.split(r"[\s,;{}]+", body) if t]
        if not tokens:
            raise error(f"{what} {p} has no bytes")
        data_list = []
        for tok in tokens:
            m = _HEX_TOKEN.fullmatch(tok)
            if not m:
                raise error(f"{what} {p}: '{tok}' is not a hex byte (like 0x1f)")
            data_list.append(int(m.group(1), 16))
        data = bytes(data_list)
    if not data:
        raise error(f"{what} {p} is empty")
    return data
