"""Direction widgets: the newest displacement of each sensor as an amplified arrow.

One :class:`DirectionWidget` per sensor, in the sensor frame (X right =
robot right, Y up = robot forward), as the original monitor's "Direction
Widget". The arrow is the processed (filtered, calibrated) displacement of
the newest history row, ``s{k}_dx, s{k}_dy`` (m), times a gain in screen
pixels per metre: chosen automatically or fixed by the user.
The automatic gain is a 1-2-5 step that keeps the typical displacement of
the last ``GAIN_WINDOW_S`` (1 s) of history inside the circle: the
``GAIN_PERCENTILE`` (95th) percentile of the speed times the median time
between rows (:func:`gain_peak`). It is based on speed and time, not on the
largest displacement of the last rows, so one long reply (after a pause, a
registers refresh or a 1 kHz fetch) does not shrink the arrows to dots for
seconds; that reply's own arrow is drawn clipped at the circle's edge.
When the values are stale (link lost, polling paused: ``ctx.stale``) the arrow is
not drawn and the dial says so ("link lost: no data since 14:03:12") in grey.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QFont, QFontMetricsF, QPainter, QPen, QPixmap, QPolygonF
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.widgets.style import sensor_colour, stale_text

__all__ = ["GAINS_PX_PER_MM", "DirectionPanel", "DirectionWidget", "auto_gain", "gain_peak"]

#: Gains offered (screen pixels per millimetre of displacement), 1-2-5 steps.
GAINS_PX_PER_MM = (0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000)
#: Seconds of history the auto gain looks back over.
GAIN_WINDOW_S = 1.0
#: Percentile of the speed over that window the auto gain fits in the circle.
GAIN_PERCENTILE = 95.0
#: Rows read from the history's end to find the last GAIN_WINDOW_S (>= 1 s at 1 kHz).
TAIL_ROWS = 1024
#: Part of the circle's radius the largest recent displacement may fill.
FILL = 0.9
#: Colour of the texts of a dial whose values are stale.
STALE_COLOUR = "#888888"


def auto_gain(peak_m: float, radius_px: float) -> float:
    """The largest offered gain (px/m) that draws ``peak_m`` within ``FILL`` of the radius."""
    best = GAINS_PX_PER_MM[0] * 1e3
    for g in GAINS_PX_PER_MM:
        if peak_m * g * 1e3 <= FILL * radius_px:
            best = g * 1e3
    return best


def gain_peak(t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
              window_s: float = GAIN_WINDOW_S, percentile: float = GAIN_PERCENTILE) -> float:
    """The displacement (m) the auto gain fits: the ``percentile`` of the speed (m/s)
    over the rows with ``t`` (s) in the last ``window_s`` seconds, times their median
    time step (s). 0 when there is no finite speed or fewer than two rows."""
    if len(t) < 2:
        return 0.0
    keep = t >= t[-1] - window_s
    if keep.sum() < 2:
        keep[-2:] = True
    tt = t[keep]
    speed = np.hypot(vx[keep], vy[keep])
    speed = speed[np.isfinite(speed)]
    steps = np.diff(tt)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if not len(speed) or not len(steps):
        return 0.0
    return _percentile(speed, percentile) * _percentile(steps, 50.0)


def _percentile(a: np.ndarray, q: float) -> float:
    """``np.percentile(a, q)`` (linear) by two partitions: this runs every frame, and
    np.percentile's own overhead is several times the work for a second of rows."""
    k = (len(a) - 1) * q / 100.0
    lo = int(k)
    hi = min(lo + 1, len(a) - 1)
    part = np.partition(a, (lo, hi))
    return float(part[lo] + (part[hi] - part[lo]) * (k - lo))


def _text(p: QPainter, font: QFont, colour: str, rect: QRectF, align, text: str) -> None:
    """One line of ``text`` in ``rect`` (px) with ``font`` and ``colour``."""
    p.setFont(font)
    p.setPen(QColor(colour))
    p.drawText(rect, align, text)


