"""ROS 2 parameters files (`--ros-args --params-file FILE`), checked before rcl reads them.

rcl parses the file inside `rclpy.init`, and what it says of a bad one is a
traceback ending in "Couldn't parse params file ... at /project/src/parse.c".
This check names the usual mistakes first, in one line with what is wrong and
where: a file that is not YAML, or not a mapping of node names (namespaces
nest, `/**` matches every node) down to `ros__parameters`, or a list that mixes
kinds of values. What else rcl refuses, it reports itself
(`camo_nodes.topics.init_ros` turns that into one line too).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from .exceptions import UsageError

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
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ParamsFileError(f"{path}: {path.stat().st_size} bytes is not a parameters file")
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise ParamsFileError(f"cannot read parameters file {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ParamsFileError(f"{path}: a parameters file is UTF-8 text") from None
    try:
        documents = list(yaml.safe_load_all(text))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        raise ParamsFileError(f"{path} is not YAML{where}") from None
    except RecursionError:
        raise ParamsFileError(f"{path} nests too deeply to be a parameters file") from None
    for document in documents:
        if document is None:
            continue
        if not isinstance(document, dict):
            raise ParamsFileError(
                f"{path}: a parameters file maps NODE: {{{PARAMETERS_KEY}: {{NAME: VALUE}}}}"
            )
        _check_nodes(path, document, "")
    return [d for d in documents if d]


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
    for document in check_params_file(path):
        for where, values in _sections(document):
            if where == "/**":
                general.update(_flat(values))
            elif where.split("/")[-1] == node:
                own.update(_flat(values))
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
