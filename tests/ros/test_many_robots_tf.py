"""Two robots on one /tf (issue 25): each robot's nodes in their own namespace with
``frame_prefix`` r1/ or r2/, TF on, real processes. Every frame on /tf and /tf_static
belongs to one robot, each frame has one parent, and a tf2-style lookup resolves each
robot's tree: map -> odom -> base_link -> each mouse frame."""

from __future__ import annotations

import os
import subprocess

import pytest
from fakes import wait_until

pytest.importorskip("rclpy")
from nav_msgs.msg import Odometry

from mm_beagle.tools.harness import BeagleClient, beagle_process, stop_process
from mm_pc.core.angles import quaternion_yaw

pytestmark = pytest.mark.ros

ROBOTS = {
    "r1": {"backend": "sim", "sim_trajectory": "straight", "sim_speed": 0.2},
    "r2": {"backend": "sim", "sim_trajectory": "still"},
}
MICE = ("mouse_spidev1_0", "mouse_spidev1_1")
COUNTS = tuple(f"{m}_counts" for m in MICE)  # SensorData's frames, children of the mice


def parents_of(transforms) -> dict[str, set[str]]:
    """child frame -> every parent it was published under."""
    out: dict[str, set[str]] = {}
    for t in transforms:
        out.setdefault(t.child_frame_id, set()).add(t.header.frame_id)
    return out


def lookup_chain(parents: dict[str, set[str]], source: str, target: str) -> list[str]:
    """The frames from ``source`` up to ``target`` (tf2's walk to the common parent, here
    always an ancestor); AssertionError if the tree is cut or a frame has two parents."""
    chain = [source]
    while chain[-1] != target:
        up = parents.get(chain[-1])
        assert up, f"{chain[-1]} has no parent: {source} does not reach {target}"
        assert len(up) == 1, f"{chain[-1]} has several parents {up}"
        chain.append(next(iter(up)))
        assert len(chain) < 10, chain
    return chain


def tf2_resolves(transforms, statics, source: str, target: str) -> bool | None:
    """tf2's own lookup where tf2_ros is importable (None where it is not: no PyPI wheel)."""
    try:
        import tf2_ros
        from rclpy.time import Time
    except ImportError:
        return None
    buffer = tf2_ros.Buffer()
    for t in statics:
        buffer.set_transform_static(t, "test")
    for t in transforms:
        buffer.set_transform(t, "test")
    return buffer.can_transform(target, source, Time())


