"""The ROS packages' launch files: they start the executables and parameters the tests run.

``launch``/``launch_ros`` are not among the PyPI ROS wheels, so where they cannot be imported
each launch file is checked statically (ast): every executable is a console script of its
package whose entry module the tests run, every parameter name is in the node's parameter
table, every params file exists and holds only known parameters, every included launch file
exists and declares the arguments given to it, every LaunchConfiguration is declared. Where
``launch`` is importable, each file is also imported and its description built.
"""

from __future__ import annotations

import ast
import importlib.util
import re
from functools import cache
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("mm_beagle", "mm_pc")
LAUNCH_FILES = sorted(p for pkg in PACKAGES for p in (ROOT / pkg / "launch").glob("*.launch.py"))
#: configurations launch_ros itself keeps (PushRosNamespace's), read with a default
LAUNCH_ROS_CONFIGURATIONS = frozenset({"ros_namespace"})
# The node modules whose PARAMETERS table lives elsewhere.
PARAM_TABLE_FILE = {
    "mm_beagle.node.node": "mm_beagle/node/params.py",
    "mm_pc.ros.fusion_node": "mm_pc/ros/fusion_params.py",
}


@cache
def scripts() -> dict[str, str]:
    """pyproject's console scripts: name -> the program module its launcher in
    ``<package>/commands.py`` starts (``prerequisites.launch("<program>", "<module>")``)."""
    text = (ROOT / "pyproject.toml").read_text()
    body = re.search(r"^\[project\.scripts\]\n(.*?)(?=^\[)", text, re.M | re.S).group(1)
    out = {}
    for name, target in re.findall(r'^([\w-]+) = "([\w.:]+)"', body, re.M):
        module, _, func = target.partition(":")
        tree = ast.parse(_module_file(module).read_text())
        launcher = next(f for f in tree.body if isinstance(f, ast.FunctionDef) and f.name == func)
        call = next(n for n in ast.walk(launcher) if isinstance(n, ast.Call) and n.args)
        out[name] = call.args[1].value
    return out


def _module_file(module: str) -> Path:
    return ROOT / (module.replace(".", "/") + ".py")


@cache
def parameter_names(module: str) -> frozenset[str]:
    """The keys of the PARAMETERS dict literal of a node module (read, not imported)."""
    path = ROOT / PARAM_TABLE_FILE.get(module, _module_file(module).relative_to(ROOT))
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "PARAMETERS" for t in node.targets
        ):
            return frozenset(k.value for k in node.value.keys)
    raise AssertionError(f"no PARAMETERS table in {path}")


@cache
def node_name(module: str) -> str:
    """The name a node module gives its node (NODE_NAME or super().__init__("...")."""
    text = _module_file(module).read_text()
    found = re.search(r'^NODE_NAME = "(\w+)"', text, re.M) or re.search(
        r'super\(\).__init__\("(\w+)"', text
    )
    assert found, module
    return found.group(1)


NODE_MODULES = {node_name(m): m for m in {scripts()[s] for s in scripts()} if "node" in m}


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _kw(call: ast.Call, name: str):
    return next((k.value for k in call.keywords if k.arg == name), None)


def _const(node) -> str:
    assert isinstance(node, ast.Constant) and isinstance(node.value, str), ast.dump(node)
    return node.value


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and _call_name(n) == name]


