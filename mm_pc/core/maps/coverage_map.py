"""Coverage grid map of a lawn: which cells are perimeter, unmowed, mowed, obstacle.

After the seed ``001`` (ArduMower "Kartierung"): a matrix map with square cells of
0.3 m (``cell_size``, a parameter) that a mower updates cyclically from its position.
Pure numpy, no ROS, no Qt.

Derivations and measurements: docs/maps-and-fixes.md,
section "mm_pc.core.maps.coverage_map in detail".
"""

from __future__ import annotations

import io
import math
import os
import tempfile
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

__all__ = [
    "CODE_NAMES",
    "COLORS_RGB",
    "COLORS_RGB8",
    "DEFAULT_CELL_SIZE",
    "MOWED",
    "MOWER",
    "OBSTACLE",
    "PERIMETER",
    "SEED_SHAPE",
    "UNKNOWN",
    "UNMOWED",
    "CoverageMap",
    "UpdateResult",
]

UNKNOWN, PERIMETER, UNMOWED, MOWED, MOWER, OBSTACLE = 0, 1, 2, 3, 4, 5
CODE_NAMES = ("unknown", "perimeter", "unmowed", "mowed", "mower", "obstacle")

#: The seed's colour map, row = code, RGB in 0..1.
COLORS_RGB = (
    (1.0, 1.0, 1.0),  # unknown: white
    (1.0, 0.0, 0.0),  # perimeter: red
    (0.5, 0.8, 0.0),  # unmowed: dark green
    (0.0, 1.0, 0.0),  # mowed: light green
    (0.0, 0.0, 1.0),  # mower: blue
    (1.0, 0.5, 1.0),  # obstacle: magenta
)
#: The same as uint8 (0..255), shape (6, 3), read-only: ``COLORS_RGB8[codes]``.
COLORS_RGB8 = np.array([[round(255 * c) for c in rgb] for rgb in COLORS_RGB], dtype=np.uint8)
COLORS_RGB8.flags.writeable = False

DEFAULT_CELL_SIZE = 0.3  # m
SEED_SHAPE = (81, 71)  # (ny, nx) of the seed's Karte

_STORED_CODES = frozenset((UNKNOWN, PERIMETER, UNMOWED, MOWED, OBSTACLE))
# What a cell becomes when the mower leaves it, indexed by its base code (4 never in base).
_LEFT = (UNKNOWN, PERIMETER, MOWED, MOWED, MOWER, OBSTACLE)
_FORMAT = "mm_pc.core.maps.coverage_map"
_VERSION = 1


class UpdateResult(NamedTuple):
    """What one :meth:`CoverageMap.update` did.

    ``cell``: (iy, ix) of the position, None when outside the map.
    ``entered``: the position entered a new cell (the map was updated).
    ``outside``: the position lies outside the map; nothing was changed.
    ``changed``: the cells whose shown code changed, as (iy, ix, new_code).
    """

    cell: tuple[int, int] | None
    entered: bool
    outside: bool
    changed: tuple[tuple[int, int, int], ...]


_OUTSIDE = UpdateResult(None, False, True, ())


# --- argument checks ---------------------------------------------------------------------


def _check_cell_size(cell_size: float | np.ndarray) -> float:
    try:
        s = float(cell_size)
    except (TypeError, ValueError):
        raise ValueError(f"cell size must be a number of metres > 0, got {cell_size!r}") from None
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"cell size must be a finite number of metres > 0, got {cell_size!r}")
    return s


def _check_shape(shape: Sequence[int]) -> tuple[int, int]:
    try:
        ny, nx = shape
    except (TypeError, ValueError):
        raise ValueError(f"map shape must be (ny, nx), got {shape!r}") from None
    ok = all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in (ny, nx))
    if not ok or ny <= 0 or nx <= 0:
        raise ValueError(f"map shape (ny, nx) must be two integers > 0 (cells), got {shape!r}")
    return int(ny), int(nx)


def _check_origin(origin: Sequence[float] | np.ndarray) -> tuple[float, float]:
    try:
        x0, y0 = (float(v) for v in origin)
    except (TypeError, ValueError):
        raise ValueError(f"origin must be (x0, y0) in metres, got {origin!r}") from None
    if not (math.isfinite(x0) and math.isfinite(y0)):
        raise ValueError(f"origin must be finite metres, got {origin!r}")
    return x0, y0


