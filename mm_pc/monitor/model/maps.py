"""The Maps tab's model (no Qt): live-map settings, feeding a path to the grid, the simulated run.

:func:`build_sim_run` simulates the mowing run and fuses it through the one fusion loop
(:func:`mm_pc.sim.field_run.run_fusion`); the widgets only draw what these return.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from mm_pc.core.maps.coverage_map import (
    DEFAULT_CELL_SIZE,
    SEED_SHAPE,
    UNMOWED,
    CoverageMap,
    UpdateResult,
)

__all__ = [
    "FILLS",
    "MAX_CELLS",
    "MAX_SIDE_CELLS",
    "SIM_CUT_WIDTH",
    "MapSettings",
    "SimRun",
    "build_sim_run",
    "circles",
    "default_settings",
    "feed_positions",
    "make_map",
    "sim_map",
]

#: Contents of a new live map: every cell lawn (unmowed), every cell unknown, or a
#: perimeter rectangle rasterised by CoverageMap.from_polygon.
FILLS = {"lawn": "all lawn (unmowed)", "unknown": "all unknown", "rectangle": "perimeter rectangle"}
MAX_SIDE_CELLS = 4000
MAX_CELLS = 4_000_000  # 16 MB of image, 8 MB of codes
SIM_MARGIN_M = 1.5  # the simulated run's map reaches this far beyond the plot
#: the simulated mower's cutting width (m): as wide as its lanes are apart
#: (mm_pc.sim.field_run.LANE_SPACING), so a whole run mows the whole plot. Fed as its
#: centre alone (one 0.3 m cell per 1 m lane) the map stayed two thirds unmowed.
SIM_CUT_WIDTH = 1.0
_CIRCLE = np.linspace(0.0, 2.0 * math.pi, 73)


# --- map settings and the live map -------------------------------------------------------


@dataclass(frozen=True)
class MapSettings:
    """What "New map…" makes: ``cell_size`` m, ``shape`` (ny, nx) cells, ``origin`` (x0, y0)
    m = the south-west corner of cell (0, 0), ``fill`` one of :data:`FILLS`, and for
    ``fill == "rectangle"`` the perimeter ``rect`` = (x, y, width, height) m, (x, y) its
    south-west corner."""

    cell_size: float
    shape: tuple[int, int]
    origin: tuple[float, float]
    fill: str = "lawn"
    rect: tuple[float, float, float, float] | None = None


def default_settings() -> MapSettings:
    """The seed's 81 x 71 cells of 0.3 m, all lawn, centred on the odom origin (the start)."""
    ny, nx = SEED_SHAPE
    s = DEFAULT_CELL_SIZE
    return MapSettings(s, (ny, nx), (-nx * s / 2, -ny * s / 2), "lawn")


def make_map(settings: MapSettings) -> CoverageMap:
    """A new CoverageMap for ``settings``; ValueError (from CoverageMap) if they do not fit."""
    if settings.fill not in FILLS:
        raise ValueError(f"fill must be one of {sorted(FILLS)}, got {settings.fill!r}")
    if settings.fill == "rectangle":
        if settings.rect is None:
            raise ValueError("a perimeter rectangle needs rect = (x, y, width, height) m")
        x, y, w, h = settings.rect
        polygon = ((x, y), (x + w, y), (x + w, y + h), (x, y + h))
        return CoverageMap.from_polygon(
            polygon, settings.cell_size, settings.origin, shape=settings.shape
        )
    if settings.fill == "lawn":
        codes = np.full(settings.shape, UNMOWED, dtype=np.uint8)
        return CoverageMap.from_array(codes, settings.cell_size, settings.origin)
    return CoverageMap(settings.shape, settings.cell_size, settings.origin)


