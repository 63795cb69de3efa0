"""The file level of every loader of outside input: a path that names a readable regular file
of a sane size, or the loader's own error in one line.

A loader (images, layouts, parameters files) checks its file here first and its content after,
so that an empty path, a path the system refuses as too long, a folder or a file too big to be
what it claims is said the same way by every one of them.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from camo_core.exceptions import CamoError

MAX_PATH = 4096  # bytes, as Linux's PATH_MAX
MAX_NAME = 255  # bytes of one path component, as Linux's NAME_MAX
SHOWN = 80  # characters of a path a message shows


def shown(path: str | os.PathLike) -> str:
    """A path as a one-line message shows it: at most SHOWN characters, no line breaks."""
    text = os.fspath(path)
    text = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    return text if len(text) <= SHOWN else f"{text[: SHOWN // 2]}...{text[-SHOWN // 2 + 3 :]}"


def checked_path(
    path: str | os.PathLike | None, what: str = "", error: type[Exception] = CamoError
) -> Path:
    """`path` as a Path, if it is one the system can take (not empty, no NUL character, not
    longer than MAX_PATH bytes nor a name longer than MAX_NAME); else `error` in one line."""
    named = f"the {what} path" if what else "the path"
    if path is None or os.fspath(path) == "":
        raise error(f"{named} is empty")
    text = os.fspath(path)
    if "\0" in text:
        raise error(f"{named} {shown(text)} holds a NUL character")
    raw = os.fsencode(text)
    if len(raw) > MAX_PATH or any(len(part) > MAX_NAME for part in raw.split(b"/")):
        raise error(
            f"{named} is too long ({len(raw)} bytes; at most {MAX_PATH}, {MAX_NAME} a name): "
            f"{shown(text)}"
        )
    return Path(text)


def checked_file(
    path: str | os.PathLike | None,
    what: str,
    max_bytes: int,
    error: type[CamoError] = CamoError,
) -> Path:
    """`path` as a Path, if it names a regular file that we may read, of at most `max_bytes`;
    else `error` naming `what` and the path in one line."""
    path = checked_path(path, what, error)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise error(f"cannot read {what} {shown(path)}: not found") from None
    except OSError as exc:
        raise error(f"cannot read {what} {shown(path)}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"the {what} {shown(path)} is a folder, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise error(f"the {what} {shown(path)} is not a regular file")
    if info.st_size > max_bytes:
        raise error(
            f"the {what} {shown(path)} has {info.st_size} bytes: at most {max_bytes} are read"
        )
    if not os.access(path, os.R_OK):
        raise error(f"cannot read {what} {shown(path)}: permission denied")
    return path
