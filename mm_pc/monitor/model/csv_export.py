"""One sensor's rows of the history as a table: the columns (units in the names) and the
CSV export of every row (no Qt; the Data list picks the file and shows the result).

The CSV holds each value rounded to what it means (:data:`CSV_DECIMALS`: t to the µs,
displacements to the µm, speeds to the µm/s) in its shortest form, and the counts as
integers: ``-1.81``, not ``-1.8097499999998323``; ``1600``, not ``1600.0``.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from mm_pc.monitor.model.history import History
from mm_pc.monitor.model.session import sensor_columns

__all__ = ["COLUMNS", "CSV_DECIMALS", "CSV_HEADER", "column_name", "csv_chunks", "csv_columns",
           "export_csv", "history_csv_chunks", "write_csv_columns"]

#: (header with unit, field: "t" or a sensor field, scale from SI, format)
COLUMNS: tuple[tuple[str, str, float, str], ...] = (
    ("t (s)", "t", 1.0, "{:.3f}"),
    ("dX (mm)", "dx", 1e3, "{:.4f}"),
    ("dY (mm)", "dy", 1e3, "{:.4f}"),
    ("raw dX (mm)", "raw_dx", 1e3, "{:.4f}"),
    ("raw dY (mm)", "raw_dy", 1e3, "{:.4f}"),
    ("vX (mm/s)", "vx", 1e3, "{:.2f}"),
    ("vY (mm/s)", "vy", 1e3, "{:.2f}"),
    ("lifts", "lifts", 1.0, "{:.0f}"),
    ("CPI", "cpi", 1.0, "{:.0f}"),
    ("quality", "quality", 1.0, "{:.0f}"),  # the newest poll's figure; nan = the chip has none
    ("low-q polls", "lowq", 1.0, "{:.0f}"),  # polls below the chip's threshold (taken as lifts)
)
#: CSV header names (units in the name; dX/dY processed = filtered and calibrated)
CSV_HEADER = (
    "t_s", "dx_mm", "dy_mm", "raw_dx_mm", "raw_dy_mm", "vx_mm_s", "vy_mm_s", "lifts", "cpi",
    "quality", "low_quality_polls",
)


#: per CSV column: decimals it is rounded to, or None: an integer count ("nan" where the
#: history has none, e.g. the quality of a chip without a figure)
CSV_DECIMALS: tuple[int | None, ...] = (6, 3, 3, 3, 3, 3, 3, None, None, None, None)


def _csv_values(col: np.ndarray, decimals: int | None) -> list:
    """A column as the CSV writes it (floats print in their shortest form)."""
    if decimals is not None:
        return (np.round(col, decimals) + 0.0).tolist()  # + 0.0: no "-0.0"
    finite = np.isfinite(col)
    if finite.all():
        return np.rint(col).astype(np.int64).tolist()
    return [round(v) if ok else "nan" for v, ok in zip(col.tolist(), finite.tolist(),
                                                              strict=True)]


def column_name(sensor_index: int, field: str) -> str:
    """The history column of ``field`` ("t" or a sensor field) of sensor ``sensor_index``."""
    return field if field == "t" else sensor_columns(sensor_index)[field]


def export_csv(history: History | None, sensor_index: int, path: str | Path) -> int:
    """Write every row of one sensor to a CSV file, oldest first; returns the row count.

    Columns (header line first): t_s, dx_mm, dy_mm (processed), raw_dx_mm,
    raw_dy_mm, vx_mm_s, vy_mm_s, lifts, cpi, quality (nan: the chip has none),
    low_quality_polls; rounded as :data:`CSV_DECIMALS` says. Raises ValueError for no data or
    a sensor the history does not have (no file written), OSError when the
    file cannot be written.
    """
    return write_csv_columns(csv_columns(history, sensor_index), path)


def csv_columns(history: History | None, sensor_index: int) -> list[np.ndarray]:
    """The export's columns of one sensor, copied in display units (the history may grow
    meanwhile); ValueError as :func:`export_csv`."""
    names = _names(history, sensor_index)
    return [history.column(n) * scale for n, (_h, _f, scale, _fmt) in zip(names, COLUMNS,
                                                                           strict=True)]


def _names(history: History | None, sensor_index: int) -> list[str]:
    """The history columns of the export; ValueError for no data or no such sensor."""
    if history is None:
        raise ValueError("no data yet: nothing to export")
    names = [column_name(sensor_index, f) for _h, f, _s, _f in COLUMNS]
    missing = [n for n in names if n not in history.index]
    if sensor_index < 0 or missing:
        sensors = sum(1 for c in history.columns if c.endswith("_cpi"))
        raise ValueError(f"no sensor {sensor_index!r} in the history; sensors: 0..{sensors - 1}")
    return names


def write_csv_columns(cols: list[np.ndarray], path: str | Path) -> int:
    """Write the columns of :func:`csv_columns` as CSV (header first); returns the rows."""
    *_, written = csv_chunks(cols, path)
    return written


#: rows written per :func:`csv_chunks` step (~7 ms on a quiet 2-core PC)
CSV_CHUNK_ROWS = 2500


def csv_chunks(cols: list[np.ndarray], path: str | Path, rows: int = CSV_CHUNK_ROWS):
    """Write the columns of :func:`csv_columns` as CSV ``rows`` rows a step (a generator: it
    yields the rows written so far after the header and after each step; the file is closed
    when it is exhausted or closed). The same file as one go: a GUI writes it a step per
    timer tick instead of holding its thread (an hour of rows took ~0.6 s in one go)."""
    n = len(cols[0])
    return _write_steps(path, ([c[i : i + rows] for c in cols] for i in range(0, n, rows)), n)


def history_csv_chunks(history: History | None, sensor_index: int, path: str | Path,
                       rows: int = CSV_CHUNK_ROWS):  # fmt: skip
    """:func:`csv_chunks` of the rows ``history`` holds now, each step copying only its own
    rows (copying an hour's strided columns at once took 48-124 ms). Rows appended meanwhile
    are not written; a step raises ValueError (the file is left incomplete) when the history
    was cleared or dropped its oldest rows since the start. ValueError at once as
    :func:`export_csv`."""
    names = _names(history, sensor_index)
    n, dropped = len(history), history.dropped_rows
    scales = [scale for _h, _f, scale, _fmt in COLUMNS]

    def parts():
        for i in range(0, n, rows):
            if len(history) < n or history.dropped_rows != dropped:
                raise ValueError("the data was cleared or its oldest rows dropped during "
                                 "the export: export again")
            yield [history.column(name)[i : min(i + rows, n)] * scale
                   for name, scale in zip(names, scales, strict=True)]

    return _write_steps(path, parts(), n)


def _write_steps(path: str | Path, parts, n: int):
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(CSV_HEADER)
        yield 0
        done = 0
        for part in parts:
            out.writerows(zip(*(_csv_values(c, d) for c, d in zip(part, CSV_DECIMALS,
                                                                   strict=True)), strict=True))
            done = min(n, done + len(part[0]))
            yield done
