"""Patch files only from the directory configured at start (``patch_dir``).

The vendor patch code runs on the sensor's DSP, so where it comes from is a security
boundary: mm-beagle and mm-beagle-agent load patch files only from ``patch_dir``, fixed when
they start ('' = patch loading off), and a peer may name a file in it, never send a path
elsewhere or the code itself.  The check resolves every symlink and ``..`` first, so a link
inside ``patch_dir`` that points out of it is refused like an absolute path elsewhere.
"""

from __future__ import annotations

from pathlib import Path


class PatchPathError(ValueError):
    """A patch file outside patch_dir, or patch loading off; the message says which."""


def resolve_patch_file(patch_dir: str, name: str) -> str:
    """The real path of patch file ``name`` inside ``patch_dir``, or '' when ``name`` is ''.

    ``name`` is relative to ``patch_dir`` or absolute; either way its resolved path (symlinks
    and ``..`` followed) must lie inside the resolved ``patch_dir``, which must be a
    directory.  Raises PatchPathError naming both; nothing is read or changed."""
    if not name:
        return ""
    if not isinstance(name, str) or "\x00" in name:
        raise PatchPathError(f"patch file name must be a plain string, got {name!r}")
    if not patch_dir:
        raise PatchPathError(
            f"patch loading is off: patch file {name!r} given but 'patch_dir' is '' "
            "(set patch_dir to the directory that holds the patch files)"
        )
    root = Path(patch_dir).expanduser()
    try:
        root = root.resolve(strict=True)
    except (OSError, RuntimeError) as exc:
        raise PatchPathError(f"'patch_dir' {patch_dir!r} cannot be used: {exc}") from None
    if not root.is_dir():
        raise PatchPathError(f"'patch_dir' {patch_dir!r} is not a directory")
    try:
        real = (root / Path(name).expanduser()).resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise PatchPathError(f"patch file {name!r} cannot be resolved: {exc}") from None
    if not real.is_relative_to(root):
        raise PatchPathError(
            f"patch file {name!r} resolves to {real}, outside patch_dir {root}: refused"
        )
    if not real.is_file():
        raise PatchPathError(f"patch file {name!r} is not a file in patch_dir {root}")
    return str(real)
