"""Checks of values read from a bag's YAML: each names where the value sits and what it
should be, in one line (BagError), before anything uses it."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from camo_bag.container import BagError
from camo_core.inputs.strict_yaml import described, parse_yaml

INT64_MAX = 2**63 - 1
Check = Callable[[Any, str], Any]


def load_yaml(text: str, where: str) -> Any:
    """YAML text as data, read strictly (`camo_core.inputs.strict_yaml.parse_yaml`: no
    duplicate keys, YAML 1.2 scalars, one document); BagError naming the line where it is not
    YAML."""
    return parse_yaml(text, where, BagError)


def shown(value: Any) -> str:
    """A value as an error quotes it, in a user's words (`inputs.described`): on one line."""
    return described(value)


def bad(where: str, wanted: str, value: Any) -> BagError:
    return BagError(f"{where} must be {wanted} (got {shown(value)})")


def integer(lo: int, hi: int) -> Check:
    """An int in lo..hi (a bool is not one, though YAML's true is an int to Python)."""

    def check(value: Any, where: str) -> int:
        if type(value) is not int or not lo <= value <= hi:
            raise bad(where, f"an integer in {lo}..{hi}", value)
        return value

    return check


def text(choices: Iterable[str] | None = None, nonempty: bool = False) -> Check:
    allowed = None if choices is None else tuple(choices)

    def check(value: Any, where: str) -> str:
        if not isinstance(value, str):
            raise bad(where, "a string", value)
        if allowed is not None and value not in allowed:
            raise bad(where, "one of " + ", ".join(allowed), value)
        if nonempty and not value:
            raise bad(where, "a non-empty string", value)
        return value

    return check


def boolean(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise bad(where, "true or false", value)
    return value


def anything(value: Any, where: str) -> Any:
    return value


def optional(check: Check) -> Check:
    """`check`, or null."""
    return lambda value, where: None if value is None else check(value, where)


def listed(item: Check, nonempty: bool = False) -> Check:
    def check(value: Any, where: str) -> list:
        if not isinstance(value, list) or (nonempty and not value):
            raise bad(where, "a non-empty list" if nonempty else "a list", value)
        return [item(v, f"{where}[{k}]") for k, v in enumerate(value)]

    return check


def mapping(fields: dict[str, Check], required: Iterable[str] = (), open_: bool = False) -> Check:
    """A mapping of these fields (those in `required` present); other keys are refused unless
    `open_` (kept unchecked then)."""
    needed = tuple(required)

    def check(value: Any, where: str) -> dict:
        if not isinstance(value, dict):
            raise bad(where, "a mapping", value)
        for key in needed:
            if key not in value:
                raise BagError(f"{where} lacks its field {key}")
        out = {}
        for key, item in value.items():
            if key in fields:
                # "FILE: a.b": a file's fields after a colon, nested ones after a dot
                out[key] = fields[key](item, f"{where}{' ' if where.endswith(':') else '.'}{key}")
            elif open_:
                out[key] = item
            else:
                known = ", ".join(fields)
                raise BagError(f"{where} has an unknown field {shown(key)} (known: {known})")
        return out

    return check
