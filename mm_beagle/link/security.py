"""Can this ROS installation run DDS security (SROS2)?  ``mm-security check`` answers.

SROS2 needs Fast DDS built with its security plugins (``-DSECURITY=ON``): the
authentication plugin ``builtin.PKI-DH``, the cryptography plugin ``builtin.AES-GCM-GMAC``
and the access-control plugin ``builtin.Access-Permissions``.  The check looks for them in
two independent ways:

* **the library**: the plugin names are string constants of a Fast DDS built with them;
  their absence from ``libfastrtps``/``libfastdds`` means the plugins are not compiled in.
  Whether it links OpenSSL is reported too (the PyPI wheels link it for the TLS TCP
  transport, so OpenSSL alone proves nothing);
* **a real node**: one ``rclpy`` node started with ``ROS_SECURITY_ENABLE=true`` on a
  placeholder enclave (files present, contents irrelevant) in a private temporary
  keystore.  A Fast DDS without security refuses before it reads any file, with
  "This Fast DDS version doesn't have the security libraries".

Exit codes: 0 security available, 1 not available (the evidence is printed), 2 bad usage.
Nothing is written outside a private temporary directory, which is removed.
See docs/hardware-setup.md, section Security.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

#: the DDS Security 1.1 builtin plugin names as Fast DDS's property values spell them
PLUGINS = ("builtin.PKI-DH", "builtin.AES-GCM-GMAC", "builtin.Access-Permissions")

#: the files rmw_fastrtps looks for in an enclave directory
ENCLAVE_FILES = (
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
)

_LIB_NAME = re.compile(r"^lib(fastrtps|fastdds)\.so(\.\d+)*$")
PROBE_TIMEOUT_S = 30.0


def fastdds_libraries(prefixes: list[Path] | None = None) -> list[Path]:
    """The Fast DDS shared libraries under ``prefixes`` (default: this interpreter's prefix
    and every AMENT_PREFIX_PATH entry), each once: the wheels ship libfastrtps.so, .so.2.14
    and .so.2.14.5 as copies, so one file per library and size is kept (the longest name)."""
    if prefixes is None:
        prefixes = [Path(sys.prefix)]
        prefixes += [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(":") if p]
    found: dict[tuple[str, int], Path] = {}
    for prefix in prefixes:
        lib = prefix / "lib"
        if not lib.is_dir():
            continue
        for entry in sorted(lib.iterdir()):
            match = _LIB_NAME.match(entry.name)
            if match and entry.is_file():
                real = entry.resolve()
                key = (match.group(1), real.stat().st_size)
                if key not in found or len(real.name) > len(found[key].name):
                    found[key] = real
    return list(found.values())


def scan_library(path: Path) -> dict:
    """What one library file holds: {"path", "plugins": {name: bool}, "openssl": bool}.

    ``openssl`` is true when the file names libssl or libcrypto (its DT_NEEDED entries are
    plain strings in the file)."""
    data = path.read_bytes()
    return {
        "path": str(path),
        "plugins": {name: name.encode() in data for name in PLUGINS},
        "openssl": b"libssl" in data or b"libcrypto" in data,
    }


_PROBE = """
import rclpy
rclpy.init()
try:
    rclpy.create_node("mm_security_probe")
except Exception as exc:
    print("REFUSED", str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
else:
    print("CREATED")
"""


def probe_node(timeout: float = PROBE_TIMEOUT_S) -> dict:
    """Start one secured rclpy node on a placeholder enclave: {"created": bool, "message"}.

    "created" with placeholder files would mean the plugins are there (and then refuse the
    files); the message is the rmw's first error line."""
    with tempfile.TemporaryDirectory(prefix="mm-security-") as tmp:
        enclave = Path(tmp, "enclaves", "probe")
        enclave.mkdir(parents=True)
        for name in ENCLAVE_FILES:
            (enclave / name).write_text("placeholder\n")
        env = dict(os.environ)
        env.update(
            ROS_SECURITY_KEYSTORE=tmp,
            ROS_SECURITY_ENABLE="true",
            ROS_SECURITY_STRATEGY="Enforce",
            ROS_SECURITY_ENCLAVE_OVERRIDE="/probe",
            ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
            ROS_LOG_DIR=tmp,
        )
        try:
            out = subprocess.run(
                [sys.executable, "-c", _PROBE],
                env=env,
                capture_output=True,
                text=True,
                timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            return {"created": False, "message": f"the probe node did not finish in {timeout:g} s"}
    for line in out.stdout.splitlines():
        if line.startswith("CREATED"):
            return {"created": True, "message": ""}
        if line.startswith("REFUSED"):
            return {"created": False, "message": line.removeprefix("REFUSED").strip()}
    tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
    return {"created": False, "message": f"the probe exited {out.returncode}: {tail}"}


def check(probe: bool = True) -> dict:
    """The whole finding: {"available": bool, "libraries": [...], "probe": {...} | None}."""
    libs = [scan_library(p) for p in fastdds_libraries()]
    has_plugins = bool(libs) and all(all(lib["plugins"].values()) for lib in libs)
    result = {"libraries": libs, "probe": probe_node() if probe else None}
    result["available"] = has_plugins and (not probe or result["probe"]["created"])
    return result


def _report(result: dict) -> str:
    lines = []
    if not result["libraries"]:
        lines.append("no libfastrtps/libfastdds found under this prefix or AMENT_PREFIX_PATH")
    for lib in result["libraries"]:
        lines.append(lib["path"])
        for name, there in lib["plugins"].items():
            lines.append(f"  {name}: {'present' if there else 'absent'}")
        lines.append(f"  links OpenSSL: {'yes' if lib['openssl'] else 'no'}")
    if result["probe"] is not None:
        p = result["probe"]
        lines.append(
            "secured node on a placeholder enclave: "
            + ("created" if p["created"] else f"refused: {p['message']}")
        )
    lines.append(
        "DDS security: available"
        if result["available"]
        else "DDS security: NOT available with this Fast DDS (see docs/hardware-setup.md#security)"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="mm-security",
        description="Find out whether this ROS installation's Fast DDS can run DDS security "
        "(SROS2). Exit 0 available, 1 not available, 2 bad usage.",
    )
    sub = p.add_subparsers(dest="verb", required=True)
    c = sub.add_parser("check", help="look for the security plugins and try a secured node")
    c.add_argument("--json", action="store_true", help="one JSON line instead of text")
    c.add_argument("--no-probe", action="store_true", help="only look at the library files")
    args = p.parse_args(argv)  # bad usage: argparse's one line and exit 2
    result = check(probe=not args.no_probe)
    print(json.dumps(result) if args.json else _report(result))
    return 0 if result["available"] else 1


if __name__ == "__main__":
    sys.exit(main())
