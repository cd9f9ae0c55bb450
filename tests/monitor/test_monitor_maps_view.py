"""The Maps tab: coverage grid from the live pose and from the simulated mowing run."""

from __future__ import annotations

import math
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtWidgets import QApplication

from mm_pc.core.fixes.gps import gps_accuracy_m
from mm_pc.core.maps.coverage_map import COLORS_RGB, MOWED, MOWER, UNMOWED, CoverageMap
from mm_pc.core.maps.trilateration import plane_distances
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model import maps as mm
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.widgets.maps_view import grid_item
from mm_pc.monitor.widgets.maps_view import view as mv
from mm_pc.monitor.widgets.maps_view.palette import DISPLAY_RGB8 as COLORS_RGB8
from mm_pc.monitor.widgets.maps_view.palette import PATH_STYLES, luminance

ROOT = Path(__file__).resolve().parents[2]




def make_view(qtbot) -> mv.MapsView:
    ctx = MonitorContext(MonitorSession())
    view = mv.MapsView(ctx)
    qtbot.addWidget(view)
    view.resize(1100, 700)
    return view


def reference_map(settings: mm.MapSettings, x, y) -> CoverageMap:
    """The map the live view must hold: every row fed to CoverageMap.update."""
    ref = mm.make_map(settings)
    for xi, yi in zip(x, y, strict=True):
        ref.update(float(xi), float(yi))
    return ref


def assert_image_shows(view: mv.MapsView, cmap: CoverageMap) -> None:
    np.testing.assert_array_equal(view.grid.rgb(), COLORS_RGB8[cmap.codes])


@pytest.fixture(scope="module")
def run() -> mm.SimRun:
    return mm.build_sim_run(1)


# --- live ------------------------------------------------------------------------------------


def test_live_grid_pixels_equal_codes_after_sim_replies(qtbot, feed):
    view = make_view(qtbot)
    replies = list(sim_replies("figure_eight", rate_hz=20.0, seconds=24.0))
    # in batches, as replies arrive between frames
    for start in range(0, len(replies), 37):
        feed(view.ctx, replies[start : start + 37])
        view.refresh()
        assert_image_shows(view, view.live_map)
    hist = view.ctx.session.history
    x, y = hist.column("x"), hist.column("y")
    ref = reference_map(view.live_settings, x, y)
    np.testing.assert_array_equal(view.live_map.codes, ref.codes)
    codes = view.live_map.codes
    assert np.count_nonzero(codes == MOWED) > 10
    assert np.count_nonzero(codes == MOWER) == 1
    assert view.live_map.mower_cell == view.live_map.cell_of(x[-1], y[-1])
    assert view.status.text().startswith(f"robot at x = {x[-1]:.2f} m, y = {y[-1]:.2f} m")
    assert "71 (x) x 81 (y) cells of 0.3 m" in view.status.text()


def test_only_changed_cells_are_written(qtbot, feed):
    view = make_view(qtbot)
    replies = sim_replies("figure_eight", rate_hz=20.0, seconds=20.0)
    feed(view.ctx, (next(replies) for _ in range(150)))
    view.refresh()
    written: list[tuple[int, int, int]] = []
    original = view.grid.write_cells

    def spy(changed):
        changed = list(changed)
        written.extend(changed)
        return original(changed)

    view.grid.write_cells = spy
    before_rgb = view.grid.rgb()
    before_count = view.grid.pixels_written
    before_codes = view.live_map.codes.copy()
    feed(view.ctx, (next(replies) for _ in range(40)))
    view.refresh()
    cells = {(iy, ix) for iy, ix, _ in written}
    assert 0 < len(cells) < 40
    assert view.grid.pixels_written - before_count == len(cells)
    differs = np.argwhere(np.any(view.grid.rgb() != before_rgb, axis=-1))
    assert {tuple(c) for c in differs.tolist()} <= cells
    assert {tuple(c) for c in np.argwhere(view.live_map.codes != before_codes).tolist()} == {
        tuple(c) for c in differs.tolist()
    }
    # nothing new: refresh returns at once and writes nothing
    count = view.grid.pixels_written
    view.refresh()
    assert view.grid.pixels_written == count
    assert_image_shows(view, view.live_map)


def test_write_cells_touches_only_the_given_pixels():
    item = grid_item.GridImageItem()
    cmap = CoverageMap.from_array(np.full((50, 60), UNMOWED), 0.3)
    item.set_map(cmap)
    before = item.rgb()
    # the same cell twice: the last code wins and it counts once
    assert item.write_cells([(7, 11, MOWER), (3, 59, MOWED), (7, 11, MOWED)]) == 2
    after = item.rgb()
    assert np.argwhere(np.any(after != before, axis=-1)).tolist() == [[3, 59], [7, 11]]
    np.testing.assert_array_equal(after[7, 11], COLORS_RGB8[MOWED])
    assert item.pixels_written == 2
    assert item.write_cells([]) == 0


