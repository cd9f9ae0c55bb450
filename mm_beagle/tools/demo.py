"""./compile demo: mm-beagle on emulated sensors driving a figure eight, plus a live view.

The node runs as its own process with the sim backend (two emulated sensors,
PLN2033s unless ``--sim-chips`` names others, behind the real drivers, fed by the
ground-truth simulator); the live text view
(mm-watch) shows what it serves until Ctrl-C, or for ``--duration`` seconds.
Both use a private ROS_DOMAIN_ID and localhost-only discovery.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile

from mm_beagle.tools.harness import BeagleClient, beagle_process, use_isolated_ros_env


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="./compile demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=0.0, help="seconds; 0 = until Ctrl-C")
    parser.add_argument("--trajectory", default="figure_eight", help="sim path of the robot")
    parser.add_argument(
        "--sim-chips",
        default="",
        help="emulated chip of each sensor, e.g. pmw3360,pmw3360 (default pln2033)",
    )
    args = parser.parse_args(argv)
    if args.duration < 0:
        parser.error("--duration must be >= 0")
    env = use_isolated_ros_env()
    folder = tempfile.mkdtemp(prefix="mm-demo-")  # private: mode 700
    code = 1
    try:
        code = _run(args, env, os.path.join(folder, "mm_beagle.log"))
    finally:
        if code == 0:  # a failure's message names the log: then it stays
            shutil.rmtree(folder, ignore_errors=True)
    return code


def _run(args, env: dict, log: str) -> int:
    """The node on emulated sensors and the live view; 0 when data arrived."""
    print(
        f"Starting mm-beagle on emulated sensors (trajectory {args.trajectory}, "
        f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}); node log: {log}",
        flush=True,
    )
    params: dict[str, object] = {"backend": "sim", "sim_trajectory": args.trajectory}
    if args.sim_chips:
        params["chips"] = [args.sim_chips]
    with beagle_process(params, env=env, log_path=log) as proc:
        client = BeagleClient("mm_demo")
        ready = client.wait(30)
        client.close()
        if not ready or proc.poll() is not None:
            print(f"mm-beagle did not come up; see {log}", file=sys.stderr)
            return 1
        print("mm-beagle is up. Live view (Ctrl-C to stop):", flush=True)
        from mm_beagle.tools.watch import run

        received = run(args.duration, "/mm_beagle", 0.5)
    print(f"Stopped. {received} SensorData messages received.")
    return 0 if received else 1


if __name__ == "__main__":
    sys.exit(main())
