"""SparkFun Optical Tracking Odometry Sensor (OTOS): driver, emulator, register facts."""

from .driver import EFFECTIVE_CPI, OTOS, OTOS_INFO, InvalidSettingError, Pose, PoseReading
from .emulator import ConstantYawRate, EmulatedOTOS, NoRotation

__all__ = [
    "EFFECTIVE_CPI",
    "OTOS",
    "OTOS_INFO",
    "ConstantYawRate",
    "EmulatedOTOS",
    "InvalidSettingError",
    "NoRotation",
    "Pose",
    "PoseReading",
]