def test_cell_iy_ix_covers_its_square_in_metres_with_row_0_at_the_bottom(qtbot):
    view = make_view(qtbot)
    s, x0, y0 = 0.5, -2.0, 3.0
    cmap = CoverageMap.from_array([[1, 2, 2], [3, 5, 2]], s, (x0, y0))  # row 0 = south
    view.set_live_map(cmap, mm.MapSettings(s, (2, 3), (x0, y0), "unknown"))
    r = view.grid.mapRectToParent(view.grid.boundingRect())
    assert (r.left(), r.top(), r.width(), r.height()) == pytest.approx((x0, y0, 1.5, 1.0))
    for iy, ix in ((0, 0), (1, 2), (1, 1)):
        cell = view.grid.mapRectToParent(QRectF(ix, iy, 1, 1))
        assert (cell.left(), cell.top(), cell.width(), cell.height()) == pytest.approx(
            (x0 + ix * s, y0 + iy * s, s, s)
        )
    # rendered: the south-west cell (perimeter, red) is drawn below the obstacle above it
    view.show()
    qtbot.waitExposed(view)
    view.plot.setRange(xRange=(x0, x0 + 1.5), yRange=(y0, y0 + 1.0), padding=0)
    QApplication.processEvents()
    image = view.plot_widget.viewport().grab().toImage()

    def colour_at(x: float, y: float) -> tuple[int, int, int]:
        p = view.plot_widget.mapFromScene(view.plot.vb.mapViewToScene(QPointF(x, y)))
        c = image.pixelColor(p.x(), p.y())
        return c.red(), c.green(), c.blue()

    assert colour_at(x0 + 0.25, y0 + 0.25) == tuple(COLORS_RGB8[1])  # (0, 0) perimeter
    assert colour_at(x0 + 0.75, y0 + 0.75) == tuple(COLORS_RGB8[5])  # (1, 1) obstacle
    assert colour_at(x0 + 0.25, y0 + 0.75) == tuple(COLORS_RGB8[3])  # (1, 0) mowed
    p_low = view.plot_widget.mapFromScene(view.plot.vb.mapViewToScene(QPointF(x0, y0 + 0.25)))
    p_high = view.plot_widget.mapFromScene(view.plot.vb.mapViewToScene(QPointF(x0, y0 + 0.75)))
    assert p_low.y() > p_high.y()  # north is up


def test_robot_outside_the_map_is_a_status_line(qtbot, feed):
    view = make_view(qtbot)
    dialog = view.open_new_map_dialog()
    for key, text in (("cell", "0.1"), ("ny", "4"), ("nx", "4"), ("x0", "-0.2"), ("y0", "-0.2")):
        dialog.fields[key].edit.setText(text)
    assert dialog.apply()
    feed(view.ctx, sim_replies("straight", rate_hz=20.0, seconds=3.0))  # 0.6 m east
    view.refresh()
    x = view.ctx.session.history.column("x")[-1]
    y = view.ctx.session.history.column("y")[-1]
    assert x > 0.2
    assert view.status.text().startswith(f"robot outside the map at x = {x:.2f} m, y = {y:.2f} m")
    assert view.live_result.outside
    assert_image_shows(view, view.live_map)
    assert np.count_nonzero(view.live_map.codes == MOWED) >= 1  # the cells it crossed


def test_session_reset_starts_the_same_map_afresh(qtbot, feed):
    view = make_view(qtbot)
    feed(view.ctx, sim_replies("figure_eight", rate_hz=20.0, seconds=10.0))
    view.refresh()
    assert np.count_nonzero(view.live_map.codes == MOWED) > 0
    settings = view.live_settings
    view.ctx.reset()
    assert view.live_settings == settings
    assert np.all(view.live_map.codes == UNMOWED)
    assert_image_shows(view, view.live_map)
    assert "reset" in view.status.text()
    feed(view.ctx, sim_replies("figure_eight", rate_hz=20.0, seconds=3.0))
    view.refresh()
    assert np.count_nonzero(view.live_map.codes == MOWER) == 1
    assert_image_shows(view, view.live_map)


# --- "New map…" ------------------------------------------------------------------------------