def tree_of(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


def declared_arguments(tree: ast.AST) -> set[str]:
    return {_const(c.args[0]) for c in calls(tree, "DeclareLaunchArgument")}


def share_paths(tree: ast.AST) -> list[tuple[str, Path]]:
    """PathJoinSubstitution([FindPackageShare("pkg"), "a", "b"]) -> (pkg, pkg's source a/b)."""
    out = []
    for call in calls(tree, "PathJoinSubstitution"):
        first, *rest = call.args[0].elts
        if not (isinstance(first, ast.Call) and _call_name(first) == "FindPackageShare"):
            continue  # not in a package's share folder (robot.launch.py's node names)
        if not isinstance(first.args[0], ast.Constant):
            continue  # robot.launch.py's include helper: its calls are checked there
        pkg = _const(first.args[0])
        out.append((pkg, ROOT / pkg / Path(*(_const(p) for p in rest))))
    return out


def package_of(path: Path) -> str:
    return path.relative_to(ROOT).parts[0]


def test_there_are_the_launch_files_the_issue_names():
    names = {(package_of(p), p.name) for p in LAUNCH_FILES}
    assert names == {
        ("mm_beagle", "beagle.launch.py"),
        ("mm_beagle", "robot.launch.py"),
        ("mm_pc", "odometry.launch.py"),
        ("mm_pc", "fusion.launch.py"),
        ("mm_pc", "monitor.launch.py"),
    }


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_statically(path):
    tree = tree_of(path)
    assert any(
        isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description"
        for n in tree.body
    )
    declared = declared_arguments(tree)
    used = {_const(c.args[0]) for c in calls(tree, "LaunchConfiguration")}
    used -= LAUNCH_ROS_CONFIGURATIONS
    assert used <= declared, f"undeclared launch arguments {used - declared}"

    tested = "\n".join(p.read_text() for p in (ROOT / "tests").rglob("*.py"))
    tested += (ROOT / "mm_beagle/tools/harness.py").read_text()
    for node in calls(tree, "Node"):
        pkg, exe = _const(_kw(node, "package")), _const(_kw(node, "executable"))
        module = scripts().get(exe)
        assert module and module.startswith(pkg + "."), f"{exe} is no console script of {pkg}"
        assert f'"{module}"' in tested, f"the tests never run {module}"
        assert _const(_kw(node, "name")) == node_name(module)
        for names in _parameter_overrides(tree, node):
            unknown = names - parameter_names(module)
            assert not unknown, f"{exe} declares no parameter {unknown}"
    for call in calls(tree, "ExecutableInPackage"):
        exe, pkg = _const(call.args[0]), _const(call.args[1])
        assert scripts()[exe].startswith(pkg + ".")
    for pkg, source in share_paths(tree):
        assert source.is_file(), f"{source} (share/{pkg}/...) does not exist"
        if source.suffix == ".yaml":
            check_params_file(source)


def _parameter_overrides(tree: ast.Module, node: ast.Call) -> list[set[str]]:
    """The parameter names a Node call sets: its ``parameters=[..., {dict}]`` literals, or,
    where it is built in a function (launch's OpaqueFunction), every dict literal and
    ``d["name"] = ...`` of that function."""
    entries = _kw(node, "parameters")
    if isinstance(entries, ast.List):
        found = [{_const(k) for k in e.keys} for e in entries.elts if isinstance(e, ast.Dict)]
        if all(isinstance(e, ast.Dict | ast.Call) for e in entries.elts):
            return found
    function = next(
        f
        for f in tree.body
        if isinstance(f, ast.FunctionDef) and any(n is node for n in ast.walk(f))
    )
    found = [{_const(k) for k in d.keys} for d in ast.walk(function) if isinstance(d, ast.Dict)]
    for sub in ast.walk(function):
        if isinstance(sub, ast.Assign) and isinstance(sub.targets[0], ast.Subscript):
            found.append({_const(sub.targets[0].slice)})
    return found


def check_params_file(path: Path) -> None:
    data = yaml.safe_load(path.read_text())
    assert data, path
    for key, section in data.items():
        # /**/NAME: the node in any namespace (a bare NAME would match only /NAME)
        assert key.startswith("/**/"), f"{path.name}: {key} applies only outside a namespace"
        node = key.removeprefix("/**/")
        assert node in NODE_MODULES, f"{path.name}: no node is named {node}"
        unknown = set(section["ros__parameters"]) - parameter_names(NODE_MODULES[node])
        assert not unknown, f"{path.name}: {node} has no parameter {unknown}"


def test_the_params_file_check_can_fail(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**/mm_odometry:\n  ros__parameters:\n    rate: 15.0\n    rat: 1.0\n")
    with pytest.raises(AssertionError, match="rat"):
        check_params_file(bad)
    bad.write_text("mm_odometry:\n  ros__parameters:\n    rate: 15.0\n")
    with pytest.raises(AssertionError, match="only outside a namespace"):
        check_params_file(bad)


def test_odometry_params_file_lists_every_parameter_with_its_default():
    rclpy = pytest.importorskip("rclpy")
    assert rclpy
    from mm_pc.ros.odometry_node import PARAMETERS

    data = yaml.safe_load((ROOT / "mm_pc/config/mm_odometry.yaml").read_text())
    params = data["/**/mm_odometry"]["ros__parameters"]
    assert set(params) == set(PARAMETERS)
    for name, (default, _desc) in PARAMETERS.items():
        assert params[name] == default, name


def _includes(tree: ast.AST) -> list[tuple[str, str, set[str]]]:
    """robot.launch.py's _include(package, file, {args}) calls."""
    out = []
    for call in calls(tree, "_include"):
        args = {_const(k) for k in call.args[2].keys}
        out.append((_const(call.args[0]), _const(call.args[1]), args))
    return out


def test_robot_starts_the_usual_set_and_the_monitor_only_on_request():
    tree = tree_of(ROOT / "mm_beagle/launch/robot.launch.py")
    included = _includes(tree)
    assert {(p, f) for p, f, _ in included} == {
        ("mm_beagle", "beagle.launch.py"),
        ("mm_pc", "odometry.launch.py"),
        ("mm_pc", "fusion.launch.py"),
        ("mm_pc", "monitor.launch.py"),
    }
    for pkg, name, args in included:
        target = tree_of(ROOT / pkg / "launch" / name)
        assert args <= declared_arguments(target), (name, args)
    conditional = {
        _const(c.args[1]) for c in calls(tree, "_include") if _kw(c, "condition") is not None
    }
    assert conditional == {"monitor.launch.py"}
    assert "monitor" in declared_arguments(tree)
    executables = set()
    for _pkg, name, _ in included:
        target = tree_of(ROOT / _pkg / "launch" / name)
        executables |= {_const(_kw(n, "executable")) for n in calls(target, "Node")}
        executables |= {_const(c.args[0]) for c in calls(target, "ExecutableInPackage")}
    assert {"mm-beagle", "mm-odometry", "mm-fusion", "mm-monitor"} <= executables


#: each node's launch file -> its parameters-file argument and that argument's default
NODE_PARAMS = {
    "beagle.launch.py": ("beagle_params", ("mm_beagle", "mm_beagle.yaml")),
    "odometry.launch.py": ("odometry_params", ("mm_pc", "mm_odometry.yaml")),
    "fusion.launch.py": ("fusion_params", ("mm_pc", "mm_fusion.yaml")),
}


def _declarations(tree: ast.AST) -> dict[str, ast.Call]:
    return {_const(c.args[0]): c for c in calls(tree, "DeclareLaunchArgument")}


def _config_default(declaration: ast.Call) -> tuple[str, str] | None:
    """(package, file) of a default ``PathJoinSubstitution([FindPackageShare(pkg), "config",
    file])`` or robot.launch.py's ``_config(pkg, file)``, else None."""
    default = _kw(declaration, "default_value")
    if not isinstance(default, ast.Call):
        return None
    if _call_name(default) == "_config":
        return _const(default.args[0]), _const(default.args[1])
    if _call_name(default) == "PathJoinSubstitution":
        first, *rest = default.args[0].elts
        if [_const(r) for r in rest[:-1]] == ["config"]:
            return _const(first.args[0]), _const(rest[-1])
    return None


def test_each_node_launch_file_has_a_params_argument_of_its_own():
    """One name per node (beagle_params, ...), never a shared params_file: included side by
    side, a shared name would carry the first file's value into the others (issue 25)."""
    for name, (argument, config) in NODE_PARAMS.items():
        tree = tree_of(ROOT / package_of_launch(name) / "launch" / name)
        declared = _declarations(tree)
        with_config = {a for a, c in declared.items() if _config_default(c)}
        assert with_config == {argument}, (name, with_config)
        assert _config_default(declared[argument]) == config, name
        assert "params_file" not in declared, name
        nodes = calls(tree, "Node")
        assert nodes
        for node in nodes:  # each node reads it (directly or through a list built before)
            function = next(
                f for f in tree.body if isinstance(f, ast.FunctionDef)
                and any(n is node for n in ast.walk(f))
            )  # fmt: skip
            read = {_const(c.args[0]) for c in calls(function, "LaunchConfiguration")}
            assert argument in read, (name, argument)
    arguments = [a for a, _ in NODE_PARAMS.values()]
    assert len(set(arguments)) == len(arguments)


def package_of_launch(name: str) -> str:
    (path,) = [p for p in LAUNCH_FILES if p.name == name]
    return package_of(path)


def test_robot_includes_cannot_leak_arguments_into_each_other():
    """ros2/launch (jazzy) does not scope an include: IncludeLaunchDescription sets its
    launch_arguments in the including context and the included DeclareLaunchArgument sets
    its default there only where the name is still unset, so the next include reads the
    first one's value (robot.launch.py gave all three nodes mm_beagle.yaml this way). So:
    every argument an included file declares and is not given must be declared by no
    other include and not by robot.launch.py (whose own arguments would reach it unasked),
    each params argument is passed explicitly from robot.launch.py's argument of the same
    name with the same default, and each include runs in a scoped GroupAction."""
    tree = tree_of(ROOT / "mm_beagle/launch/robot.launch.py")
    robot = _declarations(tree)
    included = _includes(tree)
    for k, (pkg, name, given) in enumerate(included):
        declared = declared_arguments(tree_of(ROOT / pkg / "launch" / name))
        implicit = declared - given
        for other_pkg, other, other_given in included[:k] + included[k + 1 :]:
            shared = implicit & (declared_arguments(tree_of(ROOT / other_pkg / "launch" / other))
                                 | other_given)  # fmt: skip
            assert not shared, f"{name} takes {shared} from whatever {other} set"
        assert not implicit & set(robot), f"{name} takes {implicit & set(robot)} unasked"
        if name in NODE_PARAMS:
            argument, config = NODE_PARAMS[name]
            assert argument in given, f"robot.launch.py does not pass {argument} to {name}"
            assert _config_default(robot[argument]) == config, argument
    (helper,) = [f for f in tree.body if isinstance(f, ast.FunctionDef) and f.name == "_include"]
    (group,) = calls(helper, "GroupAction")
    assert any(n is calls(helper, "IncludeLaunchDescription")[0] for n in ast.walk(group))
    scoped = _kw(group, "scoped")
    assert scoped is None or scoped.value is True, "the include's group must be scoped"
    forwarding = _kw(group, "forwarding")
    assert forwarding is None or forwarding.value is True, (
        "forwarding=False would also drop an outer PushRosNamespace / SetRemap"
    )


def test_monitor_launch_passes_only_options_mm_monitor_knows():
    from mm_pc.monitor.app import _parser

    known = {o for a in _parser()._actions for o in a.option_strings}
    tree = tree_of(ROOT / "mm_pc/launch/monitor.launch.py")
    (proc,) = calls(tree, "ExecuteProcess")
    flags = {
        e.value
        for e in _kw(proc, "cmd").elts
        if isinstance(e, ast.Constant) and e.value.startswith("--")
    }
    assert flags and flags <= known, flags - known


HAVE_LAUNCH = all(importlib.util.find_spec(m) for m in ("launch", "launch_ros"))


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_launch_file_builds_its_description(path):
    import launch

    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert isinstance(description, launch.LaunchDescription)
    names = {a.name for a in description.get_launch_arguments()}
    assert declared_arguments(tree_of(path)) <= names


CONFIG_FILES = sorted(p for pkg in PACKAGES for p in (ROOT / pkg / "config").glob("*.yaml"))


@pytest.mark.ros
@pytest.mark.parametrize("path", CONFIG_FILES, ids=lambda p: p.name)
@pytest.mark.parametrize("namespace", ["", "/robot1"])
def test_params_file_reaches_its_node_in_any_namespace(tmp_path, path, namespace):
    """rcl matches a bare node name only at the root namespace: launched with namespace:=,
    a file keyed `mm_beagle:` would be dropped silently (checked with rclpy, not assumed)."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.node import Node

    data = yaml.safe_load(path.read_text())
    for key, section in data.items():
        params = section["ros__parameters"]
        name = next(n for n, v in params.items() if isinstance(v, float))
        params[name] = params[name] + 1.5  # a value no default has
        copy = tmp_path / path.name
        copy.write_text(yaml.safe_dump({key: {"ros__parameters": {name: params[name]}}}))
        args = ["x", "--ros-args", "--params-file", str(copy)]
        if namespace:
            args += ["-r", f"__ns:={namespace}"]
        context = rclpy.Context()
        rclpy.init(args=args, context=context)
        try:
            node = Node(key.removeprefix("/**/"), context=context)
            assert node.declare_parameter(name, 0.0).value == params[name], (key, namespace)
            node.destroy_node()
        finally:
            rclpy.shutdown(context=context)


FAKE_NODE = """#!{python}
import json, sys
args = sys.argv[1:]
files = [args[i + 1] for i, a in enumerate(args) if a == "--params-file"]
record = {{"argv": args, "params_files": files,
          "params": [open(f).read() for f in files]}}
with open({out!r} + "/" + {name!r} + ".json", "w") as out:
    json.dump(record, out)
"""


def _fake_prefix(tmp_path: Path) -> tuple[Path, Path]:
    """An ament prefix whose packages share this tree's launch/ and config/ and whose
    executables only write down how they were started (out/<executable>.json)."""
    import sys

    prefix, out = tmp_path / "prefix", tmp_path / "out"
    out.mkdir()
    index = prefix / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True)
    for pkg in PACKAGES:
        (index / pkg).touch()
        (prefix / "share" / pkg).mkdir()
        for folder in ("launch", "config"):
            (prefix / "share" / pkg / folder).symlink_to(ROOT / pkg / folder)
        lib = prefix / "lib" / pkg
        lib.mkdir(parents=True)
        for exe, module in scripts().items():
            if module.startswith(pkg + "."):
                script = lib / exe
                script.write_text(FAKE_NODE.format(python=sys.executable, out=str(out), name=exe))
                script.chmod(0o755)
    return prefix, out


def _run_launch(
    path: Path, arguments: dict[str, str], prefix: Path, out: Path, monkeypatch, outer=()
):
    """``ros2 launch`` of ``path`` with ``arguments`` as ros2launch does it (an include of the
    file with the command line's arguments), after the actions ``outer`` in one group (as a
    file of the user's that includes it); {executable: its argv and parameters files}."""
    import json
    import os

    from launch import LaunchDescription, LaunchService
    from launch.actions import GroupAction, IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource

    ament = os.environ.get("AMENT_PREFIX_PATH", "")
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{prefix}{os.pathsep}{ament}")
    source = PythonLaunchDescriptionSource(str(path))
    include = IncludeLaunchDescription(source, launch_arguments=arguments.items())
    service = LaunchService()
    service.include_launch_description(LaunchDescription([GroupAction([*outer, include])]))
    assert service.run() == 0
    return {p.stem: json.loads(p.read_text()) for p in out.glob("*.json")}


def _params_file_of(run: dict, exe: str) -> str:
    """The one parameters file of ``exe`` that is not launch_ros's temporary one."""
    (named,) = [f for f in run[exe]["params_files"] if "launch_params_" not in f]
    return named


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
def test_robot_launch_starts_each_node_with_its_own_parameters_file(tmp_path, monkeypatch):
    """The resolved command lines (real launch, executables that only record them): each
    node its own package's file; a node's own argument reaches only that node; an old-style
    params_file:= reaches none; namespace and frame_prefix reach all three."""
    prefix, out = _fake_prefix(tmp_path)
    robot = ROOT / "mm_beagle/launch/robot.launch.py"
    run = _run_launch(robot, {"backend": "sim"}, prefix, out, monkeypatch)
    assert set(run) == {"mm-beagle", "mm-odometry", "mm-fusion"}
    for exe, config in (("mm-beagle", "mm_beagle/config/mm_beagle.yaml"),
                        ("mm-odometry", "mm_pc/config/mm_odometry.yaml"),
                        ("mm-fusion", "mm_pc/config/mm_fusion.yaml")):  # fmt: skip
        assert _params_file_of(run, exe).endswith("share/" + config), run[exe]
    assert "backend: sim" in "".join(run["mm-beagle"]["params"])

    for p in out.glob("*.json"):
        p.unlink()
    custom = tmp_path / "odo.yaml"
    custom.write_text("/**/mm_odometry:\n  ros__parameters:\n    rate: 5.0\n")
    run = _run_launch(
        robot, {"odometry_params": str(custom), "params_file": "/nowhere.yaml",
                "namespace": "r1", "frame_prefix": "r1/"}, prefix, out, monkeypatch,
    )  # fmt: skip
    assert _params_file_of(run, "mm-odometry") == str(custom)
    assert _params_file_of(run, "mm-beagle").endswith("share/mm_beagle/config/mm_beagle.yaml")
    assert _params_file_of(run, "mm-fusion").endswith("share/mm_pc/config/mm_fusion.yaml")
    for exe, record in run.items():
        assert "/nowhere.yaml" not in record["params_files"], exe
        assert "__ns:=/r1" in record["argv"], (exe, record["argv"])
        assert "frame_prefix: r1/" in "".join(record["params"]), (exe, record["params"])


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
def test_robot_launch_passes_an_outer_namespace_and_tf_remap_to_its_nodes(tmp_path, monkeypatch):
    """Many robots by /tf remapping: a user's file includes robot.launch.py after
    PushRosNamespace and SetRemap; the scoped groups inside still forward them."""
    from launch_ros.actions import PushRosNamespace, SetRemap

    prefix, out = _fake_prefix(tmp_path)
    outer = [PushRosNamespace("r2"), SetRemap("/tf", "tf"), SetRemap("/tf_static", "tf_static")]
    robot = ROOT / "mm_beagle/launch/robot.launch.py"
    run = _run_launch(robot, {"backend": "sim"}, prefix, out, monkeypatch, outer)
    assert set(run) == {"mm-beagle", "mm-odometry", "mm-fusion"}
    for exe, record in run.items():
        argv = record["argv"]
        assert "__ns:=/r2" in argv and "/tf:=tf" in argv and "/tf_static:=tf_static" in argv, (
            exe, argv,
        )  # fmt: skip


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
@pytest.mark.parametrize(
    ("arguments", "outer", "beagle"),
    [
        ({}, (), "/mm_beagle"),
        ({"namespace": "r1"}, (), "/r1/mm_beagle"),
        ({"namespace": "/r1"}, (), "/r1/mm_beagle"),
        ({}, ("r2",), "/r2/mm_beagle"),
        ({"namespace": "r1"}, ("r2",), "/r2/r1/mm_beagle"),
    ],
)
def test_robot_launch_monitor_watches_the_robots_own_mm_beagle(
    tmp_path, monkeypatch, arguments, outer, beagle
):
    """monitor:=true: mm-monitor (a process, not a Node: no namespace of its own) is told the
    mm_beagle node robot.launch.py started, under ``namespace`` and an outer namespace too
    (it watched /mm_beagle whatever the namespace, with the real launch)."""
    from launch_ros.actions import PushRosNamespace

    prefix, out = _fake_prefix(tmp_path)
    robot = ROOT / "mm_beagle/launch/robot.launch.py"
    run = _run_launch(
        robot, {"backend": "sim", "monitor": "true", **arguments}, prefix, out, monkeypatch,
        [PushRosNamespace(ns) for ns in outer],
    )  # fmt: skip
    assert set(run) == {"mm-beagle", "mm-odometry", "mm-fusion", "mm-monitor"}
    argv = run["mm-monitor"]["argv"]
    given = argv[argv.index("--beagle") + 1]
    assert "/" + given.strip("/") == beagle, argv  # mm-monitor makes the name absolute
    started = run["mm-beagle"]["argv"]
    ns = next((a.removeprefix("__ns:=") for a in started if a.startswith("__ns:=")), "")
    assert f"{ns.rstrip('/')}/mm_beagle" == beagle, started  # the node it started


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
def test_beagle_launch_list_arguments_reach_the_node_in_a_file_it_accepts(tmp_path, monkeypatch):
    """chips:= goes into launch_ros's own parameters file as a list (a ``!!python/tuple``
    there); mm-beagle's --params-file check takes every file it is given (it refused that
    one: exit 2 with the real launch)."""
    from mm_pc.ros.spin import params_file_problems

    prefix, out = _fake_prefix(tmp_path)
    beagle = ROOT / "mm_beagle/launch/beagle.launch.py"
    arguments = {"backend": "sim", "chips": "pmw3389", "namespace": "r2", "frame_prefix": "r2/"}
    run = _run_launch(beagle, arguments, prefix, out, monkeypatch)
    argv = run["mm-beagle"]["argv"]
    assert params_file_problems(argv) == [], argv
    (launch_file,) = [f for f in run["mm-beagle"]["params_files"] if "launch_params_" in f]
    text = run["mm-beagle"]["params"][run["mm-beagle"]["params_files"].index(launch_file)]
    assert "python/tuple" in text  # how launch_ros writes a list
    assert "- pmw3389" in text and "frame_prefix: r2/" in text and "backend: sim" in text
