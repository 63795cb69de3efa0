"""What a sweep runs: products of axes over `./camo sim`'s options, times replicates, and each
trial's identity and seed.

A trial is a `./camo sim` command line: its options (the sweep's fixed options and one value of
every axis) and a seed. The trial's id is a hash of its options, replicate number, root seed and
driver; its seed comes from `numpy.random.SeedSequence(root_seed, spawn_key=...)` with a key
derived from its options and replicate. Neither depends on where the trial sits in the sweep, so
its result is the same whatever the engine, order, batch or number of workers.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import os
import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from camo_core.cli.commands import add_sim_arguments
from camo_core.cli.options import Parser
from camo_core.exceptions import UsageError
from camo_core.inputs.files import shown
from camo_core.inputs.numeric import items, number
from camo_core.inputs.strict_yaml import described, read_yaml

DRIVERS = ("sim", "ros")
# Options of ./camo sim that are not a trial's: where it writes, the seed (a trial's own, from the
# root seed), real readings, parameters files and a previous round (--after: a trial is a
# first round; its value was passed over, the table's rows wrong).
NOT_AXES = {"out", "force", "seed", "sensed", "params_file", "help", "after"}
SPEC_KEYS = {"seed", "trials", "driver", "options", "axes", "blocks", "slurm"}
MAX_TRIALS = 10_000_000
MAX_FILE_BYTES = 16 * 1024 * 1024  # a sweep file is a few lines


@cache
def sim_parser() -> Parser:
    """A parser of ./camo sim's options: the options a trial takes."""
    return add_sim_arguments(Parser(prog="camo sim"))


@cache
def defaults() -> argparse.Namespace:
    """./camo sim's options when none is given."""
    return sim_parser().parse_args([])


@cache
def sim_actions() -> dict[str, argparse.Action]:
    """Option name (dest: rho_comm) -> its argparse action, for the options a trial can set."""
    return {
        action.dest: action
        for action in sim_parser()._actions
        if action.option_strings
        and action.dest not in NOT_AXES
        and action.default != "==SUPPRESS=="
    }


def typed(name: str, value: Any) -> Any:
    """An option's value as ./camo sim's parser reads it (`"0.10"` and `0.1` are one value)."""
    actions = sim_actions()
    if name == "seed":
        raise UsageError("seed is not an axis: --trials gives replicates, --seed the root seed")
    if name not in actions:
        known = ", ".join(sorted(actions))
        raise UsageError(f"unknown option or axis {name!r}: not an option of ./camo sim ({known})")
    action = actions[name]
    if action.nargs == 0:  # a flag
        if not isinstance(value, bool):
            raise UsageError(f"{name} is a flag: true or false (got {described(value)})")
        return value
    if isinstance(value, list | dict | tuple) or value is None:
        raise UsageError(f"{name}: one value, not {described(value)}")
    text = str(value).strip()
    # The type as the parser converts it: a Parser reads type=int/float strictly.
    convert = sim_parser()._registry_get("type", action.type, action.type) or str
    try:
        out = convert(text)
    except (TypeError, ValueError, argparse.ArgumentTypeError):
        raise UsageError(f"{name}: {described(value)} is not a valid value") from None
    if action.choices is not None and out not in action.choices:
        choices = ", ".join(map(str, action.choices))
        raise UsageError(f"{name}: {described(value)} is not one of {choices}")
    if isinstance(out, float) and not math.isfinite(out):
        raise UsageError(f"{name}: {described(value)} is not a finite number")
    if name == "image":  # a.png and ./a.png are one image
        out = os.path.normpath(out)
    return out


RANGE = re.compile(r"^\s*([-+0-9.eE]+)\s*:\s*([-+0-9.eE]+)\s*:\s*([-+0-9.eE]+)\s*$")


def axis_values(name: str, given: Any) -> list[Any]:
    """An axis's values: a list (YAML), `FROM:TO:STEP` (TO included) or `a,b,c`."""
    if isinstance(given, list):
        raw = given
    elif isinstance(given, str) and RANGE.match(given):
        raw = value_range(name, *RANGE.match(given).groups())
    elif isinstance(given, str):
        # `0,,1`: an empty value is an error (and no value at all, "axis ... is empty")
        raw = items(given, f"axis {name}") if given.strip() else []
    else:
        raw = [given]
    names = name.split(",")
    values = [typed(names[0], v) for v in raw]
    for other in names[1:]:
        for v in raw:
            typed(other, v)
    if not values:
        raise UsageError(f"axis {name} is empty")
    if len(set(map(repr, values))) != len(values):
        raise UsageError(f"axis {name} repeats a value")
    return values


