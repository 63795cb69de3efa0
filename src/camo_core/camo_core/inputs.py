"""The file level of every loader of outside input: a path that names a readable regular file
of a sane size, or the loader's own error in one line.

A loader (images, layouts, parameters files) checks its file here first and its content after,
so that an empty path, a path the system refuses as too long, a folder or a file too big to be
what it claims is said the same way by every one of them.
"""

from __future__ import annotations

import math
import os
import re
import stat
from pathlib import Path

from camo_core.exceptions import CamoError, UsageError

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


# ---- numbers in outside text ---------------------------------------------------------------
#
# Python's int() and float() take more than a person means by a number: `1_0` is 10, the
# Arabic-Indic `١` and the full-width `１` are 1, `infinity` is a float. Every number that
# comes from outside (a command line, a layout CSV, a sweep's axis, an environment variable)
# is read by this one grammar instead:
#
#     number  = [sign] (digits ["." [digits]] | "." digits) [("e" | "E") [sign] digits]
#     integer = [sign] digits
#     sign = "+" | "-";  digits = one or more of the ASCII 0-9
#
# with spaces and tabs around it ignored. `nan`, `inf` and `infinity` (any case, with a sign)
# only where the caller allows them; a number whose value overflows to infinity is refused too.

NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)
INTEGER = re.compile(r"[+-]?[0-9]+", re.ASCII)
SPECIAL = re.compile(r"[+-]?(?:nan|inf|infinity)", re.ASCII | re.IGNORECASE)
MAX_NUMBER_CHARS = 100  # a longer "number" is a mistake (and int() refuses 4300 digits)
BLANKS = " \t"


class NumberError(UsageError, ValueError):
    """Text that is not a number by the grammar above: a CamoError (one line, exit 2) that
    argparse's type conversion takes as a ValueError too ("invalid int value: '1_0'")."""


def number(text: str, what: str = "a number", *, special: bool = False) -> float:
    """`text` as a float by the grammar above (nan and inf only if `special`); else
    NumberError saying `what` was wanted."""
    if isinstance(text, str):
        bare = text.strip(BLANKS)
        if len(bare) <= MAX_NUMBER_CHARS:
            if NUMBER.fullmatch(bare):
                value = float(bare)
                if math.isfinite(value) or special:
                    return value
            elif special and SPECIAL.fullmatch(bare):
                return float(bare)
    raise NumberError(f"want {what} (ASCII digits, as -1.5 or 2e-3), got {_quoted(text)}")


def integer(text: str, what: str = "a whole number") -> int:
    """`text` as an int by the grammar above; else NumberError saying `what` was wanted."""
    if isinstance(text, str):
        bare = text.strip(BLANKS)
        if len(bare) <= MAX_NUMBER_CHARS and INTEGER.fullmatch(bare):
            return int(bare)
    raise NumberError(f"want {what} (ASCII digits, as 12 or -3), got {_quoted(text)}")


def items(text: str, what: str, sep: str = ",") -> list[str]:
    """The `sep`-separated items of a list: an empty item (`0,,1`, a trailing `,`) is an
    error, not left out."""
    parts = text.split(sep)
    if any(not part.strip(BLANKS) for part in parts):
        raise NumberError(f"{what} has an empty item: {_quoted(text)}")
    return [part.strip(BLANKS) for part in parts]


def _quoted(text) -> str:
    return repr(shown(text)) if isinstance(text, str) else repr(text)
