"""Command-line options shared by every command that runs a camouflage (sim, errors, run, ...)."""

from __future__ import annotations

import argparse
import copy
import itertools
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import with_contrast
from camo_core.exceptions import UsageError
from camo_core.inputs.files import checked_path, shown
from camo_core.inputs.images import load_image
from camo_core.inputs.numeric import integer, number
from camo_core.results.folders import FolderDenied, output_folder
from camo_core.schema import Declared, with_role


@dataclass(frozen=True)
class Combination:
    """How an option goes with others: it `needs` one of them, or `excludes` each of them
    (`why`: said after the one line). Options are named by their flags; an option counts as
    given when its value differs from its declared default (from the command line or a
    parameters file)."""

    option: str
    needs: tuple[str, ...] = ()
    excludes: tuple[str, ...] = ()
    why: str = ""


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors, and no abbreviations: `--row` is not `--rows`. With
    `add_params_file_option()`, options can come from a ROS 2 parameters file too."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        # `type=int` and `type=float` read by camo_core.inputs' grammar, not Python's (`1_0`,
        # `١`); argparse looks types up here, for this parser's groups and subcommands too.
        self.register("type", int, strict_int)
        self.register("type", float, strict_float)
        self.combinations: list[Combination] = []
        self._declared: dict[str, object] | None = None  # each option's default as declared

    def combine(self, *rules: Combination) -> None:
        """Rules of which options need, exclude or mean nothing without which others: checked
        once every option is parsed (and a parameters file read), in one line."""
        self.combinations.extend(rules)

    def given(self, args: argparse.Namespace, flag: str) -> bool:
        action = self._option_actions()[flag]
        value = getattr(args, action.dest, None)
        declared = (self._declared or {}).get(action.dest, action.default)
        unset = value is None or value is False or (isinstance(value, list | str) and not value)
        return not unset and value != declared  # (0 is a value: --camera 0)

    def _option_actions(self) -> dict[str, argparse.Action]:
        return {flag: a for a in self._actions for flag in a.option_strings}

    def check_combinations(self, args: argparse.Namespace) -> None:
        for rule in self.combinations:
            if not self.given(args, rule.option):
                continue
            why = f": {rule.why}" if rule.why else ""
            if rule.needs and not any(self.given(args, n) for n in rule.needs):
                self.error(f"{rule.option} needs {' or '.join(rule.needs)}{why}")
            for other in rule.excludes:
                if self.given(args, other):
                    self.error(f"{rule.option} and {other} do not go together{why}")

    def error(self, message: str) -> NoReturn:  # one line, not usage + message
        # `--sensed -1,1=5`: argparse takes "-1,1=5" for an option, and says only this.
        dashed = re.fullmatch(r"argument (?:\S+/)?(--?[^\s/:]+): expected one argument", message)
        if dashed:
            message += f" (a value that begins with '-' is given as {dashed[1]}=VALUE)"
        raise UsageError(message)

    def add_params_file_option(self, node: str) -> None:
        """--params-file FILE: a ROS 2 parameters file whose `/**` and `<node>` keys set options
        (`rho_comm: 0.1` is --rho-comm 0.1); options on the command line override it."""
        self.add_argument(
            "--params-file",
            metavar="FILE",
            type=a_path,
            default=None,
            help=f"ROS 2 parameters YAML (keys /** and {node}); the command line overrides it",
        )
        self.set_defaults(params_node=node)

    def parse_with_ros_args(self, argv: list[str] | None = None):
        """(options, ROS arguments) of a node's command line: everything before `--ros-args` is
        ours and must parse (a misspelt option is an error, not a ROS argument); from
        `--ros-args` on it is rclpy's."""
        argv = list(sys.argv[1:] if argv is None else argv)
        at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
        return self.parse_args(argv[:at]), argv[at:]

    def parse_known_args(self, args=None, namespace=None):
        if self._declared is None:  # before a parameters file changes the defaults
            self._declared = {a.dest: a.default for a in self._actions}
        parsed, rest = self._parse_with_file(args, namespace)
        self.check_combinations(parsed)
        return parsed, rest

    def _parse_with_file(self, args, namespace):
        if not any(a.dest == "params_file" for a in self._actions):  # (a subcommand's, say)
            return super().parse_known_args(args, namespace)
        first, _ = super().parse_known_args(args, copy.copy(namespace))
        path = getattr(first, "params_file", None)
        if path is None:
            return super().parse_known_args(args, namespace)
        from camo_core.cli.params_file import (
            options_from_file,  # the YAML reader, only when a file is given
        )

        # The file's values as defaults, so that what the command line gives wins.
        self.set_defaults(**options_from_file(self, path, first.params_node))
        return super().parse_known_args(args, namespace)