def value_range(name: str, first: str, last: str, step: str) -> list[Any]:
    try:
        a, b, d = number(first), number(last), number(step)
    except ValueError:
        raise UsageError(f"axis {name}: {first}:{last}:{step} is not FROM:TO:STEP") from None
    if not d > 0 or not all(map(math.isfinite, (a, b, d))) or b < a:
        raise UsageError(f"axis {name}: {first}:{last}:{step} needs FROM <= TO and STEP > 0")
    count = math.floor((b - a) / d + 1e-9) + 1
    if count > 100_000:
        raise UsageError(f"axis {name}: {first}:{last}:{step} has {count} values")
    integers = all(re.fullmatch(r"[-+]?\d+", t) for t in (first, last, step))
    return [int(a + k * d) if integers else round(a + k * d, 12) for k in range(count)]


@dataclass(frozen=True)
class Trial:
    trial_id: str
    replicate: int
    seed: int
    options: dict[str, Any]  # option name -> value: the fixed options and this trial's axes

    def sim_args(self) -> list[str]:
        """The trial as ./camo sim's options (without --seed and --out)."""
        return sim_args(self.options)


def sim_args(options: dict[str, Any]) -> list[str]:
    actions = sim_actions()
    args: list[str] = []
    for name, value in options.items():
        if value is None:  # an option left at a default of None: ./camo sim is not given it
            continue
        flag = max(actions[name].option_strings, key=len)
        if actions[name].nargs == 0:
            args += [flag] if value else []
        else:
            args += [flag, repr(value) if isinstance(value, float) else str(value)]
    return args


def canonical(data: Any) -> bytes:
    return json.dumps(data, sort_keys=True, separators=(",", ":")).encode()


@dataclass
class SweepSpec:
    """A sweep: the union of products of axes (blocks), fixed options, replicates, a root seed."""

    blocks: list[dict[str, list[Any]]]  # axis ("rho_comm", or tied "rho_meas,rho_comm") -> values
    options: dict[str, Any] = field(default_factory=dict)
    trials: int = 1
    seed: int = 0
    driver: str = "sim"
    slurm: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.driver not in DRIVERS:
            raise UsageError(
                f"driver must be one of {', '.join(DRIVERS)} (got {described(self.driver)})"
            )
        if isinstance(self.trials, bool) or not isinstance(self.trials, int) or self.trials < 1:
            raise UsageError(f"trials must be a positive integer (got {described(self.trials)})")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise UsageError(f"seed must be a non-negative integer (got {described(self.seed)})")
        if not self.blocks or not all(self.blocks):
            raise UsageError("a sweep needs at least one axis (--axis NAME=VALUES)")
        self.options = {name: typed(name, value) for name, value in self.options.items()}
        names = self.axis_names()
        for name in names:
            if name in self.options:
                raise UsageError(f"{name} is both an axis and a fixed option")
        sources = {"image", "pattern"} & (set(names) | set(self.options))
        if len(sources) > 1:
            raise UsageError("a sweep takes --image or --pattern values, not both")
        self.refuse_more_than(MAX_TRIALS)

    def refuse_more_than(self, limit: int, flag: str = "") -> None:
        """One line if the sweep has more than `limit` trials (`flag`: the option that set it)."""
        count = self.count()
        if count > limit:
            most = f"{flag} {limit:,}" if flag else f"the {limit:,} a sweep may have"
            raise UsageError(
                f"the sweep has {count:,} trials, more than {most}: fewer values or replicates"
            )

    def axis_names(self) -> list[str]:
        """Every option an axis sets, in order of first appearance: the table's axis columns."""
        names: list[str] = []
        for block in self.blocks:
            for axis in block:
                names += [n for n in axis.split(",") if n not in names]
        return names

    def count(self) -> int:
        points = sum(math.prod(len(v) for v in block.values()) for block in self.blocks)
        return points * self.trials

    def trial_list(self) -> list[Trial]:
        """Every trial once, in a fixed order; a point in two blocks is one point."""
        out, seen = [], set()
        names = self.axis_names()
        for block in self.blocks:
            axes = list(block.items())
            for values in itertools.product(*(v for _, v in axes)):
                options = dict(self.options)
                for (axis, _), value in zip(axes, values, strict=True):
                    for name in axis.split(","):
                        options[name] = value
                # An axis another block sweeps takes ./camo sim's default here, so that one
                # point reached from two blocks is one trial.
                for name in names:
                    options.setdefault(name, getattr(defaults(), name))
                key = canonical(options)
                if key in seen:
                    continue
                seen.add(key)
                out += [self.trial(options, r) for r in range(self.trials)]
        return out

    def trial(self, options: dict[str, Any], replicate: int) -> Trial:
        digest = hashlib.sha256(canonical(options)).digest()
        spawn_key = (*(int.from_bytes(digest[k : k + 4], "little") for k in range(0, 16, 4)),)
        sequence = np.random.SeedSequence(self.seed, spawn_key=(*spawn_key, replicate))
        seed = int(sequence.generate_state(1, np.uint64)[0])
        identity = {"options": options, "replicate": replicate, "root": self.seed}
        identity["driver"] = self.driver
        trial_id = hashlib.sha256(canonical(identity)).hexdigest()[:20]
        return Trial(trial_id, replicate, seed, options)

    def as_dict(self) -> dict[str, Any]:
        """The spec as sweep.yaml keeps it (axes as lists of values)."""
        data: dict[str, Any] = {"seed": self.seed, "trials": self.trials, "driver": self.driver}
        data["options"] = dict(self.options)
        data["blocks"] = [{axis: list(values) for axis, values in b.items()} for b in self.blocks]
        if self.slurm:
            data["slurm"] = dict(self.slurm)
        return data

    def same_sweep(self, other: SweepSpec) -> bool:
        """The same points, root seed and driver (the number of replicates may differ, the
        order of values too): a table of one can take the other's trials."""

        def points(spec: SweepSpec) -> set[bytes]:
            return {canonical(t.options) for t in spec.with_trials(1).trial_list()}

        same = (self.seed, self.driver, self.axis_names()) == (
            other.seed,
            other.driver,
            other.axis_names(),
        )
        return same and points(self) == points(other)

    def with_trials(self, trials: int) -> SweepSpec:
        return SweepSpec(self.blocks, self.options, trials, self.seed, self.driver, self.slurm)


