"""Map view and direction widgets: what they draw equals the session's history and pose.

Run the hour-of-data timing with ``-s`` to see it printed:
``python -m pytest -q -s tests/monitor/test_monitor_map.py -k hour``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PySide6.QtCore import QPointF, Qt
from PySide6.QtGui import QColor, QImage

from mm_pc.core.geometry import SensorMount
from mm_pc.core.odometry import Pose2D
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.path_decimator import PathDecimator
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.widgets.direction_widget import (
    GAINS_PX_PER_MM,
    DirectionPanel,
    auto_gain,
    gain_peak,
)
from mm_pc.monitor.widgets.map_view.raster import PathRaster
from mm_pc.monitor.widgets.map_view.view import (
    FOLLOW_ZONE,
    MAX_ROWS_PER_REFRESH,
    MAX_WIDTH_M,
    MIN_WIDTH_M,
    MapView,
)
from mm_pc.monitor.widgets.style import ROBOT_COLOUR, sensor_colour

# -- helpers ---------------------------------------------------------------------------------


@pytest.fixture
def ctx() -> MonitorContext:
    return MonitorContext(MonitorSession())


@pytest.fixture
def view(qtbot, ctx) -> MapView:
    v = MapView(ctx)
    qtbot.addWidget(v)
    v.resize(900, 650)
    v.show()
    qtbot.waitExposed(v)
    return v


def world(view: MapView, x: float, y: float) -> tuple[float, float]:
    """A point of the robot group (base_link) in odom, as drawn."""
    q = view.body.mapToParent(QPointF(float(x), float(y)))
    return q.x(), q.y()


def history_points(hist, cx: str, cy: str) -> set[tuple[float, float]]:
    return set(zip(hist.column(cx).tolist(), hist.column(cy).tolist(), strict=True))


def assert_path_from_history(view: MapView, key, hist, cx: str, cy: str) -> np.ndarray:
    x, y = view.path_data(key)
    hx, hy = hist.column(cx), hist.column(cy)
    assert len(x) >= 2
    assert (x[0], y[0]) == (hx[0], hy[0])
    assert (x[-1], y[-1]) == (hx[-1], hy[-1])
    pts = history_points(hist, cx, cy)
    assert all(p in pts for p in zip(x.tolist(), y.tolist(), strict=True))
    return x


def hour_rows(session: MonitorSession, rows: int = 360_000, rate: float = 100.0) -> np.ndarray:
    """Rows of an hour at ``rate`` Hz: a mower's stripes 20 m long, 0.2 m apart, at 0.2 m/s,
    with the sensors where their mounts are (columns as the session's history)."""
    hist = session.history
    t = np.arange(rows) / rate
    s = 0.2 * t
    stripe, along = np.divmod(s, 20.2)
    on_line = along < 20.0
    back = stripe % 2 == 1
    x = np.where(on_line, np.where(back, 20.0 - along, along), np.where(back, 0.0, 20.0))
    y = 0.2 * stripe + np.where(on_line, 0.0, along - 20.0)
    yaw = np.where(on_line, np.where(back, math.pi, 0.0), math.pi / 2)
    out = np.zeros((rows, len(hist.columns)))
    col = hist.index
    out[:, col["t"]], out[:, col["dt"]] = t, 1 / rate
    out[:, col["x"]], out[:, col["y"]], out[:, col["yaw"]] = x, y, yaw
    c, sn = np.cos(yaw), np.sin(yaw)
    for k, m in enumerate(session.mounts):
        out[:, col[f"s{k}_wx"]] = x + c * m.x - sn * m.y
        out[:, col[f"s{k}_wy"]] = y + sn * m.x + c * m.y
        out[:, col[f"s{k}_dy"]] = 0.002
    return out


def distinct_colours(img: QImage, step: int = 3) -> set[int]:
    return {
        img.pixel(x, y) for x in range(0, img.width(), step) for y in range(0, img.height(), step)
    }


def has_colour(img: QImage, colour: str, tol: int = 40) -> bool:
    want = QColor(colour)
    for x in range(0, img.width(), 2):
        for y in range(0, img.height(), 2):
            c = QColor(img.pixel(x, y))
            if (abs(c.red() - want.red()) + abs(c.green() - want.green())
                    + abs(c.blue() - want.blue())) < tol:
                return True
    return False


class FakeDrag:
    """Enough of pyqtgraph's MouseDragEvent for ViewBox.mouseDragEvent (a pan by dx px)."""

    def __init__(self, dx: float, button=Qt.MouseButton.LeftButton) -> None:
        self._button, self._dx = button, dx

    def accept(self):
        pass

    def button(self):
        return self._button

    def pos(self):
        return pg.Point(100 + self._dx, 100)

    def lastPos(self):  # noqa: N802 - pyqtgraph API
        return pg.Point(100, 100)


class FakeWheel:
    def __init__(self, delta: int, pos: QPointF) -> None:
        self._delta, self._pos = delta, pos

    def delta(self):
        return self._delta

    def pos(self):
        return self._pos

    def accept(self):
        pass


# -- the decimation (pure) ----------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.tuples(st.floats(-0.01, 0.01), st.floats(-0.01, 0.01)), min_size=1,
                   max_size=300),
    cuts=st.lists(st.integers(0, 300), max_size=5),
)
def test_decimation_keeps_path_points_within_a_cell_and_is_incremental(steps, cuts):
    pts = np.cumsum(np.array(steps), axis=0) + 3.0
    x, y = pts[:, 0], pts[:, 1]
    whole = PathDecimator()
    whole.update(x, y)
    parts = PathDecimator()
    for c in [*sorted(cuts), len(x)]:
        parts.update(x[: min(c, len(x))], y[: min(c, len(x))])
    assert parts.rows_seen == whole.rows_seen == len(x)
    assert parts.bounds == (x.min(), x.max(), y.min(), y.max())
    index = {p: i for i, p in reversed(list(enumerate(zip(x.tolist(), y.tolist(), strict=True))))}
    for level, eps in enumerate(PathDecimator.LEVEL_EPS_M):
        kx, ky = whole.points(level, x, y)
        px, py = parts.points(level, x, y)
        np.testing.assert_array_equal(kx, px)
        np.testing.assert_array_equal(ky, py)
        assert (kx[0], ky[0]) == (x[0], y[0])
        assert (kx[-1], ky[-1]) == (x[-1], y[-1])
        kept = [index[p] for p in zip(kx.tolist(), ky.tolist(), strict=True)]
        assert kept == sorted(kept)
        # every dropped point is in the cell of the last point kept before it
        last = np.maximum.accumulate(np.isin(np.arange(len(x)), kept) * np.arange(len(x)))
        d = np.hypot(x - x[last], y - y[last])
        assert np.all(d <= math.sqrt(2) * eps + 1e-12)


