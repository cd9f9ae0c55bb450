"""CSV export of one sensor's history rows (model/csv_export.py): values, no Qt.

The Data list's Export CSV… button only picks the file (tests/monitor/test_monitor_views.py).
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from mm_pc.monitor.model.csv_export import (
    COLUMNS,
    CSV_DECIMALS,
    CSV_HEADER,
    _csv_values,
    column_name,
    export_csv,
)
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies


def session_of(seconds: float) -> MonitorSession:
    """A session that has taken in ``seconds`` of the simulated figure eight at 100 Hz."""
    session = MonitorSession()
    for reply in sim_replies("figure_eight", 100.0, seconds):
        session.process(reply)
    return session


def test_export_csv_round_trip(tmp_path):
    hist = session_of(5.0).history
    path = tmp_path / "s1.csv"
    assert export_csv(hist, 1, path) == len(hist)
    with open(path, newline="") as fh:
        assert next(csv.reader(fh)) == list(CSV_HEADER)
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    assert data.shape == (len(hist), 11) == (len(hist), len(COLUMNS))
    # oldest first, each value to its µs, µm or µm/s (issue 29: no float noise)
    np.testing.assert_allclose(data[:, 0], hist.column("t"), atol=5.01e-7, rtol=0)
    np.testing.assert_allclose(data[:, 1], hist.column("s1_dx") * 1e3, atol=5.01e-4, rtol=0)
    np.testing.assert_allclose(data[:, 4], hist.column("s1_raw_dy") * 1e3, atol=5.01e-4, rtol=0)
    np.testing.assert_allclose(data[:, 6], hist.column("s1_vy") * 1e3, atol=5.01e-4, rtol=0)
    np.testing.assert_array_equal(data[:, 8], hist.column("s1_cpi"))
    np.testing.assert_array_equal(data[:, 9], hist.column("s1_quality"))  # nan: no figure
    np.testing.assert_array_equal(data[:, 10], hist.column("s1_lowq"))
    assert column_name(1, "vy") == "s1_vy" and column_name(1, "t") == "t"
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))[1:]
    for row in rows:
        for text, decimals in zip(row, CSV_DECIMALS, strict=True):
            if decimals is None:  # counts: integers (or nan: no quality figure)
                assert text == "nan" or text == str(int(text)), text
            else:  # the shortest form of the rounded value: no noise digits, no -0.0
                assert len(text.lstrip("-").split(".")[1]) <= decimals, text
                assert text == repr(round(float(text), decimals)) and text != "-0.0", text
    assert rows[1][8] == "1600"


def test_csv_values_are_rounded_in_their_shortest_form():
    col = np.array([-1.8097499999998323, 0.1 + 0.2, -0.0001, 2.0])
    assert _csv_values(col, 3) == [-1.81, 0.3, 0.0, 2.0]
    assert [repr(v) for v in _csv_values(col, 3)] == ["-1.81", "0.3", "0.0", "2.0"]
    assert _csv_values(np.array([1600.0, 3.0]), None) == [1600, 3]
    assert _csv_values(np.array([np.nan, 42.0]), None) == ["nan", 42]


def test_export_csv_refuses_bad_input(tmp_path):
    hist = session_of(1.0).history
    with pytest.raises(ValueError, match=r"no sensor 2 in the history; sensors: 0\.\.1"):
        export_csv(hist, 2, tmp_path / "x.csv")
    with pytest.raises(ValueError, match="no data yet"):
        export_csv(None, 0, tmp_path / "x.csv")
    assert not (tmp_path / "x.csv").exists()
    with pytest.raises(OSError):
        export_csv(hist, 0, tmp_path / "missing_dir" / "x.csv")
