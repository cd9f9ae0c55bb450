"""Rectangle arithmetic of the map's raster (no Qt): meet, contain, subtract, tile, clip.

Pixel rectangles are (u0, u1, v0, v1) with u0 <= u < u1, v0 <= v < v1.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Rect", "inside", "meets", "minus", "segments_meeting", "tiles"]


Rect = tuple[int, int, int, int]  # (u0, u1, v0, v1): pixels u0 <= u < u1, v0 <= v < v1


def meets(a: Rect, b: Rect) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def inside(inner, outer) -> bool:
    """Rectangle ``inner`` inside ``outer``; (x0, x1, y0, y1) in any one unit."""
    return outer[0] <= inner[0] and inner[1] <= outer[1] and outer[2] <= inner[2] and (
        inner[3] <= outer[3])


def minus(a: Rect, b: Rect) -> list[Rect]:
    """``a`` without ``b``: up to four rectangles (bands above, below, left, right)."""
    if not meets(a, b):
        return [a]
    out = []
    if a[2] < b[2]:
        out.append((a[0], a[1], a[2], b[2]))
    if b[3] < a[3]:
        out.append((a[0], a[1], b[3], a[3]))
    v0, v1 = max(a[2], b[2]), min(a[3], b[3])
    if a[0] < b[0]:
        out.append((a[0], b[0], v0, v1))
    if b[1] < a[1]:
        out.append((b[1], a[1], v0, v1))
    return out


def tiles(r: Rect, size: int) -> list[Rect]:
    return [(u, min(u + size, r[1]), v, min(v + size, r[3]))
            for v in range(r[2], r[3], size) for u in range(r[0], r[1], size)]


def segments_meeting(u, v, connect, rect):
    """The polylines (points ``u``, ``v``, ``connect`` as for arrayToQPath) cut down to
    the segments whose bounding box meets ``rect`` = (u0, u1, v0, v1)."""
    u0, u1, v0, v1 = rect
    a, b = slice(0, -1), slice(1, None)
    seg = ((np.maximum(u[a], u[b]) >= u0) & (np.minimum(u[a], u[b]) <= u1)
           & (np.maximum(v[a], v[b]) >= v0) & (np.minimum(v[a], v[b]) <= v1))
    if connect is not None:
        seg &= connect[:-1]
    keep = np.zeros(len(u), dtype=bool)
    keep[:-1] = seg
    keep[1:] |= seg
    joined = np.append(seg, False)
    return u[keep], v[keep], joined[keep]
