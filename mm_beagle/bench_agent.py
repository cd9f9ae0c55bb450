"""mm-bench agent: what the board agent costs and what its link guarantees.

Each figure comes from real processes in one run:
- ``cpu_us_per_poll``: the agent's own ``--self-test --bench-stub`` (two sensors,
  the motion burst answered by a constant stub after an emulated bring-up, the
  link served, polling flat out), natively and, where the armhf root can be had,
  under qemu-arm (``cpu_us_per_poll_qemu_arm``, else null with the reason);
- ``cpu_percent_paced``: the same at 1 kHz paced;
- ``rss_mb``: the spidev path (no numpy), sensors absent;
- ``bandwidth_kib_s``, ``latency_p50_ms``/``p99``: an agent on emulated sensors and
  the node's :class:`~mm_beagle.remote.RemoteAgent` in this process (no ROS
  needed), latency from a poll's stamp to the node's shared state, one clock;
- ``counts_lost`` over ``link_drops`` forced drops (a :class:`DropProxy` cut) of
  a few seconds: node totals and every ring poll against the emulator's truth.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .harness import agent_command, agent_process, free_port
from .link_proxy import DropProxy
from .poller import PollerConfig
from .remote import RemoteAgent

ARMHF_TOOL = Path(__file__).resolve().parents[2] / "shared" / "tools" / "armhf-root"


def self_test(args: list[str], timeout: float = 120) -> dict:
    res = subprocess.run(
        agent_command({"realtime_priority": 0, "listen": [f"tcp/127.0.0.1:{free_port()}"]}) + args,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    if res.returncode != 0:
        raise RuntimeError(f"agent self-test failed: {res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def qemu_arm_self_test(seconds: float) -> tuple[dict | None, str]:
    """The stub self-test inside the Debian 12 armhf root, or (None, why not)."""
    tool = os.environ.get("MM_ARMHF_ROOT_TOOL") or str(ARMHF_TOOL)
    if not Path(tool).exists():
        return None, f"no armhf-root tool at {tool}"
    if os.geteuid() != 0:
        return None, "the armhf root needs root (chroot)"
    try:
        root = armhf_root_with_agent(tool)
    except (subprocess.SubprocessError, OSError, RuntimeError) as exc:
        return None, f"armhf root not available: {exc}"
    cmd = [
        tool,
        "run",
        "env",
        "PYTHONPATH=/opt/src",
        "/opt/venv/bin/python",
        "-m",
        "mm_beagle.agent",
        "--backend",
        "sim",
        "--realtime-priority",
        "0",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--self-test",
        str(seconds),
        "--bench-stub",
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if res.returncode != 0:
        return None, f"self-test under qemu failed: {res.stderr[-500:]}"
    del root
    return json.loads(res.stdout.strip().splitlines()[-1]), ""


def armhf_root_with_agent(tool: str) -> Path:
    """The armhf root with /opt/venv (Debian's packages + the zenoh wheel) and our code."""
    root = Path(
        subprocess.run(
            [tool, "path"], capture_output=True, text=True, check=True, timeout=900
        ).stdout.strip()
    )
    if not (root / "opt/venv/lib/python3.11/site-packages/zenoh").exists():
        wheels = root / "tmp/wheels"
        subprocess.run(
            [tool, "wheels", str(wheels), "eclipse-zenoh>=1.5,<2"],
            check=True,
            capture_output=True,
            timeout=600,
        )
        subprocess.run([tool, "venv"], check=True, capture_output=True, timeout=600)
        subprocess.run(
            [tool, "run", "sh", "-c", "/opt/venv/bin/pip install -q --no-index /tmp/wheels/*.whl"],
            check=True,
            capture_output=True,
            timeout=900,
        )
    src = root / "opt/src"
    repo = Path(__file__).resolve().parents[1]
    for pkg in ("pln2033", "mm_beagle", "mm_pc"):
        shutil.rmtree(src / pkg, ignore_errors=True)
        shutil.copytree(repo / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return root


def _truth_and_node(remote: RemoteAgent) -> tuple[int, int]:
    """(|truth - node totals| summed, polls whose ring counts differ from the totals)."""
    lost = 0
    for i in range(remote.n):
        t = remote.state.snapshot(i)
        lost += abs(t.gen_x - t.x_total) + abs(t.gen_y - t.y_total)
    return lost, remote.polls_lost


def link_run(seconds: float, drops: int, drop_s: float) -> dict:
    """Agent process + RemoteAgent here, through a DropProxy; ``drops`` cuts."""
    port = free_port()
    proxy = DropProxy(port)
    cfg = PollerConfig(devices=["/dev/spidev1.0", "/dev/spidev1.1"], ring_size=131072)
    opts = {"backend": "sim", "listen": [f"tcp/127.0.0.1:{port}"], "sim_trajectory": "meander"}
    with agent_process(opts):
        remote = RemoteAgent(cfg, proxy.endpoint, clock_sync=False)
        remote.start()
        deadline = time.monotonic() + 20
        while remote.unavailable() and time.monotonic() < deadline:
            time.sleep(0.05)
        if remote.unavailable():
            raise RuntimeError(remote.unavailable())
        time.sleep(0.5)
        remote.apply_latency_ms.clear()
        sent0 = remote.agent_status.get("bytes_sent", 0)
        t0 = time.monotonic()
        time.sleep(seconds)
        sent1 = remote.agent_status.get("bytes_sent", 0)
        elapsed = time.monotonic() - t0
        lat = np.array(remote.apply_latency_ms)
        start_seq = [remote.state.snapshot(i).seq for i in range(remote.n)]
        start_tot = [remote.state.snapshot(i) for i in range(remote.n)]
        for _ in range(drops):
            proxy.cut()
            time.sleep(drop_s)
            proxy.restore()
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and (remote.unavailable() or not remote.link_up):
                time.sleep(0.05)
            time.sleep(1.0)
        time.sleep(1.0)
        lost, polls_lost = _truth_and_node(remote)
        ring_mismatch = 0
        for i in range(remote.n):
            t = remote.state.snapshot(i)
            first, _next, dropped, arr = remote.state.samples(i, start_seq[i], 0)
            ring_mismatch += dropped
            ring_mismatch += abs(
                int(arr["dx"][: t.seq - first].sum()) - (t.x_total - start_tot[i].x_total)
            )
            ring_mismatch += abs(
                int(arr["dy"][: t.seq - first].sum()) - (t.y_total - start_tot[i].y_total)
            )
        result = {
            "bandwidth_kib_s": round((sent1 - sent0) / elapsed / 1024, 1),
            "latency_p50_ms": round(float(np.percentile(lat, 50)), 3),
            "latency_p99_ms": round(float(np.percentile(lat, 99)), 3),
            "link_drops": remote.link_drops,
            "link_drop_seconds": drop_s,
            "counts_lost": lost,
            "ring_polls_lost": polls_lost,
            "ring_vs_totals_counts": ring_mismatch,
        }
        remote.stop()
    proxy.close()
    return result


def bench_agent(seconds: float = 3.0, drops: int = 5, drop_s: float = 3.0) -> dict:
    flat = self_test(["--backend", "sim", "--self-test", str(seconds), "--bench-stub"])
    paced = self_test(
        ["--backend", "sim", "--self-test", str(seconds), "--bench-stub", "--bench-paced"]
    )
    spidev = self_test(
        [
            "--backend",
            "spidev",
            "--devices",
            "/dev/spidev99.0",
            "/dev/spidev99.1",
            "--self-test",
            "2",
        ]
    )
    qemu, why = qemu_arm_self_test(seconds)
    out = {
        "cpu_us_per_poll": flat["cpu_us_per_poll"],
        "cpu_us_per_poll_qemu_arm": qemu["cpu_us_per_poll"] if qemu else None,
        "qemu_arm_note": why or "qemu-user timing, not the board's",
        "rss_mb_qemu_arm": qemu["rss_mb"] if qemu else None,
        "cpu_percent_paced": round(paced["cpu_us_per_poll"] * paced["rate_hz"] / 1e4, 2),
        "paced_rate_hz": paced["rate_hz"],
        "rss_mb": spidev["rss_mb"],
        "rss_mb_sim_backend": flat["rss_mb"],
        "polls_flat_out": flat["polls"],
    }
    out.update(link_run(seconds * 3, drops, drop_s))
    out["goals"] = {
        "cpu_us_per_poll": "<= 3 (x86, two sensors)",
        "cpu_us_per_poll_qemu_arm": "<= 30",
        "rss_mb": "<= 40",
        "counts_lost": "0",
        "latency_p99_ms": "<= 20",
    }
    return out


if __name__ == "__main__":
    print(json.dumps(bench_agent(), indent=1))
    sys.exit(0)
