"""The OTOS firmware's per-axis Kalman filter, as a model (state: position, velocity, acceleration).

Written from the equations of firmware 1.0 (sparkfun/SparkFun_Optical_Tracking_Odometry_Sensor,
Firmware/SFE/Src/otosKalmanFilter.cpp; no code copied): constant-acceleration prediction
with the firmware's first-order covariance step (the dt^2 terms dropped, as there), scalar
updates of the velocity or the acceleration (the covariance updated in place in the
firmware's loop order, so the rows below the measured state see its updated row), the
process noise diagonal per axis (:data:`Q_LINEAR`, :data:`Q_HEADING`) and the measurement
variances the firmware passes (:data:`R_VEL`, :data:`R_ACC`, :data:`R_GYRO`; the two
linear ones times the ``enVar`` bit).
Units: m, m/s, m/s^2 (heading: rad, rad/s, rad/s^2); variances in those units squared.
"""

from __future__ import annotations

Q_LINEAR = (1e-8, 1e-6, 1e-4)  # main.cpp xKf, yKf
Q_HEADING = (1e-10, 1e-7, 1e-1)  # main.cpp hKf
R_VEL = 6e-3  # optical velocity update, times enVar
R_ACC = 9e-4  # accelerometer update, times enVar
R_GYRO = 1e-3  # gyro rate update of the heading filter (always)


class AxisFilter:
    """One axis: ``x`` = [position, velocity, acceleration], ``p`` its 3x3 covariance."""

    def __init__(self, q: tuple[float, float, float]) -> None:
        self.q = q
        self.reset()

    def reset(self) -> None:
        """otosKalmanFilter::reset: state and covariance zero."""
        self.x = [0.0, 0.0, 0.0]
        self.p = [[0.0] * 3 for _ in range(3)]

    def predict(self, dt: float) -> None:
        x, p, q = self.x, self.p, self.q
        x[0] += x[1] * dt
        x[1] += x[2] * dt
        # F P F' + Q without the dt^2 terms, element by element in the firmware's order
        p[0][0] += (p[0][1] + p[1][0]) * dt + q[0]
        p[0][1] += (p[0][2] + p[1][1]) * dt
        p[0][2] += p[1][2] * dt
        p[1][0] += (p[1][1] + p[2][0]) * dt
        p[1][1] += (p[1][2] + p[2][1]) * dt + q[1]
        p[1][2] += p[2][2] * dt
        p[2][0] += p[2][1] * dt
        p[2][1] += p[2][2] * dt
        p[2][2] += q[2]

    def update(self, measurement: float, variance: float, idx: int) -> None:
        """A scalar measurement of state ``idx`` (1 velocity, 2 acceleration)."""
        x, p = self.x, self.p
        s = p[idx][idx] + variance
        if s <= 0.0:  # the firmware would divide by zero (enVar 0 on a fresh filter)
            return
        k = [p[0][idx] / s, p[1][idx] / s, p[2][idx] / s]
        y = measurement - x[idx]
        for i in range(3):
            x[i] += k[i] * y
        # in place, in the firmware's loop order: the rows after ``idx`` see its updated row
        for i in range(3):
            for j in range(3):
                p[i][j] -= p[idx][j] * k[i]
