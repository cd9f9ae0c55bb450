"""Patch files only from the directory configured at start (``patch_dir``).

The vendor patch code runs on the sensor's DSP, so where it comes from is a security
boundary: mm-beagle and mm-beagle-agent load patch files only from ``patch_dir``, fixed when
they start ('' = patch loading off), and a peer may name a file in it, never send a path
elsewhere or the code itself.  The check resolves every symlink and ``..`` first, so a link
inside ``patch_dir`` that points out of it is refused like an absolute path elsewhere.

A peer's file is also size-checked before it is read (:func:`check_patch_file_size`: no
larger than the chip's patch RAM can use), and the code is written between polls in steps
(:func:`patch_load_steps`), so naming a large file or asking for many loads never holds up
the 1 kHz poll.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from pln2033.errors import PatchError

if TYPE_CHECKING:
    from pln2033.pln2033 import PLN2033

# Bytes of file per byte of patch code: a hex text file takes '0x1f, ' (6 characters) a
# byte; 8 leaves room for comments and line ends.
FILE_BYTES_PER_CODE_BYTE = 8
STEP_WORDS = 32  # register transfers between two chances to poll (~0.1-1 ms on a BBB)


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


def max_patch_file_bytes(words: int) -> int:
    """The largest patch file worth reading for a patch RAM of ``words`` 16-bit words."""
    return 2 * words * FILE_BYTES_PER_CODE_BYTE


def check_patch_file_size(path: str, words: int) -> None:
    """PatchPathError unless ``path`` is a regular file small enough to hold at most
    ``words`` words of patch code (:func:`max_patch_file_bytes`); nothing is read."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise PatchPathError(f"patch file {path} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise PatchPathError(f"patch file {path} is not a regular file")
    limit = max_patch_file_bytes(words)
    if st.st_size > limit:
        raise PatchPathError(
            f"patch file {path} has {st.st_size} bytes; the chip's patch RAM holds {words} "
            f"words (a file of at most {limit} bytes): refused unread"
        )


def patch_load_steps(driver: PLN2033, words: list[int], step: int = STEP_WORDS) -> Iterator[None]:
    """:meth:`PLN2033.load_patch <pln2033.pln2033.PLN2033.load_patch>` (write the code, read
    it back, enable it) in steps of ``step`` words, yielding between them: the caller polls
    in between. Each step sets the memory pointer itself, so polls in between (which touch
    only the motion registers) cannot move it. Raises PatchError (checks, verify) or
    SensorError (the bus)."""
    driver.check_patch(words)
    m = driver.map
    for k in range(0, len(words), step):
        driver.write_register("memory_pointer", m.patch_start + k)
        for word in words[k : k + step]:
            driver.write_register("memory_data", word)
        yield
    for k in range(0, len(words), step):
        driver.write_register("memory_pointer", m.patch_start + k)
        for j, word in enumerate(words[k : k + step]):
            got = driver.read_register("memory_data")
            if got != word:
                raise PatchError(
                    f"{driver.name}: patch code verify failed at word {k + j} "
                    f"(address {m.patch_start + k + j:#06x}): wrote {word:#06x}, read {got:#06x}"
                )
        yield
    value = driver.read_register("system_control")
    driver.write_register("system_control", value | m.patch_enable_bit)