def spec_from_yaml(path: str | Path) -> dict[str, Any]:
    """A SWEEP.yaml's contents, checked for shape (values are checked by SweepSpec)."""
    data = read_yaml(path, "sweep file", MAX_FILE_BYTES, UsageError)
    name = shown(path)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise UsageError(f"{name}: a sweep file is a mapping of {', '.join(sorted(SPEC_KEYS))}")
    unknown = set(data) - SPEC_KEYS
    if unknown:
        first = sorted(unknown, key=str)[0]
        raise UsageError(
            f"{name}: unknown key {described(first)} (keys: {', '.join(sorted(SPEC_KEYS))})"
        )
    if "axes" in data and "blocks" in data:
        raise UsageError(f"{name}: give axes or blocks, not both")
    for key in ("options", "axes", "slurm"):
        if not isinstance(data.get(key, {}), dict):
            raise UsageError(f"{name}: {key} must be a mapping")
    blocks = data.get("blocks", [])
    if not isinstance(blocks, list) or not all(isinstance(b, dict) for b in blocks):
        raise UsageError(f"{name}: blocks must be a list of mappings of axes")
    for key in ("options", "axes", "slurm"):
        _names_only(name, key, [data.get(key, {})])
    _names_only(name, "blocks", blocks)
    return data


def _names_only(name: str, key: str, mappings: list[dict]) -> None:
    """The keys of a sweep file's mappings are option names: text, not 1 or null."""
    for mapping in mappings:
        for option in mapping:
            if not isinstance(option, str):
                raise UsageError(f"{name}: {key}: {described(option)} is not an option name")


def build_spec(
    file_data: dict[str, Any] | None,
    axes: list[str],
    options: list[str],
    trials: int | None,
    seed: int | None,
    driver: str | None,
) -> SweepSpec:
    """The sweep from a file's contents and the command line (which adds axes and overrides)."""
    data = dict(file_data or {})
    blocks = [dict(b) for b in data.get("blocks", [])] or [dict(data.get("axes", {}))]
    for text in axes:
        name, sep, values = text.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--axis takes NAME=VALUES (got {text!r})")
        for block in blocks:
            if name.strip() in block:
                raise UsageError(f"axis {name.strip()} is given twice")
            block[name.strip()] = values
    for block in blocks:
        seen: set[str] = set()
        for axis in block:
            names = [n.strip() for n in axis.split(",")]
            if not all(names):
                raise UsageError(f"axis {axis!r} has an empty option name (tied: NAME,NAME)")
            twice = (seen & set(names)) or {n for n in names if names.count(n) > 1}
            if twice:
                raise UsageError(f"axis {sorted(twice)[0]} is given twice")
            seen.update(names)
    fixed = dict(data.get("options", {}))
    for text in options:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--set takes NAME=VALUE (got {text!r})")
        fixed[name.strip()] = value
    checked = [{axis: axis_values(axis, v) for axis, v in block.items()} for block in blocks]
    return SweepSpec(
        blocks=[b for b in checked],
        options=fixed,
        trials=data.get("trials", 1) if trials is None else trials,
        seed=data.get("seed", 0) if seed is None else seed,
        driver=data.get("driver", "sim") if driver is None else driver,
        slurm=dict(data.get("slurm", {})),
    )
