"""Screenshots of every main tab of the whole monitor, against a real mm-beagle sim node.

The images are monitor-<tab>.png in the screenshot folder (tests/monitor/conftest.py;
`./compile docs-images` puts them in docs/images, which the user guide shows);
each is checked for non-trivial content: many distinct colours and a
sizeable part of the picture that is not background.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtGui import QImage

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.export import grab_png
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.ros_bridge import RosBridge

pytestmark = pytest.mark.ros


def content_stats(path: Path) -> tuple[int, float]:
    """(distinct colours, share of pixels that differ from the most common colour)."""
    img = QImage(str(path))
    assert not img.isNull(), path
    counts: dict[int, int] = {}
    step = 3
    n = 0
    for y in range(0, img.height(), step):
        for x in range(0, img.width(), step):
            c = img.pixel(x, y)
            counts[c] = counts.get(c, 0) + 1
            n += 1
    background = max(counts.values())
    return len(counts), 1.0 - background / n


#: the module-wide mm-beagle of tests/monitor/conftest.py
BEAGLE_PARAMS = {"backend": "sim", "sim_trajectory": "figure_eight", "sim_lift_rate": 0.5}


@pytest.fixture(scope="module")
def live_window(qapp, beagle_node, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shots")
    config = MonitorConfig(rate_hz=50.0, calibration_file=tmp / "cal.yaml")
    bridge = RosBridge("/mm_beagle", 50.0, node_name="mm_monitor_shots")
    ctx = MonitorContext(MonitorSession(), bridge, config)
    window = MainWindow(ctx)
    window.resize(1280, 800)
    window.show()
    bridge.start()
    try:
        yield window
    finally:
        bridge.stop()
        window.close()


@pytest.mark.screenshot
def test_every_tab_screenshot_has_content(live_window, qapp, screenshot_dir):
    window = live_window
    session = window.ctx.session
    # the two-sensor method: Health's residual plot has data (with 'exact' it is empty)
    assert window.set_method("two-sensor")
    # about 8 s of the figure eight at 50 Hz
    wait_until(lambda: session.history is not None and len(session.history) > 400, 40,
               "8 s of history", pump=qapp.processEvents)
    assert window.views["Registers"].request_registers() == 2
    table = window.views["Registers"].table
    wait_until(lambda: table.item(0, 0) is not None and "0x" in table.item(0, 0).text(), 10,
               "the registers table", pump=qapp.processEvents)
    # Debug: three manual samples and each sensor's single polls (else two empty plots)
    debug = window.views["Debug"]
    for n in range(1, 4):
        debug.request_sample()
        wait_until(lambda n=n: len(debug.samples) >= n, 10, "a manual sample",
                   pump=qapp.processEvents)
    for dev in session.devices:
        debug.fetch_polls(dev)
    wait_until(lambda: len(debug.polls) == len(session.devices), 10, "the single polls",
               pump=qapp.processEvents)
    debug.refresh()
    for i in range(window.tabs.count()):
        title = window.tabs.tabText(i)
        window.tabs.setCurrentIndex(i)
        for _ in range(5):
            window.frame()
            qapp.processEvents()
        path = grab_png(window, screenshot_dir / f"monitor-{title.lower()}.png")
        colours, share = content_stats(path)
        assert colours > 20, f"{title}: only {colours} colours"
        assert share > 0.05, f"{title}: {share:.1%} of the picture is not background"
    residual = session.history.column("residual")
    assert np.count_nonzero(np.isfinite(residual)) > 300  # what the Health plot draws
    window.tabs.setCurrentIndex(0)
    assert session.stats.used > 400


#: the small laptop screen the window must fit, and a large one (docs/user-guide.md)
WINDOW_SIZES = ((1024, 700), (1600, 1000))


@pytest.mark.screenshot
@pytest.mark.parametrize(("width", "height"), WINDOW_SIZES)
def test_whole_window_at_small_and_large_sizes(live_window, qapp, screenshot_dir, width, height):
    window = live_window
    session = window.ctx.session
    wait_until(lambda: session.history is not None and len(session.history) > 200, 40,
               "4 s of history", pump=qapp.processEvents)
    window.tabs.setCurrentIndex(0)
    window.resize(width, height)
    for _ in range(5):
        window.frame()
        qapp.processEvents()
    assert (window.width(), window.height()) == (width, height)  # nothing widened it
    assert window.control_dock.isVisible() and window.direction_dock.isVisible()
    path = grab_png(window, screenshot_dir / f"monitor-{width}x{height}.png")
    img = QImage(str(path))
    assert (img.width(), img.height()) == (width, height)
    colours, share = content_stats(path)
    assert colours > 20 and share > 0.05
    window.resize(1280, 800)
