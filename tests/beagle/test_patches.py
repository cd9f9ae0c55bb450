"""patch_dir: patch files only from the directory fixed at start, whatever a name says."""

from __future__ import annotations

import pytest

from mm_beagle.poller.patches import PatchPathError, resolve_patch_file


@pytest.fixture
def dirs(tmp_path):
    root = tmp_path / "patches"
    (root / "sub").mkdir(parents=True)
    (root / "ok.patch").write_text("0x12, 0x34\n")
    (root / "sub" / "deep.patch").write_text("0x12, 0x34\n")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "evil.patch").write_text("0xDE, 0xAD\n")
    (root / "link.patch").symlink_to(outside / "evil.patch")
    (root / "dirlink").symlink_to(outside)
    (root / "inner.patch").symlink_to(root / "ok.patch")  # a link that stays inside
    return root, outside


def test_names_inside_patch_dir_resolve_to_their_real_file(dirs):
    root, _ = dirs
    real = root.resolve()
    assert resolve_patch_file(str(root), "ok.patch") == str(real / "ok.patch")
    assert resolve_patch_file(str(root), "sub/deep.patch") == str(real / "sub" / "deep.patch")
    assert resolve_patch_file(str(root), "sub/../ok.patch") == str(real / "ok.patch")
    assert resolve_patch_file(str(root), str(root / "ok.patch")) == str(real / "ok.patch")
    assert resolve_patch_file(str(root), "inner.patch") == str(real / "ok.patch")
    assert resolve_patch_file(str(root), "") == ""  # no patch
    assert resolve_patch_file("", "") == ""


@pytest.mark.parametrize(
    ("name", "expect"),
    [
        ("../elsewhere/evil.patch", "outside patch_dir"),
        ("sub/../../elsewhere/evil.patch", "outside patch_dir"),
        ("link.patch", "outside patch_dir"),  # a symlink out
        ("dirlink/evil.patch", "outside patch_dir"),  # a directory symlink out
        ("/etc/hostname", "outside patch_dir"),  # an absolute path elsewhere
        ("nope.patch", "not a file"),
        ("sub", "not a file"),
        ("ok\x00.patch", "plain string"),
    ],
)
def test_names_that_leave_patch_dir_are_refused(dirs, name, expect):
    root, _ = dirs
    with pytest.raises(PatchPathError, match=expect):
        resolve_patch_file(str(root), name)


def test_patch_dir_unset_means_patch_loading_off(dirs):
    root, _ = dirs
    with pytest.raises(PatchPathError, match="patch loading is off"):
        resolve_patch_file("", str(root / "ok.patch"))


def test_a_patch_dir_that_is_missing_or_a_file_is_refused(dirs, tmp_path):
    root, _ = dirs
    with pytest.raises(PatchPathError, match="cannot be used"):
        resolve_patch_file(str(tmp_path / "missing"), "ok.patch")
    with pytest.raises(PatchPathError, match="not a directory"):
        resolve_patch_file(str(root / "ok.patch"), "ok.patch")
