"""mm-security check: the evidence that the wheels' Fast DDS has no DDS security plugins.

The finding is the wheels' (docs/hardware-setup.md, Security); if a future wheel carries the
plugins, test_the_wheels_fast_dds_has_no_security fails and the docs must change with it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mm_beagle.link import security


def _run(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mm_beagle.link.security", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_scan_library_finds_the_plugin_names_and_openssl(tmp_path):
    with_plugins = tmp_path / "libfastdds.so.3"
    with_plugins.write_bytes(
        b"\x7fELF..libssl.so.3\x00builtin.PKI-DH\x00builtin.AES-GCM-GMAC\x00"
        b"builtin.Access-Permissions\x00"
    )
    without = tmp_path / "libfastrtps.so.2.14.5"
    without.write_bytes(b"\x7fELF..libtinyxml2.so\x00DDS\x00")
    found = security.scan_library(with_plugins)
    assert found["plugins"] == {name: True for name in security.PLUGINS}
    assert found["openssl"] is True
    bare = security.scan_library(without)
    assert bare["plugins"] == {name: False for name in security.PLUGINS}
    assert bare["openssl"] is False


def test_fastdds_libraries_keeps_one_copy_per_library(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    for name in ("libfastrtps.so", "libfastrtps.so.2.14", "libfastrtps.so.2.14.5"):
        (lib / name).write_bytes(b"x" * 100)
    (lib / "libfastcdr.so.2").write_bytes(b"y" * 100)  # not Fast DDS itself
    found = security.fastdds_libraries([tmp_path])
    assert [p.name for p in found] == ["libfastrtps.so.2.14.5"]


def test_the_wheels_fast_dds_has_no_security():
    """The documented command, run for real: library scan plus a secured node."""
    if not security.fastdds_libraries():
        pytest.skip("no libfastrtps/libfastdds in this environment (source install/setup.bash)")
    out = _run("check", "--json")
    assert out.returncode == 1, out.stderr
    result = json.loads(out.stdout)
    assert result["available"] is False
    assert result["libraries"]
    for lib in result["libraries"]:
        assert lib["plugins"] == {name: False for name in security.PLUGINS}
        assert lib["openssl"] is True  # linked for TLS over TCP, not for DDS security
    assert result["probe"]["created"] is False
    assert "doesn't have the security libraries" in result["probe"]["message"]


def test_the_text_report_says_not_available():
    if not security.fastdds_libraries():
        pytest.skip("no libfastrtps/libfastdds in this environment (source install/setup.bash)")
    out = _run("check", "--no-probe")
    assert out.returncode == 1
    assert "builtin.PKI-DH: absent" in out.stdout
    assert out.stdout.strip().splitlines()[-1].startswith("DDS security: NOT available")


@pytest.mark.parametrize("args", [(), ("bogus",), ("check", "--nope")])
def test_bad_usage_exits_2_without_traceback(args):
    out = _run(*args)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr and "usage: mm-security" in out.stderr
