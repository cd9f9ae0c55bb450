"""The agent's sim backend mounts its emulated sensors where ``--sim-mounts`` says, as the
node's ``sim_mounts`` does (mm-monitor --sim --agent --sim-mounts; issue 27 follow-up)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from mm_beagle.link import agent_cli
from mm_beagle.link.agent import AgentPoller, make_state

LISTEN = ["--listen", "tcp/127.0.0.1:7447", "--realtime-priority", "0"]


def _poller(*args: str) -> AgentPoller:
    cfg = agent_cli.config_from_args(agent_cli.build_parser().parse_args([*LISTEN, *args]))
    return AgentPoller(cfg.poller, make_state(cfg.poller))


def test_the_agents_emulated_polls_follow_off_nominal_mounts() -> None:
    """Straight ahead at 0.2 m/s: a sensor turned by a yaw sees the motion turned by that
    yaw in its own counts (+30 and -20 deg: opposite ways), against the same run as designed."""
    yaws = (30.0, -20.0)
    mounts = ";".join(f"0.05,{y},{yaw}" for y, yaw in zip((-0.04, 0.04), yaws, strict=True))
    base = ["--backend", "sim", "--sim-trajectory", "straight", "--sim-speed", "0.2"]
    turned = _poller(*base, "--sim-mounts", mounts)
    assert turned.cfg.sim.mounts == [
        (0.05, -0.04, math.radians(30.0)),
        (0.05, 0.04, math.radians(-20.0)),
    ]
    nominal = _poller(*base)
    for poller in (turned, nominal):
        poller.run(max_polls=400, paced=True)  # 0.4 s of the sim's clock: ~5000 counts
        # (unpaced, 400 polls took ~4 ms: ~50 counts, too few for 0.02 rad under load)
    turn = []  # the direction of each sensor's counts, turned against as designed
    for i in range(2):
        t, n = turned.state.snapshot(i), nominal.state.snapshot(i)
        assert (t.x_total, t.y_total) == (t.gen_x, t.gen_y)  # nothing lost
        assert math.hypot(t.x_total, t.y_total) > 50 and math.hypot(n.x_total, n.y_total) > 50
        turn.append(math.atan2(t.x_total, t.y_total) - math.atan2(n.x_total, n.y_total))
    sign = math.copysign(1.0, turn[0])  # the chip's axis convention
    for i, yaw in enumerate(yaws):
        assert turn[i] == pytest.approx(sign * math.radians(yaw), abs=0.02)


@pytest.mark.parametrize(
    ("mounts", "why"),
    [
        ("0.05,0,1", "'sim_mounts' has 1 sensors for 2 devices"),
        ("0.05,0;0.05,0,1", "'sim_mounts' needs X,Y,YAW per sensor (m, m, degrees)"),
        ("0.05,0,999;0.05,0,1", "'sim_mounts': sensor 0 (0.05,0,999) needs |x|, |y| <= 1 m"),
        ("0.05,nan,1;0.05,0,1", "'sim_mounts': sensor 0 (0.05,nan,1) needs"),
    ],
)
def test_bad_sim_mounts_exit_2_with_one_line(mounts: str, why: str) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "mm_beagle.link.agent_cli", "--backend", "sim", *LISTEN,
         "--sim-mounts", mounts, "--self-test", "1"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        line for line in out.stderr.strip().splitlines() if line.startswith("mm-beagle-agent")
    ]
    assert len(out.stderr.strip().splitlines()) == 1
    assert out.stderr.startswith(f"mm-beagle-agent: error: {why}")
    assert out.stdout == ""  # never ran


def test_sim_mounts_need_the_sim_backend_and_take_a_leading_minus() -> None:
    with pytest.raises(ValueError, match="'sim_mounts' goes with backend sim"):
        agent_cli.config_from_args(
            agent_cli.build_parser().parse_args(
                agent_cli._joined([*LISTEN, "--backend", "spidev", "--sim-mounts", "0,0,0;0,0,0"])
            )
        )
    args = agent_cli.build_parser().parse_args(
        agent_cli._joined([*LISTEN, "--backend", "sim", "--sim-mounts", "-0.05,0,0;-0.05,0.1,-3"])
    )
    assert agent_cli.config_from_args(args).poller.sim.mounts[1] == (
        -0.05,
        0.1,
        math.radians(-3),
    )


def test_the_monitor_passes_its_sim_mounts_to_the_agent(monkeypatch) -> None:
    """mm-monitor --sim calibration_run --agent [--sim-mounts ...]: the mounts reach the
    agent's command line (harness.emulated_sensors) and the agent's sim backend, exactly."""
    import argparse
    import contextlib

    from mm_beagle.tools import harness
    from mm_pc.monitor import app
    from mm_pc.monitor.model.sim_mounts import CALIBRATION_SIM_MOUNTS, to_parameter

    args = argparse.Namespace(sim="calibration_run", agent=True, sim_mounts="-0.05,0.02,4;0.05,0,0")
    assert app._sim_mounts_problem(args) == ""
    assert to_parameter(app._sim_mounts(args)) == pytest.approx(
        [-0.05, 0.02, math.radians(4), 0.05, 0.0, 0.0]
    )
    args.sim_mounts = None  # calibration_run's known error, behind the agent too
    assert app._sim_mounts(args) == CALIBRATION_SIM_MOUNTS

    started: list[dict] = []

    @contextlib.contextmanager
    def fake(options, *rest):
        started.append(options)
        yield None

    monkeypatch.setattr(harness, "agent_process", fake)
    monkeypatch.setattr(harness, "beagle_process", fake)
    param = to_parameter(CALIBRATION_SIM_MOUNTS)
    with harness.emulated_sensors("calibration_run", {}, "/nonexistent/log", True, "", param):
        pass
    command = harness.agent_command({**started[0], "listen": ["tcp/127.0.0.1:7447"]})
    parsed = agent_cli.build_parser().parse_args(agent_cli._joined(command[3:]))
    mounts = agent_cli.config_from_args(parsed).poller.sim.mounts
    assert [v for m in mounts for v in m] == pytest.approx(param, abs=1e-12)
    assert "sim_mounts" not in started[1]  # the node in remote mode emulates nothing
