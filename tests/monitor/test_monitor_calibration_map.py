"""The Map draws the sensors where the calibration in force says they are (issue 28 item 4):
the fitted positions and the mounting yaw turned by the fitted angle, not the geometry's."""

from __future__ import annotations

import math

import pytest

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.widgets.map_view.view import MapView


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


def _drawn(view: MapView, k: int) -> tuple[float, float, float]:
    """Sensor k's dot (base_link, m) and the direction of its +Y arrow (rad)."""
    dot = view.sensor_items[k]["dot"].pos()
    ax, ay = view.sensor_items[k]["axes"].getData()
    # 3 segments per arrow, X first: points 6-7 are the Y arrow's shaft
    return dot.x(), dot.y(), math.atan2(ay[7] - ay[6], ax[7] - ax[6])


def test_built_mounts_take_the_fitted_position_and_turn_the_yaw():
    cal = Calibration({"a": SensorCalibration(math.radians(3.0), 1.0, x=0.051, y=-0.0385)})
    built = cal.built_mounts(("a", "b"), (*DEFAULT_MOUNTS, SensorMount(0.0, 0.0)))
    assert built[0] == SensorMount(0.051, -0.0385, pytest.approx(math.radians(3.0)))
    assert built[1] == DEFAULT_MOUNTS[1]  # no calibration for "b": the geometry's
    assert built[2] == SensorMount(0.0, 0.0)  # no device yet: as given
    assert Calibration().built_mounts((), DEFAULT_MOUNTS) == tuple(DEFAULT_MOUNTS)


def test_the_map_draws_the_fitted_mounts_once_a_calibration_is_applied(qtbot, view, ctx, feed):
    feed(ctx, rate_hz=50, seconds=1)
    view.refresh()
    devices = ctx.session.devices
    for k, m in enumerate(DEFAULT_MOUNTS):
        assert _drawn(view, k) == pytest.approx((m.x, m.y, m.yaw), abs=1e-9)
    fitted = ((0.051, -0.0385, 3.0), (0.047, 0.041, -2.0))
    cal = Calibration({
        dev: SensorCalibration(math.radians(yaw), 1.0, x=x, y=y)
        for dev, (x, y, yaw) in zip(devices, fitted, strict=False)
    })
    ctx.set_calibration(cal, "test")
    view.refresh()
    for k, (x, y, yaw) in enumerate(fitted):
        assert _drawn(view, k) == pytest.approx((x, y, math.radians(yaw)), abs=1e-9)
    # the odometry's mounts and the drawing agree on the position
    assert [v for m in ctx.session.odometry_mounts for v in (m.x, m.y)] == pytest.approx(
        [v for x, y, _ in fitted for v in (x, y)])
    ctx.clear_calibration()
    view.refresh()
    for k, m in enumerate(DEFAULT_MOUNTS):
        assert _drawn(view, k) == pytest.approx((m.x, m.y, m.yaw), abs=1e-9)
