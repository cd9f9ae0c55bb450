"""SparkFun Optical Tracking Odometry Sensor (OTOS) register facts, as data.

Sources (read for facts; no code copied):

- [lib]  sparkfun/SparkFun_Qwiic_OTOS_Arduino_Library, src/sfTk/sfDevOTOS.h and .cpp
         (register map, product id, scalar encoding and range, pose units, status bits).
- [py]   sparkfun/qwiic_otos_py, qwiic_otos.py (the same map; rounds the scalar, where the
         Arduino library truncates).
- [fw]   sparkfun/SparkFun_Optical_Tracking_Odometry_Sensor, Firmware/SFE/Inc/registers.h,
         Src/registers.cpp, Src/main.cpp, Inc/otosConstants.h, Src/pose2d.cpp,
         Core/Src/stm32c0xx_it.c (the firmware 1.0 itself: 96-byte register buffer, auto
         increment, raw PAA5160/LSM6DSO copies at 0x44..0x5B, when host writes take effect).
- [hw]   the same repository, docs/hardware_overview.md (2.5 m/s tracking speed, 20 000 DPI,
         IO9 "data ready").

docs/sensors.md (OTOS section) tells the story; every constant below names its source.
"""

from __future__ import annotations

import math

ADDRESS = 0x17  # [lib] kDefaultAddress; no address register (0x03 commented out [fw])
PRODUCT_ID = 0x5F  # [lib] kProductId, [fw] kOtosProdID
REGISTER_COUNT = 96  # [fw] kNumRegisters: reads past 0x5F return 0

# --- register addresses [lib] sfDevOTOS.h, [fw] registers.h -------------------------------
PRODUCT_ID_REG = 0x00
HW_VERSION = 0x01  # high nibble major, low nibble minor; firmware 1.0 reports hw 1.1 [fw]
FW_VERSION = 0x02  # firmware 1.0 [fw]
SCALAR_LINEAR = 0x04  # int8, scale = 1 + value * 0.001 [lib]
SCALAR_ANGULAR = 0x05
IMU_CALIB = 0x06  # write N samples (2.4 ms each); reads the samples still to take, 0 = done
RESET = 0x07  # bit 0: reset tracking; the firmware clears it when done [fw]
SIGNAL_PROCESS = 0x0E  # bits: enLut, enAcc, enRot, enVar (all set at power-up [fw])
SELF_TEST = 0x0F  # bits: start, inProgress, pass, fail
OFFSET = 0x10  # x, y, h: int16 little endian each (0x10..0x15)
STATUS = 0x1F
POSITION = 0x20  # x, y, h (0x20..0x25)
VELOCITY = 0x26  # (0x26..0x2B)
ACCELERATION = 0x2C  # (0x2C..0x31)
POSITION_STD = 0x32  # std devs: position, velocity, acceleration (0x32..0x43)
VELOCITY_STD = 0x38
ACCELERATION_STD = 0x3E
LSM_RAW = 0x44  # [fw] raw LSM6DSO gyro x,y,z then accel x,y,z (0x44..0x4F), int16 LE
PAA_BURST = 0x50  # [fw] the PAA5160's 12-byte motion burst of the latest update (0x50..0x5B)
PAA_BURST_LEN = 12

# --- status register bits [lib] sfe_otos_status_t, [fw] registers.h ----------------------------
STATUS_WARN_TILT = 0x01  # tilt above 0.2 rad: accelerometer ignored [fw main.cpp]
STATUS_WARN_OPTICAL = 0x02  # optical tracking unreliable: IMU only [lib]
STATUS_ERROR_PAA = 0x40  # the optical chip failed (sticky until power-off) [fw]
STATUS_ERROR_LSM = 0x80  # the IMU failed (sticky) [fw]

RESET_TRACKING = 0x01  # [lib] resetTracking writes 0x01 to RESET
SELF_TEST_START = 0x01
SELF_TEST_IN_PROGRESS = 0x02
SELF_TEST_PASS = 0x04
SELF_TEST_FAIL = 0x08
SIGNAL_PROCESS_DEFAULT = 0x0F  # [fw] resetRegisters: enLut | enAcc | enRot | enVar
SP_LUT = 0x01  # [fw] main.cpp: the velocity lookup table corrects the PAA5160's resolution
SP_ACC = 0x02  # accelerometer updates, and the optical-rejection rule (the warning bit)
SP_ROT = 0x04  # optical velocity and acceleration turned into the world frame by the heading
SP_VAR = 0x08  # measurement variances on (0: the linear filters take each measurement as exact)

# --- the firmware's optical-rejection rule [fw] main.cpp sensorUpdate --------------------------
REJECT_MEASURED_MPS = 0.25  # |vx| + |vy| measured below this ...
REJECT_ESTIMATED_MPS = 0.5  # ... while the filters' |vx| + |vy| is above this: warning, IMU only
LUT_LIMIT_IPS = 100  # [fw] otosLut.h: the table spans -100..100 in/s per axis, 1.0 outside

# --- units of the int16 pose registers [lib] sfDevOTOS.h, [fw] otosConstants.h -------------------
POS_M_PER_LSB = 10.0 / 32768  # +-10 m full scale: 0.305 mm per LSB
HEADING_RAD_PER_LSB = math.pi / 32768  # +-pi rad
VEL_MPS_PER_LSB = 5.0 / 32768
VEL_RPS_PER_LSB = math.radians(2000.0) / 32768  # +-2000 deg/s
ACC_MPSS_PER_LSB = 16.0 * 9.80665 / 32768  # +-16 g
ACC_RPSS_PER_LSB = math.pi * 1000.0 / 32768
#: one LSB of each word of the pose block (position, velocity, acceleration; x, y, heading),
#: in register order; the std-dev block that follows repeats it
POSE_BLOCK_LSB = (
    POS_M_PER_LSB,
    POS_M_PER_LSB,
    HEADING_RAD_PER_LSB,
    VEL_MPS_PER_LSB,
    VEL_MPS_PER_LSB,
    VEL_RPS_PER_LSB,
    ACC_MPSS_PER_LSB,
    ACC_MPSS_PER_LSB,
    ACC_RPSS_PER_LSB,
)

