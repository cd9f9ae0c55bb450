"""The register map as data: defaults, YAML overrides, validation, CPI encoding.

Driver and emulator both read a RegisterMap, so an override must move both
to the same bytes; a malformed override must fail loudly with a message that
names the offending key.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from pln2033 import INCH_M, RegisterMapError
from pln2033.motion import ConstantVelocity
from pln2033.pln2033 import PLN2033, REGISTER_NAMES, EmulatedPLN2033, RegisterMap


class FakeClock:
    """A manual clock: tests set ``t``; the emulator calls it."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def write_yaml(tmp_path: Path, text: str, name: str = "map.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


# --- defaults ---------------------------------------------------------------------------


def test_register_names_are_the_13_registers_in_the_seed_order():
    assert REGISTER_NAMES == (
        "status",
        "delta_x_disp",
        "delta_y_disp",
        "command_high",
        "command_low",
        "memory_pointer",
        "memory_data",
        "mode_control",
        "power_control",
        "mode_status",
        "system_control",
        "miscellaneous",
        "interrupt_output",
    )


def test_default_map_values():
    m = RegisterMap.default()
    assert m.addresses == {name: i for i, name in enumerate(REGISTER_NAMES)}
    assert (m.write_flag, m.address_mask) == (0x80, 0x7F)
    assert (m.status_motion, m.status_lift) == (0x0080, 0x0010)
    assert (m.status_overflow_x, m.status_overflow_y, m.status_reserved) == (0x4, 0x8, 0xFF00)
    assert m.commands == {"set_x_cpi": 1, "set_y_cpi": 2, "get_x_cpi": 3, "get_y_cpi": 4}
    assert (m.cpi_min, m.cpi_max, m.cpi_step, m.cpi_default) == (100, 6400, 100, 1000)
    assert (m.power_down_bit, m.soft_reset_bit, m.patch_enable_bit) == (1, 1, 2)
    assert (m.memory_words, m.patch_start, m.presence_pattern) == (4096, 0, 0x0A5A)


def test_empty_yaml_file_gives_the_defaults(tmp_path):
    assert RegisterMap.load(write_yaml(tmp_path, "")) == RegisterMap.default()
    assert RegisterMap.load(write_yaml(tmp_path, "# only a comment\n")) == RegisterMap.default()


# --- overrides ----------------------------------------------------------------------------

SHUFFLED = """\
    registers:
      status: 0x20
      delta_x_disp: 0x22
      delta_y_disp: 0x21
      memory_pointer: 0x30
      memory_data: 0x31
    frame:
      write_flag: 0x80
    commands:
      set_x_cpi: 0x11
      get_x_cpi: 0x13
    cpi:
      default: 800
"""


def test_override_changes_only_the_given_keys(tmp_path):
    m = RegisterMap.load(write_yaml(tmp_path, SHUFFLED))
    d = RegisterMap.default()
    assert m.addresses["status"] == 0x20
    assert m.addresses["delta_x_disp"] == 0x22
    assert m.addresses["delta_y_disp"] == 0x21
    assert m.addresses["command_high"] == d.addresses["command_high"]
    assert m.commands == {"set_x_cpi": 0x11, "set_y_cpi": 2, "get_x_cpi": 0x13, "get_y_cpi": 4}
    assert m.cpi_default == 800
    assert m.cpi_max == d.cpi_max


def test_from_dict_does_not_mutate_its_argument():
    override = {"registers": {"status": 0x40}}
    RegisterMap.from_dict(override)
    assert override == {"registers": {"status": 0x40}}
    assert RegisterMap.default().addresses["status"] == 0


def test_override_moves_driver_and_emulator_to_the_same_bytes(tmp_path):
    m = RegisterMap.load(write_yaml(tmp_path, SHUFFLED))
    clock = FakeClock()
    cpi = 1600
    vx, vy = 0.05, -0.02
    emu = EmulatedPLN2033(ConstantVelocity(vx, vy), regmap=m, clock=clock, record=True)
    drv = PLN2033(emu, regmap=m)
    drv.check_presence()
    assert emu.cpi_x == 800  # the overridden power-up default
    drv.set_cpi(cpi)
    assert (drv.get_x_cpi(), drv.get_y_cpi(), emu.cpi_x, emu.cpi_y) == (cpi, cpi, cpi, cpi)
    drv.load_patch([0x1234, 0xBEEF])
    assert emu.ram[:2] == [0x1234, 0xBEEF]
    drv.read_motion()
    emu.stats.history.clear()
    clock.t = 0.1
    motion = drv.read_motion()
    # The motion burst uses the overridden addresses.
    assert emu.stats.history[0][0] == (0x20, 0, 0, 0x22, 0, 0, 0x21, 0, 0)
    assert motion.dx == pytest.approx(vx * 0.1 * cpi / INCH_M, abs=1)
    assert motion.dy == pytest.approx(vy * 0.1 * cpi / INCH_M, abs=1)
    assert motion.dx > 0 > motion.dy


