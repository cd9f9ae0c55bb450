"""Calibration from a straight run (mm_pc.core.calibration).

Sign convention under test: a sensor mounted with yaw error psi reports the
ideal vector turned by -psi (pln2033.motion.Rotated, SensorMount.yaw); the
seed's formula then gives angle_offset = psi, and apply() turns by +psi.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.angles import wrap_pi as normalize_angle
from mm_pc.core.calibration import (
    Calibration,
    SensorCalibration,
    calibrate_straight_run,
)
from mm_pc.core.frames import counts_to_m, m_to_counts
from mm_pc.core.geometry import SensorMount
from mm_pc.sim.robot import figure_eight, sensor_displacements, straight

CPI = 1600
DT = 0.001
S1 = "/dev/spidev1.0"
S2 = "/dev/spidev1.1"


def angle_diff(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


def quantised_run_sum(dx: np.ndarray, dy: np.ndarray, cpi: int = CPI) -> tuple[float, float]:
    """Summed counts of a run read as whole counts (floor of the cumulative position,
    as the emulator does), back in metres."""
    cx = np.floor(m_to_counts(np.concatenate([[0.0], np.cumsum(dx)]), cpi))
    cy = np.floor(m_to_counts(np.concatenate([[0.0], np.cumsum(dy)]), cpi))
    counts_x = np.diff(cx).astype(np.int64)
    counts_y = np.diff(cy).astype(np.int64)
    return float(counts_to_m(counts_x.sum(), cpi)), float(counts_to_m(counts_y.sum(), cpi))


def simulated_run(psi: float, distance: float, speed: float, mount_xy=(0.049, -0.0395)):
    v, omega = straight(speed=speed, distance=distance, dt=DT)
    mount = SensorMount(mount_xy[0], mount_xy[1], psi)
    return sensor_displacements(v, omega, DT, mount)


# --- the seed's formula, sign convention ---------------------------------------------


@given(
    psi_deg=st.floats(min_value=-44.999, max_value=44.999),
    distance=st.floats(min_value=0.2, max_value=5.0),
    backward=st.booleans(),
)
@settings(max_examples=40, deadline=None)
def test_recovers_mounting_angle_with_cpi_quantisation(psi_deg, distance, backward):
    psi = math.radians(psi_deg)
    speed = -0.5 if backward else 0.5
    dx, dy = simulated_run(psi, distance, speed)
    x, y = quantised_run_sum(dx, dy)
    cal = calibrate_straight_run(x, y)
    assert math.degrees(angle_diff(cal.angle_offset, psi)) < 0.05
    # The simulator drives whole 1 ms steps, so compare with the distance it drove.
    driven = math.hypot(dx.sum(), dy.sum())
    assert driven == pytest.approx(distance, abs=abs(speed) * DT)
    assert cal.distance == pytest.approx(driven, abs=3 * 0.0254 / CPI)
    assert cal.scale == 1.0
    # The corrected run points straight ahead (or back).
    cx, cy = cal.apply(x, y)
    assert abs(cx) < 1e-3 * distance
    assert math.copysign(1.0, cy) == math.copysign(1.0, speed)


def test_five_degree_goal():
    psi = math.radians(5.0)
    x, y = quantised_run_sum(*simulated_run(psi, 1.0, 0.2))
    cal = calibrate_straight_run(x, y)
    assert abs(cal.angle_offset_deg - 5.0) < 0.05


@pytest.mark.parametrize("psi_deg", [-30.0, -5.0, 0.0, 5.0, 30.0])
@pytest.mark.parametrize("backward", [False, True])
def test_offset_equals_mounting_yaw_exactly_without_quantisation(psi_deg, backward):
    psi = math.radians(psi_deg)
    dx, dy = simulated_run(psi, 1.0, -0.2 if backward else 0.2)
    cal = calibrate_straight_run(dx.sum(), dy.sum())
    assert cal.angle_offset == pytest.approx(psi, abs=1e-9)
    assert cal.distance == pytest.approx(1.0)


def test_seed_formula_by_hand():
    # Forward run reported with +X (axes turned CCW): offset is positive.
    cal = calibrate_straight_run(math.sin(0.2), math.cos(0.2))
    assert cal.angle_offset == pytest.approx(0.2)
    # Backward: both components flip, atan_real = -pi/2, same offset.
    cal = calibrate_straight_run(-math.sin(0.2), -math.cos(0.2))
    assert cal.angle_offset == pytest.approx(0.2)
    # A perfectly mounted sensor.
    assert calibrate_straight_run(0.0, 0.3).angle_offset == 0.0
    assert calibrate_straight_run(0.0, -0.3).angle_offset == 0.0


@given(st.floats(min_value=-math.radians(80), max_value=math.radians(80)))
def test_calibration_undoes_the_mounting_error_on_any_path(psi):
    """Calibrated on a straight run, the sensor then reports what an ideal one would,
    also while turning (figure eight)."""
    mount_xy = (0.049, 0.0395)
    dx, dy = simulated_run(psi, 0.5, 0.3, mount_xy)
    cal = calibrate_straight_run(dx.sum(), dy.sum())
    v, omega = figure_eight(speed=0.3, radius=0.3, dt=0.01)
    mx, my = sensor_displacements(v, omega, 0.01, SensorMount(*mount_xy, psi))
    ix, iy = sensor_displacements(v, omega, 0.01, SensorMount(*mount_xy, 0.0))
    cx, cy = cal.apply(mx, my)
    np.testing.assert_allclose(cx, ix, atol=1e-12)
    np.testing.assert_allclose(cy, iy, atol=1e-12)


# --- the rotation: both components from the unrotated vector --------------------------


def original_rotation(angle: float, x: float, y: float) -> tuple[float, float]:
    """The original C++ (seed, Kalibrierung): y' uses the already-rotated x'."""
    x = math.cos(angle) * x + (-math.sin(angle) * y)
    y = math.sin(angle) * x + math.cos(angle) * y
    return x, y


def test_original_rotation_was_wrong_ours_round_trips():
    psi = math.radians(10.0)
    ideal = (0.01, 0.02)  # a sample with both components
    reported = (
        math.cos(psi) * ideal[0] + math.sin(psi) * ideal[1],
        -math.sin(psi) * ideal[0] + math.cos(psi) * ideal[1],
    )
    cal = SensorCalibration(psi)
    ours = cal.apply(*reported)
    assert ours == pytest.approx(ideal, abs=1e-15)
    theirs = original_rotation(psi, *reported)
    assert theirs[0] == pytest.approx(ideal[0], abs=1e-15)  # x' was right ...
    assert abs(theirs[1] - ideal[1]) > 1e-4  # ... y' was not
    # The original does not even preserve the length.
    assert math.hypot(*theirs) != pytest.approx(math.hypot(*ideal), rel=1e-6)
    assert math.hypot(*ours) == pytest.approx(math.hypot(*ideal), rel=1e-12)


@given(
    st.floats(min_value=-math.pi, max_value=math.pi, exclude_min=True),
    st.floats(min_value=-1.0, max_value=1.0),
    st.floats(min_value=-1.0, max_value=1.0),
)
def test_apply_round_trips_any_vector(psi, x, y):
    # Report (x, y) through a mount turned by psi, correct with offset psi: back to (x, y).
    rx = math.cos(psi) * x + math.sin(psi) * y
    ry = -math.sin(psi) * x + math.cos(psi) * y
    got = SensorCalibration(psi).apply(rx, ry)
    assert got == pytest.approx((x, y), abs=1e-12)


def test_apply_is_vectorised_and_keeps_shape():
    cal = SensorCalibration(0.3, 1.0, 1.5)
    x = np.linspace(-1, 1, 12).reshape(3, 4)
    y = np.linspace(2, -2, 12).reshape(3, 4)
    ax, ay = cal.apply(x, y)
    assert ax.shape == ay.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            sx, sy = cal.apply(float(x[i, j]), float(y[i, j]))
            assert ax[i, j] == pytest.approx(sx) and ay[i, j] == pytest.approx(sy)
    assert isinstance(cal.apply(1, 2)[0], float)
    # Integer count arrays work too.
    ix, iy = cal.apply(np.array([3, 4]), np.array([5, 6]))
    assert ix.dtype == float and iy.dtype == float


# --- scale factor ------------------------------------------------------------------------


def test_scale_factor_from_true_distance():
    # The sensor really runs at 1600 CPI but the monitor assumes 1700: the run measures short.
    dx, dy = simulated_run(math.radians(3.0), 1.0, 0.2)
    cx = np.floor(m_to_counts(np.cumsum(dx), CPI))[-1]
    cy = np.floor(m_to_counts(np.cumsum(dy), CPI))[-1]
    x, y = float(counts_to_m(cx, 1700)), float(counts_to_m(cy, 1700))
    cal = calibrate_straight_run(x, y, true_distance=1.0)
    assert cal.distance == pytest.approx(1600 / 1700, rel=1e-4)
    assert cal.scale == pytest.approx(1700 / 1600, rel=1e-4)
    ax, ay = cal.apply(x, y)
    assert math.hypot(ax, ay) == pytest.approx(1.0, rel=1e-12)
    assert ax == pytest.approx(0.0, abs=1e-4)
    assert abs(cal.angle_offset_deg - 3.0) < 0.05


def test_scale_default_is_one():
    assert calibrate_straight_run(0.01, 0.5).scale == 1.0


@pytest.mark.parametrize("true_distance", [0.0, -1.0, float("nan"), float("inf"), "1 m", True])
def test_bad_true_distance(true_distance):
    with pytest.raises(ValueError, match="true distance"):
        calibrate_straight_run(0.01, 0.5, true_distance=true_distance)


# --- bad runs -------------------------------------------------------------------------------


def test_y_zero_is_an_error():
    with pytest.raises(ValueError, match=r"Y = 0.*sideways"):
        calibrate_straight_run(0.3, 0.0)
    with pytest.raises(ValueError, match="Y = 0"):
        calibrate_straight_run(-0.3, -0.0)


def test_zero_length_run_is_an_error():
    with pytest.raises(ValueError, match=r"too short: 0\.00 cm travelled, at least 5\.00 cm"):
        calibrate_straight_run(0.0, 0.0)


def test_short_run_names_distance_and_minimum():
    with pytest.raises(ValueError, match=r"4\.24 cm travelled, at least 5\.00 cm needed"):
        calibrate_straight_run(0.03, 0.03)
    # A custom minimum.
    with pytest.raises(ValueError, match=r"at least 50\.00 cm"):
        calibrate_straight_run(0.0, 0.3, min_distance=0.5)
    assert calibrate_straight_run(0.0, 0.04, min_distance=0.01).distance == pytest.approx(0.04)
    # Zero length is an error even with min_distance 0.
    with pytest.raises(ValueError, match="too short"):
        calibrate_straight_run(0.0, 0.0, min_distance=0.0)


@pytest.mark.parametrize(
    ("x", "y", "message"),
    [
        (float("nan"), 1.0, "X displacement must be finite"),
        (0.1, float("nan"), "Y displacement must be finite"),
        (float("inf"), 1.0, "X displacement must be finite"),
        (0.1, -float("inf"), "Y displacement must be finite"),
        ("0.1", 1.0, "X displacement must be a number"),
        (0.1, None, "Y displacement must be a number"),
        (0.1, True, "Y displacement must be a number"),
    ],
)
def test_non_finite_or_non_numeric_run(x, y, message):
    with pytest.raises(ValueError, match=message):
        calibrate_straight_run(x, y)


@pytest.mark.parametrize("min_distance", [-0.01, float("nan")])
def test_bad_min_distance(min_distance):
    with pytest.raises(ValueError, match="min_distance"):
        calibrate_straight_run(0.0, 1.0, min_distance=min_distance)


def test_numpy_scalars_accepted():
    cal = calibrate_straight_run(np.float64(0.0), np.int64(1))
    assert cal.distance == 1.0


# --- SensorCalibration / Calibration objects ----------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((4.0, 0.0, 1.0), r"angle_offset must be in \(-pi, pi\]"),
        ((-math.pi, 0.0, 1.0), r"angle_offset must be in \(-pi, pi\]"),
        ((0.0, -1.0, 1.0), "distance must be >= 0"),
        ((0.0, 0.0, 0.0), "scale must be > 0"),
        ((0.0, 0.0, -2.0), "scale must be > 0"),
        ((float("nan"), 0.0, 1.0), "angle_offset must be finite"),
        ((0.0, 0.0, "1"), "scale must be a number"),
    ],
)
def test_sensor_calibration_validates(args, message):
    with pytest.raises(ValueError, match=message):
        SensorCalibration(*args)


def test_pi_is_allowed_and_normalize_angle():
    assert SensorCalibration(math.pi).angle_offset == math.pi
    assert normalize_angle(-math.pi) == math.pi
    assert normalize_angle(3 * math.pi) == pytest.approx(math.pi)
    assert normalize_angle(2 * math.pi + 0.1) == pytest.approx(0.1)
    assert normalize_angle(-0.1) == -0.1


def test_identity():
    ident = SensorCalibration.identity()
    assert ident.apply(0.3, -0.2) == (0.3, -0.2)
    cal = Calibration.identity([S1, S2])
    assert set(cal) == {S1, S2} and len(cal) == 2
    assert cal[S1] == ident
    # Unknown sensors are identity too.
    assert Calibration().apply("/dev/other", 1.0, 2.0) == (1.0, 2.0)
    assert Calibration().get(S1) == ident


def test_calibration_applies_per_sensor():
    cal = Calibration({S1: SensorCalibration(math.pi / 2), S2: SensorCalibration(0.0, 0.0, 2.0)})
    assert cal.apply(S1, 1.0, 0.0) == pytest.approx((0.0, 1.0))
    assert cal.apply(S2, 1.0, 0.0) == pytest.approx((2.0, 0.0))
    assert S1 in cal and "/dev/x" not in cal
    assert cal.sensors == {S1: cal[S1], S2: cal[S2]}


@pytest.mark.parametrize("sid", ["", 3, None])
def test_calibration_rejects_bad_sensor_ids(sid):
    with pytest.raises(ValueError, match="sensor id"):
        Calibration({sid: SensorCalibration()})


def test_calibration_rejects_non_calibration_values():
    with pytest.raises(ValueError, match="expected a SensorCalibration"):
        Calibration({S1: (0.0, 1.0, 1.0)})


# --- YAML ---------------------------------------------------------------------------------

angles = st.floats(min_value=-math.pi, max_value=math.pi, exclude_min=True)
distances = st.floats(min_value=0.0, max_value=100.0)
scales = st.floats(min_value=1e-3, max_value=1e3)


@given(
    st.dictionaries(
        st.text(min_size=1, max_size=20),
        st.builds(SensorCalibration, angles, distances, scales),
        max_size=4,
    )
)
@settings(max_examples=30)
def test_yaml_round_trip(sensors):
    cal = Calibration(sensors)
    back = Calibration.from_yaml(cal.to_yaml())
    assert back == cal  # exact: floats are written with full precision


def test_yaml_layout_and_file_round_trip(tmp_path):
    run = calibrate_straight_run(0.01, 0.5, true_distance=0.49)
    cal = Calibration({S1: run, S2: SensorCalibration()})
    text = cal.to_yaml()
    assert text.startswith("version: 2\nmethod: ''\ndate: ''\nsensors:\n")
    assert "angle_offset_rad:" in text and "distance_m:" in text
    assert "scale_x:" in text and "scale_y:" in text and "x_m" not in text
    path = tmp_path / "calibration.yaml"
    cal.save(path)
    assert Calibration.load(path) == cal
    assert not (tmp_path / "calibration.yaml.tmp").exists()
    # Overwrite.
    Calibration.identity([S1]).save(path)
    assert Calibration.load(path) == Calibration.identity([S1])


def test_load_missing_file_is_os_error(tmp_path):
    with pytest.raises(OSError):
        Calibration.load(tmp_path / "nope.yaml")


def test_empty_sensors_allowed():
    assert Calibration.from_yaml("version: 1\nsensors: {}\n") == Calibration()
    assert Calibration.from_yaml("version: 1\nsensors:\n") == Calibration()


GOOD_ENTRY = "{angle_offset_rad: 0.1, distance_m: 1.0, scale: 1.0}"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "expected a mapping with 'version' and 'sensors', got NoneType"),
        ("- 1\n- 2\n", "expected a mapping .* got list"),
        ("just text", "expected a mapping .* got str"),
        ("version: 1\nsensors: {a: [1\n", "not valid YAML"),
        ("sensors: {}\n", r"missing key\(s\) \['version'\]"),
        ("version: 1\n", r"missing key\(s\) \['sensors'\]"),
        ("version: 1\nsensors: {}\nextra: 3\n", r"unknown key\(s\) \['extra'\]"),
        ("version: 3\nsensors: {}\n", r"unsupported version 3, expected one of \[1, 2\]"),
        ("version: 1\nmethod: fit\nsensors: {}\n", r"unknown key\(s\) \['method'\]"),
        ("version: 2\nmethod: guess\nsensors: {}\n", "calibration method must be one of"),
        (
            "version: 2\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1, scale: 1}}\n",
            r"calibration of /dev/a: unknown key\(s\) \['scale'\]",
        ),
        (
            "version: 2\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1, scale_x: 1, "
            "scale_y: 1, x_m: 0.05}}\n",
            "a position needs both x and y",
        ),
        (
            "version: 2\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1, scale_x: 1, "
            "scale_y: 1, x_se_m: -1}}\n",
            "x_se must be >= 0",
        ),
        ("version: true\nsensors: {}\n", "unsupported version True"),
        ("version: 1\nsensors: [1, 2]\n", "'sensors' must be a mapping"),
        ("version: 1\nsensors: {/dev/a: 3}\n", "calibration of /dev/a: expected a mapping"),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1.0}}\n",
            r"calibration of /dev/a: missing key\(s\) \['scale'\]",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1.0, "
            "scale: 1.0, offset: 2}}\n",
            r"calibration of /dev/a: unknown key\(s\) \['offset'\]",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: '0.1', distance_m: 1.0, scale: 1}}\n",
            "angle_offset must be a number, got '0.1' \\(str\\)",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: yes, scale: 1}}\n",
            "distance must be a number, got True",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: .nan, distance_m: 1, scale: 1}}\n",
            "angle_offset must be finite",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: -1, scale: 1}}\n",
            "distance must be >= 0",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 0.1, distance_m: 1, scale: 0}}\n",
            "scale must be > 0",
        ),
        (
            "version: 1\nsensors: {/dev/a: {angle_offset_rad: 7.0, distance_m: 1, scale: 1}}\n",
            r"angle_offset must be in \(-pi, pi\]",
        ),
        (f"version: 1\nsensors: {{1: {GOOD_ENTRY}}}\n", "sensor id must be a non-empty string"),
        (f"version: 1\nsensors: {{'': {GOOD_ENTRY}}}\n", "sensor id must be a non-empty string"),
    ],
)
def test_bad_yaml(text, message):
    with pytest.raises(ValueError, match=message):
        Calibration.from_yaml(text)


def test_bad_file_is_value_error(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("version: 1\nsensors: {/dev/a: {scale: 1}}\n")
    with pytest.raises(ValueError, match="missing key"):
        Calibration.load(path)


# --- version 2: per-axis scales, position, standard errors ---------------------------------


def test_version_1_files_keep_loading(tmp_path):
    path = tmp_path / "old.yaml"
    path.write_text(
        "version: 1\nsensors:\n  /dev/spidev1.0: {angle_offset_rad: 0.087, distance_m: 1.0, "
        "scale: 1.25}\n"
    )
    cal = Calibration.load(path)
    c = cal[S1]
    assert (c.angle_offset, c.scale, c.scale_x, c.scale_y) == (0.087, 1.25, 1.25, 1.25)
    assert c.position is None and cal.method == "" and cal.date == ""
    expect = (-1.25 * math.sin(0.087), 1.25 * math.cos(0.087))
    assert cal.apply(S1, 0.0, 1.0) == pytest.approx(expect)
    cal.save(path)  # rewritten as version 2, same values
    assert path.read_text().startswith("version: 2\n")
    assert Calibration.load(path) == cal


def test_version_2_round_trip_and_per_axis_apply(tmp_path):
    c = SensorCalibration(
        0.05, 2.0, scale_x=1.1, scale_y=0.9, x=0.05, y=-0.04, angle_offset_se=1e-4,
        scale_x_se=0.01, scale_y_se=1e-4, x_se=2e-4, y_se=1e-4,
    )
    cal = Calibration({S1: c}, method="fit", date="2026-12-01T19:30:00+00:00")
    path = tmp_path / "cal.yaml"
    cal.save(path)
    back = Calibration.load(path)
    assert back == cal and back.method == "fit" and back[S1].position == (0.05, -0.04)
    # scale per axis first, then the rotation
    x, y = c.apply(1.0, 2.0)
    ca, sa = math.cos(0.05), math.sin(0.05)
    assert (x, y) == pytest.approx((ca * 1.1 - sa * 1.8, sa * 1.1 + ca * 1.8))


def test_mounts_take_the_fitted_positions_and_keep_the_rest():
    m0, m1 = SensorMount(0.049, -0.0395, 0.01), SensorMount(0.049, 0.0395)
    cal = Calibration({S2: SensorCalibration(x=0.05, y=0.04)})
    assert cal.mounts([S1, S2], [m0, m1]) == (m0, SensorMount(0.05, 0.04))
    assert Calibration().mounts([S1], [m0, m1]) == (m0,)
    with pytest.raises(ValueError, match="2 sensors need 2 mounts"):
        cal.mounts([S1, S2], [m0])


def test_load_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("version: 2\nsensors: 3\n")
    with pytest.raises(ValueError, match=f"calibration file {path}: calibration: 'sensors'"):
        Calibration.load(path)
    path.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ValueError, match=f"calibration file {path}: not a text file"):
        Calibration.load(path)
    with pytest.raises(OSError, match=f"calibration file {tmp_path / 'nope.yaml'}: No such file"):
        Calibration.load(tmp_path / "nope.yaml")
