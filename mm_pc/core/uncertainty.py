"""How uncertain the mouse odometry is: a random-walk model for the covariance.

Pure math, no ROS. The seed reports a spread of 1-2 cm over 100 cm for these
sensors; so position variance grows linearly with the distance travelled
(random walk): var += Q_POS * |ds| per interval, Q_POS = (0.015 m)^2 per m.
Heading variance grows with the distance and the angle turned:
var_yaw += Q_YAW_DIST * |ds| + Q_YAW_TURN * |dtheta|. These are stated
defaults, not measurements on real hardware; a user with a test drive should
set their own (parameters of mm-odometry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Variance (m^2, rad^2) put on z, roll and pitch, which a planar robot does not observe
#: (the usual convention for 2-D odometry).
UNOBSERVED_VARIANCE = 1e6

Q_POS = 0.015**2  # m^2 per m travelled
Q_YAW_DIST = 0.01**2  # rad^2 per m travelled
Q_YAW_TURN = 0.01**2  # rad^2 per rad turned


@dataclass
class PoseUncertainty:
    """Accumulated pose variances (x, y in m^2 in odom; yaw in rad^2)."""

    q_pos: float = Q_POS
    q_yaw_dist: float = Q_YAW_DIST
    q_yaw_turn: float = Q_YAW_TURN
    var_along: float = field(default=0.0, init=False)
    var_yaw: float = field(default=0.0, init=False)

    def __post_init__(self) -> None:
        for name in ("q_pos", "q_yaw_dist", "q_yaw_turn"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")

    def add(self, distance: float, turned: float) -> None:
        """One interval: ``distance`` m travelled (any sign), ``turned`` rad."""
        self.var_along += self.q_pos * abs(distance)
        self.var_yaw += self.q_yaw_dist * abs(distance) + self.q_yaw_turn * abs(turned)

    def reset(self) -> None:
        self.var_along = self.var_yaw = 0.0

    def pose_covariance(self) -> list[float]:
        """Row-major 6x6 (x, y, z, roll, pitch, yaw) for nav_msgs/Odometry.

        z, roll and pitch are not observed by a planar robot: a large variance
        (1e6) says so, the usual convention for 2-D odometry.
        """
        return planar_covariance_6x6(np.diag([self.var_along, self.var_along, self.var_yaw]))


def twist_covariance(cpi: float, dt: float) -> list[float]:
    """Row-major 6x6 for the twist: one count of quantisation per interval.

    A count is 0.0254/cpi m; over an interval dt its velocity uncertainty is
    about that / dt (uniform quantisation: std = step/sqrt(12)).
    """
    if not (cpi > 0 and dt > 0):
        raise ValueError(f"cpi and dt must be > 0, got cpi={cpi}, dt={dt}")
    step = 0.0254 / cpi / dt
    var_v = step * step / 12.0
    # omega from a sensor about 5 cm off the axle
    return planar_covariance_6x6(np.diag([var_v, var_v, var_v / 0.05**2]))


def planar_covariance_6x6(p3) -> list[float]:
    """Row-major 6x6 (x, y, z, roll, pitch, yaw) of ROS messages from the 3x3 of (x, y, yaw).

    The one place that knows the layout: z, roll and pitch get :data:`UNOBSERVED_VARIANCE`.
    """
    p = np.asarray(p3, dtype=float)
    if p.shape != (3, 3):
        raise ValueError(f"a planar covariance is 3x3 (x, y, yaw), got shape {p.shape}")
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = p
    c[2, 2] = c[3, 3] = c[4, 4] = UNOBSERVED_VARIANCE
    return c.reshape(-1).tolist()