def strict_int(text: str) -> int:
    """`type=int` of a Parser: camo_core.inputs.numeric.integer (argparse says "invalid int
    value")."""
    return integer(text)


def strict_float(text: str) -> float:
    """`type=float` of a Parser: camo_core.inputs.numeric.number, finite."""
    return number(text)


def a_path(text: str) -> Path:
    """A path option's argparse type: not empty (Path("") would be ".", the current folder),
    not longer than the system takes."""
    return checked_path(text, "", argparse.ArgumentTypeError)


a_path.__name__ = "path"


MAX_SECONDS = 86400.0  # a day: a wait longer than that is a mistake (and 1e300 overflows timers)


def seconds(text: str) -> float:
    """A duration option's argparse type: a number of seconds in (0, MAX_SECONDS] (not NaN)."""
    try:
        value = number(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seconds, a number (got {text!r})") from None
    if not 0 < value <= MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"seconds in (0, {MAX_SECONDS:g}] (got {text!r})")
    return value


seconds.__name__ = "seconds"


def add_options(
    parser: argparse.ArgumentParser, cls: type, only: tuple[str, ...] | None = None
) -> None:
    """The command-line options of a dataclass's declared parameters (camo_core.schema), or of
    `only` those: one `--name-with-dashes` each, typed, ranged and documented from its
    declaration. An option left out has the declared default (None where the dataclass fills
    it in, "" as None)."""
    for name, d in with_role(cls, "cli").items():
        if only is not None and name not in only:
            continue
        if d.kind is bool:
            parser.add_argument(d.option, action="store_true", help=help_of(d))
            continue
        parser.add_argument(
            d.option,
            type=converter(d),
            default=None if d.default in (None, "") else d.default,
            choices=d.spec.choices or None,
            metavar=d.spec.metavar or None,
            help=help_of(d),
        )


def help_of(d: Declared) -> str:
    """An option's help: what it is, its unit and range, its default."""
    s = d.spec
    bounds = "" if s.choices else d.describe_range()
    unit = f" {s.unit}" if s.unit and s.unit != "robots" else ""
    about = f"; {bounds}{unit}" if bounds else ""
    if d.default is None or d.default == "" or (d.kind is int and d.default == 0 and s.none_means):
        default = s.none_means
    elif d.kind is bool:
        return f"{s.help}{about}"
    else:
        default = f"{d.default:g}" if isinstance(d.default, float) else str(d.default)
    return f"{s.help}{about} (default: {default})" if default else f"{s.help}{about}"


def converter(d: Declared):
    """The option's argparse type: its kind, or its keyword ("auto") as itself."""
    kind = {int: _whole, float: _real}.get(d.kind, str)

    def convert(text):
        if not d.spec.keyword:
            return kind(text)  # argparse says "invalid int value: 'x'"
        if text == d.spec.keyword:
            return text
        try:
            return kind(text)
        except (TypeError, ValueError):
            expected = {int: "a whole number", float: "a number"}.get(d.kind, "text")
            if d.spec.unit and d.kind is int:
                expected += f" of {d.spec.unit}"
            raise argparse.ArgumentTypeError(
                f"{expected} or {d.spec.keyword} (got {text!r})"
            ) from None

    convert.__name__ = d.kind.__name__  # argparse names the type in its "invalid ..." errors
    convert.kind = d.kind  # type: ignore[attr-defined]  # what a parameters file must give
    return convert


def _whole(value) -> int:
    """An integer from a command line or a parameters file ("+3" too; not 3.5, not true)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    if isinstance(value, str):
        return integer(value)
    raise ValueError(value)


def _real(value) -> float:
    """A number from a command line or a parameters file (a YAML 3 or 0.5 too; not true)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str):
        return number(value)
    raise ValueError(value)


