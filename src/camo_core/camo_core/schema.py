"""One declaration per parameter: a dataclass field that carries its help, unit, range and roles.

A parameter of a run (`CamoParams`, `ProtocolParams`) or of a node (the projector's, a bridge's)
is declared once, as a field made by `param()`. Everything else is derived from that field:
the command-line options (`camo_core.cli.options.add_options`), the ROS parameters a node
declares and the `-p NAME:=VALUE` arguments of the processes a run starts
(`camo_nodes.topics.parameters`), `params.yaml` (through the options), the run's setup on the
params topic (`to_dict` / `from_dict`), the summary's parameter fields (`values(..., "summary")`)
and the axes a sweep may vary (the options of `./camo sim`).

No argparse and no ROS here: this module only describes and checks.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from camo_core.exceptions import CamoError

METADATA_KEY = "camo"  # the key of a field's metadata that holds its Spec


class ParameterError(CamoError):
    """A parameter outside its allowed range; the message names it and the range."""


@dataclass(frozen=True)
class Spec:
    """What a parameter is, besides its name, type and default."""

    help: str
    unit: str = ""  # "s", "probability", "robots", ...
    low: float | None = None  # inclusive bounds of a number
    high: float | None = None
    above: bool = False  # low is exclusive: the value must be > low
    choices: tuple[str, ...] = ()
    keyword: str = ""  # a word the command line takes instead of a value ("auto")
    metavar: str = ""
    none_means: str = ""  # for a parameter that may be None: what None stands for
    off: Any = None  # a value outside the range that turns the parameter off (levels 0)
    cli: bool = True  # an option of the commands that take its dataclass
    ros: bool = True  # a ROS parameter of the nodes that take its dataclass
    summary: bool = False  # written into summary.json
    noise: bool = False  # an error probability: zero in the error-free reference of a sweep


def param(default: Any, help: str, **spec: Any) -> Any:
    """A dataclass field declared with its Spec (see Spec for the keywords)."""
    return field(default=default, metadata={METADATA_KEY: Spec(help, **spec)})


@dataclass(frozen=True)
class Declared:
    """One declared parameter of a dataclass."""

    name: str
    kind: type  # int, float, bool, str or tuple
    optional: bool  # None is a value (see Spec.none_means)
    default: Any
    spec: Spec

    @property
    def option(self) -> str:
        """Its command-line spelling."""
        return "--" + self.name.replace("_", "-")

    def describe(self) -> str:
        """What a value must be: "an integer in 1..8192", "a number in [0, 1]", "a number > 0"."""
        what = {int: "an integer", float: "a number"}.get(self.kind, "a value")
        bounds = self.describe_range()
        if not bounds:
            return what
        return f"{what} {bounds}" if bounds[0] in "<>" else f"{what} in {bounds}"

    def describe_range(self) -> str:
        s = self.spec
        if s.choices:
            return "one of " + ", ".join(s.choices)
        if s.low is None and s.high is None:
            return ""
        if self.kind is int:
            return f"{s.low}..{s.high}" if s.high is not None else f">= {s.low}"
        low = "(" if s.above else "["
        if s.high is None:
            return f"{'>' if s.above else '>='} {s.low:g}"
        return f"{low}{s.low:g}, {s.high:g}]"


def _kind_of(hint: Any) -> tuple[type, bool]:
    args = typing.get_args(hint)
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        kinds = [a for a in args if a is not type(None)]
        return _kind_of(kinds[0])[0], type(None) in args
    origin = typing.get_origin(hint)
    return (origin or hint), False


def declared(cls: type) -> dict[str, Declared]:
    """The parameters a dataclass declares with param(), in field order (cached per class)."""
    # A typed front for the cache: mypy takes functools.cache's argument as Hashable, which
    # type[Any] (the type() of an Any) is not, though every class is.
    return _declared(cls)


@cache
def _declared(cls: type) -> dict[str, Declared]:
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        spec = f.metadata.get(METADATA_KEY)
        if spec is None:
            continue
        kind, optional = _kind_of(hints[f.name])
        default = f.default if f.default is not dataclasses.MISSING else None
        # A default of None is filled in by the dataclass (the profile's, say): None is a value
        # it may be given.
        out[f.name] = Declared(f.name, kind, optional or default is None, default, spec)
    return out


def with_role(cls: type, role: str) -> dict[str, Declared]:
    """The parameters of `cls` that have a role: "cli", "ros", "summary" or "noise"."""
    return {n: d for n, d in declared(cls).items() if getattr(d.spec, role)}


def values(obj: Any, role: str) -> dict[str, Any]:
    """An instance's values of the parameters with `role`, in declaration order."""
    return {name: getattr(obj, name) for name in with_role(type(obj), role)}


# ---- checking -----------------------------------------------------------------------------


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def checked(d: Declared, value: Any) -> Any:
    """`value` as parameter `d` holds it (an integer where a number is declared becomes that
    number), or ParameterError in one line."""
    s = d.spec
    if value is None and d.optional:
        return None
    if s.off is not None and type(value) is type(s.off) and value == s.off:
        return value
    if d.kind is bool:
        if not isinstance(value, bool):
            raise ParameterError(f"{d.name} must be true or false (got {value!r})")
        return value
    if d.kind is str:
        if not isinstance(value, str):
            raise ParameterError(f"{d.name} must be text (got {value!r})")
        if s.choices and value not in s.choices:
            raise ParameterError(f"{d.name} must be one of {', '.join(s.choices)} (got {value!r})")
        return value
    if d.kind is int:
        high = math.inf if s.high is None else s.high
        if not _is_int(value) or not (s.low is None or s.low <= value <= high):
            raise ParameterError(f"{d.name} must be {d.describe()} (got {value!r})")
        return value
    if d.kind is float:
        ok = _is_number(value) and math.isfinite(value)
        if ok and s.low is not None:
            ok = value > s.low if s.above else value >= s.low
        if ok and s.high is not None:
            ok = value <= s.high
        if not ok:
            raise ParameterError(f"{d.name} must be {d.describe()} (got {value!r})")
        return float(value)
    return value  # structured values (tuples) are checked by their dataclass


def check_fields(obj: Any) -> None:
    """Check (and normalise, e.g. int -> float) every declared parameter of a frozen dataclass
    instance, in its __post_init__."""
    for name, d in declared(type(obj)).items():
        object.__setattr__(obj, name, checked(d, getattr(obj, name)))


def to_dict(obj: Any) -> dict[str, Any]:
    """The declared parameters of an instance, as JSON and YAML take them (tuples as lists)."""
    return {name: _plain(getattr(obj, name)) for name in declared(type(obj))}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def from_dict(cls: type, data: Any, what: str = "") -> Any:
    """An instance from to_dict()'s form: unknown keys and wrong kinds of values are a
    ParameterError in one line (`what` says where the values came from)."""
    where = f"{what}: " if what else ""
    if not isinstance(data, dict):
        raise ParameterError(f"{where}parameters must be a mapping of names to values")
    known = declared(cls)
    unknown = sorted(set(data) - set(known), key=str)
    if unknown:
        raise ParameterError(
            f"{where}unknown parameter {unknown[0]!r} (known: {', '.join(known)})"
        )
    try:
        return cls(**data)
    except ParameterError as exc:
        raise ParameterError(f"{where}{exc}") from None
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{where}{exc}") from None
