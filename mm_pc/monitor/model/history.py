"""A columnar, append-only history of float64 rows with bounded memory (no Qt, no ROS).

The monitor appends one row per reply (15-500 Hz) and the views read whole
columns as numpy views many times a second, so appends must be amortised O(1)
and reads free of copies. Capacity doubles as rows arrive, up to
``max_rows``; beyond that the oldest half is dropped (memory stays bounded,
and ``dropped_rows`` says how much was let go).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

__all__ = ["History"]


class History:
    """Rows of named float64 columns.

    ``columns``: the column names, in row order. ``max_rows``: upper bound of
    rows kept (>= 2). ``initial``: first capacity.
    """

    def __init__(
        self, columns: Sequence[str], max_rows: int = 2_000_000, initial: int = 4096
    ) -> None:
        names = list(columns)
        if not names or len(set(names)) != len(names):
            raise ValueError(f"columns must be unique names, got {names!r}")
        if not (isinstance(max_rows, int) and max_rows >= 2):
            raise ValueError(f"max_rows must be an integer >= 2, got {max_rows!r}")
        self.columns = tuple(names)
        self.index = {n: i for i, n in enumerate(names)}
        self.max_rows = max_rows
        self._data = np.empty((min(initial, max_rows), len(names)))
        self._n = 0
        #: rows discarded to stay within ``max_rows`` since the last clear
        self.dropped_rows = 0
        #: increments on every change; views compare it to skip redraws
        self.version = 0

    def __len__(self) -> int:
        return self._n

    @property
    def nbytes(self) -> int:
        """Bytes held by the buffer (its capacity, not just the used rows)."""
        return self._data.nbytes

    def append(self, row: Iterable[float]) -> None:
        """Add one row (one value per column, in column order)."""
        values = np.fromiter(row, dtype=float, count=len(self.columns))
        self._make_room(1)
        self._data[self._n] = values
        self._n += 1
        self.version += 1

    def extend(self, rows: np.ndarray) -> None:
        """Add many rows at once: an array of shape (N, n_columns)."""
        rows = np.asarray(rows, dtype=float)
        if rows.ndim != 2 or rows.shape[1] != len(self.columns):
            raise ValueError(f"expected shape (N, {len(self.columns)}), got {rows.shape}")
        rows = rows[-self.max_rows :]
        self._make_room(len(rows))
        self._data[self._n : self._n + len(rows)] = rows
        self._n += len(rows)
        self.version += 1

    def _make_room(self, k: int) -> None:
        need = self._n + k
        if need > self.max_rows:
            keep = max(self.max_rows // 2, self.max_rows - k) if k < self.max_rows else 0
            keep = min(keep, self._n)
            self.dropped_rows += self._n - keep
            self._data[:keep] = self._data[self._n - keep : self._n]
            self._n = keep
            need = self._n + k
        if need > len(self._data):
            cap = min(self.max_rows, max(need, 2 * len(self._data)))
            grown = np.empty((cap, len(self.columns)))
            grown[: self._n] = self._data[: self._n]
            self._data = grown

    def column(self, name: str) -> np.ndarray:
        """A read-only view of one column's filled part."""
        try:
            view = self._data[: self._n, self.index[name]]
        except KeyError:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns)}") from None
        view.flags.writeable = False
        return view

    def last(self, name: str, default: float = float("nan")) -> float:
        """The newest value of a column (``default`` when empty)."""
        return float(self._data[self._n - 1, self.index[name]]) if self._n else default

    def tail(self, n: int) -> np.ndarray:
        """The newest ``n`` rows (a copy), oldest first."""
        return self._data[max(0, self._n - n) : self._n].copy()

    def truncate(self, n: int) -> None:
        """Keep the oldest ``n`` rows (0 <= n <= len): a replay's seek back to a keyframe."""
        if not 0 <= n <= self._n:
            raise ValueError(f"cannot keep {n!r} of {self._n} rows")
        self._n = n
        self.version += 1

    def clear(self) -> None:
        """Drop every row (the capacity shrinks back)."""
        self._data = np.empty((min(4096, self.max_rows), len(self.columns)))
        self._n = 0
        self.dropped_rows = 0
        self.version += 1
