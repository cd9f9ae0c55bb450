"""The SparkFun OTOS's own settings from this project's calibration (issue 15 part 5).

The OTOS fuses its optical counts and gyro on the chip; it corrects them with a
linear and an angular scalar (0.872..1.127) and a mounting offset, and forgets
all three at power-off. This module turns a :class:`~mm_pc.core.calibration.Calibration`
into those values, so the node re-applies them at every start (driver options
``linear_scalar``, ``angular_scalar``, ``offset``). Frames: the OTOS's x right,
y forward, heading CCW, which is the project's sensor frame; the offset is the
sensor's position relative to the robot's turning centre. docs/sensors.md (OTOS
section) says how to measure the angular scalar.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pln2033.otos import regs

from .calibration import Calibration
from .geometry import SensorMount


@dataclass(frozen=True)
class OtosSettings:
    """What the OTOS driver writes at every start (scalars dimensionless; offset m, m, rad)."""

    linear_scalar: float
    angular_scalar: float
    offset: tuple[float, float, float]

    def driver_options(self) -> dict[str, object]:
        """The keyword options of :class:`pln2033.otos.driver.OTOS`."""
        return {
            "linear_scalar": self.linear_scalar,
            "angular_scalar": self.angular_scalar,
            "offset": self.offset,
        }


def _in_chip_range(which: str, value: float, why: str) -> float:
    problem = regs.scalar_problem(value, which)
    if problem:
        raise ValueError(f"{problem}; {why}")
    return round(value, 3)


def linear_scalar(scale_x: float, scale_y: float) -> float:
    """The one linear scalar the chip takes for the fit's per-axis scales (true / measured).

    The geometric mean: the chip scales both axes alike. ValueError when it lies outside
    the chip's range (a height or surface error beyond +-12.7 % needs a mechanical fix).
    """
    s = math.sqrt(scale_x * scale_y)
    return _in_chip_range(
        "linear",
        s,
        "the calibration's scale is beyond what the chip corrects: check the "
        "sensor's height above the floor (SparkFun: 10 mm) and the surface",
    )


def angular_scalar(true_turn_rad: float, chip_turn_rad: float) -> float:
    """The angular scalar from a spin test: the true turn (e.g. 10 turns against a mark)
    over the turn the OTOS's on-chip heading reported (both rad, same sign)."""
    if not (math.isfinite(true_turn_rad) and math.isfinite(chip_turn_rad)) or chip_turn_rad == 0:
        raise ValueError(
            f"a spin test needs finite, non-zero turns, got true {true_turn_rad!r} rad and "
            f"chip {chip_turn_rad!r} rad"
        )
    if true_turn_rad * chip_turn_rad < 0:
        raise ValueError("the chip turned the other way than the robot: check the OTOS's mounting")
    return _in_chip_range(
        "angular", true_turn_rad / chip_turn_rad, "spin at least 5 turns and measure again"
    )


def otos_settings(
    calibration: Calibration, device: str, mount: SensorMount, angular: float = 1.0
) -> OtosSettings:
    """The OTOS settings of ``device`` (configured ``mount``, base_link m/rad) under
    ``calibration``: the fitted scales as the linear scalar, the fitted position (else the
    mount's) and yaw (mount yaw + the calibration's angle) as the offset."""
    cal = calibration.get(device)
    lin = linear_scalar(*cal.scales)
    x, y = cal.position if cal.position is not None else (mount.x, mount.y)
    # base_link (x forward, y left) -> the OTOS frame (x right, y forward)
    h = math.remainder(mount.yaw + cal.angle_offset, math.tau)
    return OtosSettings(lin, _in_chip_range("angular", angular, "measure it by a spin test"),
                        (-y, x, h))  # fmt: skip


def chip_options(settings: OtosSettings) -> list[str]:
    """The node's ``chip_options`` entries for these settings (docs/beagle-node.md)."""
    x, y, h = settings.offset
    return [
        f"otos.linear_scalar={settings.linear_scalar:.3f}",
        f"otos.angular_scalar={settings.angular_scalar:.3f}",
        f"otos.offset={x:.4f},{y:.4f},{h:.4f}",
    ]


def _floats(text: str, n: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be {n} comma-separated numbers, got {text!r}")
    return values


def main(argv: list[str] | None = None) -> int:
    """``mm-otos-settings CALIBRATION --device DEV --mount X,Y,YAW [--spin TRUE,CHIP]``:
    print the node's chip_options for the OTOS; exit 2 naming what is wrong."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(
        prog="mm-otos-settings",
        description="The OTOS's linear/angular scalars and offset from a calibration file, as "
        "the mm-beagle chip_options that re-apply them at every start.",
    )
    ap.add_argument("calibration", help="calibration YAML (the monitor's wizard writes it)")
    ap.add_argument("--device", required=True, help="the OTOS's device id, e.g. /dev/i2c-2")
    ap.add_argument("--mount", default="0,0,0", help="configured mount x,y,yaw (base_link m, rad)")
    ap.add_argument("--spin", help="spin test: true turn,chip turn (rad) for the angular scalar")
    args = ap.parse_args(argv)
    try:
        mount = SensorMount(*_floats(args.mount, 3, "--mount"))
        angular = angular_scalar(*_floats(args.spin, 2, "--spin")) if args.spin else 1.0
        settings = otos_settings(Calibration.load(args.calibration), args.device, mount, angular)
    except (OSError, ValueError) as exc:
        print(f"mm-otos-settings: {exc}", file=sys.stderr)
        return 2
    print("chip_options:")
    for line in chip_options(settings):
        print(f'  - "{line}"')
    return 0