def _check_codes(codes) -> np.ndarray:
    """A copy of ``codes`` as a uint8 (ny, nx) array of storable codes."""
    a = np.asarray(codes)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"codes must be a non-empty 2-D array (ny, nx), got shape {a.shape}")
    whole = a.dtype.kind in "iub" or (
        a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a))
    )
    if not whole:
        raise ValueError(f"codes must be whole numbers, got dtype {a.dtype}")
    bad = sorted(set(np.unique(a).tolist()) - _STORED_CODES)
    if bad:
        allowed = ", ".join(f"{c} {CODE_NAMES[c]}" for c in sorted(_STORED_CODES))
        raise ValueError(
            f"unknown cell code(s) {bad[:10]}; a stored map may hold {allowed} "
            "(4 mower is runtime state and never stored)"
        )
    return a.astype(np.uint8)


def _check_polygon(vertices) -> np.ndarray:
    try:
        p = np.array(vertices, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("polygon must be an (N, 2) array of x, y in metres") from None
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"polygon must be an (N, 2) array of x, y in metres, got {p.shape}")
    if len(p) >= 2 and np.array_equal(p[0], p[-1]):
        p = p[:-1]  # closed explicitly: the closing edge is implied anyway
    if len(p) < 3:
        raise ValueError(f"polygon needs at least 3 distinct vertices, got {len(p)}")
    if not np.all(np.isfinite(p)):
        raise ValueError("polygon vertices must be finite metres (no NaN or inf)")
    x, y = p[:, 0], p[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) == 0:
        raise ValueError("polygon has zero area (all vertices on one line)")
    return p


# --- polygon rasterisation (grid units: u = (x - x0)/s, v = (y - y0)/s) -------------------


def _inside_cells(u: np.ndarray, v: np.ndarray, ny: int, nx: int) -> np.ndarray:
    """Bool (ny, nx): cell centre inside the polygon (even-odd rule).

    For each row centre the x of every edge crossing is found (rows x edges);
    a crossing toggles every cell whose centre lies right of it, summed with
    a bincount and a running sum along the row.
    """
    ua, va = u, v
    ub, vb = np.roll(u, -1), np.roll(v, -1)
    vc = np.arange(ny)[:, None] + 0.5
    crosses = (va <= vc) != (vb <= vc)  # half-open: a vertex on the line counts once
    rows, edges = np.nonzero(crosses)
    dv = vb[edges] - va[edges]  # never 0 where an edge crosses
    uc = ua[edges] + (vc[rows, 0] - va[edges]) * (ub[edges] - ua[edges]) / dv
    first = np.clip(np.floor(uc - 0.5).astype(np.int64) + 1, 0, nx)
    toggles = np.bincount(rows * (nx + 1) + first, minlength=ny * (nx + 1))
    parity = np.cumsum(toggles.reshape(ny, nx + 1), axis=1) & 1
    return parity[:, :nx].astype(bool)


