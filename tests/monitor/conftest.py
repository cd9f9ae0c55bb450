"""Fixtures the monitor's tests share: where screenshots go, and how one is taken.

A test run writes its screenshots to a temporary folder, so ``./compile test`` leaves the
tracked docs/images alone; ``./compile docs-images`` sets ``MM_SCREENSHOT_DIR=docs/images``
and runs only the tests marked ``screenshot``, which is how those pictures are regenerated.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: set by ``./compile docs-images``; unset, screenshots go to a temporary folder
SCREENSHOT_DIR_ENV = "MM_SCREENSHOT_DIR"


@pytest.fixture(scope="session")
def screenshot_dir(tmp_path_factory) -> Path:
    """The folder screenshots are written to (docs/images only on request)."""
    where = os.environ.get(SCREENSHOT_DIR_ENV)
    if where:
        path = Path(where)
        path.mkdir(parents=True, exist_ok=True)
        return path
    return tmp_path_factory.mktemp("screenshots")


@pytest.fixture
def screenshot(screenshot_dir):
    """``screenshot(widget, name)``: lay out pending changes, grab the widget, save it as
    ``name`` in :func:`screenshot_dir` and return the image the checks look at."""
    from PySide6.QtWidgets import QApplication

    def save(widget, name: str):
        QApplication.processEvents()  # pending layout requests (labels whose text just changed)
        img = widget.grab().toImage()
        assert img.save(str(screenshot_dir / name)), name
        return img

    return save


@pytest.fixture(scope="module")
def beagle_node(request, tmp_path_factory):
    """One mm-beagle per test module, on emulated sensors, stopped after the module.

    The module's ``BEAGLE_PARAMS`` say how it runs: a dict of node parameters, or a
    function of a temporary folder that returns one (to write a register map there).
    """
    pytest.importorskip("rclpy")
    pytest.importorskip("mm_interfaces")
    from mm_beagle.tools.harness import beagle_process

    tmp = tmp_path_factory.mktemp("beagle")
    params = getattr(request.module, "BEAGLE_PARAMS", {"backend": "sim"})
    if callable(params):
        params = params(tmp)
    with beagle_process(params, env=dict(os.environ), log_path=str(tmp / "beagle.log")) as proc:
        yield proc


def _feed(ctx, replies=None, *, name="figure_eight", rate_hz=100.0, seconds=None, start_ns=None):
    """Hand ``replies`` to ``ctx.on_reply`` (by default the simulated replies of
    ``sim_replies(name, rate_hz, seconds)``), as the bridge would; how many."""
    if replies is None:
        from mm_pc.monitor.model.sim_feed import sim_replies

        kw = {} if start_ns is None else {"start_ns": start_ns}
        replies = sim_replies(name, rate_hz, seconds, **kw)
    n = 0
    for reply in replies:
        ctx.on_reply(reply)
        n += 1
    return n


@pytest.fixture
def feed():
    """``feed(ctx, replies=None, *, name, rate_hz, seconds, start_ns)``: see :func:`_feed`."""
    return _feed


@pytest.fixture
def fake_bridge():
    """A stand-in for RosBridge: the signals and request methods the views use; ``calls``
    records the requests (``("settings", device)``, ``("resolution", device, cpi)``)."""
    from PySide6.QtCore import QObject, Signal

    class FakeBridge(QObject):
        settings_received = Signal(str, object)
        settings_failed = Signal(str, str)
        resolution_done = Signal(str, bool, str, int)
        diagnostics_received = Signal(object)
        stats_updated = Signal(object)

        def __init__(self) -> None:
            super().__init__()
            self.calls: list[tuple] = []

        def request_settings(self, device: str) -> None:
            self.calls.append(("settings", device))

        def set_resolution(self, device: str, cpi: int) -> None:
            self.calls.append(("resolution", device, cpi))

    return FakeBridge()
