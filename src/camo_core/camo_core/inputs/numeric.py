"""Numbers in outside text: one grammar for every number camo reads from outside.

Python's int() and float() take more than a person means by a number: `1_0` is 10, the
Arabic-Indic `١` and the full-width `１` are 1, `infinity` is a float. Every number that
comes from outside (a command line, a layout CSV, a sweep's axis, an environment variable)
is read by this one grammar instead:

    number  = [sign] (digits ["." [digits]] | "." digits) [("e" | "E") [sign] digits]
    integer = [sign] digits
    sign = "+" | "-";  digits = one or more of the ASCII 0-9

with spaces and tabs around it ignored. `nan`, `inf` and `infinity` (any case, with a sign)
only where the caller allows them; a number whose value overflows to infinity is refused too.
"""

from __future__ import annotations

import math
import re

from camo_core.exceptions import UsageError
from camo_core.inputs.files import shown

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
