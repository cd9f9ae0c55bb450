"""Maps: the coverage grid of a lawn, beacons, GPS fixes and raw vs fused paths (metres).

Two sources, chosen in the "Source" box:

* **Live pose** -- the monitor's own pose (history columns ``x, y``, odom
  frame) drives a :class:`~mm_pc.core.maps.coverage_map.CoverageMap`: the robot's cell
  shows "mower", the cells it left become "mowed" by the seed's rules. Every
  row added since the last frame is fed (only the rows where the cell changes
  are handed to :meth:`CoverageMap.update`, which is the same thing: staying
  in a cell changes nothing), so no cell is skipped when many rows arrive at
  once. "New map…" (:class:`NewMapDialog`) sets cell size, size in cells,
  origin and contents (all lawn, all unknown, or a perimeter rectangle
  rasterised with :meth:`CoverageMap.from_polygon`). A position outside the
  map is a status line, not an error. A session reset starts the same map
  afresh.
* **Simulated run** -- "Simulate mowing run" builds
  :func:`mm_pc.sim.field_run.simulate_field_run` and :func:`~mm_pc.sim.field_run.run_fusion`
  in a worker thread (about 2.5 s; the result of a seed is cached), then plays
  it with a timer at 1x..100x or all at once: the coverage grid from the TRUE
  path, the four beacons (names) and the range circles of the newest range
  set (in the robot's plane, ``sqrt(r^2 - h^2)``), the GPS fixes of the last
  minute (filled if :func:`~mm_pc.core.fixes.gps.gps_fix_usable`) with circles of
  :func:`~mm_pc.core.fixes.gps.gps_accuracy_m` for the newest few, and truth, raw
  mouse odometry and fused (EKF) paths with the current errors.

Drawing the grid costs O(changed cells), not O(map)
---------------------------------------------------
:class:`GridImageItem` holds the map as a ``QImage`` (Format_RGB32, the raster
engine's native format, so painting converts nothing) and a numpy view on
its pixel memory. A map update writes only the pixels of
``UpdateResult.changed`` (one uint32 each) and marks only their rectangles
dirty (``QGraphicsItem.update(rect)``); ``paint`` draws only the exposed
source rectangle. Nothing is copied or converted per update: on a
1000 x 1000 map one changed cell costs the same as on the seed's 81 x 71
(measured, offscreen, write + repaint of the dirty cell: 0.07 ms median on
both; pyqtgraph's ``ImageItem.updateImage``, which rebuilds its QImage from
the whole array, took 1.1 ms on 81 x 71 and 6 ms on 1000 x 1000). Only a new
map (or switching the source) writes the whole image once. The plot has no
``showGrid``: its lines cost ~15 ms per full repaint in software rendering.

Image placement: cell ``(iy, ix)`` is pixel (row iy, column ix), and the item
maps pixel (ix, iy) to ``(x0 + ix*s, y0 + iy*s)``, so it covers
``[x0 + ix*s, x0 + (ix+1)*s] x [y0 + iy*s, y0 + (iy+1)*s]``; the y axis
points up, so row 0 (south) is at the bottom.
"""

from __future__ import annotations

import concurrent.futures
import functools
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF, Qt, QTimer
from PySide6.QtGui import QImage, QPainter, QTransform
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QGraphicsItem,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.maps.coverage_map import (
    CODE_NAMES,
    COLORS_RGB8,
    DEFAULT_CELL_SIZE,
    SEED_SHAPE,
    UNMOWED,
    CoverageMap,
    UpdateResult,
)
from mm_pc.monitor.widgets.style import ERROR_STYLE, parse_number

__all__ = [
    "FILLS",
    "MAX_CELLS",
    "MAX_SIDE_CELLS",
    "SPEEDS",
    "GridImageItem",
    "MapSettings",
    "MapsView",
    "NewMapDialog",
    "SimRun",
    "build_sim_run",
    "default_settings",
    "feed_positions",
    "make_map",
]