def test_driver_and_emulator_with_different_maps_disagree():
    """The agreement above is not vacuous: mismatched maps swap the axes."""
    clock = FakeClock()
    emu = EmulatedPLN2033(ConstantVelocity(0.01, 0.0), clock=clock)
    swapped = RegisterMap.from_dict({"registers": {"delta_x_disp": 2, "delta_y_disp": 1}})
    drv = PLN2033(emu, regmap=swapped)
    clock.t = 1.0
    motion = drv.read_motion()
    assert motion.dx == 0
    assert motion.dy == pytest.approx(0.01 * 1000 / INCH_M, abs=1)


# --- malformed overrides ------------------------------------------------------------------

BAD_MAPS = [
    pytest.param(
        "registres:\n  status: 1\n",
        ["unknown key 'registres'", "known:", "'registers'"],
        id="unknown-top-level-key",
    ),
    pytest.param(
        "registers:\n  stauts: 1\n",
        ["unknown key 'registers.stauts'", "'status'"],
        id="unknown-register",
    ),
    pytest.param(
        "registers:\n  status: 0x01\n",
        ["two registers share an address"],
        id="duplicate-address",
    ),
    pytest.param(
        "registers:\n  status: '0x10'\n",
        ["'registers.status' must be an integer 0..0x7f", "'0x10'"],
        id="string-address",
    ),
    pytest.param(
        "registers:\n  status: 1.5\n",
        ["'registers.status' must be an integer 0..0x7f", "1.5"],
        id="float-address",
    ),
    pytest.param(
        "registers:\n  status: true\n",
        ["'registers.status' must be an integer", "True"],
        id="bool-address",
    ),
    pytest.param(
        "registers:\n  status: 0x80\n",
        ["'registers.status' must be an integer 0..0x7f", "128"],
        id="address-above-mask",
    ),
    pytest.param(
        "registers:\n  status: -1\n",
        ["'registers.status' must be an integer 0..0x7f", "-1"],
        id="negative-address",
    ),
    pytest.param(
        "registers: [1, 2]\n",
        ["'registers' must be a mapping"],
        id="section-not-a-mapping",
    ),
    pytest.param(
        "status_bits:\n  lift: 0x10000\n",
        ["'status_bits.lift' must be an integer 0..0xffff", "65536"],
        id="status-bit-over-16-bits",
    ),
    pytest.param(
        "frame:\n  write_flag: 0x100\n",
        ["'frame.write_flag' must be an integer 0..0xff"],
        id="write-flag-over-8-bits",
    ),
    pytest.param(
        "frame:\n  write_flag: 0x01\n",
        ["frame.write_flag", "address_mask"],
        id="write-flag-inside-address-mask",
    ),
    pytest.param(
        "frame:\n  write_flag: 0\n",
        ["frame.write_flag", "address_mask"],
        id="write-flag-zero",
    ),
    pytest.param(
        "cpi:\n  min: 7000\n",
        ["cpi range is empty", "min=7000", "max=6400"],
        id="cpi-min-above-max",
    ),
    pytest.param(
        "cpi:\n  step: 0\n",
        ["cpi range is empty", "step=0"],
        id="cpi-step-zero",
    ),
    pytest.param(
        "cpi:\n  min: 150\n",
        ["cpi.min", "150", "step"],
        id="cpi-min-not-on-the-step-grid",
    ),
    pytest.param(
        "cpi:\n  default: 150\n",
        ["cpi.default", "150", "allowed: 100..6400 in steps of 100"],
        id="cpi-default-not-allowed",
    ),
    pytest.param(
        "commands:\n  set_x_cpi: x\n",
        ["'commands.set_x_cpi' must be an integer", "'x'"],
        id="command-not-an-integer",
    ),
    pytest.param(
        "registers:\n  status: [0\n",
        ["is not valid YAML"],
        id="bad-yaml",
    ),
    pytest.param(
        "- 1\n- 2\n",
        ["must be a YAML mapping"],
        id="yaml-list",
    ),
]


@pytest.mark.parametrize(("text", "fragments"), BAD_MAPS)
def test_bad_yaml_override_raises_register_map_error(tmp_path, text, fragments):
    path = write_yaml(tmp_path, text)
    with pytest.raises(RegisterMapError) as info:
        RegisterMap.load(path)
    message = str(info.value)
    for fragment in fragments:
        assert fragment in message
    # Nothing global changed: the defaults are still the defaults.
    assert RegisterMap.default().addresses == {n: i for i, n in enumerate(REGISTER_NAMES)}


def test_register_map_error_is_a_value_error():
    with pytest.raises(ValueError, match="unknown key 'bogus'"):
        RegisterMap.from_dict({"bogus": 1})


def test_missing_register_map_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(RegisterMapError) as info:
        RegisterMap.load(path)
    assert str(info.value) == f"cannot read register map {path}: No such file or directory"