# --- scalars [lib] kMinScalar/kMaxScalar, setLinearScalar ----------------------------------
SCALAR_MIN = 0.872  # int8 -128
SCALAR_MAX = 1.127  # int8 +127
SCALAR_STEP = 0.001

# --- timing [lib] calibrateImu, selfTest; [fw] main.cpp --------------------------------------
IMU_SAMPLE_S = 0.0024  # one IMU sample at 416 Hz: also the firmware's update period
IMU_SAMPLES_MAX = 255
POWER_UP_IMU_SAMPLES = 64  # the firmware's quick calibration at power-up, after 100 ms
UPDATE_HZ = 416  # [fw] LSM6DSO data rate; every update rewrites 0x20..0x5B

# --- the PAA5160 inside [fw] sfePaa5160.h/.cpp, main.cpp; [hw] -------------------------------
PAA_CPI = 20_000  # the firmware sets the PAA5160 to its maximum, 20 000 DPI
PAA_BURST_DX = 2  # delta X low byte in the burst (then high), delta Y at 4, 5 [fw main.cpp]
PAA_BURST_DY = 4
MAX_SPEED_MPS = 2.5  # [hw] hardware_overview.md: PAA5160E1 tracking speed 2.5 m/s

#: The register dump for the Registers view: (name, address, bytes), the chip's order.
#: Two-byte entries are int16 little endian shown as their 16-bit pattern.
DUMP: tuple[tuple[str, int, int], ...] = (
    ("product_id", PRODUCT_ID_REG, 1),
    ("hw_version", HW_VERSION, 1),
    ("fw_version", FW_VERSION, 1),
    ("scalar_linear", SCALAR_LINEAR, 1),
    ("scalar_angular", SCALAR_ANGULAR, 1),
    ("imu_calib", IMU_CALIB, 1),
    ("reset", RESET, 1),
    ("signal_process", SIGNAL_PROCESS, 1),
    ("self_test", SELF_TEST, 1),
    ("offset_x", OFFSET, 2),
    ("offset_y", OFFSET + 2, 2),
    ("offset_h", OFFSET + 4, 2),
    ("status", STATUS, 1),
    ("pos_x", POSITION, 2),
    ("pos_y", POSITION + 2, 2),
    ("pos_h", POSITION + 4, 2),
    ("vel_x", VELOCITY, 2),
    ("vel_y", VELOCITY + 2, 2),
    ("vel_h", VELOCITY + 4, 2),
    ("acc_x", ACCELERATION, 2),
    ("acc_y", ACCELERATION + 2, 2),
    ("acc_h", ACCELERATION + 4, 2),
    ("pos_std_x", POSITION_STD, 2),
    ("pos_std_y", POSITION_STD + 2, 2),
    ("pos_std_h", POSITION_STD + 4, 2),
    ("vel_std_x", VELOCITY_STD, 2),
    ("vel_std_y", VELOCITY_STD + 2, 2),
    ("vel_std_h", VELOCITY_STD + 4, 2),
    ("acc_std_x", ACCELERATION_STD, 2),
    ("acc_std_y", ACCELERATION_STD + 2, 2),
    ("acc_std_h", ACCELERATION_STD + 4, 2),
    ("lsm_gyro_x", LSM_RAW, 2),
    ("lsm_gyro_y", LSM_RAW + 2, 2),
    ("lsm_gyro_z", LSM_RAW + 4, 2),
    ("lsm_acc_x", LSM_RAW + 6, 2),
    ("lsm_acc_y", LSM_RAW + 8, 2),
    ("lsm_acc_z", LSM_RAW + 10, 2),
    *((f"paa_burst_{i:02d}", PAA_BURST + i, 1) for i in range(PAA_BURST_LEN)),
)
DUMP_LEN = PAA_BURST + PAA_BURST_LEN  # one read of 0x00..0x5B covers the dump


def scalar_problem(value: object, which: str) -> str | None:
    """Why ``value`` cannot be the OTOS's ``which`` ("linear"/"angular") scalar, or None."""
    allowed = (
        f"the OTOS accepts {SCALAR_MIN}..{SCALAR_MAX} in steps of {SCALAR_STEP} "
        f"(int8 register, scale = 1 + value * {SCALAR_STEP})"
    )
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{which} scalar must be a number, got {value!r}: {allowed}"
    if not math.isfinite(value) or not SCALAR_MIN <= value <= SCALAR_MAX:
        return f"{which} scalar {value} is out of range: {allowed}"
    return None


def encode_scalar(value: float) -> int:
    """A scalar (0.872..1.127) as its register byte: round((s - 1) / 0.001) as int8 [py]."""
    raw = max(-128, min(127, round((value - 1.0) / SCALAR_STEP)))
    return raw & 0xFF


def decode_scalar(byte: int) -> float:
    """The register byte as a scalar: 1 + int8 * 0.001 [lib]."""
    raw = byte - 0x100 if byte & 0x80 else byte
    return round(1.0 + raw * SCALAR_STEP, 3)


def signed16(lo: int, hi: int) -> int:
    value = lo | (hi << 8)
    return value - 0x10000 if value & 0x8000 else value


def int16_bytes(value: int) -> tuple[int, int]:
    """``value`` wrapped into int16, as (low, high) bytes (the registers are little endian)."""
    value &= 0xFFFF
    return value & 0xFF, value >> 8

