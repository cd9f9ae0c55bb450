"""The shipped parameter file, the demo and the live view."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from fakes import scaled

pytest.importorskip("rclpy")
from mm_beagle.node.params import PARAMETERS
from mm_beagle.tools.watch import HEADER, SensorView, format_row

ROOT = Path(__file__).resolve().parents[2]


def test_params_file_lists_every_parameter_with_its_default():
    data = yaml.safe_load((ROOT / "mm_beagle/config/mm_beagle.yaml").read_text())
    params = data["/**/mm_beagle"]["ros__parameters"]  # any namespace
    assert set(params) == set(PARAMETERS)
    for name, (default, _desc) in PARAMETERS.items():
        assert params[name] == default, name


def test_watch_row_shows_mm_per_s_and_metres():
    view = SensorView(x_speed=0.0123, y_speed=-0.2, x_total=1.5, y_total=-2.25, cpi=800, lifts=3)
    row = format_row("/dev/spidev1.0", view, "up", 999.6)
    assert row.split() == [
        "/dev/spidev1.0",
        "up",
        "1000",
        "12.3",
        "-200.0",
        "1.500",
        "-2.250",
        "800",
        "3",
        "0.0000",
        "?",
        "-",
    ]
    assert len(row) == len(HEADER)  # the columns line up under the header
    view.chip, view.quality = "pmw3360", 48
    row = format_row("/dev/spidev1.0", view, "up", 999.6)
    assert row.split()[-2:] == ["pmw3360", "48"] and len(row) == len(HEADER)


@pytest.mark.ros
def test_demo_runs_and_shows_both_sensors():
    out = subprocess.run(
        [sys.executable, "-m", "mm_beagle.tools.demo", "--duration", "6"],
        capture_output=True,
        text=True,
        timeout=scaled(120),
        env=dict(os.environ),
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "/dev/spidev1.0       up" in out.stdout
    assert "/dev/spidev1.1       up" in out.stdout
    assert "SensorData messages received" in out.stdout
    log = Path(out.stdout.split("node log: ", 1)[1].split()[0])  # a private folder, printed
    assert log.name == "mm_beagle.log" and log.parent.name.startswith("mm-demo-")
    assert not log.parent.exists()  # a run that ended well removes it (one failing keeps it)


@pytest.mark.ros
def test_watch_command_ends_cleanly_after_its_duration(tmp_path):
    """mm-watch --duration used to abort at exit (rc 134, a daemon thread inside spin)."""
    from mm_beagle.tools.harness import BeagleClient, beagle_process

    client = BeagleClient("mm_watch_test_client")
    params = {"backend": "sim", "diagnostics_period": 0.3}
    with beagle_process(params, env=dict(os.environ), log_path=str(tmp_path / "n.log")):
        assert client.wait(scaled(60)), (tmp_path / "n.log").read_text()
        client.close()
        runs = [
            subprocess.run(
                [sys.executable, "-m", "mm_beagle.tools.watch", "--duration", "6"],
                capture_output=True, text=True, timeout=scaled(120), env=dict(os.environ),
            )
            for _ in range(1)
        ]
    for out in runs:
        assert out.returncode == 0, out.stdout + out.stderr
        assert "terminate called" not in out.stderr
    assert "/dev/spidev1.0 " in runs[-1].stdout and "/dev/spidev1.1 " in runs[-1].stdout


def test_bench_rejects_bad_arguments():
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.bench.cli", "poll", "--seconds", "1"],
        capture_output=True,
        text=True,
        timeout=scaled(120),
    )
    assert out.returncode == 2
    assert "--seconds >= 3" in out.stderr


@pytest.mark.parametrize(
    "args, text",
    [
        (["--clients", "0"], "1 <= --clients <= 64"),
        (["--clients", "65"], "1 <= --clients <= 64"),
        (["--rate", "-1"], "--rate >= 0"),
        (["--cursor", "bogus"], "invalid choice: 'bogus'"),
    ],
)
def test_bench_poll_rejects_bad_client_options(args, text):
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.bench.cli", "poll", *args],
        capture_output=True,
        text=True,
        timeout=scaled(120),
    )
    assert out.returncode == 2
    assert text in out.stderr and "Traceback" not in out.stderr