def test_every_key_of_the_default_file_is_overridable(tmp_path):
    """Writing the default file back as an override reproduces the defaults."""
    import importlib.resources

    text = importlib.resources.files("pln2033.pln2033").joinpath("default_regmap.yaml").read_text()
    data = yaml.safe_load(text)
    path = tmp_path / "copy.yaml"
    path.write_text(yaml.safe_dump(data))
    assert RegisterMap.load(path) == RegisterMap.default()


# --- CPI encoding ------------------------------------------------------------------------

ALLOWED = "allowed: 100..6400 in steps of 100"
DEFAULT = RegisterMap.default()


def test_allowed_cpi_is_100_to_6400_in_steps_of_100():
    m = RegisterMap.default()
    assert list(m.allowed_cpi) == [100 * k for k in range(1, 65)]


@given(st.sampled_from(list(DEFAULT.allowed_cpi)))
def test_cpi_encode_decode_round_trip_over_the_allowed_set(cpi):
    m = DEFAULT
    assert m.cpi_problem(cpi) is None
    code = m.encode_cpi(cpi)
    assert 1 <= code <= 64
    assert m.decode_cpi(code) == cpi


@given(st.integers(min_value=-(2**20), max_value=2**20))
def test_cpi_problem_accepts_exactly_the_allowed_set(cpi):
    m = DEFAULT
    problem = m.cpi_problem(cpi)
    if cpi in m.allowed_cpi:
        assert problem is None
    else:
        assert problem is not None
        assert ALLOWED in problem
        assert str(cpi) in problem


@pytest.mark.parametrize(
    ("cpi", "fragment"),
    [
        (0, "CPI 0 is out of range"),
        (99, "CPI 99 is out of range"),
        (6401, "CPI 6401 is out of range"),
        (150, "CPI 150 is not supported by the sensor's encoding"),
        (1.5, "CPI must be an integer, got 1.5"),
        ("800", "CPI must be an integer, got '800'"),
        (True, "CPI must be an integer, got True"),
        (None, "CPI must be an integer, got None"),
    ],
)
def test_cpi_problem_messages(cpi, fragment):
    problem = RegisterMap.default().cpi_problem(cpi)
    assert problem is not None
    assert fragment in problem
    assert problem.endswith(f"({ALLOWED})")


@given(
    step=st.integers(min_value=1, max_value=500),
    k_min=st.integers(min_value=1, max_value=20),
    k_span=st.integers(min_value=0, max_value=100),
    data=st.data(),
)
@settings(max_examples=40)
def test_any_valid_cpi_override_is_self_consistent(step, k_min, k_span, data):
    """allowed_cpi, cpi_problem and the encoding agree for every accepted map."""
    cpi_min = step * k_min
    cpi_max = min(cpi_min + step * k_span, 0xFFFF)
    if cpi_max < cpi_min:
        return
    default = data.draw(st.sampled_from(list(range(cpi_min, cpi_max + 1, step))))
    m = RegisterMap.from_dict(
        {"cpi": {"min": cpi_min, "max": cpi_max, "step": step, "default": default}}
    )
    allowed = list(m.allowed_cpi)
    assert allowed[0] == cpi_min
    assert m.cpi_problem(m.cpi_default) is None
    for cpi in (allowed[0], allowed[-1], data.draw(st.sampled_from(allowed))):
        assert m.cpi_problem(cpi) is None
        assert m.decode_cpi(m.encode_cpi(cpi)) == cpi
        assert 0 <= m.encode_cpi(cpi) <= 0xFFFF


# --- the facts table (docs/sensors.md, "PLN2033") ------------------------------------------


def _pln2033_facts_table() -> str:
    doc = (Path(__file__).parents[2] / "docs" / "sensors.md").read_text()
    section = doc.split("\n## PLN2033\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("|")]
    assert len(rows) >= 22, "the facts table lost rows"  # header, rule and 20 facts
    return "\n".join(rows)


def test_the_facts_table_names_every_default_of_the_register_map_with_its_value():
    """Every key of default_regmap.yaml is in the table with the value the file holds (the
    registers as one row: their addresses are their order), and no row names a key the
    map does not have: the table cannot drift from the defaults a user overrides."""
    import re
    from importlib import resources

    table = _pln2033_facts_table()
    text = resources.files("pln2033.pln2033").joinpath("default_regmap.yaml").read_text()
    defaults = yaml.safe_load(text)
    named = dict(re.findall(r"`([a-z_]+\.[a-z_]+)` (0x[0-9A-Fa-f]+|\d+)", table))
    want = {
        f"{section}.{key}": value
        for section, keys in defaults.items()
        if section != "registers"
        for key, value in keys.items()
    }
    assert set(named) == set(want)
    for key, value in want.items():
        assert int(named[key], 0) == value, key
    assert "`registers.*`" in table and "0x00…0x0C" in table
    assert [defaults["registers"][r] for r in REGISTER_NAMES] == list(range(len(REGISTER_NAMES)))
    # every row says whether vendor code was checked (none exists) and what fixes it
    for row in table.splitlines()[2:]:
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", row)[1:-1]]
        assert len(cells) == 6, row
        assert cells[3].startswith("no: no vendor code exists"), row
        assert cells[5], row
