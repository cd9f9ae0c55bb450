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
  in a process of its own (:class:`~mm_pc.monitor.model.sim_process.SimJob`, how long
  in :data:`~mm_pc.monitor.model.sim_process.SIM_TYPICAL`: on a thread it held the
  interpreter lock and the window stuttered), with a busy bar,
  the seconds so far and a Cancel; the result of a seed is kept; then plays
  it with a timer at 1x..100x or all at once: the coverage grid from the TRUE
  path, the four beacons (names) and the range circles of the newest range
  set (in the robot's plane, ``sqrt(r^2 - h^2)``), the GPS fixes of the last
  minute (filled if :func:`~mm_pc.core.fixes.gps.gps_fix_usable`) with circles of
  :func:`~mm_pc.core.fixes.gps.gps_accuracy_m` for the newest few, and truth, raw
  mouse odometry and fused (EKF) paths with the current errors.

The grid image is :class:`~.grid_item.GridImageItem`; the model, :mod:`mm_pc.monitor.model.maps`.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF, Qt, QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.maps.coverage_map import (
    CODE_NAMES,
    CoverageMap,
    UpdateResult,
)
from mm_pc.monitor.model.maps import (
    SIM_CUT_WIDTH,
    MapSettings,
    SimRun,
    circles,
    default_settings,
    feed_positions,
    make_map,
    sim_map,
)
from mm_pc.monitor.model.sim_process import SIM_TYPICAL, SimJob, build_in_child
from mm_pc.monitor.widgets.maps_view.dialog import NewMapDialog
from mm_pc.monitor.widgets.maps_view.grid_item import GridImageItem
from mm_pc.monitor.widgets.maps_view.palette import DISPLAY_RGB8, PATH_STYLES
from mm_pc.monitor.widgets.style import ERROR_STYLE

__all__ = ["SPEEDS", "MapsView"]

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
LEGEND_WIDTH = 190  # px, the least; as wide as the widest legend

PATH_COLOURS = {key: style[0] for key, style in PATH_STYLES.items()}
BEACON_COLOUR = "#7b2fbe"
GPS_COLOUR = "#e6a800"


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
        for code, rgb in enumerate(DISPLAY_RGB8)
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
        self._job: SimJob | None = None
        self._runs: dict[int, SimRun] = {}  # seed -> built run (the child's cache is gone)
        self._to_load: SimRun | None = None  # arrived, shown from the next tick
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
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setToolTip("stop building the simulated run")
        self.cancel_button.clicked.connect(self.cancel_simulation)
        self.cancel_button.hide()
        self.progress = QProgressBar()
        self.progress.setRange(0, 0)  # busy: the simulation reports no fraction done
        self.progress.setMaximumWidth(120)
        self.progress.setTextVisible(False)
        self.progress.hide()
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
        # two rows, so the tab fits an 800 px window while a run is built (progress, Cancel)
        first, second = QHBoxLayout(), QHBoxLayout()
        first.addWidget(QLabel("Source"))
        first.addWidget(self.source_box)
        first.addWidget(self.new_map_button)
        first.addSpacing(16)
        first.addWidget(self.progress)
        first.addWidget(self.cancel_button)
        first.addStretch(1)
        second.addWidget(self.sim_button)
        second.addWidget(self.seed_box)
        second.addWidget(QLabel("Speed"))
        second.addWidget(self.speed_box)
        second.addStretch(1)
        bar = QVBoxLayout()
        bar.setSpacing(2)
        bar.addLayout(first)
        bar.addLayout(second)
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
        self._fit_legend_column(LEGEND_WIDTH)
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
            key: pg.PlotDataItem([], [], pen=pg.mkPen(colour, width=PATH_STYLES[key][1],
                                                      style=PATH_STYLES[key][2]))
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
            self.paths["fused"],  # wide, under the others
            self.paths["raw"],  # dashed
            self.paths["truth"],  # on top: thin black over the fused path
            self.beacons,
        ]
        for item in self.sim_items:
            plot.addItem(item)
        for key, text in (("truth", "truth (thin black)"),
                          ("fused", "fused, EKF (wide blue)"),
                          ("raw", "raw mouse odometry (dashed)")):
            self.sim_legend.addItem(self.paths[key], text)
        self.sim_legend.addItem(self.beacons, "beacon")
        self.sim_legend.addItem(self.range_circles, "range (newest set)")
        self.sim_legend.addItem(self.gps_good, f"GPS fix, last {GPS_TRAIL} (usable)")
        self.sim_legend.addItem(self.gps_bad, "GPS fix (not usable)")
        self.sim_legend.addItem(self.gps_circles, f"GPS accuracy (newest {GPS_CIRCLES})")
        self._fit_legend_column(LEGEND_WIDTH)

    def _fit_legend_column(self, least: float) -> None:
        """The legends' column as wide as the widest legend shown (px; at least ``least``):
        its names ("raw mouse odometry (dashed)") were cut at the view's edge."""
        legends = [lg for lg in (getattr(self, "code_legend", None),
                                 getattr(self, "sim_legend", None))
                   if lg is not None and lg.isVisibleTo(lg.parentItem())]
        for lg in legends:
            lg.updateSize()
        width = max([least, *(lg.boundingRect().width() + 6 for lg in legends)])
        self.legend_box.setMinimumWidth(width)
        self.legend_box.setMaximumWidth(width)

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
        self._fit_legend_column(LEGEND_WIDTH)
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
            if self._job is None:
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
        """Build the simulated run in a child process; it plays when ready."""
        if self._job is not None:
            return
        self._to_load = None
        seed = self.seed_box.value() if seed is None else int(seed)
        self.error.hide()
        if seed in self._runs:
            self.load_simulation(self._runs[seed])
            return
        self.sim_button.setEnabled(False)
        self.progress.show()
        self.cancel_button.show()
        self.status.setText(f"simulating the mowing run (seed {seed}) in its own process… "
                            f"({SIM_TYPICAL})")
        self._job = SimJob(seed, target=self.sim_target)
        self.timer.start()

    #: the child's function (tests replace it with one that fails or hangs)
    sim_target = staticmethod(build_in_child)

    def cancel_simulation(self) -> None:
        """Stop building the simulated run (its process is terminated)."""
        if self._job is None:
            return
        job, self._job = self._job, None
        job.cancel()
        self._end_job()
        self.status.setText(f"simulation (seed {job.seed}) cancelled after {job.elapsed_s:.1f} s")

    def _end_job(self) -> None:
        self.sim_button.setEnabled(True)
        self.progress.hide()
        self.cancel_button.hide()

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
        if self._job is not None:
            result = self._job.poll()
            if result is None:
                self.status.setText(f"simulating the mowing run (seed {self._job.seed}) in its "
                                    f"own process… {self._job.elapsed_s:.0f} s ({SIM_TYPICAL})")
                return
            job, self._job = self._job, None
            self._end_job()
            kind, value = result
            if kind != "ok":  # anything the simulation raised: show it where it happened
                self.timer.stop()
                self.status.setText(f"simulation (seed {job.seed}) failed")
                self.error.setText(f"simulated run failed: {value}")
                self.error.show()
                return
            self._runs[job.seed] = value
            # shown from the next tick: unpickling (~35 ms at a load of 6) and showing it
            # (~20 ms) in one turn of the event loop held the window up 80-130 ms
            self._to_load = value
            return
        if self._to_load is not None:
            run, self._to_load = self._to_load, None
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
        changed, _ = feed_positions(self.sim_map, truth[lo : k + 1, 0], truth[lo : k + 1, 1],
                                    SIM_CUT_WIDTH)
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
        self.range_circles.setData(*circles(centres, radii))

    def _draw_gps(self, k: int) -> None:
        run = self.run
        n = int(np.searchsorted(run.gps_k, k, side="right"))
        shown = slice(max(0, n - GPS_TRAIL), n)
        xy, usable = run.gps_xy[shown], run.gps_usable[shown]
        self.gps_good.setData(xy[usable, 0], xy[usable, 1])
        self.gps_bad.setData(xy[~usable, 0], xy[~usable, 1])
        first = max(0, n - GPS_CIRCLES)
        self.gps_circles.setData(*circles(run.gps_xy[first:n], run.gps_accuracy[first:n]))
