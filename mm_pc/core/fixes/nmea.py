"""NMEA GGA and GLL sentences (the ones seed 004 reads), parsed with checksum verification.

Malformed input raises ValueError saying which field was wrong.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from mm_pc.core.fixes.gps import GpsQuality

__all__ = [
    "GgaFix",
    "GllFix",
    "nmea_checksum",
    "parse_gga",
    "parse_gll",
]


@dataclass(frozen=True)
class GgaFix:
    """A parsed GGA sentence: UTC seconds of day, position (deg, north/east +), quality."""

    time_s: float
    lat: float
    lon: float
    fix_type: int
    satellites: int
    hdop: float
    altitude_m: float | None = None
    talker: str = "GP"

    @property
    def quality(self) -> GpsQuality:
        """The fix's :class:`GpsQuality`."""
        return GpsQuality(self.hdop, self.satellites, self.fix_type)


@dataclass(frozen=True)
class GllFix:
    """A parsed GLL sentence: position (deg), UTC seconds of day, validity, mode letter."""

    lat: float
    lon: float
    time_s: float
    valid: bool
    mode: str | None = None
    talker: str = "GP"


def nmea_checksum(body: str) -> int:
    """XOR of the characters between '$' and '*' (an int 0..255)."""
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return cs


_TIME_RE = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")
_LAT_RE = re.compile(r"^(\d{2})(\d{2}(?:\.\d+)?)$")
_LON_RE = re.compile(r"^(\d{3})(\d{2}(?:\.\d+)?)$")


def _nmea_fields(sentence: str, kind: str) -> tuple[str, list[str]]:
    """Check framing and checksum; return (talker, fields after the address)."""
    if not isinstance(sentence, str):
        raise ValueError(f"NMEA sentence must be a str, got {type(sentence).__name__}")
    s = sentence.strip()
    if not s.isascii():
        raise ValueError(f"NMEA sentence must be ASCII: {s!r}")
    if not s.startswith("$"):
        raise ValueError(f"NMEA sentence must start with '$': {s!r}")
    body, star, given = s[1:].rpartition("*")
    if not star:
        raise ValueError(f"NMEA sentence has no '*hh' checksum: {s!r}")
    if not re.fullmatch(r"[0-9A-Fa-f]{2}", given):
        raise ValueError(f"NMEA checksum must be two hex digits, got {given!r}")
    computed = nmea_checksum(body)
    if int(given, 16) != computed:
        raise ValueError(
            f"NMEA checksum mismatch: sentence says {given.upper()}, computed {computed:02X}"
        )
    fields = body.split(",")
    address = fields[0]
    if not re.fullmatch(r"[A-Z]{2}" + kind, address):
        raise ValueError(f"expected a {kind} sentence (e.g. GP{kind}), got {address!r}")
    return address[:2], fields[1:]


def _required(fields: list[str], i: int, name: str) -> str:
    if i >= len(fields) or fields[i] == "":
        raise ValueError(f"NMEA field '{name}' is empty")
    return fields[i]


def _parse_time(text: str) -> float:
    m = _TIME_RE.match(text)
    if not m:
        raise ValueError(f"NMEA time must be hhmmss[.ss], got {text!r}")
    h, mi, s = int(m[1]), int(m[2]), float(m[3])
    if h > 23 or mi > 59 or s >= 61:
        raise ValueError(f"NMEA time out of range: {text!r}")
    return h * 3600 + mi * 60 + s


def _parse_angle(text: str, hemi: str, kind: str) -> float:
    """ddmm.mmmm (lat) or dddmm.mmmm (lon) plus N/S or E/W -> signed degrees."""
    rx, signs, limit = (_LAT_RE, "NS", 90.0) if kind == "latitude" else (_LON_RE, "EW", 180.0)
    m = rx.match(text)
    if not m:
        width = 2 if kind == "latitude" else 3
        raise ValueError(f"NMEA {kind} must be {'d' * width}mm.mmmm, got {text!r}")
    deg, minutes = int(m[1]), float(m[2])
    if minutes >= 60:
        raise ValueError(f"NMEA {kind} minutes must be < 60, got {text!r}")
    value = deg + minutes / 60
    if value > limit:
        raise ValueError(f"NMEA {kind} must be <= {limit:g} deg, got {text!r}")
    if hemi not in signs:
        raise ValueError(f"NMEA {kind} hemisphere must be {signs[0]} or {signs[1]}, got {hemi!r}")
    return value if hemi == signs[0] else -value


def _parse_number(text: str, name: str, cast=float):
    try:
        v = cast(text)
    except ValueError:
        raise ValueError(f"NMEA field '{name}' is not a number: {text!r}") from None
    if cast is float and not math.isfinite(v):
        raise ValueError(f"NMEA field '{name}' is not finite: {text!r}")
    return v


def parse_gga(sentence: str) -> GgaFix:
    """Parse ``$--GGA,hhmmss.ss,ddmm.mm,N,dddmm.mm,E,q,nn,hdop,alt,M,...*hh``.

    Checks the checksum (required). Time, position, fix type, satellites and
    HDOP must be present; altitude may be empty. Raises ValueError on any
    defect (a receiver without a fix sends empty positions: no fix here).
    """
    talker, f = _nmea_fields(sentence, "GGA")
    if len(f) < 9:
        raise ValueError(f"GGA needs at least 9 fields after the address, got {len(f)}")
    time_s = _parse_time(_required(f, 0, "time"))
    lat = _parse_angle(_required(f, 1, "latitude"), _required(f, 2, "N/S"), "latitude")
    lon = _parse_angle(_required(f, 3, "longitude"), _required(f, 4, "E/W"), "longitude")
    fix_type = _parse_number(_required(f, 5, "fix quality"), "fix quality", int)
    sats = _parse_number(_required(f, 6, "satellites"), "satellites", int)
    hdop = _parse_number(_required(f, 7, "HDOP"), "HDOP", float)
    alt = _parse_number(f[8], "altitude", float) if f[8] else None
    quality = GpsQuality(hdop, sats, fix_type)  # range checks with messages
    return GgaFix(time_s, lat, lon, quality.fix_type, quality.satellites, quality.hdop, alt, talker)


def parse_gll(sentence: str) -> GllFix:
    """Parse ``$--GLL,ddmm.mm,N,dddmm.mm,E,hhmmss.ss,A[,mode]*hh``.

    ``valid``: status A (the seed's "data valid") and, if the NMEA 2.3 mode
    letter is there, not N (no fix), E (estimated), M (manual) or S (simulator).
    Checksum required; empty position/time/status raise ValueError.
    """
    talker, f = _nmea_fields(sentence, "GLL")
    if len(f) < 6:
        raise ValueError(f"GLL needs at least 6 fields after the address, got {len(f)}")
    lat = _parse_angle(_required(f, 0, "latitude"), _required(f, 1, "N/S"), "latitude")
    lon = _parse_angle(_required(f, 2, "longitude"), _required(f, 3, "E/W"), "longitude")
    time_s = _parse_time(_required(f, 4, "time"))
    status = _required(f, 5, "status")
    if status not in ("A", "V"):
        raise ValueError(f"GLL status must be A (valid) or V (invalid), got {status!r}")
    mode = f[6] if len(f) > 6 and f[6] else None
    valid = status == "A" and mode not in ("N", "E", "M", "S")
    return GllFix(lat, lon, time_s, valid, mode, talker)