def feed_positions(
    cmap: CoverageMap, x: np.ndarray, y: np.ndarray, width: float = 0.0
) -> tuple[list[tuple[int, int, int]], UpdateResult | None]:
    """Feed a path (x, y m, map frame) to ``cmap``; (changed cells in order, last result).

    Non-finite rows are skipped. Only the rows whose cell differs from the row
    before (and the last row) are passed to :meth:`CoverageMap.update`: a row in
    the same cell changes nothing there. The cell index uses the map's own
    arithmetic, ``floor((x - x0) / s)``. The result is None when no row was finite.

    ``width`` > 0 (m): a cutting deck that wide, across the direction of travel, mows
    too: at each such row the points across it (at most half a cell apart) are fed
    before the centre, so the cells under the deck end mowed and the mower is shown at
    the centre.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.all():
        x, y = x[ok], y[ok]
    if x.size == 0:
        return [], None
    x0, y0 = cmap.origin
    s = cmap.cell_size
    ix = np.floor((x - x0) / s)
    iy = np.floor((y - y0) / s)
    step = np.empty(x.size, dtype=bool)
    step[0] = True
    step[1:] = (ix[1:] != ix[:-1]) | (iy[1:] != iy[:-1])
    step[-1] = True
    changed: list[tuple[int, int, int]] = []
    result = None
    rows = np.flatnonzero(step)
    across = _deck_offsets(width, s)
    for n, i in enumerate(rows.tolist()):
        if across.size and rows.size > 1:
            j, k = (rows[n - 1], i) if n else (i, rows[1])
            dx, dy = x[k] - x[j], y[k] - y[j]
            norm = math.hypot(dx, dy)
            if norm > 0:
                for off in across:  # the deck's points, left of travel to right
                    r = cmap.update(float(x[i] - dy / norm * off), float(y[i] + dx / norm * off))
                    changed.extend(r.changed)
        result = cmap.update(float(x[i]), float(y[i]))
        changed.extend(result.changed)
    return changed, result


def _deck_offsets(width: float, cell: float) -> np.ndarray:
    """Offsets (m, left of travel positive) across a deck of ``width``, at most half a
    cell apart, both edges included, without the centre; empty for no width."""
    if not width > 0:
        return np.empty(0)
    n = math.ceil(width / (cell / 2)) + 1
    offsets = np.linspace(width / 2, -width / 2, n)
    return offsets[np.abs(offsets) > 1e-9]


# --- the simulated run ---------------------------------------------------------------------


@dataclass(frozen=True)
class SimRun:
    """A simulated field run ready to draw: ``sim`` (:class:`mm_pc.sim.field_run.FieldSim`),
    ``fused`` (N+1, 3) EKF poses, GPS fixes in plot metres ``gps_xy`` (M, 2) with
    ``gps_k`` (request index), ``gps_accuracy`` (m) and ``gps_usable``; ``range_k``
    the request index of every range set."""

    sim: object
    fused: np.ndarray
    gps_xy: np.ndarray
    gps_k: np.ndarray
    gps_accuracy: np.ndarray
    gps_usable: np.ndarray
    range_k: np.ndarray


@functools.lru_cache(maxsize=4)
def build_sim_run(seed: int = 1) -> SimRun:
    """Simulate the mowing run for ``seed`` and fuse it (about 2.5 s; cached per seed,
    the run is deterministic)."""
    from mm_pc.core.fixes.gps import gps_accuracy_m, gps_fix_usable
    from mm_pc.sim.field_run import run_fusion, simulate_field_run

    sim = simulate_field_run(int(seed))
    fused = run_fusion(sim)
    gps = sim.gps
    lat = np.array([g.lat for g in gps])
    lon = np.array([g.lon for g in gps])
    gx, gy = sim.grid.to_local(lat, lon)
    return SimRun(
        sim=sim,
        fused=fused,
        gps_xy=np.column_stack([gx, gy]),
        gps_k=np.array([g.k for g in gps], dtype=np.int64),
        gps_accuracy=np.array([gps_accuracy_m(g.quality) for g in gps]),
        gps_usable=np.array([gps_fix_usable(g.quality) for g in gps], dtype=bool),
        range_k=np.array([r.k for r in sim.ranges], dtype=np.int64),
    )


def sim_map(run: SimRun) -> CoverageMap:
    """The plot's perimeter rectangle as a map reaching SIM_MARGIN_M beyond it."""
    w, h = run.sim.plot
    s = DEFAULT_CELL_SIZE
    origin = (-SIM_MARGIN_M, -SIM_MARGIN_M)
    shape = (math.ceil((h + 2 * SIM_MARGIN_M) / s), math.ceil((w + 2 * SIM_MARGIN_M) / s))
    return CoverageMap.from_polygon(((0, 0), (w, 0), (w, h), (0, h)), s, origin, shape=shape)


def circles(centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outline points of several circles, NaN between them (for connect='finite')."""
    if len(radii) == 0:
        return np.empty(0), np.empty(0)
    c, s = np.cos(_CIRCLE), np.sin(_CIRCLE)
    xs = centres[:, :1] + radii[:, None] * c
    ys = centres[:, 1:2] + radii[:, None] * s
    gap = np.full((len(radii), 1), np.nan)
    return np.hstack([xs, gap]).ravel(), np.hstack([ys, gap]).ravel()
