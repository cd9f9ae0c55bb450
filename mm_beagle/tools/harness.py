"""Run mm-beagle as a separate process and talk to it over real ROS 2 services.

Used by the demo, the benchmarks and the integration tests. Every run gets
localhost-only discovery (UDP on 127.0.0.1, no shared memory) and, unless the user set
ROS_DOMAIN_ID, its own random domain (1..101) that no other run of ours holds, so nothing
leaves this machine and parallel runs do not see each other.
"""

from __future__ import annotations

import math
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from mm_pc.ros.services import service_types

ISOLATED_MARK = "MM_ISOLATED_ROS_DOMAIN"  # set once a process has its private domain


#: private domains are drawn from here: inside 0..101, which the ROS 2 docs call safe on
#: Linux (higher ids reach into the ephemeral port range), and not 0, every ROS 2's default
ISOLATED_DOMAINS = range(1, 102)


#: the socket whose abstract name holds this process's private domain (see _reserve_domain)
_domain_hold = None


def _reserve_domain() -> int:
    """A random id of :data:`ISOLATED_DOMAINS` that no other process of ours holds.

    Held by binding the abstract Unix socket name ``mm-ros-domain-<id>`` (Linux): the
    kernel refuses a second binder and frees the name when this process ends, so two
    test runs or demos at once never share a domain (a random pick alone met another
    run's /mm_beagle about once in ten runs beside four others) and no file is left.
    """
    global _domain_hold
    ids = list(ISOLATED_DOMAINS)
    random.shuffle(ids)
    for domain in ids:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            sock.bind(f"\0mm-ros-domain-{domain}")
        except OSError:  # held by another run (or no abstract names here: take the pick)
            sock.close()
            if sys.platform != "linux":
                return domain
            continue
        _domain_hold = sock
        return domain
    return ids[0]  # all 101 held: share one rather than fail


def isolated_ros_env(domain_id: int | None = None, keep_user_domain: bool = True) -> dict[str, str]:
    """This process's environment with a private domain and localhost-only discovery.

    A process that already has one (a test session, the demo) keeps it: a second,
    different domain would cut it off from the nodes it already talks to. A
    ROS_DOMAIN_ID the user set is kept too (their nodes live there); only without
    one (or with ``keep_user_domain=False``: the test suite, which must not meet
    a user's live nodes) is a random id of :data:`ISOLATED_DOMAINS` chosen.
    """
    env = dict(os.environ)
    if domain_id is None:
        user = env.get("ROS_DOMAIN_ID", "").strip() if keep_user_domain else ""
        kept = env.get(ISOLATED_MARK) or user
        domain_id = int(kept) if kept.isdigit() else _reserve_domain()
    env["ROS_DOMAIN_ID"] = env[ISOLATED_MARK] = str(domain_id)
    env.pop("ROS_STATIC_PEERS", None)
    _localhost_transports(env)
    env["PYTHONUNBUFFERED"] = "1"
    return env


#: the environment keys :func:`_localhost_transports` sets (and use_isolated_ros_env copies)
DDS_KEYS = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "FASTRTPS_DEFAULT_PROFILES_FILE")

#: the name our profile files start with (a parent's is kept, whatever its folder)
PROFILE_PREFIX = "mm-fastdds-localhost-"

#: Fast DDS participants of our localhost runs: UDPv4 on 127.0.0.1 only, no shared memory
#: (multicast discovery on loopback, 127.0.0.1 also as initial peer)
LOCALHOST_UDP_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>mm_localhost_udp</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="mm_localhost_udp" is_default_profile="true">
    <rtps>
      <userTransports><transport_id>mm_localhost_udp</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
      <builtin>
        <initialPeersList>
          <locator><udpv4><address>127.0.0.1</address></udpv4></locator>
        </initialPeersList>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