#: Contents of a new live map: every cell lawn (unmowed), every cell unknown, or a
#: perimeter rectangle rasterised by CoverageMap.from_polygon.
FILLS = {"lawn": "all lawn (unmowed)", "unknown": "all unknown", "rectangle": "perimeter rectangle"}
MAX_SIDE_CELLS = 4000
MAX_CELLS = 4_000_000  # 16 MB of image, 8 MB of codes
#: Playback speeds: label -> factor (None = all at once).
SPEEDS = {
    "1x": 1.0,
    "2x": 2.0,
    "5x": 5.0,
    "10x": 10.0,
    "20x": 20.0,
    "50x": 50.0,
    "100x": 100.0,
    "all at once": None,
}
DEFAULT_SPEED = "20x"
PLAY_INTERVAL_MS = 33
GPS_CIRCLES = 5  # accuracy circles for the newest this many GPS fixes
GPS_TRAIL = 120  # GPS fixes shown (60 s at 2 Hz); all 1374 of a run hide the map
LEGEND_WIDTH = 190  # px
SIM_MARGIN_M = 1.5  # the simulated run's map reaches this far beyond the plot

#: uint32 0xFFRRGGBB per code: a pixel of a Format_RGB32 QImage.
CODE_PIXELS = (
    np.uint32(0xFF000000)
    | (COLORS_RGB8[:, 0].astype(np.uint32) << 16)
    | (COLORS_RGB8[:, 1].astype(np.uint32) << 8)
    | COLORS_RGB8[:, 2].astype(np.uint32)
)
CODE_PIXELS.flags.writeable = False

PATH_COLOURS = {"truth": "#000000", "raw": "#ff7f0e", "fused": "#0050c8"}
BEACON_COLOUR = "#7b2fbe"
GPS_COLOUR = "#e6a800"
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
    cmap: CoverageMap, x: np.ndarray, y: np.ndarray
) -> tuple[list[tuple[int, int, int]], UpdateResult | None]:
    """Feed a path (x, y m, map frame) to ``cmap``; (changed cells in order, last result).

    Non-finite rows are skipped. Only the rows whose cell differs from the row
    before (and the last row) are passed to :meth:`CoverageMap.update`: a row in
    the same cell changes nothing there. The cell index uses the map's own
    arithmetic, ``floor((x - x0) / s)``. The result is None when no row was finite.
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
    for i in np.flatnonzero(step).tolist():
        result = cmap.update(float(x[i]), float(y[i]))
        changed.extend(result.changed)
    return changed, result


# --- the grid image ------------------------------------------------------------------------


class GridImageItem(pg.GraphicsObject):
    """A coverage map as a QImage whose pixels are written only where cells changed.

    :meth:`set_map` draws a whole map (O(map), once); :meth:`write_cells` writes
    the given cells and repaints only their rectangles (O(cells)).
    ``pixels_written`` counts the pixels written by :meth:`write_cells`.
    """

    def __init__(self) -> None:
        super().__init__()
        self.setFlag(QGraphicsItem.GraphicsItemFlag.ItemUsesExtendedStyleOption, True)
        self._image = QImage()
        self._pixels = np.zeros((0, 0), dtype=np.uint32)
        self._bits = None
        self.pixels_written = 0

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) pixels = cells."""
        return self._pixels.shape

    def set_map(self, cmap: CoverageMap) -> None:
        """Show ``cmap`` (all cells) and place it: pixel (ix, iy) -> (x0 + ix*s, y0 + iy*s) m."""
        ny, nx = cmap.shape
        self.prepareGeometryChange()
        if self._pixels.shape != (ny, nx):
            self._image = QImage(nx, ny, QImage.Format.Format_RGB32)
            self._bits = self._image.bits()  # writable view of the image's own memory
            rows = np.frombuffer(self._bits, dtype=np.uint32).reshape(ny, -1)
            self._pixels = rows[:, :nx]
        self._pixels[:] = CODE_PIXELS[cmap.codes]
        s = cmap.cell_size
        x0, y0 = cmap.origin
        self.setTransform(QTransform(s, 0.0, 0.0, s, x0, y0))
        self.update()

    def write_cells(self, changed: Iterable[tuple[int, int, int]]) -> int:
        """Write the pixels of ``changed`` cells ((iy, ix, code); the last code of a cell
        wins) and mark their rectangles dirty; returns the number of pixels written."""
        last = {(iy, ix): code for iy, ix, code in changed}
        if not last:
            return 0
        pixels = self._pixels
        for (iy, ix), code in last.items():
            pixels[iy, ix] = CODE_PIXELS[code]
        if len(last) <= 32:
            for iy, ix in last:
                self.update(QRectF(ix, iy, 1.0, 1.0))
        else:
            cells = np.array(list(last), dtype=np.int64)
            lo, hi = cells.min(axis=0), cells.max(axis=0) + 1
            self.update(QRectF(lo[1], lo[0], hi[1] - lo[1], hi[0] - lo[0]))
        self.pixels_written += len(last)
        return len(last)

    def rgb(self) -> np.ndarray:
        """What the image shows as a (ny, nx, 3) uint8 RGB copy, row 0 = south."""
        p = self._pixels
        return np.stack([(p >> 16) & 255, (p >> 8) & 255, p & 255], axis=-1).astype(np.uint8)

    def boundingRect(self) -> QRectF:  # noqa: N802 - Qt API
        ny, nx = self._pixels.shape
        return QRectF(0.0, 0.0, float(nx), float(ny))

    def paint(self, painter: QPainter, option, widget=None) -> None:
        ny, nx = self._pixels.shape
        if nx == 0 or ny == 0:
            return
        r = option.exposedRect
        left = max(0, math.floor(r.left()))
        top = max(0, math.floor(r.top()))
        right = min(nx, math.ceil(r.right()))
        bottom = min(ny, math.ceil(r.bottom()))
        if right <= left or bottom <= top:
            return
        part = QRectF(left, top, right - left, bottom - top)
        painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, False)
        painter.drawImage(part, self._image, part)


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


