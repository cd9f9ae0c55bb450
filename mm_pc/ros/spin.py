"""Start and spin a node so that Ctrl-C and SIGTERM stop it cleanly (ROS, no Qt)."""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

RCLError = _rclpy.RCLError

#: errors of a node's set-up that mean "bad configuration": exit 2 with the message
SETUP_ERRORS = (ValueError, ParameterException, NameValidationException, OSError)


def params_file_problems(argv: Sequence[str]) -> list[str]:
    """What is wrong with each ``--params-file PATH`` in ``argv``'s ``--ros-args``
    sections ([] when nothing): missing or unreadable, not YAML (also nesting too
    deep for the parser), or not a mapping of node names. Each message names the file.

    rcl would report these as a multi-line RCLError (exit 1) from rclpy.init.
    """
    from mm_pc.core.user_file import read_user_text
    from mm_pc.core.yaml_text import parse_yaml

    problems = []
    in_ros_args = False
    args = list(argv)
    for i, arg in enumerate(args):
        if arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and arg == "--params-file":
            if i + 1 >= len(args):
                problems.append("--params-file needs a YAML file after it")
                continue
            path = Path(args[i + 1])
            where = f"--params-file {path}"
            try:  # a regular file only: a FIFO blocked the start for ever
                text = read_user_text(path)
            except UnicodeDecodeError:
                problems.append(f"{where}: not a text file (a YAML parameter file is expected)")
                continue
            except OSError as e:
                problems.append(f"{where}: cannot read it ({e.strerror or e})")
                continue
            try:
                data = parse_yaml(text, _ros_params_loader())
            except ValueError as e:
                problems.append(f"{where}: {e}")
                continue
            if not isinstance(data, dict):
                problems.append(
                    f"{where}: expected a mapping 'node_name: {{ros__parameters: {{...}}}}', "
                    f"got {type(data).__name__}"
                )
            elif problem := _layout_problem(data):
                problems.append(f"{where}: {problem}")
    return problems


def _ros_params_loader() -> type:
    """A safe YAML loader that also reads a ``!!python/tuple`` as a list: launch_ros writes a
    Node's dict of parameters with ``yaml.dump``, a list value as that tag, and rcl's parser
    reads it (``ros2 launch mm_beagle beagle.launch.py chips:=pmw3389`` was refused)."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_constructor(
        "tag:yaml.org,2002:python/tuple", lambda loader, node: loader.construct_sequence(node)
    )
    return Loader


def _layout_problem(tree: dict, path: str = "") -> str:
    """Why ``tree`` is not ``node: {ros__parameters: {name: value}}`` ('' if it is)."""
    for key, value in tree.items():
        where = f"{path}{key}"
        if not isinstance(value, dict):
            what = "parameters" if key == "ros__parameters" else "a node or namespace"
            return (
                f"'{where}' must be a mapping ({what}), got {type(value).__name__}; "
                "allowed layout: node_name: {ros__parameters: {name: value}}"
            )
        if key != "ros__parameters" and (problem := _layout_problem(value, where + ".")):
            return problem
    return ""


def init(argv: list[str] | None, prog: str = "") -> threading.Event:
    """rclpy.init without rclpy's signal handlers; SIGINT/SIGTERM set the returned event.

    A bad ``--params-file`` (:func:`params_file_problems`, or any other argument
    rcl refuses) prints ``prog: what is wrong`` (one line) and exits 2
    (SystemExit), before any node exists.

    The handler must not call into rclpy: it can run while the main thread
    holds the context's lock (inside Context.ok()), and try_shutdown() would
    then wait for that same lock forever. rclpy's own handler is not used
    either, since it re-raises KeyboardInterrupt later, possibly in the middle
    of a node's clean-up.
    """
    args = argv if argv is not None else sys.argv
    prog = prog or Path(sys.argv[0]).name
    if problems := params_file_problems(args):
        _config_exit(prog, "; ".join(problems))
    refused = ""
    with _stderr_held() as held:  # rcl logs its own "[ERROR] ... Failed to parse" first
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError as e:  # an argument rcl refuses: its first line says which
            refused = f"bad --ros-args: {_first_line(str(e))}"
        except _rclpy.UnknownROSArgsError as e:
            refused = f"unknown --ros-args {e}"
        if refused:
            held.drop()
    if refused:
        _config_exit(prog, refused)
    stop = threading.Event()

    def handler(_signum, _frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


class _stderr_held:  # noqa: N801 - used as a context manager
    """Hold what C code writes to fd 2 inside the block; pass it on at the end unless dropped."""

    def __enter__(self):
        import tempfile

        sys.stderr.flush()
        self._file = tempfile.TemporaryFile()
        self._saved = os.dup(2)
        os.dup2(self._file.fileno(), 2)
        self._keep = True
        return self

    def drop(self) -> None:
        self._keep = False

    def __exit__(self, *_exc) -> None:
        sys.stderr.flush()
        os.dup2(self._saved, 2)
        os.close(self._saved)
        if self._keep:
            self._file.seek(0)
            sys.stderr.buffer.write(self._file.read())
            sys.stderr.flush()
        self._file.close()


def _first_line(text: str) -> str:
    """rcl's message without its source locations (", at /.../parse.c:818")."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return lines[0].split(", at /")[0] if lines else "refused by rcl"


def _config_exit(prog: str, message: str) -> None:
    print(f"{prog}: {message}", file=sys.stderr, flush=True)
    raise SystemExit(2)


def stopping() -> None:
    """Ignore further SIGINT/SIGTERM: the node is already shutting down.

    Python restores the default handlers during interpreter finalisation, so
    an impatient second Ctrl-C arriving then would kill the process with
    SIGINT (exit -2) instead of the clean exit 0; an ignored signal stays
    ignored through finalisation.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def spin_until(node: Node, stop: threading.Event, executor=None) -> None:
    """Spin ``node`` until ``stop`` is set or the context shuts down (checked every 0.1 s).

    ``executor``: the executor to use (default: a new SingleThreadedExecutor);
    it is shut down on return.
    """
    executor = executor if executor is not None else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()


def run(
    prog: str,
    make_node: Callable[[], Node],
    body: Callable[[Node, threading.Event], int | None],
    argv: list[str] | None = None,
    errors: tuple[type[BaseException], ...] = SETUP_ERRORS,
) -> int:
    """The ``main`` of a node: init, build, run ``body``, clean stop; the exit code.

    A configuration error (``errors``) prints ``prog: message`` to stderr and
    gives 2; ``body``'s return value (None = 0) otherwise. Ctrl-C and SIGTERM
    end ``body`` through the stop event; the node is destroyed and rclpy shut
    down whatever happened.
    """
    stop = init(argv, prog)
    node = None
    code = 0
    try:
        node = make_node()
        code = body(node, stop) or 0
    except errors as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        code = 2
    finally:
        stopping()
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code