BAD_FIELDS = [
    ("cell", "abc", "cell size \\(m\\) must be a number"),
    ("cell", "0", "cell size \\(m\\) must be > 0"),
    ("cell", "-0.3", "cell size \\(m\\) must be > 0"),
    ("cell", "inf", "must be a finite number"),
    ("ny", "0", "rows ny must be 1..4000 cells"),
    ("ny", "2.5", "rows ny must be a whole number"),
    ("nx", "5000", "columns nx must be 1..4000 cells"),
    ("x0", "nan", "origin x0 \\(m\\) must be a finite number"),
    ("y0", "north", "origin y0 \\(m\\) must be a number"),
]


@pytest.mark.parametrize(("key", "text", "message"), BAD_FIELDS)
def test_new_map_refuses_bad_fields_and_keeps_the_map(qtbot, key, text, message, feed):
    view = make_view(qtbot)
    feed(view.ctx, sim_replies("figure_eight", rate_hz=20.0, seconds=4.0))
    view.refresh()
    old_map, old_settings, old_codes = view.live_map, view.live_settings, view.live_map.codes.copy()
    dialog = view.open_new_map_dialog()
    dialog.fields[key].edit.setText(text)
    assert not dialog.apply()
    assert dialog.fields[key].error.isVisibleTo(dialog)
    assert re.search(message, dialog.fields[key].error.text())
    for other, field in dialog.fields.items():
        if other != key:
            assert field.error.text() == ""
    assert view.live_map is old_map and view.live_settings == old_settings
    np.testing.assert_array_equal(view.live_map.codes, old_codes)
    assert_image_shows(view, old_map)


def test_new_map_refuses_too_many_cells_and_a_rectangle_that_does_not_fit(qtbot):
    view = make_view(qtbot)
    old_map = view.live_map
    dialog = view.open_new_map_dialog()
    dialog.fields["ny"].edit.setText("3000")
    dialog.fields["nx"].edit.setText("3000")
    assert not dialog.apply()
    assert "at most 4000000" in dialog.fields["nx"].error.text()
    dialog.fields["ny"].edit.setText("81")
    dialog.fields["nx"].edit.setText("71")
    dialog.set_fill("rectangle")
    dialog.fields["rw"].edit.setText("0")
    assert not dialog.apply()
    assert "width (m) must be > 0" in dialog.fields["rw"].error.text()
    dialog.fields["rw"].edit.setText("15")
    dialog.fields["rx"].edit.setText("-20")  # west of the origin -10.65
    assert not dialog.apply()
    assert dialog.fill_error.isVisibleTo(dialog)
    assert "reaches west or south of the map origin" in dialog.fill_error.text()
    dialog.fields["rx"].edit.setText("0")
    dialog.fields["rw"].edit.setText("40")  # beyond the map's east edge
    assert not dialog.apply()
    assert "polygon needs at least" in dialog.fill_error.text()
    assert view.live_map is old_map
    assert view.live_settings == mm.default_settings()


def test_new_map_from_a_perimeter_rectangle(qtbot, feed):
    view = make_view(qtbot)
    dialog = view.open_new_map_dialog()
    values = {"cell": "0.5", "ny": "20", "nx": "30", "x0": "-5", "y0": "-4"}
    values |= {"rx": "-4", "ry": "-3", "rw": "12", "rh": "6"}
    dialog.set_fill("rectangle")
    for key, text in values.items():
        dialog.fields[key].edit.setText(text)
    assert dialog.apply()
    expected = CoverageMap.from_polygon(
        ((-4, -3), (8, -3), (8, 3), (-4, 3)), 0.5, (-5.0, -4.0), shape=(20, 30)
    )
    assert view.live_settings == mm.MapSettings(
        0.5, (20, 30), (-5.0, -4.0), "rectangle", (-4.0, -3.0, 12.0, 6.0)
    )
    assert view.live_map.shape == (20, 30) and view.live_map.cell_size == 0.5
    np.testing.assert_array_equal(view.live_map.codes, expected.codes)
    assert_image_shows(view, view.live_map)
    # the robot now mows inside the perimeter
    feed(view.ctx, sim_replies("figure_eight", rate_hz=20.0, seconds=8.0))
    view.refresh()
    assert np.count_nonzero(view.live_map.codes == MOWED) > 0
    assert_image_shows(view, view.live_map)


# --- simulated run ---------------------------------------------------------------------------


