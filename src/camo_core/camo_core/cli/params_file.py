"""ROS 2 parameters files (`--ros-args --params-file FILE`), checked before rcl reads them.

rcl parses the file inside `rclpy.init`, and what it says of a bad one is a
traceback ending in "Couldn't parse params file ... at /project/src/parse.c".
This check names the usual mistakes first, in one line with what is wrong and
where: a file that is not YAML, or not a mapping of node names (namespaces
nest, `/**` matches every node) down to `ros__parameters`, or a list that mixes
kinds of values. What else rcl refuses, it reports itself
(`camo_nodes.topics.init_ros` turns that into one line too).

The options of camo's own commands come from such files too (`options_from_file`),
and every run writes the options it ran with as one (`write_params_file`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

from camo_core.exceptions import UsageError
from camo_core.inputs.strict_yaml import described, dump_yaml, read_yaml

PARAMETERS_KEY = "ros__parameters"
MAX_BYTES = 16 * 1024 * 1024  # a parameters file is a few lines; anything bigger is not one


class ParamsFileError(UsageError):
    """A parameters file that rcl would refuse."""


def _scalar_kind(value: object) -> str:
    # bool before int: YAML's true is a Python bool, which is also an int
    for kind in (bool, int, float):
        if isinstance(value, kind):
            return kind.__name__
    return "other"  # text, and what rcl reads as text


def _check_parameters(path: Path, node: str, values: object, prefix: str) -> None:
    if not isinstance(values, dict):
        raise ParamsFileError(f"{path}: {node}: {PARAMETERS_KEY} must map names to values")
    for name, value in values.items():
        if not isinstance(name, str):
            raise ParamsFileError(
                f"{path}: {node}: a parameter name is text (got {described(name)})"
            )
        full = f"{prefix}{name}"
        if isinstance(value, dict):
            _check_parameters(path, node, value, f"{full}.")
        elif isinstance(value, list):
            if any(isinstance(item, list | dict) for item in value):
                raise ParamsFileError(f"{path}: {node}: {full} is a list of lists or mappings")
            if len({_scalar_kind(item) for item in value}) > 1:
                raise ParamsFileError(f"{path}: {node}: {full} mixes kinds of values in a list")


def _check_nodes(path: Path, entries: dict, prefix: str) -> None:
    for key, value in entries.items():
        if not isinstance(key, str):
            raise ParamsFileError(f"{path}: a node name is text (got {described(key)})")
        if key == PARAMETERS_KEY:
            if not prefix:
                raise ParamsFileError(f"{path}: {PARAMETERS_KEY} must be under a node name")
            _check_parameters(path, prefix, value, "")
        elif isinstance(value, dict):
            _check_nodes(path, value, f"{prefix}/{key}".replace("//", "/"))
        else:
            raise ParamsFileError(
                f"{path}: {prefix + '/' if prefix else ''}{key} is a value outside "
                f"{PARAMETERS_KEY} (the layout is NODE: {{{PARAMETERS_KEY}: {{NAME: VALUE}}}})"
            )


def check_params_file(path: str | Path) -> list[dict]:
    """The file's documents, or the mistakes people make in a parameters file named in one
    line (ParamsFileError). Whatever else rcl refuses, it says itself when the node starts."""
    document = read_yaml(path, "parameters file", MAX_BYTES, ParamsFileError)
    path = Path(path)  # read_yaml checked it
    if document is None:
        return []
    if not isinstance(document, dict):
        raise ParamsFileError(
            f"{path}: a parameters file maps NODE: {{{PARAMETERS_KEY}: {{NAME: VALUE}}}}"
        )
    _check_nodes(path, document, "")
    return [document] if document else []


def _flat(values: dict, prefix: str = "") -> dict:
    flat = {}
    for name, value in values.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{name}."))
        else:
            flat[f"{prefix}{name}"] = value
    return flat


def _sections(entries: dict, prefix: str = ""):
    """(node path, its parameters) of every ros__parameters in a document."""
    for key, value in entries.items():
        if key == PARAMETERS_KEY:
            yield prefix, value
        elif isinstance(value, dict):
            yield from _sections(value, f"{prefix}/{key}".replace("//", "/"))


def parameters_for(path: str | Path, node: str) -> dict:
    """The parameters a file gives a node named `node` (in any namespace): those under `/**`
    first, then those under its own name, `/**/node` or `/ns/node`."""
    general, own = {}, {}
    sections = []
    for document in check_params_file(path):
        for where, values in _sections(document):
            sections.append(where)
            if where == "/**":
                general.update(_flat(values))
            elif where.split("/")[-1] == node:
                own.update(_flat(values))
    names = {where.split("/")[-1] for where in sections}
    if sections and not names & {node, "**"}:
        # A file for other nodes only (a misspelt node name): nothing of it would be used.
        raise UsageError(
            f"{path}: no section for {node} (it has {', '.join(dict.fromkeys(sections))}): "
            f"name the node /**/{node}, or /** for every node"
        )
    return {**general, **own}


def check_ros_args(args: list[str] | None) -> None:
    """Every `--params-file FILE` of a command line's ROS arguments, checked."""
    args = list(args or [])
    if "--ros-args" not in args:
        return
    ros = args[args.index("--ros-args") + 1 :]
    for k, arg in enumerate(ros):
        if arg == "--params-file":
            if k + 1 >= len(ros):
                raise ParamsFileError("--params-file needs a FILE")
            check_params_file(ros[k + 1])