def test_decimation_of_a_still_robot_keeps_first_and_last_only():
    dec = PathDecimator()
    cx, cy = np.full(1000, 0.25), np.full(1000, -1.0)
    dec.update(cx, cy)
    x, y = dec.points(0, cx, cy)
    assert list(zip(x, y, strict=True)) == [(0.25, -1.0)]
    cx, cy = np.r_[cx, [np.nan, 0.3]], np.r_[cy, [0.0, -1.0]]
    dec.update(cx, cy)
    x, y = dec.points(0, cx, cy)
    assert list(zip(x, y, strict=True)) == [(0.25, -1.0), (0.3, -1.0)]  # NaN row skipped
    assert dec.rows(0).tolist() == [0, 1001]  # row numbers, not coordinates, are kept


def segments(x, y, connect=None) -> set:
    """The segments of polylines as a set of ((x0, y0), (x1, y1))."""
    joined = np.ones(len(x) - 1, dtype=bool) if connect is None else connect[:-1]
    return {((x[i], y[i]), (x[i + 1], y[i + 1])) for i in np.flatnonzero(joined)}


def test_runs_near_a_rectangle_hold_every_segment_meeting_it():
    t = np.linspace(0, 40 * math.pi, 50_000)
    x, y = np.cos(t) * (1 + t / 40), np.sin(t) * (1 + t / 40)
    dec = PathDecimator()
    dec.update(x, y)
    level, box = 1, PathDecimator.BOX
    n = dec.level_size(level)
    assert dec.box_count(level) == n // box and n % box  # an open box at the end
    kx, ky = dec.points(level, x, y)
    every = segments(kx, ky)
    rect = (0.5, 1.5, -0.3, 0.4)
    rows, connect = dec.runs_in(level, rect)
    assert rows.dtype == np.int32 and not connect[-1]
    got = segments(x[rows], y[rows], connect)
    assert got <= every  # only segments of the path, none made up between runs
    meeting = {s for s in every
               if max(s[0][0], s[1][0]) >= 0.5 and min(s[0][0], s[1][0]) <= 1.5
               and max(s[0][1], s[1][1]) >= -0.3 and min(s[0][1], s[1][1]) <= 0.4}
    assert meeting <= got
    assert len(got) < len(every) / 3  # the far boxes were left out
    # the open box is always taken; a range of points gives the segments ending in it
    rows, connect = dec.runs_in(level, (100.0, 101.0, 100.0, 101.0))
    assert segments(x[rows], y[rows], connect) == segments(kx[(n // box) * box - 1 : n],
                                                          ky[(n // box) * box - 1 : n])
    rows, connect = dec.runs_in(level, (-9.0, 9.0, -9.0, 9.0), 100, 200)
    assert segments(x[rows], y[rows], connect) == segments(kx[99:200], ky[99:200])
    assert dec.runs_in(level, rect, 5, 5)[0].size == 0
    # the newest point, not kept, ends the tail; the tail starts at the point before
    lx, ly = dec.tail_points(level, n - 3, x, y)
    assert (lx[0], ly[0]) == (kx[n - 4], ky[n - 4])
    assert (lx[-1], ly[-1]) == (x[-1], y[-1])


def test_decimator_memory_is_four_bytes_a_kept_point_and_a_box():
    dec = PathDecimator()
    x = np.arange(100_000) * 0.002  # 2 mm a row: every level up to 2 mm keeps all
    dec.update(x, np.zeros_like(x))
    kept = sum(dec.level_size(k) for k in range(PathDecimator.LEVELS))
    assert 3 * len(x) < kept < 4.1 * len(x)
    assert dec.nbytes < 2 * kept * (4 + 32 / PathDecimator.BOX) + 11 * 256 * 36


# -- the map ---------------------------------------------------------------------------------------


def test_paths_equal_history_and_markers_sit_at_the_pose(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.refresh()
    view.fit_paths()
    view.refresh()
    hist = ctx.session.history
    x = assert_path_from_history(view, "robot", hist, "x", "y")
    assert len(x) == len(hist)  # 4 mm per row: nothing falls under a 0.5 mm cell
    for k in range(2):
        assert_path_from_history(view, k, hist, f"s{k}_wx", f"s{k}_wy")
    pose = ctx.session.pose
    assert (view.robot_marker.pos().x(), view.robot_marker.pos().y()) == pytest.approx(
        (pose.x, pose.y))
    assert (view.body.pos().x(), view.body.pos().y()) == pytest.approx((pose.x, pose.y))
    assert view.body.rotation() == pytest.approx(math.degrees(pose.yaw))
    hx, hy = view.robot_heading.getData()
    assert world(view, hx[0], hy[0]) == pytest.approx((pose.x, pose.y))
    assert world(view, hx[1], hy[1]) == pytest.approx(
        (pose.x + 0.1 * math.cos(pose.yaw), pose.y + 0.1 * math.sin(pose.yaw)))
    for k, items in enumerate(view.sensor_items):
        dot = items["dot"].pos()
        assert world(view, dot.x(), dot.y()) == pytest.approx(
            (hist.last(f"s{k}_wx"), hist.last(f"s{k}_wy")))
    assert f"{pose.x:+.3f} m" in view.pose_label.text()


def test_zoomed_out_path_is_decimated_but_still_from_the_history(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.set_visible_width(MAX_WIDTH_M, (0.0, 0.0))
    view.refresh()
    hist = ctx.session.history
    x = assert_path_from_history(view, "robot", hist, "x", "y")
    assert len(x) < len(hist) / 4
    assert view.render_stats()["levels"]["robot"] > 0


def test_refresh_does_nothing_when_the_history_did_not_change(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=2)
    view.refresh()
    view.finish_drawing()  # nothing queued off the screen either
    view.refresh()
    n = view.render_stats()["refreshes"]
    view.refresh()
    view.refresh()
    assert view.render_stats()["refreshes"] == n
    ctx.on_reply(next(iter(sim_replies("figure_eight", 50, 3))))  # a baseline: no row
    feed_more = list(sim_replies("figure_eight", 50, 2.1))[-1]
    ctx.on_reply(feed_more)
    view.refresh()
    assert view.render_stats()["refreshes"] == n + 1


def test_zoom_slider_sets_the_visible_width_and_follows_the_wheel(view, ctx):
    view.zoom_slider.setValue(0)
    assert view.visible_width() == pytest.approx(MIN_WIDTH_M, rel=1e-6)
    view.zoom_slider.setValue(view.zoom_slider.maximum())
    assert view.visible_width() == pytest.approx(MAX_WIDTH_M, rel=1e-6)
    view.zoom_slider.setValue(view.zoom_slider.maximum() // 2)
    mid = math.sqrt(MIN_WIDTH_M * MAX_WIDTH_M)
    assert view.visible_width() == pytest.approx(mid, rel=1e-6)
    assert view.width_label.text() == f"{mid:.3g} m"
    centre = view.vb.mapViewToScene(QPointF(*view.view_centre()))
    view.vb.wheelEvent(FakeWheel(120, view.vb.mapFromScene(centre)))  # zoom in
    assert view.visible_width() < mid
    assert view.zoom_slider.value() < view.zoom_slider.maximum() // 2
    view.set_visible_width(1e6)
    assert view.visible_width() == pytest.approx(MAX_WIDTH_M, rel=1e-6)


def test_follow_recentres_on_the_robot_and_a_pan_ends_it(view, ctx):
    assert view.follow_check.isChecked()  # the default
    view.follow_check.setChecked(False)
    view.set_visible_width(0.5, (5.0, 5.0))
    view.follow_check.setChecked(True)
    view.refresh()  # following was switched on: centred at once
    assert view.view_centre() == pytest.approx((0.0, 0.0), abs=1e-9)
    replies = list(sim_replies("figure_eight", 50, 10))
    pans = 0
    for r in replies[:-1]:
        centre = view.view_centre()
        ctx.on_reply(r)
        view.refresh()
        pans += view.view_centre() != centre
        pose = ctx.session.pose
        (x0, x1), (y0, y1) = view.vb.viewRange()
        cx, cy = view.view_centre()
        # the robot stays in the middle of the view ...
        assert abs(pose.x - cx) <= FOLLOW_ZONE * (x1 - x0) * (1 + 1e-6)
        assert abs(pose.y - cy) <= FOLLOW_ZONE * (y1 - y0) * (1 + 1e-6)
    # ... and the view moves now and then, not with every reply (10 s at 0.2 m/s)
    assert 3 <= pans <= len(replies) // 10, pans
    assert view.visible_width() == pytest.approx(0.5, rel=1e-6)
    view.vb.mouseDragEvent(FakeDrag(40))
    assert not view.follow_check.isChecked()
    centre = view.view_centre()
    ctx.on_reply(replies[-1])
    view.refresh()
    assert view.view_centre() == pytest.approx(centre)  # left where the user put it
    view.follow_check.setChecked(True)
    view.refresh()  # no new data, but following was switched on
    pose = ctx.session.pose
    assert view.view_centre() == pytest.approx((pose.x, pose.y), abs=1e-9)


def test_hidden_paths_are_not_updated_and_catch_up_when_shown(view, ctx):
    replies = list(sim_replies("figure_eight", 50, 20))
    for r in replies[:300]:
        ctx.on_reply(r)
    view.refresh()
    assert len(view.path_data(0)[0]) == len(ctx.session.history) == 299
    view.path_checks[0].setChecked(False)
    assert not view.paths[0].visible and not view.paths[0].live.isVisible()
    assert len(view.path_data(0)[0]) == 0  # nothing of it left in the plot
    for r in replies[300:]:
        ctx.on_reply(r)
    view.refresh()
    assert len(view.path_data(0)[0]) == 0  # a hidden path costs nothing per refresh
    assert len(view.path_data("robot")[0]) == len(replies) - 1
    view.path_checks[0].setChecked(True)
    view.refresh()
    assert_path_from_history(view, 0, ctx.session.history, "s0_wx", "s0_wy")
    view.set_path_visible("robot", False)
    assert not view.path_checks["robot"].isChecked()


def test_reset_button_clears_the_paths_and_puts_the_robot_home(view, ctx, qtbot):
    replies = list(sim_replies("figure_eight", 50, 12))
    for r in replies[:500]:
        ctx.on_reply(r)
    view.refresh()
    assert len(view.path_data("robot")[0]) > 100
    qtbot.mouseClick(view.reset_button, Qt.MouseButton.LeftButton)
    view.refresh()
    assert ctx.session.pose == Pose2D()
    for key in view.paths:
        assert len(view.path_data(key)[0]) == 0
    assert view.robot_marker.pos().x() == 0 and view.robot_marker.pos().y() == 0
    # counting carries on from the baselines: the new path starts near the origin
    for r in replies[500:550]:
        ctx.on_reply(r)
    view.refresh()
    x, y = view.path_data("robot")
    assert len(x) == len(ctx.session.history) == 50
    assert math.hypot(x[0], y[0]) < 0.01


def test_history_dropping_old_rows_rebuilds_the_paths(qtbot):
    ctx = MonitorContext(MonitorSession(max_rows=400))
    v = MapView(ctx)
    qtbot.addWidget(v)
    replies = list(sim_replies("figure_eight", 50, 12))
    for r in replies[:300]:
        ctx.on_reply(r)
    v.refresh()
    for r in replies[300:]:
        ctx.on_reply(r)
    v.refresh()
    hist = ctx.session.map_history
    assert hist.dropped_rows > 0
    assert_path_from_history(v, "robot", hist, "x", "y")


def test_sensors_appear_when_the_devices_are_known(view, ctx, feed):
    assert view.sensor_items == []
    assert list(view.path_checks) == ["robot"]
    view.refresh()  # no history yet: draws the robot at the origin
    feed(ctx, rate_hz=50, seconds=3)
    assert len(view.sensor_items) == 2
    assert list(view.path_checks) == ["robot", 0, 1]
    assert view.path_checks[1].text() == "sensor 2"
    assert DEFAULT_DEVICES[1] in view.path_checks[1].toolTip()
    view.refresh()
    assert_path_from_history(view, 1, ctx.session.history, "s1_wx", "s1_wy")


def test_view_built_after_the_devices_has_its_sensors(qtbot, ctx, feed):
    feed(ctx, rate_hz=50, seconds=2)
    v = MapView(ctx)
    qtbot.addWidget(v)
    assert len(v.sensor_items) == 2
    v.refresh()
    assert_path_from_history(v, 0, ctx.session.history, "s0_wx", "s0_wy")


def test_far_out_the_robot_is_an_arrow_pointing_along_its_heading(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=14)
    view.set_visible_width(100.0)
    view.refresh()
    marker = view.robot_marker
    assert marker.isVisible()
    to_device = marker.deviceTransform(view.plot.viewportTransform())
    tip = to_device.map(QPointF(0, 0))
    body = to_device.map(marker.path.boundingRect().center())
    back = math.atan2(-(body.y() - tip.y()), body.x() - tip.x())  # screen y grows down
    yaw = ctx.session.pose.yaw
    assert math.cos(back - (yaw + math.pi)) > 0.999  # within 2.6 degrees (pixel rounding)
    view.set_visible_width(0.5)
    view.refresh()
    assert not marker.isVisible()  # near, the outline is big enough


def test_sensor_axes_point_right_and_forward(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=4)
    view.set_visible_width(MIN_WIDTH_M, (0.0, 0.0))
    view.refresh()
    pose, m = ctx.session.pose, ctx.session.mounts[0]
    ax, ay = view.sensor_items[0]["axes"].getData()
    p = [np.array(world(view, x, y)) for x, y in zip(ax, ay, strict=True)]
    # segment 0: X arrow shaft, segment 3: Y arrow shaft (3 segments per arrow)
    xdir = (p[1] - p[0]) / 0.025
    ydir = (p[7] - p[6]) / 0.025
    right = (math.sin(pose.yaw + m.yaw), -math.cos(pose.yaw + m.yaw))
    forward = (math.cos(pose.yaw + m.yaw), math.sin(pose.yaw + m.yaw))
    assert xdir == pytest.approx(right)
    assert ydir == pytest.approx(forward)
    assert view.sensor_items[0]["axes"].isVisible()


def test_a_new_geometry_moves_the_sensor_markers(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=3)
    view.refresh()
    mounts = (SensorMount(0.08, -0.05, 0.1), SensorMount(0.02, 0.06))
    ctx.session.configure_odometry(mounts=mounts)
    ctx.odometry_changed.emit()
    view.refresh()
    pose = ctx.session.pose
    for k, m in enumerate(mounts):
        dot = view.sensor_items[k]["dot"].pos()
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        assert world(view, dot.x(), dot.y()) == pytest.approx(
            (pose.x + c * m.x - s * m.y, pose.y + s * m.x + c * m.y))


@pytest.mark.screenshot
def test_map_screenshot(view, ctx, screenshot, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.refresh()
    view.fit_paths()
    view.refresh()
    img = screenshot(view, "map.png")
    assert len(distinct_colours(img)) > 20
    for colour in (ROBOT_COLOUR, sensor_colour(0), sensor_colour(1)):
        assert has_colour(img, colour), colour


# -- the raster of the paths ---------------------------------------------------------------------

PATH_COLUMNS = (("x", "y"), ("s0_wx", "s0_wy"), ("s1_wx", "s1_wy"))


def raster_array(view: MapView) -> np.ndarray:
    """The raster image as an (h, w) array of premultiplied ARGB words (a copy)."""
    img = view.raster.image
    a = np.frombuffer(img.constBits(), np.uint32).reshape(img.height(), -1)
    return a[:, : img.width()].copy()


def to_raster_px(view: MapView, x, y) -> tuple[np.ndarray, np.ndarray]:
    r = view.raster
    return (np.asarray(x) - r.ox) * r.sx, (np.asarray(y) - r.oy) * r.sy


def near_points(shape, u, v, radius: int) -> np.ndarray:
    """Pixels within ``radius`` (square) of the points (u, v)."""
    iu, iv = np.floor(u).astype(int), np.floor(v).astype(int)
    out = np.zeros(shape, dtype=bool)
    for du in range(-radius, radius + 1):
        for dv in range(-radius, radius + 1):
            ok = (iu + du >= 0) & (iu + du < shape[1]) & (iv + dv >= 0) & (iv + dv < shape[0])
            out[iv[ok] + dv, iu[ok] + du] = True
    return out


def drawn_anew(view: MapView) -> np.ndarray:
    """The raster as drawn at once from the decimators, on the same grid and area."""
    r, hist = view.raster, view.ctx.session.history
    fresh = PathRaster()
    for name in ("sx", "sy", "gx", "gy", "dx0", "dy0", "level", "keys", "dpr", "view_size"):
        setattr(fresh, name, getattr(r, name))
    fresh.done, fresh.stale = dict(r.done), False
    fresh._move(r.rect)  # a new image for the area, all of it queued
    shown = [p for p in view._drawing_order() if p.key in r.done]
    fresh.finish(shown, {p.key: (hist.column(p.columns[0]), hist.column(p.columns[1]))
                         for p in shown})
    img = fresh.image
    return np.frombuffer(img.constBits(), np.uint32).reshape(img.height(), -1).copy()


def test_raster_pixels_lie_on_the_history_and_cover_it(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.refresh()
    view.fit_paths()
    view.refresh()
    view.finish_drawing()
    hist = ctx.session.history
    drawn = (raster_array(view) >> 24) > 0  # alpha: something drawn
    near = np.zeros_like(drawn)
    for cx, cy in PATH_COLUMNS:
        u, v = to_raster_px(view, hist.column(cx), hist.column(cy))
        assert u.min() > 0 and v.min() > 0 and u.max() < drawn.shape[1] and v.max() < drawn.shape[0]
        # every row of the history is drawn, within a pixel
        assert near_points(drawn.shape, u, v, 1)[drawn].sum() > 0
        iu, iv = np.floor(u).astype(int), np.floor(v).astype(int)
        hit = np.zeros(len(iu), dtype=bool)
        for du in (-1, 0, 1):
            for dv in (-1, 0, 1):
                hit |= drawn[iv + dv, iu + du]
        assert hit.all()
        near |= near_points(drawn.shape, u, v, 3)
    assert drawn.sum() > 2000
    assert not (drawn & ~near).any()  # nothing drawn away from the history's points


def test_the_raster_is_shown_where_the_paths_are(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.follow_check.setChecked(False)
    view.set_visible_width(0.8, (0.1, 0.3))
    view.refresh()
    view.body.setVisible(False)  # the sensor dot has the sensor's colour too
    img = view.plot.viewport().grab().toImage().convertToFormat(QImage.Format.Format_RGB32)
    a = np.frombuffer(img.constBits(), np.uint32).reshape(img.height(), -1)[:, : img.width()]
    a = a.astype(np.int64)
    r, g, b = (a >> 16) & 255, (a >> 8) & 255, a & 255
    want = QColor(sensor_colour(0))
    orange = (abs(r - want.red()) + abs(g - want.green()) + abs(b - want.blue())) < 60
    to_screen = view.vb.childGroup.sceneTransform() * view.plot.viewportTransform()
    hist = ctx.session.history
    x, y = hist.column("s0_wx"), hist.column("s0_wy")
    u = to_screen.m11() * x + to_screen.m21() * y + to_screen.dx()
    v = to_screen.m12() * x + to_screen.m22() * y + to_screen.dy()
    assert orange.sum() > 300
    assert not (orange & ~near_points(orange.shape, u, v, 3)).any()
    box = view.plot.mapFromScene(view.vb.sceneBoundingRect()).boundingRect()  # not the axes
    inside = ((u > box.left() + 3) & (v > box.top() + 3) & (u < box.right() - 3)
              & (v < box.bottom() - 3))
    assert inside.sum() > 100
    iu, iv = np.floor(u[inside]).astype(int), np.floor(v[inside]).astype(int)
    hit = np.zeros(len(iu), dtype=bool)
    for du in (-1, 0, 1):
        for dv in (-1, 0, 1):
            hit |= orange[iv + dv, iu + du]
    assert hit.mean() > 0.97  # where the robot path or its outline is drawn over it: not seen


def test_new_rows_are_drawn_onto_the_raster_not_all_anew(view, ctx):
    replies = list(sim_replies("figure_eight", 50, 20))
    view.follow_check.setChecked(False)
    view.set_visible_width(2.0, (0.0, 0.0))
    for r in replies[:600]:
        ctx.on_reply(r)
    view.refresh()
    view.finish_drawing()
    before, img0 = dict(view.render_stats()["raster"]), raster_array(view)
    for r in replies[600:610]:
        ctx.on_reply(r)
        view.refresh()
    after = view.render_stats()["raster"]
    for key in ("full", "moves", "tiles"):
        assert after[key] == before[key], key  # nothing drawn anew, nothing moved
    assert after["commits"] == before["commits"] + 3 * 10  # three paths, ten rows
    raster = view.raster
    for key, path in view.paths.items():
        assert raster.done[key] == path.decimator.level_size(raster.level)
    changed = np.argwhere(raster_array(view) != img0)
    assert len(changed) > 10
    hist = ctx.session.history
    boxes = [to_raster_px(view, hist.column(cx)[598:], hist.column(cy)[598:])
             for cx, cy in PATH_COLUMNS]
    u0 = min(u.min() for u, _ in boxes) - 3
    u1 = max(u.max() for u, _ in boxes) + 3
    v0 = min(v.min() for _, v in boxes) - 3
    v1 = max(v.max() for _, v in boxes) + 3
    assert np.all((changed[:, 1] >= u0) & (changed[:, 1] <= u1))  # only where the new rows are
    assert np.all((changed[:, 0] >= v0) & (changed[:, 0] <= v1))
    # the live ends start at the last point the raster has
    for key, path in view.paths.items():
        lx, ly = path.live.getData()
        rows = path.decimator.rows(raster.level)
        cx, cy = view.paths[key].columns
        assert (lx[0], ly[0]) == (hist.column(cx)[rows[-1]], hist.column(cy)[rows[-1]])
        assert (lx[-1], ly[-1]) == (hist.column(cx)[-1], hist.column(cy)[-1])


def test_following_moves_the_raster_and_it_equals_one_drawn_anew(view, ctx):
    replies = list(sim_replies("figure_eight", 50, 40))
    for r in replies[:1500]:
        ctx.on_reply(r)
    view.set_visible_width(0.3)  # following; zoomed in so far that the image is the view
    view.refresh()  # and a margin only (the paths' extent would be too many pixels)
    raster = view.raster
    margin = 2 * PathRaster.MARGIN_PX
    assert raster.img_w == pytest.approx(view.vb.width() + margin, abs=6)
    assert raster.img_h == pytest.approx(view.vb.height() + margin, abs=6)
    full = raster.stats["full"]
    for r in replies[1500:1800]:
        ctx.on_reply(r)
        view.refresh()
    assert raster.stats["full"] == full  # following never draws everything anew
    assert raster.stats["moves"] > 5
    view.finish_drawing()
    moved, fresh = raster_array(view), drawn_anew(view)
    drawn = ((moved >> 24) > 0) | ((fresh >> 24) > 0)
    assert drawn.sum() > 1000
    # the same pixels, but for the order of paths at crossings and joins of pieces
    assert (moved != fresh)[drawn].mean() < 0.01


def robot_pixels(view: MapView) -> int:
    img = view.plot.viewport().grab().toImage().convertToFormat(QImage.Format.Format_RGB32)
    a = np.frombuffer(img.constBits(), np.uint32).reshape(img.height(), -1).astype(np.int64)
    want = QColor(ROBOT_COLOUR)
    return int(((abs(((a >> 16) & 255) - want.red()) + abs(((a >> 8) & 255) - want.green())
                 + abs((a & 255) - want.blue())) < 40).sum())


def test_a_zoom_draws_the_raster_anew_over_frames_the_old_stretched_meanwhile(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=20)
    view.follow_check.setChecked(False)
    view.set_visible_width(1.0, (0.35, 0.4))
    view.refresh()
    view.body.setVisible(False)
    raster = view.raster
    raster.VISIBLE_BUDGET_S = 0.0  # one tile a refresh
    full, sx, paints = raster.stats["full"], raster.sx, raster.stats["paints"]
    view.set_visible_width(0.5, (0.35, 0.4))
    before_sync = robot_pixels(view)  # painted before the next refresh: the old image stretched
    assert raster.stats["paints"] > paints and raster.sx == sx and before_sync > 200
    view.refresh()
    assert raster.stats["full"] == full + 1
    assert raster.sx == pytest.approx(2 * sx, rel=1e-6)
    in_view = raster.stats["pending_in_view"]
    assert in_view > 2 and raster.preview is not None and len(raster.veiled) == in_view
    during = robot_pixels(view)  # the tiles not drawn yet show the old image stretched
    frames = 1
    while raster.stats["pending_in_view"]:
        left = raster.stats["pending_in_view"]
        view.refresh()  # no new rows: the tiles left in view bring the refresh back
        frames += 1
        assert raster.stats["pending_in_view"] in (left, left - 1)  # a step a refresh
        assert frames < 10 * in_view
    assert raster.preview is None and raster.veiled == []
    assert raster.stats["full_frames"] == frames and raster.stats["full_ms"] > 0
    done = robot_pixels(view)
    assert during > 0.7 * done  # (one tile drawn of many: the rest was the stand-in)
    view.finish_drawing()
    view.plot.viewport().repaint()
    assert robot_pixels(view) == done  # what is seen was complete


def test_off_screen_parts_are_drawn_over_the_next_frames(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=40)
    view.follow_check.setChecked(False)
    view.set_visible_width(0.6, (0.0, 0.5))
    view.raster.BUDGET_S = 0.0  # nothing off the screen in this frame
    view.refresh()
    stats = view.render_stats()["raster"]
    assert stats["pending"] > 0  # the paths' extent is on the image, most of it off the screen
    shown = view.plot.viewport().grab().toImage()
    view.finish_drawing()
    view.plot.viewport().repaint()
    assert view.plot.viewport().grab().toImage() == shown  # what is seen was complete
    del view.raster.BUDGET_S
    view.raster.invalidate()
    view._dirty = True
    frames = 0
    while True:
        view.refresh()  # no new rows: the work left brings the refresh back anyway
        frames += 1
        if not view.render_stats()["raster"]["pending"]:
            break
        assert frames < 200
    n = view.render_stats()["refreshes"]
    view.refresh()
    assert view.render_stats()["refreshes"] == n  # all done: nothing brings it back


def test_hiding_a_path_draws_the_raster_without_it(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=10)
    view.fit_paths()
    view.refresh()
    view.finish_drawing()
    full = view.raster.stats["full"]
    view.set_path_visible(1, False)
    view.refresh()
    # not drawn over frames with the old image (it has the path) standing in
    assert view.raster.preview is None and view.raster.stats["pending_in_view"] == 0
    view.finish_drawing()
    assert view.raster.stats["full"] == full + 1 and 1 not in view.raster.done
    a = raster_array(view).astype(np.int64)
    want = QColor(sensor_colour(1))
    rgb = ((a >> 16) & 255, (a >> 8) & 255, a & 255)
    assert not ((abs(rgb[0] - want.red()) + abs(rgb[1] - want.green())
                 + abs(rgb[2] - want.blue()) < 30) & ((a >> 24) == 255)).any()


# -- direction widgets -----------------------------------------------------------------------------


@pytest.fixture
def panel(qtbot, ctx) -> DirectionPanel:
    p = DirectionPanel(ctx)
    qtbot.addWidget(p)
    p.resize(240, 440)
    p.show()
    qtbot.waitExposed(p)
    return p


def test_direction_vector_is_the_newest_displacement_times_the_gain(panel, ctx, feed):
    assert panel.widgets == [] and not panel.waiting.isHidden()
    feed(ctx, rate_hz=50, seconds=5)
    assert len(panel.widgets) == 2 and panel.waiting.isHidden()
    panel.refresh()
    hist = ctx.session.history
    for k, w in enumerate(panel.widgets):
        dx, dy = hist.last(f"s{k}_dx"), hist.last(f"s{k}_dy")
        assert (dx, dy) != (0.0, 0.0)
        assert w.vector_px() == pytest.approx((dx * w.gain, dy * w.gain))
        t = hist.column("t")
        last_s = t >= t[-1] - 1.0  # the gain looks back one second, not a number of rows
        speed = np.hypot(hist.column(f"s{k}_vx"), hist.column(f"s{k}_vy"))[last_s]
        peak = np.percentile(speed, 95) * np.median(np.diff(t[last_s]))
        assert peak == pytest.approx(0.2 / 50, rel=0.3)  # ~0.2 m/s at 50 Hz: ~4 mm per reply
        assert w.gain == auto_gain(peak, w.radius_px())
        assert peak * w.gain <= 0.9 * w.radius_px()
        speed = math.hypot(hist.last(f"s{k}_vx"), hist.last(f"s{k}_vy"))
        assert w.speed == pytest.approx(speed)
    index = panel.gain_box.findData(10 * 1e3)
    panel.gain_box.setCurrentIndex(index)
    for k, w in enumerate(panel.widgets):
        assert w.gain == 1e4
        assert w.vector_px() == pytest.approx(
            (hist.last(f"s{k}_dx") * 1e4, hist.last(f"s{k}_dy") * 1e4))


def test_one_long_reply_does_not_shrink_the_auto_gain(panel, ctx, feed):
    feed(ctx, rate_hz=50, seconds=5)
    panel.refresh()
    gains = [w.gain for w in panel.widgets]
    hist = ctx.session.history
    row = hist.tail(1)[0].copy()
    # a reply 0.6 s late (after a pause or a registers refresh): 30x the displacement, the
    # same speed
    row[hist.index["t"]] += 0.6
    for k in range(2):
        for f in ("dx", "dy"):
            row[hist.index[f"s{k}_{f}"]] *= 30
    hist.append(row)
    panel.refresh()
    for k, w in enumerate(panel.widgets):
        big = math.hypot(hist.last(f"s{k}_dx"), hist.last(f"s{k}_dy"))
        assert auto_gain(big, w.radius_px()) < gains[k] / 10  # the old largest-of-100-rows rule
        assert w.gain == gains[k]
        assert w.vector_px() == pytest.approx((hist.last(f"s{k}_dx") * w.gain,
                                               hist.last(f"s{k}_dy") * w.gain))
    panel.widgets[0].grab()  # the long arrow is painted clipped at the circle, no error


def test_gain_peak_is_a_speed_percentile_over_one_second():
    t = np.arange(0, 3, 0.01)
    v = np.full_like(t, 0.1)
    v[-1] = 5.0  # one fast row does not move the 95th percentile
    assert gain_peak(t, v, np.zeros_like(t)) == pytest.approx(0.1 * 0.01)
    assert gain_peak(t[:1], v[:1], v[:1]) == 0.0
    assert gain_peak(t, np.full_like(t, np.nan), v * np.nan) == 0.0
    v[: len(t) - 150] = 3.0  # older than one second: not looked at
    assert gain_peak(t, v, np.zeros_like(t)) == pytest.approx(0.1 * 0.01)


def test_the_dial_face_is_drawn_once_per_size(panel, ctx, feed):
    feed(ctx, rate_hz=50, seconds=2)
    panel.refresh()
    dial = panel.widgets[0]
    dial.grab()
    face = dial._dial_cache
    assert face is not None and face[0][:2] == (dial.width(), dial.height())
    dial.set_sample(0.001, -0.002, 0.05, 0.002)
    dial.grab()
    assert dial._dial_cache is face  # a new sample draws on the same face
    dial.resize(dial.width() + 30, dial.height())
    dial.grab()
    assert dial._dial_cache is not face and dial._dial_cache[0][:2] == (
        dial.width(), dial.height())  # fmt: skip


def test_the_gain_percentile_is_numpys_percentile():
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    from mm_pc.monitor.widgets.direction_widget import _percentile

    @settings(max_examples=300, deadline=None)
    @given(arrays(float, st.integers(1, 40), elements=st.floats(-1e3, 1e3)),
           st.floats(0.0, 100.0))  # fmt: skip
    def check(a, q):
        assert _percentile(a, q) == pytest.approx(float(np.percentile(a, q)), abs=1e-9)

    check()


def test_direction_refresh_skips_unchanged_history(panel, ctx, monkeypatch, feed):
    feed(ctx, rate_hz=50, seconds=2)
    panel.refresh()
    calls = []
    for w in panel.widgets:
        monkeypatch.setattr(w, "set_sample", lambda *a: calls.append(a))
    panel.refresh()
    assert calls == []
    ctx.reset()
    panel.refresh()
    assert calls == [(0.0, 0.0, 0.0, 0.0)] * 2


def test_auto_gain_steps():
    assert auto_gain(0.0, 100) == GAINS_PX_PER_MM[-1] * 1e3
    assert auto_gain(0.002, 100) == 20e3  # 2 mm * 20 px/mm = 40 px <= 90 px; 50 px/mm is 100
    assert auto_gain(10.0, 100) == GAINS_PX_PER_MM[0] * 1e3


@pytest.mark.screenshot
def test_direction_screenshot(panel, ctx, screenshot, feed):
    feed(ctx, rate_hz=50, seconds=30)
    panel.refresh()
    img = screenshot(panel, "direction.png")
    assert len(distinct_colours(img, 2)) > 10
    assert has_colour(img, sensor_colour(0)) and has_colour(img, sensor_colour(1))


# -- an hour of 100 Hz data ---------------------------------------------------------------------


def fill_hour(ctx: MonitorContext, rows: int = 360_000) -> None:
    """Put an hour of synthetic 100 Hz rows into the session (History.extend), pose at the end.
    The session must know its devices (``MonitorSession(devices=...)``)."""
    session = ctx.session
    data = hour_rows(session, rows)
    session.history.extend(data)
    session.map_history.extend(map_rows(session, data))
    col = session.history.index
    session.odometry.reset(Pose2D(*data[-1, [col["x"], col["y"], col["yaw"]]]))


def map_rows(session: MonitorSession, rows: np.ndarray) -> np.ndarray:
    """The map's columns (session.map_history) of history-shaped rows."""
    col = session.history.index
    return rows[:, [col[name] for name in session.map_history.columns]]


def time_frames(view: MapView, ctx: MonitorContext, app, n: int = 60):
    """Milliseconds of ``view.refresh()`` after one new row each (the robot 2 mm further
    along its stripe), and of refresh plus Qt repainting what changed."""
    hist = ctx.session.history
    col = hist.index
    row = hist.tail(1)[0]
    refresh_ms, frame_ms = [], []
    for _ in range(n):
        row = row.copy()
        for name in ("x", "s0_wx", "s1_wx"):
            row[col[name]] += 0.002 * math.cos(row[col["yaw"]])
        hist.append(row)
        ctx.session.map_history.extend(map_rows(ctx.session, row[None, :]))
        ctx.session.odometry.reset(Pose2D(row[col["x"]], row[col["y"]], row[col["yaw"]]))
        t0 = time.perf_counter()
        view.refresh()
        t1 = time.perf_counter()
        app.processEvents()
        t2 = time.perf_counter()
        refresh_ms.append((t1 - t0) * 1e3)
        frame_ms.append((t2 - t0) * 1e3)
    return np.array(refresh_ms), np.array(frame_ms)


def test_an_hour_of_100hz_data_refreshes_cheaply(qtbot, qapp, capsys):
    ctx = MonitorContext(MonitorSession(devices=DEFAULT_DEVICES))
    view = MapView(ctx)
    qtbot.addWidget(view)
    view.resize(1200, 800)
    view.show()
    qtbot.waitExposed(view)
    fill_hour(ctx)
    hist = ctx.session.history
    assert len(hist) == 360_000
    catch_up = []
    while not catch_up or view.render_stats()["behind"]:
        t0 = time.perf_counter()
        view.refresh()
        catch_up.append((time.perf_counter() - t0) * 1e3)
    assert len(catch_up) == 360_000 // MAX_ROWS_PER_REFRESH
    report = [f"taking in 360000 rows x 3 paths: {len(catch_up)} refreshes, p50 "
              f"{np.percentile(catch_up, 50):.0f} ms, max {max(catch_up):.0f} ms"]
    for label, width, follow in (("follow, 1 m wide", 1.0, True),
                                 ("whole mowed area, 30 m wide", 30.0, False),
                                 ("whole mowed area, 30 m wide, follow", 30.0, True),
                                 ("zoomed out, 200 m wide", 200.0, False)):
        view.follow_check.setChecked(follow)
        view.set_visible_width(width, (10.0, 10.0))
        view.refresh()
        while view.render_stats()["raster"]["pending_in_view"]:
            view.refresh()
        zoom_ms = view.render_stats()["raster"]["full_ms"]
        zoom_frames = view.render_stats()["raster"]["full_frames"]
        qapp.processEvents()
        refresh_ms, frame_ms = time_frames(view, ctx, qapp)
        t1 = time.perf_counter()
        for _ in range(3):
            view.grab()
        grab_ms = (time.perf_counter() - t1) / 3 * 1e3
        stats = view.render_stats()
        report.append(
            f"{label}: refresh p50 {np.percentile(refresh_ms, 50):.2f} p95 "
            f"{np.percentile(refresh_ms, 95):.2f} max {refresh_ms.max():.2f} ms; refresh + "
            f"repaint p50 {np.percentile(frame_ms, 50):.1f} p95 {np.percentile(frame_ms, 95):.1f}"
            f" max {frame_ms.max():.1f} ms; whole-widget repaint {grab_ms:.0f} ms; "
            f"points {stats['points']['robot']} x 3, level {stats['levels']['robot']}; "
            f"zoom to it {zoom_ms:.0f} ms in {zoom_frames} refreshes, raster "
            f"{stats['raster']['size']} px"
        )
        if width >= 30:  # the whole path is in view: it starts and ends where the history does
            assert_path_from_history(view, "robot", hist, "x", "y")
    memory = view.render_stats()["memory_mb"]
    report.append(f"memory: decimators {memory['decimators']:.1f} MB, raster "
                  f"{memory['raster']:.1f} MB")
    # row numbers, 4 bytes, of ~4 x 360 000 kept points a path (2 mm a row: levels 0-2 keep
    # all, then half, a quarter, ...), up to twice that while the arrays grow, and boxes
    assert memory["decimators"] < 3 * 2 * 4 * 360_000 * (4 + 32 / PathDecimator.BOX) / 1e6
    assert memory["raster"] <= PathRaster.MAX_PIXELS * 4 / 1e6
    with capsys.disabled():
        print("\n" + "\n".join(report))


def test_a_stretch_without_single_polls_is_drawn_dashed_in_the_gap_colour(view, ctx, qtbot):
    from fakes import FakeRing
    from test_monitor_session import _poll_replies

    from mm_pc.monitor.widgets.style import GAP_COLOUR
    from mm_pc.sim.robot import trajectory

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:6000], w[:6000])
    for r in _poll_replies(ring, [0, *range(100, 6001, 100)], skip=(3000,)):
        ctx.on_reply(r)
    view.refresh()
    view.fit_paths()
    view.refresh()
    (g,) = ctx.session.gaps
    assert view.gap_segments().tolist() == [[g.x0, g.y0, g.x1, g.y1]]
    img = view.plot.grab().toImage()
    assert has_colour(img, GAP_COLOUR)
    ctx.reset()
    view.refresh()
    assert len(view.gap_segments()) == 0


# -- cursor coordinates, measure, Fit's margin, the zoom label (issue 29 items 5, 13) -------


def _viewport_point(view: MapView, x: float, y: float):
    """The map viewport's pixel at odom (x, y) m."""
    return view.plot.mapFromScene(view.vb.mapViewToScene(QPointF(x, y)))


def test_the_cursor_s_coordinates_and_a_measured_distance(qtbot, view, ctx, feed):
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    feed(ctx, rate_hz=50, seconds=2)
    view.refresh()
    view.follow_check.setChecked(False)
    view.set_visible_width(2.0, (0.0, 0.0))
    vp = view.plot.viewport()
    label = view.pointer.label
    qtbot.wait(20)  # pyqtgraph passes on at most one move per 10 ms
    QTest.mouseMove(vp, _viewport_point(view, 0.3, -0.2))
    text = label.text()
    assert label.isVisible() and text.startswith("cursor x +0.3") and "y -0.2" in text
    cx, cy = (float(v) for v in (text.split("x ")[1].split(" m")[0],
                                 text.split("y ")[1].split(" m")[0]))
    px = view.visible_width() / view.vb.width()  # one pixel (m)
    assert cx == pytest.approx(0.3, abs=2 * px) and cy == pytest.approx(-0.2, abs=2 * px)
    assert "distance" not in text
    assert label.width() >= label.sizeHint().width()  # not cut

    QTest.mouseClick(vp, Qt.MouseButton.LeftButton, pos=_viewport_point(view, 0.0, 0.0))
    assert view.pointer.a is None  # Measure is off: a click measures nothing
    view.measure_button.setChecked(True)
    QTest.mouseClick(vp, Qt.MouseButton.LeftButton, pos=_viewport_point(view, -0.3, -0.3))
    qtbot.wait(20)  # pyqtgraph passes on at most one move per 10 ms
    QTest.mouseMove(vp, _viewport_point(view, 0.0, 0.1))  # the line follows the mouse
    assert "distance 0.5" in label.text()
    qtbot.wait(QApplication.doubleClickInterval() + 50)  # two clicks, not a double-click
    QTest.mouseClick(vp, Qt.MouseButton.LeftButton, pos=_viewport_point(view, 0.3, 0.5))
    (ax, ay), (bx, by) = view.pointer.a, view.pointer.b
    d = math.hypot(bx - ax, by - ay)
    assert d == pytest.approx(1.0, abs=3 * px)  # a 0.6 x 0.8 m right triangle
    assert f"distance {d:.3f} m (dx {bx - ax:+.3f}, dy {by - ay:+.3f})" in label.text()
    x, y = view.pointer.line.getData()
    assert list(x) == [ax, bx] and list(y) == [ay, by] and view.pointer.line.isVisible()
    qtbot.wait(20)  # pyqtgraph passes on at most one move per 10 ms
    QTest.mouseMove(vp, _viewport_point(view, -0.5, 0.5))  # fixed once both points are set
    assert f"distance {d:.3f} m" in label.text()
    view.measure_button.setChecked(False)
    assert view.pointer.a is None and not view.pointer.line.isVisible()
    assert "distance" not in label.text()


def test_fit_leaves_a_margin_around_the_paths_and_the_robot(view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=30)
    view.refresh()
    view.fit_paths()
    (x0, x1), (y0, y1) = view.vb.viewRange()
    width = x1 - x0
    x0b, x1b, y0b, y1b = view.paths["robot"].decimator.bounds
    pose = ctx.session.pose
    for px, py in ((x0b, y0b), (x1b, y1b), (pose.x, pose.y)):
        # every path point and the robot's centre at least its reach and 5 % inside
        assert x0 + 0.15 + 0.04 * width < px < x1 - 0.15 - 0.04 * width
        assert y0 + 0.15 < py < y1 - 0.15


def test_the_zoom_label_keeps_one_unit(view):
    texts = []
    for w in (0.2, 0.5, 0.99, 1.0, 1.01, 5.0, 150.0):
        view.set_visible_width(w)
        texts.append(view.width_label.text())
    assert texts == ["0.2 m", "0.5 m", "0.99 m", "1 m", "1.01 m", "5 m", "150 m"]