def circle_radii(curve, n_circles: int, centres) -> np.ndarray:
    x, y = curve.getData()
    pieces_x = np.split(x, np.flatnonzero(np.isnan(x)))
    pieces_y = np.split(y, np.flatnonzero(np.isnan(y)))
    radii = []
    for px, py, (cx, cy) in zip(pieces_x[:n_circles], pieces_y[:n_circles], centres, strict=True):
        ok = np.isfinite(px)
        d = np.hypot(px[ok] - cx, py[ok] - cy)
        assert np.ptp(d) < 1e-9
        radii.append(d[0])
    return np.array(radii)


def test_simulate_button_draws_beacons_circles_gps_and_paths(qtbot, run):
    view = make_view(qtbot)
    view.speed_box.setCurrentText("all at once")
    qtbot.mouseClick(view.sim_button, Qt.MouseButton.LeftButton)
    # built in a process of its own, with a busy bar and a Cancel while it runs
    assert view._job is not None and view._job.process.pid != os.getpid()
    assert not view.progress.isHidden() and not view.cancel_button.isHidden()
    assert not view.sim_button.isEnabled() and "own process" in view.status.text()
    last = len(run.sim.t) - 1
    qtbot.waitUntil(lambda: view.run is not None and view.sim_k == last, timeout=60_000)
    assert view.progress.isHidden() and view.cancel_button.isHidden()
    assert view.sim_button.isEnabled() and not view._job
    np.testing.assert_array_equal(view.run.fused, run.fused)  # the same run as in-process
    sim = view.run.sim
    assert view.source == "sim" and view.source_box.currentData() == "sim"
    # beacons with names
    bx, by = view.beacons.getData()
    assert list(zip(bx, by, strict=True)) == [(b.x, b.y) for b in sim.beacons]
    assert [t.textItem.toPlainText() for t in view.beacon_labels] == ["SW", "SE", "NE", "NW"]
    # range circles of the newest range set, in the robot's plane
    centres = [(b.x, b.y) for b in sim.beacons]
    radii = circle_radii(view.range_circles, 4, centres)
    np.testing.assert_allclose(radii, plane_distances(sim.beacons, sim.ranges[-1].ranges))
    # GPS: the newest fixes, accuracy circles for the newest five
    gps = sim.gps[-mv.GPS_CIRCLES :]
    radii = circle_radii(view.gps_circles, mv.GPS_CIRCLES, view.run.gps_xy[-mv.GPS_CIRCLES :])
    np.testing.assert_allclose(radii, [gps_accuracy_m(g.quality) for g in gps])
    n_good = np.count_nonzero(view.run.gps_usable[-mv.GPS_TRAIL :])
    assert len(view.gps_good.getData()[0]) == n_good > 0
    assert len(view.gps_bad.getData()[0]) == mv.GPS_TRAIL - n_good
    # the three paths
    for key, poses in (("truth", sim.truth), ("raw", sim.raw), ("fused", view.run.fused)):
        x, y = view.paths[key].getData()
        np.testing.assert_array_equal(x, poses[:, 0])
        np.testing.assert_array_equal(y, poses[:, 1])
    # errors shown: the fused one below the raw one
    raw, fused = view.sim_errors
    assert raw == pytest.approx(math.hypot(*(sim.raw[-1, :2] - sim.truth[-1, :2])))
    assert fused < 0.2 < 1.0 < raw
    shown = re.search(r"raw odometry ([\d.]+) m, fused ([\d.]+) m", view.status.text())
    assert float(shown[2]) < float(shown[1])
    # the grid comes from the TRUE path
    ref = mm.sim_map(view.run)
    mm.feed_positions(ref, sim.truth[:, 0], sim.truth[:, 1], mm.SIM_CUT_WIDTH)
    np.testing.assert_array_equal(view.sim_map.codes, ref.codes)
    assert_image_shows(view, view.sim_map)
    assert np.count_nonzero(ref.codes == MOWED) > 500


def test_playback_is_progressive_and_switching_source_keeps_both_maps(qtbot, run, feed):
    view = make_view(qtbot)
    feed(view.ctx, sim_replies("figure_eight", rate_hz=20.0, seconds=5.0))
    view.refresh()
    view.speed_box.setCurrentText("100x")
    view.load_simulation(run)
    assert view.sim_k == 0 and view.timer.isActive()
    view._clock = time.monotonic() - 1.0  # one second of wall time = 100 s of the run
    view._tick()
    assert run.sim.t[view.sim_k] == pytest.approx(100.0, abs=1.0)
    x, _ = view.paths["truth"].getData()
    assert len(x) == view.sim_k + 1
    assert_image_shows(view, view.sim_map)
    k = view.sim_k
    view.set_source("live")
    assert not view.timer.isActive() and view.sim_k == k
    assert_image_shows(view, view.live_map)
    assert not view.paths["raw"].isVisible() and view.robot.isVisible()
    view.set_source("sim")
    assert view.timer.isActive()
    assert_image_shows(view, view.sim_map)
    view.speed_box.setCurrentText("all at once")
    assert view.sim_k == len(run.sim.t) - 1
    view._tick()
    assert not view.timer.isActive()
    with pytest.raises(ValueError, match="source must be 'live' or 'sim'"):
        view.set_source("gps")
    assert view.source == "sim"


