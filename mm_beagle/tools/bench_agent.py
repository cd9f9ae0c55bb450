"""mm-bench agent: what the board agent costs and what its link guarantees.

Each figure comes from real processes in one run:
- ``cpu_us_per_poll``: the agent's own ``--self-test --bench-stub`` (two sensors,
  the motion burst answered by a constant stub after an emulated bring-up, the
  link served, polling flat out), natively and, where this machine can have the
  Debian 12 armhf root of ``tools/armhf-root`` (root, binfmt_misc), under qemu-arm
  (``cpu_us_per_poll_qemu_arm``, else null with the reason);
- ``cpu_us_per_poll_minimal_loop``: the smallest loop that polls at all, in the
  same run (this shared 2-core VM is noisy: compare the ratio); beside the agent's
  whole-process figure, its poll thread's own (``_poll_thread``: what the minimal loop is,
  one thread) and the whole process with credentials (``_with_credentials``: the MAC on
  every frame); under qemu-arm the minimal loop too, and the ratio;
- ``cpu_percent_paced``: the same at 1 kHz paced;
- ``rss_mb``: the spidev path (no numpy), sensors absent;
- ``bandwidth_kib_s``, ``latency_p50_ms``/``p99``: an agent on emulated sensors and
  the node's :class:`~mm_beagle.link.remote.RemoteAgent` in this process (no ROS
  needed), latency from a poll's stamp to the node's shared state, one clock;
- ``counts_lost`` over ``link_drops`` forced drops of a few seconds (a
  :class:`~mm_beagle.tools.link_proxy.ProxyProcess` cut): node totals and every ring
  poll against the emulator's truth;
- ``hostile``: the attacks of issue 27 on an agent on emulated sensors, one after the
  other (:func:`hostile_run`, :mod:`~mm_beagle.tools.hostile_peer`): per attack the
  longest gap between two polls (ms, from the agent's ring), and at the end the counts
  lost, the refusals and the agent's RSS now and at its peak; ``hostile_spidev`` the same
  memory figures of the spidev agent (no numpy, sensors absent) under the floods.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mm_beagle.link.remote import RemoteAgent
from mm_beagle.poller.poller import PollerConfig
from mm_beagle.tools.harness import agent_command, agent_process, free_port
from mm_beagle.tools.hostile_peer import PollWatch, flood, peak_rss_mb, stuck_reader
from mm_beagle.tools.link_proxy import ProxyProcess

# The project's board check (tools/armhf-root in the checkout), or MM_ARMHF_ROOT_TOOL.
ARMHF_TOOL = Path(__file__).resolve().parents[2] / "tools" / "armhf-root"
# Where the tool puts things inside the root: ./compile agent's launcher, the checkout's copy.
AGENT_IN_ROOT = "/opt/mouse-monitor/bin/mm-beagle-agent"
SRC_IN_ROOT = "/opt/mm-src"
PYTHON_IN_ROOT = "/opt/mouse-monitor/venv/bin/python3"  # the agent's venv (Debian's python3)
# The first build of the root takes 5-12 minutes (more while another run holds its lock).
ARMHF_BUILD_TIMEOUT = 1500


class ArmhfUnavailableError(RuntimeError):
    """This machine cannot have the armhf root (the tool's exit 2): not root, no
    debootstrap/qemu-user-static and no apt-get to install them, no binfmt_misc."""


def armhf_tool() -> str | None:
    """The armhf-root tool's path, or None."""
    env = os.environ.get("MM_ARMHF_ROOT_TOOL")
    cand = Path(env) if env else ARMHF_TOOL
    return str(cand) if cand.exists() else None


def armhf(tool: str, *args: str, timeout: float = ARMHF_BUILD_TIMEOUT) -> str:
    """``tool args...``'s stdout; ArmhfUnavailableError where it cannot run here (exit 2 and
    its reason), RuntimeError on any other failure."""
    res = subprocess.run([tool, *args], capture_output=True, text=True, timeout=timeout)
    why = [line for line in res.stderr.splitlines() if "cannot run here:" in line]
    if res.returncode == 2 and why:  # (bash's own errors exit 2 too: those fail)
        raise ArmhfUnavailableError(why[-1])
    if res.returncode != 0:
        raise RuntimeError(f"{tool} {' '.join(args)} failed: {res.stderr[-2000:]}")
    return res.stdout


def minimal_loop_us(polls: int = 200_000) -> float:
    """CPU per poll (us, two sensors) of the smallest loop that does the job at all.

    The same-run baseline for ``cpu_us_per_poll``: a constant-reply stub bus,
    struct.unpack_from of the burst, struct.pack_into one ring record and the
    totals per sensor; no lift handling, seqlock, metres, flags or histogram.
    """
    reply = [0, 0, 0x80, 0, 0, 3, 0, 0, 5]
    tx = [0x00, 0, 0, 0x01, 0, 0, 0x02, 0, 0]

    def xfer(data: list[int]) -> list[int]:
        return reply[:]

    rec, tot = struct.Struct("<qhhHHB"), struct.Struct("<qqq")
    ring, totals = bytearray(65536 * rec.size * 2), bytearray(48)
    unpack = struct.Struct(">xHxhxh").unpack_from
    xs, ys, wall = [0, 0], [0, 0], time.time_ns
    c0 = time.process_time()
    for seq in range(polls):
        stamp = wall()
        for i in (0, 1):
            status, dx, dy = unpack(bytes(xfer(tx)))
            xs[i] += dx
            ys[i] += dy
            rec.pack_into(ring, ((seq % 65536) * 2 + i) * rec.size, stamp, dx, dy, status, 1600, 2)
            tot.pack_into(totals, i * 24, seq, xs[i], ys[i])
    return (time.process_time() - c0) / polls * 1e6


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


def qemu_arm_self_test(
    seconds: float, extra: tuple[str, ...] = ("--bench-stub",)
) -> tuple[dict | None, str]:
    """A self-test inside the Debian 12 armhf root (stub bus), or (None, why not)."""
    tool = armhf_tool()
    if tool is None:
        return None, f"no armhf-root tool ({ARMHF_TOOL} is missing; set MM_ARMHF_ROOT_TOOL)"
    try:
        armhf_root_with_agent(tool)
    except ArmhfUnavailableError as exc:
        return None, f"no armhf root on this machine: {exc}"
    except (subprocess.SubprocessError, OSError, RuntimeError) as exc:
        return None, f"armhf root not available: {exc}"
    cmd = [
        tool,
        "run",
        AGENT_IN_ROOT,
        "--backend",
        "sim",
        "--realtime-priority",
        "0",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--self-test",
        str(seconds),
        *extra,
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if res.returncode != 0:
        return None, f"self-test under qemu failed: {res.stderr[-500:]}"
    return json.loads(res.stdout.strip().splitlines()[-1]), ""


def qemu_arm_minimal_loop_us() -> float | None:
    """:func:`minimal_loop_us` inside the armhf root (right after a qemu self-test: the
    root is there), or None if it fails."""
    tool = armhf_tool()
    if tool is None:
        return None
    code = (
        f"import sys; sys.path.insert(0, {SRC_IN_ROOT!r}); "
        "from mm_beagle.tools.bench_agent import minimal_loop_us; print(minimal_loop_us())"
    )
    try:
        out = armhf(tool, "run", PYTHON_IN_ROOT, "-c", code, timeout=600)
        return float(out.strip().splitlines()[-1])
    except (subprocess.SubprocessError, OSError, RuntimeError, ValueError, IndexError):
        return None


def armhf_root_with_agent(tool: str) -> Path:
    """The armhf root with the agent installed by ``./compile agent`` from this checkout
    (Debian's packages + the zenoh wheel; built on first use, reinstalled when the code changed)."""
    armhf(tool, "agent")
    return Path(armhf(tool, "path").strip())


def _truth_and_node(remote: RemoteAgent) -> tuple[int, int]:
    """(|truth - node totals| summed, polls whose ring counts differ from the totals)."""
    lost = 0
    for i in range(remote.n):
        t = remote.state.snapshot(i)
        lost += abs(t.gen_x - t.x_total) + abs(t.gen_y - t.y_total)
    return lost, remote.polls_lost


def _connected(cfg: PollerConfig, endpoint: str) -> RemoteAgent:
    remote = RemoteAgent(cfg, endpoint, clock_sync=False)
    remote.start()
    deadline = time.monotonic() + 20
    while remote.unavailable() and time.monotonic() < deadline:
        time.sleep(0.05)
    if remote.unavailable():
        raise RuntimeError(remote.unavailable())
    time.sleep(0.5)
    return remote


def link_run(seconds: float, drops: int, drop_s: float) -> dict:
    """An agent process and RemoteAgents here: one direct (bandwidth, latency), one
    through a proxy process that cuts the link ``drops`` times (conservation)."""
    port = free_port()
    cfg = PollerConfig(devices=["/dev/spidev1.0", "/dev/spidev1.1"], ring_size=262144)
    opts = {"backend": "sim", "listen": [f"tcp/127.0.0.1:{port}"], "sim_trajectory": "meander"}
    with agent_process(opts):
        direct = _connected(cfg, f"tcp/127.0.0.1:{port}")
        direct.apply_latency_ms.clear()
        sent0 = direct.agent_status.get("bytes_sent", 0)
        t0 = time.monotonic()
        time.sleep(seconds)
        sent1 = direct.agent_status.get("bytes_sent", 0)
        elapsed = time.monotonic() - t0
        lat = np.array(direct.apply_latency_ms)
        direct.stop()
        proxy = ProxyProcess(port)
        remote = _connected(cfg, proxy.endpoint)
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


def _attacks(
    watch: PollWatch, endpoint: str, pid: int, patches: bool, seconds: float
) -> tuple[dict, dict]:
    """Each attack on the agent (process ``pid``) behind ``watch``: the longest poll gap
    (ms) it caused (None without polls: a spidev agent whose sensors are absent) and the
    agent's RSS after it (MB)."""
    keys = watch.keys
    rss: dict[str, float] = {}

    def window(attack) -> float | None:
        start = [watch.seq(i) for i in range(watch.n)]
        attack()
        time.sleep(0.5)
        rss[attack.__name__] = round(peak_rss_mb(pid)[0], 1)
        end = [watch.seq(i) for i in range(watch.n)]
        if not all(end):
            return None
        return round(watch.longest_gap_ms(start, end), 2)

    def quiet() -> None:
        time.sleep(seconds)

    def brackets() -> None:
        for size in (100_000, 60_000, 4000):
            for _ in range(10):
                flood(watch.session, keys["history_req"], [b"[" * size], query=False)
                flood(watch.session, keys["cmd"], [b"[" * size], query=True)

    def patch_flood() -> None:
        watch.command(cmd="load_patch", sensor=DEVICES[0], file="big.patch")
        msg = json.dumps({"cmd": "load_patch", "sensor": DEVICES[0], "file": "full.patch"})
        flood(watch.session, keys["cmd"], [msg.encode()] * 100, query=True)
        time.sleep(seconds)

    def stuck() -> None:
        proc = stuck_reader(endpoint, "mm_beagle", seconds)
        proc.stdout.readline()
        time.sleep(seconds)
        proc.kill()
        proc.wait(10)

    def big_command() -> None:
        list(watch.session.get(keys["cmd"], payload=b"x" * 200_000_000, timeout=5.0))

    gaps = {"quiet": window(quiet), "brackets_100kB": window(brackets)}
    if patches:
        gaps["load_patch_x100_and_1MiB_file"] = window(patch_flood)
    gaps["stuck_history_reader"] = window(stuck)
    gaps["command_200MB"] = window(big_command)
    return gaps, rss


DEVICES = ["/dev/spidev1.0", "/dev/spidev1.1"]


def hostile_run(seconds: float = 3.0, tmp: str | None = None) -> dict:
    """The attacks on a sim agent (poll gaps, counts lost, memory) and on a spidev agent
    with its sensors absent (memory only: the board's own figure, no numpy)."""
    import tempfile

    out: dict = {}
    with tempfile.TemporaryDirectory(dir=tmp) as d:
        patch_dir = Path(d)
        (patch_dir / "full.patch").write_bytes(bytes(range(256)) * 32)  # 4096 words
        (patch_dir / "big.patch").write_bytes(b"\x12\x34" * (1 << 19))  # 1 MiB
        for backend in ("sim", "spidev"):
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            opts: dict = {"backend": backend, "listen": [endpoint], "patch_dir": d}
            if backend == "spidev":
                opts["devices"] = ["/dev/spidev99.0", "/dev/spidev99.1"]
            with agent_process(opts) as proc:
                watch = PollWatch(endpoint)
                deadline = time.monotonic() + 60
                while watch.command(timeout=0.5, cmd="info") is None:
                    if time.monotonic() > deadline:
                        raise RuntimeError("the agent did not answer 'info'")
                time.sleep(1.0)
                rss0, _ = peak_rss_mb(proc.pid)
                gaps, rss = _attacks(watch, endpoint, proc.pid, backend == "sim", seconds)
                time.sleep(1.5)  # a status after the attacks
                rss1, peak1 = peak_rss_mb(proc.pid)
                result = {
                    "rss_mb_before": round(rss0, 1),
                    "rss_mb_after": round(rss1, 1),
                    "peak_rss_mb": round(peak1, 1),
                    "rss_mb_after_each": rss,
                    "requests_refused": watch.status.get("requests_refused"),
                    "alive": proc.poll() is None and watch.command(cmd="info") is not None,
                }
                if backend == "sim":
                    result["longest_poll_gap_ms"] = gaps
                    result["counts_lost"] = watch.counts_lost()
                watch.close()
            out["hostile" if backend == "sim" else "hostile_spidev"] = result
    return out


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
    with tempfile.TemporaryDirectory() as tmp:  # the MAC on every message the link sends
        cred = subprocess.run(
            [*agent_command({}), "--make-credentials", f"{tmp}/credentials"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        if cred.returncode != 0:
            raise RuntimeError(f"--make-credentials failed: {cred.stderr[-500:]}")
        stub = ["--backend", "sim", "--self-test", str(seconds), "--bench-stub"]
        flat_cred = self_test([*stub, "--credentials", f"{tmp}/credentials"])
    qemu, why = qemu_arm_self_test(seconds)
    qemu_minimal = qemu_arm_minimal_loop_us() if qemu else None
    qemu_paced, _ = (
        qemu_arm_self_test(seconds, ("--bench-stub", "--bench-paced"))
        if qemu
        else (
            None,
            why,
        )
    )
    minimal = minimal_loop_us()
    out = {
        "cpu_us_per_poll": flat["cpu_us_per_poll"],
        "cpu_us_per_poll_minimal_loop": round(minimal, 2),
        "ratio_to_minimal_loop": round(flat["cpu_us_per_poll"] / minimal, 2),
        # the poll thread's own CPU (no zenoh or sender thread), as the minimal loop's
        "cpu_us_per_poll_poll_thread": flat["cpu_us_per_poll_poll_thread"],
        "ratio_to_minimal_loop_poll_thread": round(
            flat["cpu_us_per_poll_poll_thread"] / minimal, 2
        ),
        # with credentials: the MAC over every frame (the sender thread's SHA-256)
        "cpu_us_per_poll_with_credentials": flat_cred["cpu_us_per_poll"],
        "ratio_to_minimal_loop_with_credentials": round(flat_cred["cpu_us_per_poll"] / minimal, 2),
        "cpu_us_per_poll_qemu_arm": qemu["cpu_us_per_poll"] if qemu else None,
        "cpu_us_per_poll_poll_thread_qemu_arm": (
            qemu.get("cpu_us_per_poll_poll_thread") if qemu else None
        ),
        "cpu_us_per_poll_minimal_loop_qemu_arm": round(qemu_minimal, 2) if qemu_minimal else None,
        "ratio_to_minimal_loop_qemu_arm": (
            round(qemu["cpu_us_per_poll"] / qemu_minimal, 2) if qemu and qemu_minimal else None
        ),
        "qemu_arm_note": why or "qemu-user timing, not the board's",
        "cpu_percent_paced_qemu_arm": (
            round(qemu_paced["cpu_us_per_poll"] * qemu_paced["rate_hz"] / 1e4, 2)
            if qemu_paced
            else None
        ),
        # peak RSS of the qemu-user process (the chroot has no /proc): qemu's own memory too
        "peak_rss_mb_qemu_arm": qemu["rss_mb"] if qemu else None,
        "cpu_percent_paced": round(paced["cpu_us_per_poll"] * paced["rate_hz"] / 1e4, 2),
        "paced_rate_hz": paced["rate_hz"],
        "rss_mb": spidev["rss_mb"],
        "rss_mb_sim_backend": flat["rss_mb"],
        "polls_flat_out": flat["polls"],
    }
    out.update(link_run(seconds * 3, drops, drop_s))
    out.update(hostile_run(seconds))
    out["goals"] = {
        "cpu_us_per_poll": "<= 3 (x86, two sensors)",
        "cpu_us_per_poll_qemu_arm": "<= 30",
        "rss_mb": "<= 40",
        "counts_lost": "0",
        "latency_p99_ms": "<= 20",
        "ratio_to_minimal_loop": "<= 1.3",
        "ratio_to_minimal_loop_qemu_arm": "<= 1.3",
        "hostile.longest_poll_gap_ms": "<= 50 under every attack, counts_lost 0",
        "hostile_spidev.peak_rss_mb": "<= 40",
    }
    return out


if __name__ == "__main__":
    print(json.dumps(bench_agent(), indent=1))
    sys.exit(0)
