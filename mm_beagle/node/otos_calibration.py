"""The OTOS's own settings from this project's calibration file, for the node (issue 15 5c).

The node side (it uses mm_pc.core, numpy): the board's agent takes the settings as plain
``--chip-options`` instead.
"""

from __future__ import annotations


def otos_options(
    devices: list[str], chips: list[str], calibration_file: str, mounts_flat: list[float]
) -> dict[str, dict[str, object]]:
    """Each OTOS's linear scalar and offset from ``calibration_file`` (issue 15 part 5c):
    the chip forgets them at power-off, so the driver writes them at every start.

    The fitted per-axis scales give the linear scalar, the fitted position (else the
    ``mounts`` entry) and yaw the offset (``mm_pc.core.otos_settings``); the angular scalar
    stays 1 (a spin test measures it: ``chip_options`` ``otos.angular_scalar=...``). No
    calibration file or no OTOS: nothing. ValueError (exit 2) for a fit beyond the chip's
    range or missing mounts."""
    if not calibration_file or "otos" not in chips:
        return {}
    from mm_pc.core.calibration import Calibration
    from mm_pc.core.geometry import SensorMount
    from mm_pc.core.otos_settings import otos_settings

    if len(mounts_flat) != 3 * len(devices):
        raise ValueError(
            f"'mounts' needs x, y, yaw for each of the {len(devices)} devices to place the "
            f"OTOS from calibration_file, got {len(mounts_flat)} numbers"
        )
    cal = Calibration.load(calibration_file)
    out = {}
    for i, (dev, chip) in enumerate(zip(devices, chips, strict=True)):
        if chip == "otos":
            mount = SensorMount(*mounts_flat[3 * i : 3 * i + 3])
            try:
                out[dev] = otos_settings(cal, dev, mount).driver_options()
            except ValueError as exc:
                raise ValueError(f"calibration_file {calibration_file}, {dev}: {exc}") from None
    return out