@pytest.mark.screenshot
def test_screenshot_after_the_simulated_run(qtbot, run, screenshot):
    view = make_view(qtbot)
    view.speed_box.setCurrentText("all at once")
    view.show()
    qtbot.waitExposed(view)
    view.load_simulation(run)
    QApplication.processEvents()
    image = screenshot(view, "maps.png")
    colours = set()
    for px in range(0, image.width(), 4):
        for py in range(0, image.height(), 4):
            c = image.pixelColor(px, py)
            colours.add((c.red(), c.green(), c.blue()))
    assert len(colours) > 30
    for code in (1, 2, 3):  # perimeter, unmowed and mowed cells are on the picture
        assert tuple(COLORS_RGB8[code]) in colours


# --- cost ------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(81, 71), (1000, 1000)])
def test_one_changed_cell_costs_the_same_on_a_large_map(qtbot, shape):
    view = make_view(qtbot)
    view.show()
    qtbot.waitExposed(view)
    cmap = CoverageMap.from_array(np.full(shape, UNMOWED), 0.3)
    view.set_live_map(cmap, mm.MapSettings(0.3, shape, (0.0, 0.0), "lawn"))
    QApplication.processEvents()
    times = []
    for i in range(30):
        t0 = time.perf_counter()
        view.grid.write_cells([(i % shape[0], 5, MOWED)])
        QApplication.processEvents()  # the repaint of the dirty cell
        times.append(time.perf_counter() - t0)
    assert view.grid.pixels_written == 30
    assert float(np.median(times)) < 0.05  # generous; measured ~0.1 ms on both sizes


def test_the_maps_palette_is_colour_blind_safe_and_keeps_the_seeds_meanings():
    assert len({tuple(c) for c in COLORS_RGB8}) == len(COLORS_RGB8)  # one colour per code
    # unmowed and mowed differ in lightness (seen without hue), not only in hue as the
    # seed's two greens
    assert luminance(COLORS_RGB8[MOWED]) - luminance(COLORS_RGB8[UNMOWED]) > 0.4
    seed = np.asarray(COLORS_RGB)
    assert abs(luminance(seed[MOWED] * 255) - luminance(seed[UNMOWED] * 255)) > 0.1  # seed: close
    # the seed's meanings by hue: unmowed green-dominant, mower blue-dominant
    assert np.argmax(COLORS_RGB8[UNMOWED]) == 1 and np.argmax(COLORS_RGB8[MOWER]) == 2
    # truth, fused and raw differ in width or dash as well as colour
    styles = {key: (width, dash) for key, (_c, width, dash, _z) in PATH_STYLES.items()}
    assert len(set(styles.values())) == 3
    assert len({c for c, *_ in PATH_STYLES.values()}) == 3


@pytest.mark.parametrize("child", ["fail", "report_error"])
def test_a_failing_simulation_is_shown_in_the_view(qtbot, monkeypatch, child):
    import sim_children

    monkeypatch.setattr(mv.MapsView, "sim_target", staticmethod(getattr(sim_children, child)))
    view = make_view(qtbot)
    view.start_simulation(7)
    qtbot.waitUntil(lambda: view._job is None, timeout=30_000)
    assert not view.error.isHidden() and view.error.text().startswith("simulated run failed: ")
    text = view.error.text()
    assert ("seed 7 refused" in text) if child == "report_error" else ("exit code 1" in text)
    assert view.run is None and view.sim_button.isEnabled() and view.progress.isHidden()


def test_cancel_stops_the_simulation_process(qtbot, monkeypatch):
    import sim_children

    monkeypatch.setattr(mv.MapsView, "sim_target", staticmethod(sim_children.hang))
    view = make_view(qtbot)
    view.start_simulation(3)
    process = view._job.process
    qtbot.waitUntil(process.is_alive, timeout=10_000)
    qtbot.mouseClick(view.cancel_button, Qt.MouseButton.LeftButton)
    assert view._job is None and not process.is_alive()
    assert "cancelled" in view.status.text() and view.sim_button.isEnabled()
    assert view.cancel_button.isHidden() and view.run is None