def _localhost_transports(env: dict[str, str]) -> None:
    """Keep ``env``'s ROS traffic on this machine, without Fast DDS shared memory.

    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` makes rmw_fastrtps add its shared-memory
    transport whatever a profile or FASTDDS_BUILTIN_TRANSPORTS says, and that transport's
    port files in /dev/shm (left by killed runs, another user's, or locked under load) print
    a red ``[RTPS_TRANSPORT_SHM Error] Failed init_port ...`` at start. So with Fast DDS
    (the default RMW) the discovery range is left at SUBNET and a default profile limits
    every participant to UDPv4 on 127.0.0.1 (:data:`LOCALHOST_UDP_PROFILE`): nothing leaves
    the machine either. A user's own profile file or another RMW keeps LOCALHOST.
    """
    env.pop("ROS_LOCALHOST_ONLY", None)  # Jazzy maps it to LOCALHOST (and SHM)
    rmw = env.get("RMW_IMPLEMENTATION", "").strip()
    users = [p for p in (env.get("FASTRTPS_DEFAULT_PROFILES_FILE", ""),
                         env.get("FASTDDS_DEFAULT_PROFILES_FILE", ""))
             if p and not Path(p).name.startswith(PROFILE_PREFIX)]  # ours: a parent's
    if rmw not in ("", "rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp") or users:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        return
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = localhost_profile_file()


def localhost_profile_file() -> str:
    """:data:`LOCALHOST_UDP_PROFILE` as a file for FASTRTPS_DEFAULT_PROFILES_FILE, rewritten
    atomically when its text differs.

    It lives in the user's cache folder (``$XDG_CACHE_HOME/mouse-monitor``, default
    ``~/.cache/...``), not in /tmp: a run must not leave files in the shared temporary
    folder, and this one is reused by every later run. Without a writable home it falls
    back to the temporary folder.
    """
    import tempfile

    name = f"{PROFILE_PREFIX}{os.getuid()}.xml"
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    folder = Path(cache) / "mouse-monitor"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK):
            raise PermissionError(folder)
    except OSError:
        folder = Path(tempfile.gettempdir())
    path = folder / name
    with suppress(OSError):
        if path.read_text() == LOCALHOST_UDP_PROFILE:
            return str(path)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=name, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(LOCALHOST_UDP_PROFILE)
    os.replace(tmp, path)
    return str(path)


def use_isolated_ros_env(
    domain_id: int | None = None, keep_user_domain: bool = True
) -> dict[str, str]:
    """Apply :func:`isolated_ros_env` to this process (before rclpy.init)."""
    env = isolated_ros_env(domain_id, keep_user_domain)
    for key in ("ROS_DOMAIN_ID", ISOLATED_MARK, *DDS_KEYS):
        if key in env:
            os.environ[key] = env[key]
    for key in ("ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY"):
        os.environ.pop(key, None)
    return env


def node_command(params: dict[str, object], namespace: str = "") -> list[str]:
    """The command line of mm-beagle with ``-p name:=value`` for each parameter."""
    cmd = [sys.executable, "-m", "mm_beagle.node", "--ros-args"]
    if namespace:
        cmd += ["-r", f"__ns:={namespace}"]
    for name, value in params.items():
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, (list, tuple)):
            text = "[" + ",".join(f"'{v}'" if isinstance(v, str) else repr(v) for v in value) + "]"
        else:
            text = str(value)
        cmd += ["-p", f"{name}:={text}"]
    return cmd


def _stop_with_parent() -> None:
    """In the child before exec: SIGINT when the parent dies (PR_SET_PDEATHSIG, Linux).

    A test run or demo that is killed (or aborts) then leaves no node running
    in the background; SIGINT gives the node its clean shutdown. An ignored
    signal stays ignored across exec, and a background job (``nohup ... &``)
    starts with SIGINT ignored, so SIGINT and SIGTERM are first reset to their
    default action and unblocked (libc calls: Python's ``signal`` works in the
    main thread only, and a child may be forked from another).
    """
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    libc.signal.restype = ctypes.c_void_p
    libc.signal.argtypes = (ctypes.c_int, ctypes.c_void_p)
    for sig in (signal.SIGINT, signal.SIGTERM):
        libc.signal(int(sig), None)  # SIG_DFL
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    libc.prctl(1, int(signal.SIGINT), 0, 0, 0)  # PR_SET_PDEATHSIG


