"""Where commands write: checked before any work starts, written atomically.

Every check and error names the path the user gave, never a temporary file:
``out/x.json: the folder out does not exist``.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import stat
from pathlib import Path

from tagbot.errors import OutputError

__all__ = ["check_output_file", "check_output_folder", "write_atomic"]

_CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)


def check_output_file(path: str | os.PathLike[str]) -> None:
    """Refuse an output file that cannot be written: its folder is missing or not writable, or
    the path exists and is not a regular file (a folder, a device such as ``/dev/null``, a FIFO,
    a socket: the atomic write would replace it with a regular file). ``-`` (stdout) always
    passes."""
    name = os.fsdecode(path)
    if name == "-":
        return
    target = Path(name)
    if target.is_dir():
        raise OutputError(f"{name}: is a folder, not a file")
    kind = _special_kind(target)
    if kind is not None:
        raise OutputError(f"{name}: is {kind}, not a regular file (outputs are files)")
    if target.exists() and not os.access(target, os.W_OK):
        raise OutputError(f"{name}: not writable")
    _check_folder(target.parent, name)


def check_output_folder(path: str | os.PathLike[str]) -> None:
    """Refuse an output folder that cannot be used: it is a file, or it (or, when it does not
    exist yet, the nearest folder above it, where it would be created) is not writable."""
    name = os.fsdecode(path)
    folder = Path(name)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{name}: exists and is not a folder")
    existing = folder
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise OutputError(f"{name}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"{name}: the folder {existing} is not writable")


def _special_kind(target: Path) -> str | None:
    """What ``target`` is when it exists and is neither a regular file nor a folder (symbolic
    links followed), else None."""
    try:
        mode = os.stat(target).st_mode
    except OSError:
        return None
    kinds = (
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
    )
    for test, kind in kinds:
        if test(mode):
            return kind
    return None if stat.S_ISREG(mode) or stat.S_ISDIR(mode) else "not a regular file"


def _check_folder(folder: Path, name: str) -> None:
    where = folder if str(folder) else Path(".")
    if not where.exists():
        raise OutputError(f"{name}: the folder {where} does not exist")
    if not where.is_dir():
        raise OutputError(f"{name}: {where} is not a folder")
    if not os.access(where, os.W_OK | os.X_OK):
        raise OutputError(f"{name}: the folder {where} is not writable")


def write_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to a fresh temporary file beside ``path``, then rename it over ``path``:
    readers see the old file or the new one, never half of one. Errors name ``path``."""
    name = os.fsdecode(path)
    target = Path(name)
    _check_folder(target.parent, name)
    while True:
        tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
        try:
            fd = os.open(tmp, _CREATE_FLAGS, 0o666)  # permissions as for open(): 0o666 & ~umask
        except FileExistsError:
            continue
        except OSError as e:
            raise OutputError(f"{name}: cannot write ({e.strerror or e})") from e
        break
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except OSError as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise OutputError(f"{name}: cannot write ({e.strerror or e})") from e
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
