"""mm-beagle-agent inside a Debian 12 armhf root through qemu-user: what a
BeagleBone Black runs, with only Debian's python3 packages and the eclipse-zenoh
armv7l wheel. Timing under qemu is not the board's: reported by mm-bench agent,
not checked here.
"""

from __future__ import annotations

import json
import subprocess

import pytest

from mm_beagle.tools import bench_agent

# The first build of the root (in the module's fixture, so in the first test's setup)
# takes 5-12 minutes: more than pytest's default 300 s per test.
pytestmark = [pytest.mark.slow, pytest.mark.timeout(bench_agent.ARMHF_BUILD_TIMEOUT + 300)]


@pytest.fixture(scope="module")
def armhf_root():
    """tools/armhf-root's root with the agent installed from this checkout; a skip with the
    tool's reason where this machine cannot have it (not root, no debootstrap and no
    apt-get to install it, binfmt_misc not mountable), a failure where building fails."""
    tool = bench_agent.armhf_tool()
    if tool is None:
        pytest.skip(f"no armhf-root tool ({bench_agent.ARMHF_TOOL}; set MM_ARMHF_ROOT_TOOL)")
    try:
        return bench_agent.armhf_root_with_agent(tool)
    except bench_agent.ArmhfUnavailableError as exc:
        pytest.skip(f"no Debian 12 armhf root under qemu-user here: {exc}")


@pytest.mark.parametrize(
    ("extra", "backend"),
    [(("--bench-stub",), "sim"), ((), "sim")],
    ids=["stub-bus", "emulated-sensors"],
)
def test_agent_self_test_runs_on_armhf_with_debian_packages_only(armhf_root, extra, backend):
    report, why = bench_agent.qemu_arm_self_test(3.0, extra)
    assert report is not None, why
    assert report["machine"].startswith("arm")
    assert report["polls"] > 100 and report["rss_mb"] > 0
    if backend == "sim" and not extra:  # the emulators' ground truth
        assert report["counts_generated"] > 0 and report["counts_lost"] == 0
    else:  # the stub bus has none
        assert report["counts_lost"] is None


def test_the_spidev_path_imports_no_numpy_on_armhf(armhf_root):
    report, why = bench_agent.qemu_arm_self_test(
        1.0, ("--backend", "spidev", "--devices", "/dev/spidev9.0")
    )
    assert report is not None, why
    assert report["imports_numpy"] is False
    assert report["backend"] == "spidev"


def test_install_agent_installs_and_runs_on_armhf(armhf_root):
    """./compile agent inside the armhf root into a fresh prefix, offline (the zenoh wheel
    from a folder), without systemd: the installed launcher runs with the installed config."""
    tool = bench_agent.armhf_tool()
    wheels = bench_agent.armhf(tool, "wheels").strip()
    prefix = "/opt/mm-install-test"
    out = subprocess.run(
        [tool, "run", "sh", "-c",
         f"rm -rf {prefix} && cd {bench_agent.SRC_IN_ROOT} && ./compile agent --prefix {prefix} "
         f"--wheel-dir {wheels} --no-systemd"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert "done" in out.stdout
    run = subprocess.run(
        [tool, "run", f"{prefix}/bin/mm-beagle-agent", "--config", "/etc/mouse-monitor/agent.yaml",
         "--backend", "sim", "--realtime-priority", "0", "--self-test", "2"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["machine"].startswith("arm") and report["counts_lost"] == 0
    assert report["polls"] > 100