def _boundary_cells(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(iy, ix) of every cell an edge passes through (may repeat).

    Each edge is cut at every grid line it crosses (parameter t along the
    edge); the midpoint of each piece lies inside one traversed cell.
    """
    ua, va = u, v
    ub, vb = np.roll(u, -1), np.roll(v, -1)
    n = len(u)
    ts, ids = [np.zeros(n), np.ones(n)], [np.arange(n), np.arange(n)]
    for a, b in ((ua, ub), (va, vb)):
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        k0 = np.floor(lo).astype(np.int64) + 1
        count = np.maximum(np.ceil(hi).astype(np.int64) - k0, 0)  # integer lines strictly inside
        edge = np.repeat(np.arange(n), count)
        offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        k = k0[edge] + offset
        ts.append((k - a[edge]) / (b[edge] - a[edge]))
        ids.append(edge)
    t, e = np.concatenate(ts), np.concatenate(ids)
    order = np.lexsort((t, e))
    t, e = t[order], e[order]
    same = e[1:] == e[:-1]
    tm, em = (t[1:][same] + t[:-1][same]) / 2, e[1:][same]
    pu = np.concatenate([ua[em] + tm * (ub[em] - ua[em]), ua])
    pv = np.concatenate([va[em] + tm * (vb[em] - va[em]), va])
    return np.floor(pv).astype(np.int64), np.floor(pu).astype(np.int64)


# --- the map ------------------------------------------------------------------------------


class CoverageMap:
    """Coverage grid map, ``codes[iy, ix]``, cells of ``cell_size`` metres.

    ``shape``: (ny, nx) cells, default the seed's 81 x 71. ``cell_size``: edge of
    a square cell in metres (default 0.3). ``origin``: (x0, y0) in metres, the
    south-west corner of cell (0, 0). A new map is all unknown; see
    :meth:`from_array`, :meth:`from_polygon` and :meth:`load` for others.
    Raises ValueError for a shape or cell size that is not > 0.
    """

    def __init__(
        self,
        shape: Sequence[int] = SEED_SHAPE,
        cell_size: float = DEFAULT_CELL_SIZE,
        origin: Sequence[float] = (0.0, 0.0),
    ) -> None:
        shape = _check_shape(shape)
        self._setup(np.zeros(shape, dtype=np.uint8), cell_size, origin)

    def _setup(self, base: np.ndarray, cell_size: float, origin: Sequence[float]) -> None:
        """Adopt ``base`` (a checked uint8 array, owned by the map) after checking the rest."""
        s = _check_cell_size(cell_size)
        x0, y0 = _check_origin(origin)
        self._cell = s
        self._x0, self._y0 = x0, y0
        self._ny, self._nx = base.shape
        self._base = base
        self._view = base.copy()
        self._mower: tuple[int, int] | None = None
        self._ro_view = self._view.view()
        self._ro_view.flags.writeable = False
        self._ro_base = self._base.view()
        self._ro_base.flags.writeable = False

    # -- construction ----------------------------------------------------------------------

    @classmethod
    def from_array(
        cls,
        codes,
        cell_size: float = DEFAULT_CELL_SIZE,
        origin: Sequence[float] = (0.0, 0.0),
    ) -> CoverageMap:
        """A map from a (ny, nx) array of codes 0, 1, 2, 3, 5 (copied), like the seed's
        ``Karte.mat``. Raises ValueError for other codes (4 included) or shapes."""
        m = cls.__new__(cls)
        m._setup(_check_codes(codes), cell_size, origin)
        return m

    @classmethod
    def from_polygon(
        cls,
        vertices,
        cell_size: float = DEFAULT_CELL_SIZE,
        origin: Sequence[float] = (0.0, 0.0),
        shape: Sequence[int] | None = None,
        margin_cells: int = 1,
    ) -> CoverageMap:
        """A map from the measured perimeter: a closed polygon, (N, 2) x, y in metres.

        Cells whose centre is inside are unmowed, cells the boundary passes
        through are perimeter, the rest unknown. ``shape`` None: just large
        enough for the polygon plus ``margin_cells`` unknown cells east and
        north. Raises ValueError for fewer than 3 vertices, non-finite values,
        zero area, or a polygon reaching outside the map (west/south of
        ``origin``, or beyond a given ``shape``).
        """
        p = _check_polygon(vertices)
        s = _check_cell_size(cell_size)
        x0, y0 = _check_origin(origin)
        if not (isinstance(margin_cells, int) and margin_cells >= 0):
            raise ValueError(f"margin_cells must be an integer >= 0, got {margin_cells!r}")
        u, v = (p[:, 0] - x0) / s, (p[:, 1] - y0) / s
        if u.min() < 0 or v.min() < 0:
            raise ValueError(
                f"polygon reaches west or south of the map origin {(x0, y0)} "
                f"(min x {p[:, 0].min():.3f} m, min y {p[:, 1].min():.3f} m); pass a lower origin"
            )
        need = (math.floor(v.max()) + 1, math.floor(u.max()) + 1)
        if shape is None:
            ny, nx = need[0] + margin_cells, need[1] + margin_cells
        else:
            ny, nx = _check_shape(shape)
            if need[0] > ny or need[1] > nx:
                raise ValueError(
                    f"polygon needs at least {need} cells (ny, nx) from the origin, "
                    f"the map has {(ny, nx)}"
                )
        base = np.zeros((ny, nx), dtype=np.uint8)
        base[_inside_cells(u, v, ny, nx)] = UNMOWED
        base[_boundary_cells(u, v)] = PERIMETER
        m = cls.__new__(cls)
        m._setup(base, s, (x0, y0))
        return m

    # -- geometry --------------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx): rows along y, columns along x."""
        return self._ny, self._nx

    @property
    def cell_size(self) -> float:
        """Cell edge in metres."""
        return self._cell

    @property
    def origin(self) -> tuple[float, float]:
        """(x0, y0) in metres: the south-west corner of cell (0, 0)."""
        return self._x0, self._y0

    @property
    def codes(self) -> np.ndarray:
        """What is shown, (ny, nx) uint8, read-only live view (the mower's cell included)."""
        return self._ro_view

    @property
    def base(self) -> np.ndarray:
        """The lawn without the mower, (ny, nx) uint8, read-only live view."""
        return self._ro_base

    @property
    def mower_cell(self) -> tuple[int, int] | None:
        """(iy, ix) of the mower's last cell inside the map, None before the first."""
        return self._mower

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(iy, ix) of the cell holding (x, y) metres, None outside the map.
        Raises ValueError for NaN or infinite positions."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"position must be finite metres, got x={x!r}, y={y!r}")
        ix = math.floor((x - self._x0) / self._cell)
        iy = math.floor((y - self._y0) / self._cell)
        if 0 <= ix < self._nx and 0 <= iy < self._ny:
            return iy, ix
        return None

    def cell_center(self, iy: int, ix: int) -> tuple[float, float]:
        """(x, y) in metres of the centre of cell (iy, ix) (no range check)."""
        return self._x0 + (ix + 0.5) * self._cell, self._y0 + (iy + 0.5) * self._cell

    def rgb(self, north_up: bool = True) -> np.ndarray:
        """The shown map as an (ny, nx, 3) uint8 RGB image in the seed's colours.
        ``north_up``: image row 0 is the northern edge (for top-down drawing)."""
        img = COLORS_RGB8[self._view]
        return img[::-1] if north_up else img

    # -- the cyclic update -----------------------------------------------------------------

    def update(self, x: float, y: float, bumper: bool = False) -> UpdateResult:
        """The mower is at (x, y) metres (map frame); ``bumper``: the bumper is pressed.

        Applies the rules in the module docstring; O(1). Returns an
        :class:`UpdateResult`. Raises ValueError (map unchanged) for NaN or
        infinite positions or a bumper value other than True/False/0/1.
        """
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"position must be finite metres, got x={x!r}, y={y!r}")
        if bumper not in (False, True):
            raise ValueError(f"bumper must be True/False (or 1/0), got {bumper!r}")
        ix = math.floor((x - self._x0) / self._cell)
        iy = math.floor((y - self._y0) / self._cell)
        if not (0 <= ix < self._nx and 0 <= iy < self._ny):
            return _OUTSIDE
        base, view = self._base, self._view
        old = self._mower
        if old is not None and old[0] == iy and old[1] == ix:
            if bumper and base.item(iy, ix) != OBSTACLE:
                return UpdateResult(old, False, False, self._mark_obstacle(iy, ix))
            return UpdateResult(old, False, False, ())
        changed = []
        if bumper:
            base[iy, ix] = OBSTACLE
            shown = OBSTACLE
        elif base.item(iy, ix) == UNKNOWN:
            shown = UNKNOWN
        else:
            shown = MOWER
        if view.item(iy, ix) != shown:
            view[iy, ix] = shown
            changed.append((iy, ix, shown))
        if old is not None:
            oy, ox = old
            left = _LEFT[base.item(oy, ox)]
            base[oy, ox] = left
            if view.item(oy, ox) != left:
                view[oy, ox] = left
                changed.append((oy, ox, left))
        new = (iy, ix)
        self._mower = new
        return UpdateResult(new, True, False, tuple(changed))

    def _mark_obstacle(self, iy: int, ix: int) -> tuple[tuple[int, int, int], ...]:
        self._base[iy, ix] = OBSTACLE
        if self._view.item(iy, ix) == OBSTACLE:
            return ()
        self._view[iy, ix] = OBSTACLE
        return ((iy, ix, OBSTACLE),)

    # -- files -----------------------------------------------------------------------------

    def save(self, path: str | os.PathLike) -> tuple[Path, Path]:
        """Write ``<stem>.npz`` and its ``<stem>.yaml`` sidecar; returns both paths.

        ``path`` may end in .npz, .yaml or nothing. Stores the base layer (no
        mower), cell size and origin. Each file is written to a temporary file
        first and renamed, so a crash never leaves half a map.
        """
        stem = Path(path)
        if stem.suffix in (".npz", ".yaml", ".yml"):
            stem = stem.with_suffix("")
        npz, side = stem.with_name(stem.name + ".npz"), stem.with_name(stem.name + ".yaml")
        _write_atomic(npz, self._npz_bytes())
        _write_atomic(side, yaml.safe_dump(self._sidecar(npz.name), sort_keys=False).encode())
        return npz, side

    def _npz_bytes(self) -> bytes:
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            format=np.array(_FORMAT),
            version=np.array(_VERSION),
            codes=self._base,
            cell_size=np.array(self._cell),
            origin=np.array([self._x0, self._y0]),
        )
        return buf.getvalue()

    def _sidecar(self, data_name: str) -> dict:
        return {
            "format": _FORMAT,
            "version": _VERSION,
            "data": data_name,
            "cell_size": self._cell,
            "origin": [self._x0, self._y0],
            "shape": [self._ny, self._nx],
            "index": "codes[iy, ix]; row iy grows with +y (north), column ix with +x (east); "
            "cell (0, 0) has its south-west corner at origin",
            "codes": {c: CODE_NAMES[c] for c in range(len(CODE_NAMES))},
            "colors_rgb8": {CODE_NAMES[c]: COLORS_RGB8[c].tolist() for c in range(6)},
        }

    @classmethod
    def load(cls, path: str | os.PathLike) -> CoverageMap:
        """A map from a file written by :meth:`save`: the .npz or its .yaml sidecar.

        Raises ValueError for a file that is not such a map (corrupt, wrong
        keys, unknown codes, bad cell size or origin, sidecar and data
        disagreeing); FileNotFoundError if it is missing.
        """
        path = Path(path)
        if path.suffix in (".yaml", ".yml"):
            meta = _read_sidecar(path)
            codes, cell, origin = _read_npz(path.parent / meta["data"])
            _check_sidecar_agrees(path, meta, codes.shape, cell, origin)
        else:
            codes, cell, origin = _read_npz(path)
        return cls.from_array(codes, cell, origin)


