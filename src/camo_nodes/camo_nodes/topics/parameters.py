"""A node's ROS parameters, declared from the dataclasses that declare them (camo_core.schema).

A node takes `-p NAME:=VALUE` and `--params-file` as any ROS 2 node does: `node_parameters`
declares every parameter of the dataclasses it is given, with its declared default and
description, and checks what it was given in one line; `ros_arguments` writes a dataclass's
values back as the `-p` arguments of a process the launcher starts. ROS parameters cannot be
unset: a parameter whose declared default is None is declared as -1 (an integer) or NaN (a
number) and read back as None.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor

from camo_core.schema import Declared, ParameterError, param, with_role

# Parameters every rclpy node has, which no node of ours declares.
ROS_OWN_PARAMETERS = {"use_sim_time", "start_type_description_service"}
UNSET = {int: -1, float: math.nan}  # an optional parameter left to its dataclass's default
# ROS integers are 64-bit signed: an unsigned 64-bit parameter (a seed) above their range
# travels as its two's complement, and is read back as itself.
INT64_MAX = 2**63 - 1


@dataclass(frozen=True)
class JoinParams:
    """The run a node alone joins."""

    run_id: str = param("", "the run to join", none_means="the only run in the domain")


def ros_default(d: Declared) -> Any:
    """The value a ROS parameter is declared with."""
    if d.default is None:
        return UNSET.get(d.kind, "")
    return d.default


def declarations(*classes: type) -> dict[str, Declared]:
    """The ROS parameters of nodes that take these dataclasses, by name."""
    out: dict[str, Declared] = {}
    for cls in classes:
        out.update(with_role(cls, "ros"))
    return out


def _kind(kind: type) -> str:
    return {bool: "a bool", int: "an integer", float: "a number", str: "text"}.get(
        kind, kind.__name__
    )


def _python(d: Declared, value: Any) -> Any:
    """A ROS parameter's value as its dataclass takes it, or ParameterError."""
    if d.kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if type(value) is not d.kind:
        raise ParameterError(f"{d.name} must be {_kind(d.kind)} (got {value!r})")
    if d.kind is int and value < 0 and _unsigned64(d):
        value += 2**64
    if d.default is None and (
        (d.kind is int and value < 0) or (d.kind is float and math.isnan(value))
    ):
        return None
    return value


def node_parameters(node, *classes: type) -> dict[str, Any]:
    """A node's ROS parameters (-p, --params-file), each declared with its default and help. A
    value of the wrong kind, or a parameter given to this node that it does not have, is a
    ParameterError in one line (rclpy would raise a traceback, or ignore it); ranges are
    checked by the dataclasses the values go to."""
    declared = declarations(*classes)
    values = {}
    for name, d in declared.items():
        descriptor = ParameterDescriptor(description=d.spec.help, dynamic_typing=True)
        value = node.declare_parameter(name, ros_default(d), descriptor).value
        values[name] = _python(d, value)
    # rclpy keeps the overrides meant for this node here (no public accessor in Jazzy).
    given = set(getattr(node, "_parameter_overrides", {}))
    unknown = sorted(given - set(declared) - ROS_OWN_PARAMETERS)
    if unknown:
        raise ParameterError(
            f"{node.get_name()} has no parameter {unknown[0]} (it has: {', '.join(declared)})"
        )
    return values


def _unsigned64(d: Declared) -> bool:
    return d.spec.low == 0 and d.spec.high is not None and d.spec.high > INT64_MAX


def ros_literal(value: Any) -> str:
    """A value as `-p NAME:=VALUE` writes it (ROS reads it as YAML)."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return repr(value)
    if value == "":
        return '""'
    return str(value)


def ros_arguments(obj: Any, **overrides: Any) -> list[str]:
    """A dataclass's ROS parameters as `-p NAME:=VALUE` arguments (`overrides` replace
    values; None leaves a parameter out)."""
    declared = with_role(type(obj), "ros")
    values = {name: getattr(obj, name) for name in declared}
    values.update(overrides)
    for name, value in values.items():
        if isinstance(value, int) and value > INT64_MAX and _unsigned64(declared[name]):
            values[name] = value - 2**64
    return [
        arg
        for name, value in values.items()
        if value is not None
        for arg in ("-p", f"{name}:={ros_literal(value)}")
    ]


def parameters_help(*classes: type) -> list[str]:
    """A node's parameters as its --help lists them: name (default): what it is; range."""
    lines = []
    for name, d in declarations(*classes).items():
        default = ros_default(d)
        shown = f"{default!r}: {d.spec.none_means}" if d.default is None else repr(default)
        bounds = "" if d.spec.choices else d.describe_range()
        choices = f"; {', '.join(d.spec.choices)}" if d.spec.choices else ""
        lines.append(f"{name} ({shown}): {d.spec.help}{'; ' + bounds if bounds else ''}{choices}")
    return lines