def add_run_options(
    parser: argparse.ArgumentParser, default_pattern: str | None = "forest"
) -> None:
    """The options shared by every command that runs one camouflage (sim, errors, run): the
    background and CamoParams' declared parameters."""
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--image", help="background image file (PNG, JPEG, BMP, TIFF, WebP, ...)")
    source.add_argument(
        "--pattern",
        choices=BACKGROUNDS,
        default=None,
        help=f"built-in background (default: {default_pattern})",
    )
    add_options(parser, CamoParams)
    add_out_options(parser)
    parser.set_defaults(default_pattern=default_pattern)
    if isinstance(parser, Parser):
        # (A parameters file's pattern with --image on the command line: the command line's
        # background overrides the file's, as any option does.)
        parser.combine(
            Combination("--scope-scale", needs=("--scope",), why="the size of --scope local's")
        )


def add_out_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=a_path, default=None, help="output folder (default results/<timestamp>/)"
    )
    parser.add_argument(
        "--force", action="store_true", help="write into --out even if it holds something"
    )


def options_of(args: argparse.Namespace, cls: type) -> dict:
    """A dataclass's parameters that a parsed command line gives (those not given are left out:
    the dataclass's defaults)."""
    given = {name: getattr(args, name, None) for name in with_role(cls, "cli")}
    return {name: value for name, value in given.items() if value is not None}


def params_from(args: argparse.Namespace) -> CamoParams:
    return CamoParams.from_options(**options_of(args, CamoParams))


def image_from(args: argparse.Namespace) -> tuple[np.ndarray, str]:
    """The background and its label; with a --contrast (sim's, errors'), at that contrast."""
    if args.image is not None:  # "" too: an empty path is an error, not the default
        image, label = load_image(args.image), str(args.image)
    else:
        name = args.pattern or args.default_pattern
        image, label = background(name), f"built-in {name}"
    contrast = getattr(args, "contrast", None)
    if contrast is not None:
        image, label = with_contrast(image, contrast), f"{label} at contrast {contrast:g}"
    return image, label


def add_contrast_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--contrast",
        type=float,
        default=None,
        help="scale the background's contrast by this factor in (0, 1] first: each value "
        "pulled toward the image's mean (default: as it is)",
    )


# The files a command writes into its output folder, and the options that name input files.
OUTPUT_NAMES = frozenset(
    ("summary.json", "figure.png", "run.gif", "params.yaml", "timing.json", "processes.json",
     "run.key", "background.png", "rounds.csv", "timeline.png", "layout.csv", "errors.png",
     "errors.csv")
)  # fmt: skip
INPUT_OPTIONS = ("image", "params_file", "calibration", "video", "then", "after")


def out_dir(args: argparse.Namespace) -> Path:
    """The output folder of --out and --force (results.folders.output_folder). With --force,
    never one where an output would replace a file the command reads (its --image, its
    --params-file: the run could then not be repeated)."""
    force = getattr(args, "force", False)
    if force and args.out is not None:
        out = Path(args.out).resolve()
        for option in INPUT_OPTIONS:
            given = getattr(args, option, None)
            for value in given if isinstance(given, list) else [given]:
                path = Path(value).resolve() if isinstance(value, str | Path) else None
                if path is not None and path.parent == out and path.name in OUTPUT_NAMES:
                    flag = "--" + option.replace("_", "-")
                    raise UsageError(
                        f"--out {shown(args.out)} would replace {path.name}, which {flag} "
                        "reads: choose another folder"
                    )
    try:
        return output_folder(args.out, force)
    except FolderDenied as exc:
        if not os.environ.get(IN_IMAGE):
            raise
        raise UsageError(
            f"{exc} (camo's image runs as uid {os.getuid()}: mount a folder it may write)"
        ) from None


IN_IMAGE = "CAMO_IN_IMAGE"  # set in camo's container image (docker/Dockerfile)


def parse_ranges(texts: list[str], count: int, option: str = "--cells") -> list[tuple[int, int]]:
    """FIRST-LAST options (robot ids, inclusive; a single id is a range of one) as sorted,
    non-overlapping ranges inside 0..count-1."""
    ranges = []
    for text in texts:
        first, dash, last = text.partition("-")
        try:
            a, b = integer(first), integer(last if dash else first)
        except ValueError:
            raise UsageError(f"{option} takes FIRST-LAST, robot ids (got {text!r})") from None
        if not 0 <= a <= b < count:
            raise UsageError(
                f"{option} {text}: robot ids run from 0 to {count - 1}, first <= last"
            )
        ranges.append((a, b))
    ranges.sort()
    for (_, b), (c, _) in itertools.pairwise(ranges):
        if c <= b:
            raise UsageError(f"{option}: ranges overlap at robot {c}")
    return ranges