class DirectionWidget(QWidget):
    """Arrow of one sensor's newest displacement (sensor frame, X right, Y up).

    ``gain_setting``: px per metre, or None for the automatic gain.
    """

    def __init__(self, index: int, device: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.index = index
        self.device = device
        self.colour = QColor(sensor_colour(index))
        self.gain_setting: float | None = None
        self.gain = GAINS_PX_PER_MM[0] * 1e3  # px/m in force
        self.dx = self.dy = 0.0  # m, sensor frame
        self.speed = 0.0  # m/s
        #: "" while the values are live; else why they are not ("paused: no data since …")
        self.stale_text = ""
        self.setMinimumSize(140, 140)
        # paintEvent fills the whole rect: Qt need not paint the panel and window under it
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self._dial_cache: tuple[tuple, QPixmap] | None = None  # (size/font key, pixmap)
        self.setToolTip(
            f"sensor {index + 1} ({device}): newest processed displacement, sensor frame "
            "(X right, Y forward = up), amplified by the gain shown"
        )

    def radius_px(self) -> float:
        """Radius of the faint reference circle (px)."""
        return 0.36 * min(self.width(), self.height())

    def set_sample(self, dx: float, dy: float, speed: float, peak: float) -> None:
        """Show displacement ``dx, dy`` (m), ``speed`` (m/s); ``peak`` (m) sets the auto gain."""
        self.dx, self.dy, self.speed = float(dx), float(dy), float(speed)
        if self.gain_setting is None:
            self.gain = auto_gain(peak, self.radius_px())
        else:
            self.gain = self.gain_setting
        self.update()

    def set_stale(self, text: str) -> None:
        """``text`` (why the values are old) hides the arrow and replaces the speed; ""
        shows them again."""
        if text != self.stale_text:
            self.stale_text = text
            self.update()

    def vector_px(self) -> tuple[float, float]:
        """The drawn arrow (px): (dx, dy) times the gain, sensor frame (X right, Y up)."""
        return self.dx * self.gain, self.dy * self.gain

    def paintEvent(self, _event) -> None:  # noqa: N802 - Qt API
        p = QPainter(self)
        p.drawPixmap(0, 0, self._dial())
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        w, h = self.width(), self.height()
        cx, cy, r = w / 2, h / 2 + 4, self.radius_px()
        bold, small = self._fonts()
        right = Qt.AlignmentFlag.AlignRight
        small_line = QFontMetricsF(small).height()
        if self.stale_text:  # no arrow: an old displacement must not look like motion
            _text(p, bold, STALE_COLOUR, QRectF(4, 2, w - 8, QFontMetricsF(bold).height()),
                  right, "– mm/s")
            _text(p, small, STALE_COLOUR, QRectF(4, cy + r + 2, w - 8, 2 * small_line),
                  Qt.AlignmentFlag.AlignHCenter | Qt.TextFlag.TextWordWrap, self.stale_text)
            p.end()
            return
        vx, vy = self.vector_px()
        length = math.hypot(vx, vy)
        if length > r > 0:  # a long reply's arrow stops at the circle (the gain fits speed)
            vx, vy = vx * r / length, vy * r / length
        self._draw_arrow(p, cx, cy, vx, vy)
        _text(p, bold, "#202020", QRectF(4, 2, w - 8, QFontMetricsF(bold).height()), right,
              f"{self.speed * 1e3:.1f} mm/s")
        mode = "auto" if self.gain_setting is None else "fixed"
        _text(p, small, "#606060", QRectF(4, h - small_line - 2, w - 8, small_line), right,
              f"gain ×{self.gain / 1e3:g} px/mm ({mode})")
        p.end()

    def _fonts(self) -> tuple[QFont, QFont]:
        """(bold, small): the title's font and the labels' font."""
        bold = QFont(self.font())
        bold.setBold(True)
        small = QFont(self.font())
        small.setPointSizeF(max(6.0, small.pointSizeF() * 0.85))
        return bold, small

    def _dial(self) -> QPixmap:
        """What does not change between samples (background, circle, axes, their labels,
        the sensor's name), drawn once per size: a repaint at 30 Hz only copies it."""
        ratio = self.devicePixelRatioF()
        key = (self.width(), self.height(), ratio, self.font().key())
        if self._dial_cache is not None and self._dial_cache[0] == key:
            return self._dial_cache[1]
        pix = QPixmap(round(self.width() * ratio), round(self.height() * ratio))
        pix.setDevicePixelRatio(ratio)
        pix.fill(Qt.GlobalColor.white)
        p = QPainter(pix)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        w, h = self.width(), self.height()
        cx, cy, r = w / 2, h / 2 + 4, self.radius_px()
        p.setPen(QPen(QColor("#d0d0d0"), 1))
        p.drawEllipse(QPointF(cx, cy), r, r)
        p.drawLine(QPointF(cx - r, cy), QPointF(cx + r, cy))
        p.drawLine(QPointF(cx, cy - r), QPointF(cx, cy + r))
        bold, small = self._fonts()
        p.setFont(small)
        p.setPen(QColor("#909090"))
        p.drawText(QPointF(cx + r + 3, cy + 4), "X")
        p.drawText(QPointF(cx - 4, cy - r - 3), "Y")
        left = Qt.AlignmentFlag.AlignLeft
        line = QFontMetricsF(bold).height()
        _text(p, bold, "#202020", QRectF(4, 2, w - 8, line), left, f"sensor {self.index + 1}")
        _text(p, small, "#606060", QRectF(4, 2 + line, w - 8, QFontMetricsF(small).height()),
              left, self.device)
        p.end()
        self._dial_cache = (key, pix)
        return pix

    def _draw_arrow(self, p: QPainter, cx: float, cy: float, vx: float, vy: float) -> None:
        length = math.hypot(vx, vy)
        if not length >= 0.5:  # also NaN
            p.setBrush(self.colour)
            p.setPen(Qt.PenStyle.NoPen)
            p.drawEllipse(QPointF(cx, cy), 2.5, 2.5)
            return
        tip = QPointF(cx + vx, cy - vy)  # screen y grows downwards
        p.setPen(QPen(self.colour, 2.5, Qt.PenStyle.SolidLine, Qt.PenCapStyle.RoundCap))
        p.drawLine(QPointF(cx, cy), tip)
        head = min(10.0, 0.4 * length)
        a = math.atan2(-vy, vx)
        left = QPointF(tip.x() - head * math.cos(a - 0.45), tip.y() - head * math.sin(a - 0.45))
        right = QPointF(tip.x() - head * math.cos(a + 0.45), tip.y() - head * math.sin(a + 0.45))
        p.setBrush(self.colour)
        p.drawPolygon(QPolygonF([tip, left, right]))


class DirectionPanel(QWidget):
    """A gain choice and one :class:`DirectionWidget` per sensor (built when the devices
    are known). :meth:`refresh` repaints only when the history changed."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.widgets: list[DirectionWidget] = []
        self._seen: tuple | None = None
        self.gain_box = QComboBox()
        self.gain_box.addItem("auto", None)
        for g in GAINS_PX_PER_MM:
            self.gain_box.addItem(f"×{g:g} px/mm", g * 1e3)
        self.gain_box.setToolTip("arrow length per millimetre of displacement (auto: fits "
                                 "the largest displacement of the last samples)")
        self.gain_box.currentIndexChanged.connect(self._on_gain)
        top = QHBoxLayout()
        top.addWidget(QLabel("Gain"))
        top.addWidget(self.gain_box, 1)
        self.waiting = QLabel("waiting for the sensors…")
        self.waiting.setStyleSheet("color: #777777")
        self.box = QVBoxLayout()
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addLayout(top)
        lay.addWidget(self.waiting)
        lay.addLayout(self.box, 1)
        ctx.devices_known.connect(self._ensure_widgets)
        ctx.session_reset.connect(self._invalidate)
        ctx.data_state_changed.connect(self._show_stale)
        self._ensure_widgets()

    def stale_text(self) -> str:
        """What the dials say instead of a value ("" while the values are live)."""
        return stale_text(self.ctx)

    def _show_stale(self, *_args) -> None:
        text = self.stale_text()
        for w in self.widgets:
            w.set_stale(text)

    def _ensure_widgets(self, *_args) -> None:
        devices = self.ctx.session.devices
        for k in range(len(self.widgets), len(devices)):
            w = DirectionWidget(k, devices[k], self)
            w.gain_setting = self.gain_box.currentData()
            w.set_stale(self.stale_text())
            self.box.addWidget(w, 1)
            w.show()  # the layout would only show it from the event loop
            self.widgets.append(w)
            self._seen = None
        self.waiting.setVisible(not self.widgets)

    def _invalidate(self) -> None:
        self._seen = None

    def _on_gain(self, _index: int) -> None:
        for w in self.widgets:
            w.gain_setting = self.gain_box.currentData()
        self._seen = None
        self.refresh()

    def refresh(self) -> None:
        """Show the newest row of every sensor; nothing to do when the history is unchanged."""
        hist = self.ctx.session.history
        key = (id(hist), hist.version) if hist is not None else None
        if key == self._seen:
            return
        self._seen = key
        self._ensure_widgets()
        if hist is None:
            return
        tail = hist.tail(TAIL_ROWS)
        for k, w in enumerate(self.widgets):
            if not len(tail):
                w.set_sample(0.0, 0.0, 0.0, 0.0)
                continue
            col = {f: tail[:, hist.index[f"s{k}_{f}"]] for f in ("dx", "dy", "vx", "vy")}
            peak = gain_peak(tail[:, hist.index["t"]], col["vx"], col["vy"])
            w.set_sample(col["dx"][-1], col["dy"][-1],
                         math.hypot(col["vx"][-1], col["vy"][-1]), peak)
