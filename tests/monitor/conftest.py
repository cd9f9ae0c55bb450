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
