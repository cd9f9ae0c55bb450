"""Read a file a user named (a config, credentials, calibration) without hanging or filling memory.

``open()`` of a FIFO waits for a writer for ever (and a Ctrl-C only lands once it returns),
``/dev/zero`` reads without end and a 2 GB file fills the board's memory: only a regular file
of at most ``limit`` bytes is read. It is opened non-blocking and checked again after the
open (a path swapped for a FIFO between the two checks), then read with a cap.
Every refusal is an OSError whose ``strerror`` says why in a few words, as for a missing
file, so callers that print ``exc.strerror`` need nothing new.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

#: the default cap: far above any config or calibration file of ours (a few kB)
MAX_BYTES = 1 << 20

_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)


def file_problem(mode: int, size: int, limit: int) -> str:
    """Why a file of ``mode`` and ``size`` bytes is not read ('' if it is)."""
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _KINDS if test(mode)), "")
        return f"not a regular file ({kind})" if kind else "not a regular file"
    if size > limit:
        return f"too large ({size} bytes; at most {limit})"
    return ""


def check_user_file(path: str | Path, limit: int = MAX_BYTES) -> None:
    """OSError unless ``path`` is a regular file of at most ``limit`` bytes (os.stat only:
    nothing is opened)."""
    st = os.stat(path)
    if problem := file_problem(st.st_mode, st.st_size, limit):
        raise OSError(errno.EINVAL, problem, str(path))


def read_user_bytes(path: str | Path, limit: int = MAX_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes; OSError otherwise."""
    check_user_file(path, limit)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(fd)
        if problem := file_problem(st.st_mode, st.st_size, limit):
            raise OSError(errno.EINVAL, problem, str(path))
        data = f.read(limit + 1)
    if len(data) > limit:  # grew since the stat
        raise OSError(errno.EFBIG, f"too large (more than {limit} bytes)", str(path))
    return data


def read_user_text(path: str | Path, limit: int = MAX_BYTES) -> str:
    """:func:`read_user_bytes` as UTF-8 text (UnicodeDecodeError, a ValueError, if it is not)."""
    return read_user_bytes(path, limit).decode("utf-8")
