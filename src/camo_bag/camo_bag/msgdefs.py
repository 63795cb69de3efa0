"""Message definitions and type hashes as rosbag2 stores them in an MCAP schema.

A schema's text is the type's own .msg file followed, for every type it uses
(recursively), by a line of exactly 80 `=`, a line `MSG: pkg/Type` and that
type's .msg file. The files come from the installed packages' share folders
(the ament index), so comments and constants are kept as written.
"""

from __future__ import annotations

import importlib
import json
import re
from functools import cache
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

from camo_core.exceptions import CamoError

SEPARATOR = "=" * 80
PRIMITIVES = {
    "bool",
    "byte",
    "char",
    "float32",
    "float64",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "string",
    "wstring",
}


class DefinitionError(CamoError):
    """A message type whose .msg file is not installed."""


def split_type(type_name: str) -> tuple[str, str]:
    """'pkg/msg/Type' or 'pkg/Type' -> ('pkg', 'Type')."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise DefinitionError(f"not a message type name: {type_name!r}")


def full_name(type_name: str) -> str:
    package, name = split_type(type_name)
    return f"{package}/msg/{name}"


def message_class(type_name: str):
    """The rclpy message class of 'pkg/msg/Type'."""
    package, name = split_type(type_name)
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError):
        raise DefinitionError(f"message type {type_name} is not installed") from None


@cache
def _msg_file(package: str, name: str) -> Path:
    try:
        path = Path(get_package_share_directory(package)) / "msg" / f"{name}.msg"
    except PackageNotFoundError:
        raise DefinitionError(
            f"package {package} is not installed (needed for {package}/{name})"
        ) from None
    if not path.is_file():
        raise DefinitionError(f"no definition file {path}")
    return path


def _used_types(package: str, text: str) -> list[tuple[str, str]]:
    """Non-primitive field types of one .msg text, in order, as (package, name)."""
    used = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        field_type = re.sub(r"\[.*\]$|<=\d+", "", line.split()[0])  # arrays and bounded strings
        if field_type in PRIMITIVES:
            continue
        if "/" in field_type:
            used.append(split_type(field_type))
        elif field_type == "Header":
            used.append(("std_msgs", "Header"))
        else:
            used.append((package, field_type))
    return used


@cache
def message_definition(type_name: str) -> str:
    """The ros2msg schema text of a type, with its dependencies after 80 '=' lines."""
    package, name = split_type(type_name)
    root = _msg_file(package, name).read_text()
    seen: list[tuple[str, str]] = []
    pending = _used_types(package, root)
    while pending:
        dep = pending.pop(0)
        if dep in seen or dep == (package, name):
            continue
        seen.append(dep)
        pending.extend(_used_types(dep[0], _msg_file(*dep).read_text()))
    parts = [root.rstrip("\n")]
    for dep_package, dep_name in seen:
        parts.append(
            f"{SEPARATOR}\nMSG: {dep_package}/{dep_name}\n"
            f"{_msg_file(dep_package, dep_name).read_text().rstrip()}"
        )
    return "\n".join(parts) + "\n"


@cache
def type_hash(type_name: str) -> str:
    """The type's RIHS01 hash from its installed type description, or '' when there is none."""
    package, name = split_type(type_name)
    try:
        path = _msg_file(package, name).with_suffix(".json")
        hashes = json.loads(path.read_text())["type_hashes"]
    except (DefinitionError, OSError, ValueError, KeyError):
        return ""
    wanted = f"{package}/msg/{name}"
    return next((h["hash_string"] for h in hashes if h["type_name"] == wanted), "")