def _write_atomic(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _read_npz(path: Path) -> tuple[np.ndarray, float, tuple[float, float]]:
    """(codes, cell_size, origin) from a saved .npz, all checked."""
    if not path.exists():
        raise FileNotFoundError(f"coverage map file {path} does not exist")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise ValueError("a single array, not an .npz archive")
        with z:
            missing = {"format", "codes", "cell_size", "origin"} - set(z.files)
            if missing:
                raise ValueError(f"missing entries {sorted(missing)}")
            if str(z["format"]) != _FORMAT:
                raise ValueError(f"format is {str(z['format'])!r}, expected {_FORMAT!r}")
            codes, cell, origin = z["codes"], z["cell_size"], z["origin"]
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as e:
        raise ValueError(f"{path} is not a readable coverage map (.npz from save()): {e}") from e
    if cell.shape != () or origin.shape != (2,):
        raise ValueError(f"{path}: cell_size must be a scalar and origin 2 values")
    try:
        codes = _check_codes(codes)
        cell_size = _check_cell_size(cell)
        origin_xy = _check_origin(origin)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from e
    return codes, cell_size, origin_xy


def _check_sidecar_agrees(path: Path, meta: dict, shape, cell: float, origin) -> None:
    try:
        agrees = (
            [int(n) for n in meta.get("shape", shape)] == list(shape)
            and math.isclose(float(meta.get("cell_size", cell)), cell)
            and np.allclose(np.asarray(meta.get("origin", origin), dtype=float), origin)
        )
    except (TypeError, ValueError):
        agrees = False
    if not agrees:
        raise ValueError(f"{path}: sidecar shape/cell_size/origin disagree with {meta['data']}")


def _read_sidecar(path: Path) -> dict:
    if not path.exists():
        raise FileNotFoundError(f"coverage map sidecar {path} does not exist")
    try:
        meta = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise ValueError(f"{path} is not valid YAML: {e}") from e
    if not isinstance(meta, dict) or meta.get("format") != _FORMAT:
        raise ValueError(f"{path} is not a coverage map sidecar (needs format: {_FORMAT})")
    data = meta.get("data")
    if not isinstance(data, str) or Path(data).name != data or not data.endswith(".npz"):
        raise ValueError(f"{path}: 'data' must name an .npz file next to the sidecar, got {data!r}")
    return meta