def start(ros_command, module: str, params: dict, ns: str) -> subprocess.Popen:
    return subprocess.Popen(
        ros_command(module, params, ns),
        env=dict(os.environ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def test_two_robots_with_frame_prefixes_share_tf_without_colliding(tmp_path, ros_command):
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import DYNAMIC_QOS, STATIC_LISTENER_QOS

    procs = {}
    for r in ROBOTS:
        prefix = {"frame_prefix": f"{r}/"}
        procs[f"{r} odometry"] = start(
            ros_command, "mm_pc.ros.odometry_node", {"rate": 20.0, **prefix}, f"/{r}"
        )
        procs[f"{r} fusion"] = start(
            ros_command, "mm_pc.ros.fusion_node", {"publish_rate": 10.0, **prefix}, f"/{r}"
        )
    client = BeagleClient("many_robots_client")
    dynamic: list = []
    static: list = []
    onboard: dict[str, list] = {r: [] for r in ROBOTS}  # mm-beagle's own ~/odom
    client.node.create_subscription(
        TFMessage, "/tf", lambda m: dynamic.extend(m.transforms), DYNAMIC_QOS
    )
    client.node.create_subscription(
        TFMessage, "/tf_static", lambda m: static.extend(m.transforms), STATIC_LISTENER_QOS
    )
    for r in ROBOTS:
        client.node.create_subscription(Odometry, f"/{r}/mm_beagle/odom", onboard[r].append, 10)
    logs = {}

    def odom_pose(r: str) -> tuple[float, float, float] | None:
        last = [t for t in list(dynamic) if t.child_frame_id == f"{r}/base_link"]
        if not last:
            return None
        tr = last[-1].transform
        q = tr.rotation
        return tr.translation.x, tr.translation.y, quaternion_yaw(q.x, q.y, q.z, q.w)

    try:
        beagle = {
            r: {**params, "frame_prefix": f"{r}/", "odometry_rate": 10.0}  # publish_tf false
            for r, params in ROBOTS.items()
        }
        with (
            beagle_process(beagle["r1"], dict(os.environ), str(tmp_path / "r1.log"), "/r1"),
            beagle_process(beagle["r2"], dict(os.environ), str(tmp_path / "r2.log"), "/r2"),
        ):
            frames = {"map", "odom", "base_link", *MICE}

            def missing() -> str:
                seen = {t.child_frame_id for t in dynamic + static}
                unseen = {f"{r}/{f}" for r in ROBOTS for f in frames - {"map"}} - seen
                roots = {t.header.frame_id for t in dynamic} & {"r1/map", "r2/map"}
                return "; ".join(
                    [f"frames not yet seen {sorted(unseen)}"] * bool(unseen)
                    + [f"map -> odom only from {sorted(roots)}"] * (len(roots) < 2)
                    + ["r1 not moving"] * ((odom_pose("r1") or (0,))[0] <= 0.05)
                    + [f"no onboard ~/odom from {[r for r, v in onboard.items() if not v]}"]
                    * (not all(onboard.values()))
                )

            try:  # six nodes starting at once: slow on a busy machine
                wait_until(lambda: not missing(), 60, "both trees (r1 moving), onboard odometry")
            except AssertionError as exc:
                raise AssertionError(f"{exc}: {missing()}") from None
            transforms, statics = list(dynamic), list(static)
    finally:
        client.close()
        for name, proc in procs.items():
            stop_process(proc)
            logs[name] = proc.communicate(timeout=5)[0]
    for name, proc in procs.items():
        assert proc.returncode == 0 and "Traceback" not in logs[name], (name, logs[name])

    every = transforms + statics
    names = {t.child_frame_id for t in every} | {t.header.frame_id for t in every}
    # every frame belongs to exactly one robot: nothing unprefixed, nothing shared
    by_robot = {r: {n.removeprefix(f"{r}/") for n in names if n.startswith(f"{r}/")}
                for r in ROBOTS}  # fmt: skip
    assert sum(len(v) for v in by_robot.values()) == len(names), names
    assert by_robot["r1"] == by_robot["r2"] == {"map", "odom", "base_link", *MICE, *COUNTS}
    parents = parents_of(every)
    for r in ROBOTS:
        # who publishes what: mm-odometry odom -> base_link and the mounts, mm-fusion map -> odom
        assert parents[f"{r}/base_link"] == {f"{r}/odom"}
        assert parents[f"{r}/odom"] == {f"{r}/map"}
        assert f"{r}/map" not in parents  # the root of its tree
        for mouse in MICE:
            assert lookup_chain(parents, f"{r}/{mouse}", f"{r}/odom") == [
                f"{r}/{mouse}",
                f"{r}/base_link",
                f"{r}/odom",
            ]
            assert lookup_chain(parents, f"{r}/{mouse}", f"{r}/map")[-1] == f"{r}/map"
            assert tf2_resolves(transforms, statics, f"{r}/{mouse}", f"{r}/odom") in (True, None)
            assert lookup_chain(parents, f"{r}/{mouse}_counts", f"{r}/base_link") == [
                f"{r}/{mouse}_counts",
                f"{r}/{mouse}",
                f"{r}/base_link",
            ]
        other = "r2" if r == "r1" else "r1"
        with pytest.raises(AssertionError, match="no parent"):
            lookup_chain(parents, f"{r}/{MICE[0]}", f"{other}/odom")  # two separate trees
        # mm-beagle's own odometry names its frames with the prefix too
        o = onboard[r][-1]
        assert (o.header.frame_id, o.child_frame_id) == (f"{r}/odom", f"{r}/base_link")
    # each tree carries its own robot's motion: r1 drove forward, r2 stood still
    assert odom_pose("r1")[0] > 0.05
    assert odom_pose("r2") == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    for r in ROBOTS:
        assert f"TF {r}/odom -> {r}/base_link" in logs[f"{r} odometry"], logs[f"{r} odometry"]
        assert f"TF {r}/map -> the mouse odometry's frame" in logs[f"{r} fusion"]
        assert f"e.g. {r}/odom)" in logs[f"{r} fusion"], logs[f"{r} fusion"]


def test_remapping_tf_per_namespace_keeps_two_robots_apart(tmp_path, ros_command):
    """The other remedy: same frame names, ``-r /tf:=tf -r /tf_static:=tf_static`` in each
    robot's namespace, so each tree is on /NS/tf and /NS/tf_static and nothing on /tf."""
    from tf2_msgs.msg import TFMessage

    from mm_pc.ros.tf import DYNAMIC_QOS, STATIC_LISTENER_QOS

    remap = ["-r", "/tf:=tf", "-r", "/tf_static:=tf_static"]
    procs = {}
    for r in ROBOTS:
        cmd = ros_command("mm_pc.ros.odometry_node", {"rate": 20.0}, f"/{r}") + remap
        procs[r] = subprocess.Popen(
            cmd, env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
    client = BeagleClient("tf_remap_client")
    got: dict[str, list] = {}
    for topic, qos in [("/tf", DYNAMIC_QOS), ("/tf_static", STATIC_LISTENER_QOS)] + [
        (f"/{r}/{name}", qos) for r in ROBOTS
        for name, qos in (("tf", DYNAMIC_QOS), ("tf_static", STATIC_LISTENER_QOS))
    ]:  # fmt: skip
        got[topic] = []
        client.node.create_subscription(
            TFMessage, topic, lambda m, topic=topic: got[topic].extend(m.transforms), qos
        )
    logs = {}
    try:
        with (
            beagle_process(ROBOTS["r1"], dict(os.environ), str(tmp_path / "r1.log"), "/r1"),
            beagle_process(ROBOTS["r2"], dict(os.environ), str(tmp_path / "r2.log"), "/r2"),
        ):
            wait_until(
                lambda: (
                    all(got[f"/{r}/{n}"] for r in ROBOTS for n in ("tf", "tf_static"))
                    and any(t.transform.translation.x > 0.05 for t in list(got["/r1/tf"]))
                ),
                60,
                "odom -> base_link and the mounts on /r1/tf(_static) and /r2/tf(_static)",
            )
    finally:
        client.close()
        for r, proc in procs.items():
            stop_process(proc)
            logs[r] = proc.communicate(timeout=5)[0]
    assert not got["/tf"] and not got["/tf_static"]  # nothing on the shared topics
    for r in ROBOTS:
        assert procs[r].returncode == 0 and "Traceback" not in logs[r], logs[r]
        parents = parents_of(got[f"/{r}/tf"] + got[f"/{r}/tf_static"])
        assert parents == {"base_link": {"odom"}, **{m: {"base_link"} for m in MICE},
                           **{f"{m}_counts": {m} for m in MICE}}  # fmt: skip
        for mouse in MICE:
            assert lookup_chain(parents, mouse, "odom") == [mouse, "base_link", "odom"]
    assert all(t.transform.translation.x == 0.0 for t in got["/r2/tf"])  # r2 stands still