# Options that name where a run writes, or that a parameters file must not repeat.
NOT_PARAMETERS = {
    *("help", "params_file", "params_node", "options_parser", "func", "command"),
    *("out", "force", "record", "default_pattern"),
}


def _option_value(action: argparse.Action, name: str, value, path: Path):
    """A parameters-file value as the option would have parsed it, or UsageError."""

    def wrong(expected: str) -> UsageError:
        return UsageError(f"{path}: {name} must be {expected} (got {described(value)})")

    if action.nargs == 0:  # a flag
        if not isinstance(value, bool):
            raise wrong("true or false")
        return value
    many = isinstance(action, argparse._AppendAction) or action.nargs in ("+", "*")
    items = value if many else [value]
    if not isinstance(items, list) or (many and not isinstance(value, list)):
        raise wrong("a list")
    parsed = []
    for item in items:
        if isinstance(item, bool | list | dict) or item is None:
            raise wrong("a number or text")
        kind = getattr(action.type, "kind", action.type)  # an option of a declared parameter
        keyword = isinstance(item, str) and item == "auto"
        if kind is int and not isinstance(item, int) and not keyword:
            raise wrong("an integer")
        if kind is float and not isinstance(item, int | float) and not keyword:
            raise wrong("a number")
        # argparse's stubs also allow a str (a type registered by name); ours are callables.
        convert = cast("Callable[[Any], Any] | None", action.type)
        try:
            item = convert(item) if convert else str(item)
        except (TypeError, ValueError, UsageError, argparse.ArgumentTypeError):
            raise wrong("a valid value") from None
        if action.choices is not None and item not in action.choices:
            raise wrong(f"one of {', '.join(map(str, action.choices))}")
        parsed.append(item)
    return parsed if many else parsed[0]


def options_from_file(parser: argparse.ArgumentParser, path: Path, node: str) -> dict:
    """The options a parameters file sets for `node`: dest -> value (UsageError if it names an
    option the command does not have, or a value of the wrong kind)."""
    actions = {a.dest: a for a in parser._actions if a.dest not in NOT_PARAMETERS}
    values = {}
    for name, value in parameters_for(path, node).items():
        action = actions.get(name)
        if action is None:
            raise UsageError(
                f"{path}: {parser.prog} has no parameter {name} (it has: {', '.join(actions)})"
            )
        values[name] = _option_value(action, name, value, path)
    return values


def write_params_file(
    parser: argparse.ArgumentParser, args: argparse.Namespace, folder: Path
) -> Path:
    """The options a command ran with, as a ROS 2 parameters file (folder/params.yaml) that
    `--params-file` takes back: the run repeated."""
    values = {}
    for action in parser._actions:
        value = getattr(args, action.dest, None)
        if action.dest in NOT_PARAMETERS or value is None or value == []:
            continue  # an option not given (a repeatable one included) is left out
        if isinstance(value, Path):
            value = str(value)
        elif isinstance(value, list | tuple):
            value = [str(v) if isinstance(v, Path) else v for v in value]
        values[action.dest] = value
    default = getattr(args, "default_pattern", None)
    if default and not {"pattern", "image"} & values.keys():
        # the built-in background it ran on, named: a later default cannot change it
        values = {"pattern": default, **values}
    path = folder / "params.yaml"
    path.write_text(
        f"# {parser.prog}: repeat with --params-file {path}\n"
        + dump_yaml({"/**": {"ros__parameters": values}})
    )
    return path