def _circles(centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outline points of several circles, NaN between them (for connect='finite')."""
    if len(radii) == 0:
        return np.empty(0), np.empty(0)
    c, s = np.cos(_CIRCLE), np.sin(_CIRCLE)
    xs = centres[:, :1] + radii[:, None] * c
    ys = centres[:, 1:2] + radii[:, None] * s
    gap = np.full((len(radii), 1), np.nan)
    return np.hstack([xs, gap]).ravel(), np.hstack([ys, gap]).ravel()


_executor: concurrent.futures.ThreadPoolExecutor | None = None


def _worker() -> concurrent.futures.ThreadPoolExecutor:
    global _executor
    if _executor is None:
        _executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="maps-sim")
    return _executor


# --- "New map…" ------------------------------------------------------------------------------



def _parse_positive(text: str, what: str) -> float:
    v = parse_number(text, what)
    if v <= 0:
        raise ValueError(f"{what} must be > 0, got {text.strip()}")
    return v


def _parse_cells(text: str, what: str) -> int:
    try:
        n = int(text.strip())
    except ValueError:
        raise ValueError(f"{what} must be a whole number of cells, got {text!r}") from None
    if not 1 <= n <= MAX_SIDE_CELLS:
        raise ValueError(f"{what} must be 1..{MAX_SIDE_CELLS} cells, got {n}")
    return n


class _Field(QWidget):
    """A line edit with a red error label beside it."""

    def __init__(self, text: str, tip: str) -> None:
        super().__init__()
        self.edit = QLineEdit(text)
        self.edit.setToolTip(tip)
        self.edit.setMaximumWidth(90)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.edit)
        lay.addWidget(self.error, 1)

    def set_error(self, message: str) -> None:
        self.error.setText(message)
        self.error.setVisible(bool(message))


class NewMapDialog(QDialog):
    """Settings of a new live coverage map; "Create" validates them.

    Bad input leaves the dialog open with a red message beside the field and
    does not touch the view's map. On success :attr:`map` and :attr:`settings`
    hold the new map and the view adopts it (:meth:`MapsView.set_live_map`).
    """

    def __init__(self, view: MapsView, parent: QWidget | None = None) -> None:
        super().__init__(parent or view)
        self.view = view
        self.setWindowTitle("New coverage map")
        self.map: CoverageMap | None = None
        self.settings: MapSettings | None = None
        cur = view.live_settings
        ny, nx = cur.shape
        rect = cur.rect or (-7.5, -5.0, 15.0, 10.0)
        self.fields = {
            "cell": _Field(f"{cur.cell_size:g}", "edge of a square cell, m (> 0; seed: 0.3)"),
            "ny": _Field(str(ny), f"rows along y (north), 1..{MAX_SIDE_CELLS}"),
            "nx": _Field(str(nx), f"columns along x (east), 1..{MAX_SIDE_CELLS}"),
            "x0": _Field(f"{cur.origin[0]:g}", "x of the map's south-west corner, m (odom frame)"),
            "y0": _Field(f"{cur.origin[1]:g}", "y of the map's south-west corner, m (odom frame)"),
            "rx": _Field(f"{rect[0]:g}", "x of the rectangle's south-west corner, m"),
            "ry": _Field(f"{rect[1]:g}", "y of the rectangle's south-west corner, m"),
            "rw": _Field(f"{rect[2]:g}", "rectangle width along x, m (> 0)"),
            "rh": _Field(f"{rect[3]:g}", "rectangle height along y, m (> 0)"),
        }
        self.fill_box = QComboBox()
        for key, text in FILLS.items():
            self.fill_box.addItem(text, key)
        self.fill_box.setCurrentIndex(list(FILLS).index(cur.fill))
        self.fill_box.currentIndexChanged.connect(self._fill_changed)
        self.fill_error = QLabel("")
        self.fill_error.setStyleSheet(ERROR_STYLE)
        self.fill_error.setWordWrap(True)
        self.fill_error.hide()

        form = QFormLayout(self)
        f = self.fields
        form.addRow("Cell size (m)", f["cell"])
        form.addRow("Rows ny (along y)", f["ny"])
        form.addRow("Columns nx (along x)", f["nx"])
        form.addRow("Origin x0 (m)", f["x0"])
        form.addRow("Origin y0 (m)", f["y0"])
        form.addRow("Contents", self.fill_box)
        form.addRow("Perimeter corner x (m)", f["rx"])
        form.addRow("Perimeter corner y (m)", f["ry"])
        form.addRow("Perimeter width (m)", f["rw"])
        form.addRow("Perimeter height (m)", f["rh"])
        form.addRow(self.fill_error)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Cancel)
        self.create_button = buttons.addButton("Create", QDialogButtonBox.ButtonRole.AcceptRole)
        self.create_button.setDefault(True)
        buttons.accepted.connect(self.apply)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)
        self._fill_changed()

    @property
    def fill(self) -> str:
        return self.fill_box.currentData()

    def set_fill(self, fill: str) -> None:
        self.fill_box.setCurrentIndex(list(FILLS).index(fill))

    def _fill_changed(self, *_args) -> None:
        for key in ("rx", "ry", "rw", "rh"):
            self.fields[key].setEnabled(self.fill == "rectangle")

    def _read(self) -> MapSettings | None:
        """The typed settings, or None with every field's message shown."""
        parsers = {
            "cell": (_parse_positive, "cell size (m)"),
            "ny": (_parse_cells, "rows ny"),
            "nx": (_parse_cells, "columns nx"),
            "x0": (parse_number, "origin x0 (m)"),
            "y0": (parse_number, "origin y0 (m)"),
        }
        if self.fill == "rectangle":
            parsers |= {
                "rx": (parse_number, "corner x (m)"),
                "ry": (parse_number, "corner y (m)"),
                "rw": (_parse_positive, "width (m)"),
                "rh": (_parse_positive, "height (m)"),
            }
        values: dict[str, float] = {}
        for key, field in self.fields.items():
            field.set_error("")
            if key in parsers:
                parse, what = parsers[key]
                try:
                    values[key] = parse(field.edit.text(), what)
                except ValueError as e:
                    field.set_error(str(e))
        if len(values) < len(parsers):
            return None
        ny, nx = int(values["ny"]), int(values["nx"])
        if ny * nx > MAX_CELLS:
            self.fields["nx"].set_error(
                f"ny x nx = {ny * nx} cells; at most {MAX_CELLS} (use larger cells)"
            )
            return None
        rect = None
        if self.fill == "rectangle":
            rect = (values["rx"], values["ry"], values["rw"], values["rh"])
        return MapSettings(values["cell"], (ny, nx), (values["x0"], values["y0"]), self.fill, rect)

    def apply(self) -> bool:
        """Validate and create the map; False (messages shown, view unchanged) on bad input."""
        self.fill_error.hide()
        settings = self._read()
        if settings is None:
            return False
        try:
            cmap = make_map(settings)
        except ValueError as e:
            self.fill_error.setText(f"map not created: {e}")
            self.fill_error.show()
            return False
        self.map, self.settings = cmap, settings
        self.view.set_live_map(cmap, settings)
        self.accept()
        return True


# --- the view ----------------------------------------------------------------------------------


def _legend(side: pg.ViewBox, offset: tuple[float, float]) -> pg.LegendItem:
    legend = pg.LegendItem(
        offset=offset, brush=pg.mkBrush(255, 255, 255, 220), labelTextColor="#222222"
    )
    legend.setParentItem(side)
    return legend


def _code_samples() -> list[tuple[pg.ScatterPlotItem, str]]:
    """One square in the seed's colour per cell code, for the legend."""
    return [
        (
            pg.ScatterPlotItem(
                symbol="s", size=13, brush=pg.mkBrush(*rgb.tolist()), pen=pg.mkPen("#444444")
            ),
            f"{code} {CODE_NAMES[code]}",
        )
        for code, rgb in enumerate(COLORS_RGB8)
    ]


class MapsView(QWidget):
    """Coverage grid (live pose or a simulated mowing run), beacons, GPS and paths."""

    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.source = "live"
        self.live_settings = default_settings()
        self.live_map = make_map(self.live_settings)
        self.live_result: UpdateResult | None = None
        self.live_xy: tuple[float, float] | None = None
        self._version = -1
        self._last_t = -math.inf
        self.run: SimRun | None = None
        self.sim_map: CoverageMap | None = None
        self.sim_k = -1
        self.sim_errors: tuple[float, float] | None = None
        self._play_t = 0.0
        self._clock = 0.0
        self._future: concurrent.futures.Future | None = None
        self.dialog: NewMapDialog | None = None

        self._build_controls()
        self._build_plot()
        lay = QVBoxLayout(self)
        lay.addLayout(self._bar)
        lay.addWidget(self.status)
        lay.addWidget(self.error)
        lay.addWidget(self.plot_widget, 1)

        self.timer = QTimer(self)
        self.timer.setInterval(PLAY_INTERVAL_MS)
        self.timer.timeout.connect(self._tick)
        ctx.session_reset.connect(self._on_reset)
        self._show_source()

    # -- construction --------------------------------------------------------------------

    def _build_controls(self) -> None:
        self.source_box = QComboBox()
        self.source_box.addItem("Live pose", "live")
        self.source_box.addItem("Simulated run", "sim")
        self.source_box.setToolTip("what the map shows: the monitor's pose, or a simulated run")
        self.source_box.currentIndexChanged.connect(
            lambda _i: self.set_source(self.source_box.currentData())
        )
        self.new_map_button = QPushButton("New map…")
        self.new_map_button.setToolTip("cell size, size, origin and perimeter of the live map")
        self.new_map_button.clicked.connect(self.open_new_map_dialog)
        self.sim_button = QPushButton("Simulate mowing run")
        self.sim_button.setToolTip(
            "a ~205 m run over a 20 m x 10 m plot: mouse odometry, GPS, beacons, compass, "
            "wire contacts, fused by the EKF; coverage drawn from the true path"
        )
        self.sim_button.clicked.connect(lambda: self.start_simulation())
        self.seed_box = QSpinBox()
        self.seed_box.setRange(1, 1_000_000)
        self.seed_box.setValue(1)
        self.seed_box.setPrefix("seed ")
        self.seed_box.setToolTip("random seed of the simulated run")
        self.speed_box = QComboBox()
        self.speed_box.addItems(list(SPEEDS))
        self.speed_box.setCurrentText(DEFAULT_SPEED)
        self.speed_box.setToolTip("playback speed of the simulated run")
        self.speed_box.currentTextChanged.connect(self._speed_changed)
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Source"))
        bar.addWidget(self.source_box)
        bar.addWidget(self.new_map_button)
        bar.addSpacing(16)
        bar.addWidget(self.sim_button)
        bar.addWidget(self.seed_box)
        bar.addWidget(QLabel("Speed"))
        bar.addWidget(self.speed_box)
        bar.addStretch(1)
        self._bar = bar
        self.status = QLabel("waiting for the robot's pose")
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()

    def _build_plot(self) -> None:
        self.plot_widget = pg.GraphicsLayoutWidget()
        self.plot_widget.setBackground("w")
        plot = self.plot = self.plot_widget.addPlot(row=0, col=0)
        plot.setAspectLocked(True)  # no showGrid: its lines cost ~15 ms per repaint here
        for name in ("left", "bottom"):
            axis = plot.getAxis(name)
            axis.setPen(pg.mkPen("#444444"))
            axis.setTextPen(pg.mkPen("#222222"))
            axis.enableAutoSIPrefix(False)
        plot.setLabel("bottom", "x (east)", units="m")
        plot.setLabel("left", "y (north)", units="m")
        # the legends live in a column of their own, so they never hide the map
        side = self.legend_box = pg.ViewBox(enableMouse=False)
        side.setMinimumWidth(LEGEND_WIDTH)
        side.setMaximumWidth(LEGEND_WIDTH)
        self.plot_widget.addItem(side, row=0, col=1)
        self.code_legend = _legend(side, (2, 2))
        self._code_samples = _code_samples()
        for sample, name in self._code_samples:
            self.code_legend.addItem(sample, name)
        self.sim_legend = _legend(side, (2, 175))

        self.grid = GridImageItem()
        plot.addItem(self.grid)
        self.robot = pg.ScatterPlotItem(
            size=9, symbol="o", brush=pg.mkBrush("#ffffff"), pen=pg.mkPen("#000000", width=2)
        )
        plot.addItem(self.robot)
        self.range_circles = pg.PlotDataItem(
            [], [], pen=pg.mkPen(BEACON_COLOUR, width=1, style=Qt.PenStyle.DashLine),
            connect="finite",
        )  # fmt: skip
        self.gps_circles = pg.PlotDataItem([], [], pen=pg.mkPen(GPS_COLOUR), connect="finite")
        self.gps_good = pg.ScatterPlotItem(
            size=6, symbol="o", brush=pg.mkBrush(GPS_COLOUR), pen=pg.mkPen("#5a4300")
        )
        self.gps_bad = pg.ScatterPlotItem(
            size=7, symbol="x", brush=pg.mkBrush("#666666"), pen=pg.mkPen("#666666")
        )
        self.paths = {
            key: pg.PlotDataItem([], [], pen=pg.mkPen(colour, width=1 if key == "truth" else 2))
            for key, colour in PATH_COLOURS.items()
        }
        for curve in self.paths.values():
            curve.setClipToView(True)
        self.beacons = pg.ScatterPlotItem(
            size=16, symbol="star", brush=pg.mkBrush(BEACON_COLOUR), pen=pg.mkPen("#000000")
        )
        self.beacon_labels: list[pg.TextItem] = []
        self.sim_items = [
            self.range_circles,
            self.gps_circles,
            self.gps_good,
            self.gps_bad,
            self.paths["raw"],
            self.paths["fused"],
            self.paths["truth"],  # on top: thin black over the fused path
            self.beacons,
        ]
        for item in self.sim_items:
            plot.addItem(item)
        for key, text in (("truth", "truth"), ("raw", "raw mouse odometry"), ("fused", "fused")):
            self.sim_legend.addItem(self.paths[key], text)
        self.sim_legend.addItem(self.beacons, "beacon")
        self.sim_legend.addItem(self.range_circles, "range (newest set)")
        self.sim_legend.addItem(self.gps_good, f"GPS fix, last {GPS_TRAIL} (usable)")
        self.sim_legend.addItem(self.gps_bad, "GPS fix (not usable)")
        self.sim_legend.addItem(self.gps_circles, f"GPS accuracy (newest {GPS_CIRCLES})")

    # -- source --------------------------------------------------------------------------

    @property
    def shown_map(self) -> CoverageMap:
        """The map the grid image shows now."""
        if self.source == "sim" and self.sim_map is not None:
            return self.sim_map
        return self.live_map

    def set_source(self, source: str) -> None:
        """'live' or 'sim'; 'sim' without a simulated run starts one."""
        if source not in ("live", "sim"):
            raise ValueError(f"source must be 'live' or 'sim', got {source!r}")
        if source == "sim" and self.run is None:
            self.start_simulation()
            return
        if source == self.source:
            return
        self.source = source
        self._show_source()

    def _show_source(self) -> None:
        self.source_box.blockSignals(True)
        self.source_box.setCurrentIndex(0 if self.source == "live" else 1)
        self.source_box.blockSignals(False)
        sim = self.source == "sim"
        for item in [*self.sim_items, *self.beacon_labels, self.sim_legend]:
            item.setVisible(sim)
        self.robot.setVisible(not sim)
        self.new_map_button.setEnabled(not sim)
        cmap = self.shown_map
        self.grid.set_map(cmap)
        self._fit(cmap)
        if sim:
            self._draw_sim()
            if self.run is not None and self.sim_k < len(self.run.sim.t) - 1:
                self._clock = time.monotonic()
                self.timer.start()  # resume playing
        else:
            if self._future is None:
                self.timer.stop()  # pause playing
            self._version = -1
            self._draw_live_status()

    def _fit(self, cmap: CoverageMap) -> None:
        ny, nx = cmap.shape
        s = cmap.cell_size
        x0, y0 = cmap.origin
        self.plot.setRange(QRectF(x0, y0, nx * s, ny * s), padding=0.03)

    # -- live ---------------------------------------------------------------------------

    def open_new_map_dialog(self) -> NewMapDialog:
        """Open "New map…" (non-modal; it applies itself on "Create")."""
        self.dialog = NewMapDialog(self)
        self.dialog.open()
        return self.dialog

    def set_live_map(self, cmap: CoverageMap, settings: MapSettings) -> None:
        """Adopt a new live map; the newest pose is placed on it at the next refresh."""
        self.live_map, self.live_settings = cmap, settings
        self.live_result = None
        if self.source == "live":
            self.grid.set_map(cmap)
            self._fit(cmap)
        self._replay_newest()

    def _replay_newest(self) -> None:
        """Start the live map from the newest pose only (not the whole history)."""
        hist = self.ctx.session.history
        if hist is not None and len(hist):
            self._last_t = float(hist.column("t")[-2]) if len(hist) > 1 else -math.inf
        self._version = -1

    def _on_reset(self) -> None:
        self.live_map = make_map(self.live_settings)
        self.live_result, self.live_xy = None, None
        self._last_t = -math.inf
        self._version = -1
        if self.source == "live":
            self.grid.set_map(self.live_map)
            self.robot.setData([], [])
            self.status.setText("map reset: waiting for the robot's pose")

    def refresh(self) -> None:
        """Feed the poses added since the last call to the live map and draw its changed
        cells; returns at once when the history did not change."""
        hist = self.ctx.session.history
        if hist is None or hist.version == self._version:
            return
        self._version = hist.version
        t = hist.column("t")
        if len(t) == 0:
            return
        if t[-1] < self._last_t:  # history restarted without a reset signal
            self._last_t = -math.inf
        start = int(np.searchsorted(t, self._last_t, side="right"))
        if start >= len(t):
            return
        self._last_t = float(t[-1])
        x, y = hist.column("x")[start:], hist.column("y")[start:]
        changed, result = feed_positions(self.live_map, x, y)
        if result is None:
            return
        self.live_result = result
        self.live_xy = (float(x[-1]), float(y[-1]))
        if self.source == "live":
            self.grid.write_cells(changed)
            self.robot.setData([self.live_xy[0]], [self.live_xy[1]])
            self._draw_live_status()

    def _draw_live_status(self) -> None:
        if self.live_xy is None or self.live_result is None:
            self.status.setText("waiting for the robot's pose")
            return
        x, y = self.live_xy
        cmap = self.live_map
        ny, nx = cmap.shape
        size = f"map {nx} (x) x {ny} (y) cells of {cmap.cell_size:g} m"
        if self.live_result.outside:
            self.status.setText(f"robot outside the map at x = {x:.2f} m, y = {y:.2f} m ({size})")
        else:
            iy, ix = self.live_result.cell
            self.status.setText(
                f"robot at x = {x:.2f} m, y = {y:.2f} m, cell (iy {iy}, ix {ix}); {size}"
            )

    # -- simulated run -------------------------------------------------------------------

    def start_simulation(self, seed: int | None = None) -> None:
        """Build the simulated run in a worker thread; it plays when ready."""
        if self._future is not None:
            return
        seed = self.seed_box.value() if seed is None else int(seed)
        self.error.hide()
        self.sim_button.setEnabled(False)
        self.status.setText(f"simulating the mowing run (seed {seed})…")
        self._future = _worker().submit(build_sim_run, seed)
        self.timer.start()

    @property
    def speed(self) -> float | None:
        """Playback factor, None = all at once."""
        return SPEEDS[self.speed_box.currentText()]

    def _speed_changed(self, _text: str) -> None:
        if self.run is not None and self.speed is None and self.source == "sim":
            self._advance_to(len(self.run.sim.t) - 1)

    def load_simulation(self, run: SimRun) -> None:
        """Show ``run`` from its start and play it at the chosen speed."""
        self.run = run
        self.sim_map = sim_map(run)
        self.sim_k = -1
        self._play_t = 0.0
        self._clock = time.monotonic()
        sim = run.sim
        self.beacons.setData([b.x for b in sim.beacons], [b.y for b in sim.beacons])
        for label in self.beacon_labels:
            self.plot.removeItem(label)
        self.beacon_labels = []
        for b in sim.beacons:
            label = pg.TextItem(b.name, color="#000000", anchor=(0.5, 1.4))
            label.setPos(b.x, b.y)
            self.plot.addItem(label)
            self.beacon_labels.append(label)
        self.source = "sim"
        self._show_source()
        self._advance_to(0)
        if self.speed is None:
            self._advance_to(len(sim.t) - 1)
        else:
            self.timer.start()

    def _tick(self) -> None:
        if self._future is not None:
            if not self._future.done():
                return
            future, self._future = self._future, None
            self.sim_button.setEnabled(True)
            try:
                run = future.result()
            except Exception as e:  # anything the simulation raised: show it where it happened
                self.timer.stop()
                self.error.setText(f"simulated run failed: {e}")
                self.error.show()
                return
            self.load_simulation(run)
            return
        if self.run is None or self.source != "sim":
            self.timer.stop()
            return
        now = time.monotonic()
        last = len(self.run.sim.t) - 1
        if self.speed is None:
            k = last
        else:
            self._play_t += (now - self._clock) * self.speed
            k = int(np.searchsorted(self.run.sim.t, self._play_t, side="right")) - 1
        self._clock = now
        self._advance_to(min(max(k, 0), last))
        if self.sim_k >= last:
            self.timer.stop()

    def _advance_to(self, k: int) -> None:
        """Feed the true path up to row k to the sim map and draw the run at k."""
        run = self.run
        if run is None or k <= self.sim_k:
            return
        truth = run.sim.truth
        lo = max(self.sim_k, 0)
        changed, _ = feed_positions(self.sim_map, truth[lo : k + 1, 0], truth[lo : k + 1, 1])
        self.sim_k = k
        self._play_t = max(self._play_t, float(run.sim.t[k]))
        if self.source == "sim":
            self.grid.write_cells(changed)
            self._draw_sim()

    def _draw_sim(self) -> None:
        run, k = self.run, self.sim_k
        if run is None or k < 0:
            return
        sim = run.sim
        for key, poses in (("truth", sim.truth), ("raw", sim.raw), ("fused", run.fused)):
            self.paths[key].setData(poses[: k + 1, 0], poses[: k + 1, 1])
        self._draw_ranges(k)
        self._draw_gps(k)
        raw = math.hypot(*(sim.raw[k, :2] - sim.truth[k, :2]))
        fused = math.hypot(*(run.fused[k, :2] - sim.truth[k, :2]))
        self.sim_errors = (raw, fused)
        speed = self.speed_box.currentText()
        self.status.setText(
            f"simulated run: t = {sim.t[k]:.1f} s of {sim.t[-1]:.1f} s ({speed}); "
            f"position error now: raw odometry {raw:.2f} m, fused {fused:.2f} m"
        )

    def _draw_ranges(self, k: int) -> None:
        from mm_pc.core.maps.trilateration import TrilaterationError, plane_distances

        run = self.run
        j = int(np.searchsorted(run.range_k, k, side="right")) - 1
        if j < 0:
            self.range_circles.setData([], [])
            return
        beacons = run.sim.beacons
        try:
            radii = plane_distances(beacons, run.sim.ranges[j].ranges)
        except TrilaterationError:  # a range shorter than the beacon height: no plane circle
            self.range_circles.setData([], [])
            return
        centres = np.array([[b.x, b.y] for b in beacons])
        self.range_circles.setData(*_circles(centres, radii))

    def _draw_gps(self, k: int) -> None:
        run = self.run
        n = int(np.searchsorted(run.gps_k, k, side="right"))
        shown = slice(max(0, n - GPS_TRAIL), n)
        xy, usable = run.gps_xy[shown], run.gps_usable[shown]
        self.gps_good.setData(xy[usable, 0], xy[usable, 1])
        self.gps_bad.setData(xy[~usable, 0], xy[~usable, 1])
        first = max(0, n - GPS_CIRCLES)
        self.gps_circles.setData(*_circles(run.gps_xy[first:n], run.gps_accuracy[first:n]))