@contextmanager
def beagle_process(
    params: dict[str, object],
    env: dict[str, str] | None = None,
    log_path: str | None = None,
    namespace: str = "",
) -> Iterator[subprocess.Popen]:
    """mm-beagle in a subprocess (in ``namespace``); stopped with SIGINT (then SIGKILL) on exit."""
    with _child(node_command(params, namespace), env or isolated_ros_env(), log_path) as proc:
        yield proc


@contextmanager
def _child(cmd: list[str], env: dict[str, str], log_path: str | None) -> Iterator[subprocess.Popen]:
    """``cmd`` in a subprocess that stops with its parent; SIGINT (then SIGKILL) on exit."""
    out = open(log_path, "w") if log_path else subprocess.DEVNULL  # noqa: SIM115
    proc = subprocess.Popen(
        cmd,
        env=env,
        stdout=out,
        stderr=subprocess.STDOUT,
        preexec_fn=_stop_with_parent if sys.platform.startswith("linux") else None,
    )
    try:
        yield proc
    finally:
        stop_process(proc)
        if not isinstance(out, int):  # a log file, not DEVNULL
            out.close()


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> int:
    """SIGINT, wait; SIGKILL if it does not stop. Returns the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
    return proc.returncode


def free_port() -> int:
    """A TCP port on loopback that nothing listens on now (for a test's agent)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def agent_command(options: dict[str, object]) -> list[str]:
    """The command line of mm-beagle-agent with ``--name value`` for each option."""
    cmd = [sys.executable, "-m", "mm_beagle.link.agent_cli"]
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if isinstance(value, bool):
            cmd.append(flag if value else "--no-" + name.replace("_", "-"))
        elif isinstance(value, (list, tuple)):
            if name == "listen":
                for v in value:
                    cmd += [flag, str(v)]
            else:
                cmd += [flag, *map(str, value)]
        else:
            cmd += [flag, str(value)]
    return cmd


@contextmanager
def agent_process(
    options: dict[str, object], log_path: str | None = None
) -> Iterator[subprocess.Popen]:
    """mm-beagle-agent in a subprocess (stopped with SIGINT, and with its parent)."""
    cmd = agent_command({"realtime_priority": 0, **options})
    with _child(cmd, {**os.environ, "PYTHONUNBUFFERED": "1"}, log_path) as proc:
        yield proc


@contextmanager
def emulated_sensors(
    trajectory: str,
    env: dict[str, str],
    log_path: str,
    through_agent: bool = False,
    chips: str = "",
    sim_mounts: list[float] | None = None,
) -> Iterator[subprocess.Popen]:
    """mm-beagle on emulated sensors: its own sim backend, or (``through_agent``) an
    mm-beagle-agent on emulated sensors and the node in backend:=remote on its link,
    the whole BBB chain on this machine. ``chips``: "pmw3360,pmw3360" (one per device,
    or one for all; '' = PLN2033s); ``sim_mounts``: the node's parameter (x, y, yaw rad
    per sensor; the agent gets them as its --sim-mounts). Yields the node's process."""
    chip_param = {"chips": [chips]} if chips else {}
    if not through_agent:
        params = {"backend": "sim", "sim_trajectory": trajectory, **chip_param}
        if sim_mounts:
            params["sim_mounts"] = sim_mounts
        with beagle_process(params, env, log_path) as p:
            yield p
        return
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agent_opts = {"backend": "sim", "sim_trajectory": trajectory, "listen": [endpoint]}
    if chips:
        agent_opts["chips"] = chips
    if sim_mounts:  # the agent's form: "X,Y,YAW;..." (m, m, degrees)
        m = [float(v) for v in sim_mounts]
        agent_opts["sim_mounts"] = ";".join(
            f"{m[k]!r},{m[k + 1]!r},{math.degrees(m[k + 2])!r}" for k in range(0, len(m), 3)
        )
    with (
        agent_process(agent_opts, log_path + ".agent"),
        beagle_process(
            {"backend": "remote", "agent": endpoint, **chip_param}, env, log_path
        ) as node,
    ):
        yield node


class BeagleClient:
    """A client node with its executor spun in a background thread.

    Calls wait on a threading.Event set by the future's done callback.
    (rclpy 7.1's ``spin_until_future_complete`` busy-loops the executor and
    measured 5-20 ms per round trip here; this pattern measured under 1 ms.)
    Also keeps the newest /diagnostics message.
    """

    def __init__(self, name: str = "mm_client", namespace: str = "/mm_beagle") -> None:
        import threading

        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor

        if not rclpy.ok():
            rclpy.init()
        self.node = rclpy.create_node(name)
        self.types = service_types()
        self.clients = {
            n: self.node.create_client(t, f"{namespace}/{n}") for n, t in self.types.items()
        }
        from rcl_interfaces.srv import GetParameters, SetParameters

        self._params_set = self.node.create_client(SetParameters, f"{namespace}/set_parameters")
        self._params_get = self.node.create_client(GetParameters, f"{namespace}/get_parameters")
        self._diag_lock = threading.Lock()
        self._diag: list[tuple[float, object]] = []
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=f"{name}_spin", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        with suppress(ExternalShutdownException, RuntimeError):
            self.executor.spin()

    def _on_diag(self, msg) -> None:
        with self._diag_lock:
            self._diag.append((time.monotonic(), msg))
            del self._diag[:-5]

    def wait(self, timeout: float = 20.0) -> bool:
        """Wait until every service of the node is available."""
        deadline = time.monotonic() + timeout
        for client in self.clients.values():
            if not client.wait_for_service(timeout_sec=max(0.0, deadline - time.monotonic())):
                return False
        return True

    def call(self, name: str, timeout: float = 5.0, retries: int = 0, **fields):
        """Call service ``name`` and wait up to ``timeout`` s for the reply.

        ``retries``: for requests that change nothing (settings, samples) only, send
        again after a timeout: a request made just after discovery can go unanswered.
        """
        client, request = self.clients[name], self.types[name].Request(**fields)
        for _ in range(retries):
            with suppress(TimeoutError):
                return self._wait_future(client, request, name, timeout)
        return self._wait_future(client, request, name, timeout)

    def _wait_future(self, client, request, what: str, timeout: float):
        import threading

        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            client.remove_pending_request(future)
            raise TimeoutError(f"{what} did not answer within {timeout} s")
        return future.result()

    def set_parameters(self, timeout: float = 5.0, **values) -> list:
        """``ros2 param set`` for each name=value: the node's SetParametersResult per name."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        req = SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
        )
        return self._wait_future(self._params_set, req, "set_parameters", timeout).results

    def get_parameters(self, *names: str, timeout: float = 5.0) -> list:
        """The node's current values of ``names`` (Python values)."""
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        req = GetParameters.Request(names=list(names))
        res = self._wait_future(self._params_get, req, "get_parameters", timeout)
        return [parameter_value_to_python(v) for v in res.values]

    def trigger(self, service: str, timeout: float = 5.0):
        """Call the std_srvs/Trigger ``service`` (full name, e.g. /mm_odometry/reset): its reply."""
        from std_srvs.srv import Trigger

        client = self.node.create_client(Trigger, service)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                raise TimeoutError(f"{service} is not offered")
            return self._wait_future(client, Trigger.Request(), service, timeout)
        finally:
            self.node.destroy_client(client)

    def diagnostics(
        self, newer_than: float = 0.0, timeout: float = 5.0
    ) -> dict[str, dict[str, str]]:
        """The newest /diagnostics received after ``newer_than`` (monotonic s), per device."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._diag_lock:
                fresh = [m for t, m in self._diag if t > newer_than]
            if fresh:
                return {
                    s.hardware_id: {kv.key: kv.value for kv in s.values} for s in fresh[-1].status
                }
            time.sleep(0.05)
        raise TimeoutError("no /diagnostics from mm_beagle")

    def close(self) -> None:
        """Stop the spin thread, then destroy the node (never while the thread still
        waits on the node's handles: that raised in the thread on a busy machine)."""
        self.executor.shutdown(timeout_sec=10.0)
        self._thread.join(10.0)
        if not self._thread.is_alive():
            self.node.destroy_node()
