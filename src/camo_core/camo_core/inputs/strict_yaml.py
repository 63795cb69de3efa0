"""YAML: one strict reading for every YAML file or text camo takes from outside.

PyYAML's SafeLoader reads YAML 1.1: `1:5:1` is the base-60 number 3901, `2001-12-14` a date,
`0x4` and `010` numbers in other bases, `yes` and `on` true, a key given twice keeps its last
value, `!!binary` is bytes, `*alias` repeats a node (a "billion laughs" bomb), and a huge integer
literal raises Python's ValueError. rcl, which reads the same parameters files, reads some of
these otherwise (`010` is 8 to it, `yes` true). So camo reads YAML as YAML 1.2's
core schema, minus what would be read differently by someone:

- plain scalars resolve to: null (`null`, `~`, nothing), true/false (`true`, `false`, also
  capitalised), decimal integers (`-12`, no leading zeros, at most MAX_DIGITS digits), decimal
  floats (`1.5`, `1e44`, `.inf`, `.nan`; one that overflows is refused) and text otherwise;
- refused, in one line naming the line: plain scalars that YAML 1.1 or rcl read as something
  else (`0x4`, `0o7`, `010`, `1_000`, `1:00`, `yes`/`no`/`on`/`off`/`y`/`n`): quote them to mean
  text; a key given twice in a mapping; merge keys (`<<`); tags other than the standard null,
  bool, int, float, str, seq and map (no dates, binary, sets); more than one document;
  nesting deeper than MAX_DEPTH or more than MAX_VALUES values as aliases expand (aliases are
  read: PyYAML writes them for a value repeated; an alias into its own node is refused); and
  characters YAML does not allow (a NUL).
"""

from __future__ import annotations

import datetime
import math
import os
import re
from typing import ClassVar

import yaml

from camo_core.exceptions import CamoError
from camo_core.inputs.files import SHOWN, checked_file, shown

MAX_DEPTH = 64  # nested lists and mappings; camo's deepest input (a bag's metadata) has 6
MAX_VALUES = 1_000_000  # scalars, lists and mappings, each alias expanded: a bomb is not data
MAX_DIGITS = 100  # of an integer literal; int64 has 19, and Python refuses more than 4300

_NULL = re.compile(r"^(?:~|null|Null|NULL|)$")
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT = re.compile(r"^[-+]?(?:0|[1-9][0-9]*)$")
_FLOAT = re.compile(
    r"^(?:[-+]?(?:(?:0|[1-9][0-9]*)(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
    r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
)
# What YAML 1.1 (PyYAML, libyaml users) or rcl's strtol/strtod read as numbers or booleans
# though YAML 1.2 reads them as text: refused rather than guessed.
_AMBIGUOUS = (
    (re.compile(r"^[-+]?0[xXoObB][0-9a-fA-F_]*$"), "a number in another base"),
    (re.compile(r"^[-+]?0[0-9_]+(?:\.[0-9_]*)?(?:[eE][-+]?[0-9]+)?$"), "an octal number"),
    (re.compile(r"^[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?$"), "a base-60 number"),
    (re.compile(r"^[-+]?[0-9.][0-9_.]*_[0-9_.]*(?:[eE][-+]?[0-9]+)?$"), "a number"),
    (re.compile(r"^(?:y|Y|yes|Yes|YES|n|N|no|No|NO|on|On|ON|off|Off|OFF)$"), "true or false"),
    (re.compile(r"^[0-9]{4}-[0-9]{1,2}-[0-9]{1,2}(?:[Tt ].*)?$"), "a date"),
)

_STANDARD = "tag:yaml.org,2002:"


_KINDS = (
    (bool, lambda v: "true" if v else "false"),
    (int, lambda v: repr(v) if abs(v) < 10**MAX_DIGITS else "an integer too long to show"),
    (float, repr),
    (str, lambda v: repr(v) if len(v) <= SHOWN else repr(v[: SHOWN - 3] + "...")),
    (list | tuple, lambda v: "a list"),
    (dict, lambda v: "a mapping"),
    (bytes | bytearray, lambda v: "binary data"),
    (datetime.date, lambda v: "a date"),
)


def described(value: object) -> str:
    """A value read from YAML in a user's words, for a one-line message: `nothing`, `true`,
    `12`, `'text'` (at most SHOWN characters), `a list`, `a mapping`; never a Python repr
    such as None, b'...' or datetime.date(...)."""
    if value is None:
        return "nothing"
    for kind, words in _KINDS:
        if isinstance(value, kind):
            return words(value)
    return "a value of another kind"


class _Refused(yaml.MarkedYAMLError):
    """What the strict loader refuses, with where (`problem_mark`)."""

    def __init__(self, problem: str, mark) -> None:
        super().__init__(problem=problem, problem_mark=mark)


class StrictLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader reading as the notes above say (use `parse_yaml`, not this)."""

    yaml_implicit_resolvers: ClassVar[dict] = {}
    yaml_constructors: ClassVar[dict] = {}
    _depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(
                    f"nests deeper than {MAX_DEPTH} levels", self.peek_event().start_mark
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_undefined(self, node):
        tag = node.tag.replace(_STANDARD, "!!")
        raise _Refused(
            f"the tag {tag} is not read (only text, numbers, true/false, null, lists and "
            "mappings)",
            node.start_mark,
        )

    def _scalar_text(self, node) -> str:
        if not isinstance(node, yaml.ScalarNode):
            self.construct_undefined(node)
        return node.value

    def construct_yaml_null(self, node):
        if not _NULL.match(self._scalar_text(node)):
            raise _Refused(f"{node.value!r} is not null", node.start_mark)

    def construct_yaml_bool(self, node):
        text = self._scalar_text(node)
        if not _BOOL.match(text):
            raise _Refused(f"{text!r} is not true or false", node.start_mark)
        return text.lower() == "true"

    def construct_yaml_int(self, node):
        text = self._scalar_text(node)
        if not _INT.match(text):
            raise _Refused(f"{text[:SHOWN]!r} is not a decimal integer", node.start_mark)
        digits = len(text.lstrip("+-"))
        if digits > MAX_DIGITS:
            raise _Refused(
                f"an integer of {digits} digits (at most {MAX_DIGITS} are read)", node.start_mark
            )
        return int(text)

    def construct_yaml_float(self, node):
        text = self._scalar_text(node)
        if not _FLOAT.match(text):
            raise _Refused(f"{text[:SHOWN]!r} is not a decimal number", node.start_mark)
        value = float(text.lower().replace(".inf", "inf").replace(".nan", "nan"))
        if math.isinf(value) and "inf" not in text.lower():
            raise _Refused(f"the number {text[:SHOWN]} is too large", node.start_mark)
        return value

    def construct_yaml_str(self, node):
        return self._scalar_text(node)

    def construct_yaml_map(self, node):
        data: dict = {}
        yield data
        if not isinstance(node, yaml.MappingNode):
            self.construct_undefined(node)
        lines: dict = {}
        for key_node, value_node in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = lines.get(key)
            except TypeError:
                raise _Refused("a key is a list or mapping", key_node.start_mark) from None
            line = key_node.start_mark.line + 1
            if first is not None:
                raise _Refused(
                    f"the key {described(key)} is given twice (lines {first} and {line})",
                    key_node.start_mark,
                )
            lines[key] = line
            data[key] = self.construct_object(value_node, deep=True)

    def construct_yaml_seq(self, node):
        data: list = []
        yield data
        if not isinstance(node, yaml.SequenceNode):
            self.construct_undefined(node)
        data.extend(self.construct_object(item, deep=True) for item in node.value)


for _tag, _first, _pattern in (
    ("bool", "tTfF", _BOOL),
    ("int", "-+0123456789", _INT),
    ("float", "-+0123456789.", _FLOAT),
    ("null", ["~", "n", "N", ""], _NULL),
):
    StrictLoader.add_implicit_resolver(_STANDARD + _tag, _pattern, list(_first))
for _tag, _construct in (
    ("null", StrictLoader.construct_yaml_null),
    ("bool", StrictLoader.construct_yaml_bool),
    ("int", StrictLoader.construct_yaml_int),
    ("float", StrictLoader.construct_yaml_float),
    ("str", StrictLoader.construct_yaml_str),
    ("seq", StrictLoader.construct_yaml_seq),
    ("map", StrictLoader.construct_yaml_map),
):
    StrictLoader.add_constructor(_STANDARD + _tag, _construct)
StrictLoader.add_constructor(None, StrictLoader.construct_undefined)


def _walk(node, level: int, sizes: dict, open_: set) -> tuple[int, int]:
    """(values, depth) of a composed node as it expands (an alias counts as often as it is
    used), refusing on the way what it holds that the notes above refuse: an ambiguous plain
    scalar, a merge key, an alias to a node that holds it, more than MAX_VALUES values or more
    than MAX_DEPTH levels. Shared nodes are walked once (a "billion laughs" is quick)."""
    known = sizes.get(id(node))
    if known is None:
        if id(node) in open_:
            raise _Refused("an alias refers to a node that holds it", node.start_mark)
        if isinstance(node, yaml.ScalarNode):
            if node.style is None and node.tag == _STANDARD + "str":
                for pattern, other in _AMBIGUOUS:
                    if pattern.match(node.value):
                        raise _Refused(
                            f"{node.value[:SHOWN]!r} is {other} to YAML 1.1 (or rcl), text to "
                            "YAML 1.2: write a decimal number or true/false, or quote it",
                            node.start_mark,
                        )
                if node.value == "<<":
                    raise _Refused("merge keys (<<) are not read", node.start_mark)
            known = (1, 1)
        else:
            if level > MAX_DEPTH:
                raise _Refused(f"nests deeper than {MAX_DEPTH} levels", node.start_mark)
            children = node.value
            if isinstance(node, yaml.MappingNode):
                children = [n for pair in node.value for n in pair]
            open_.add(id(node))
            walked = [_walk(child, level + 1, sizes, open_) for child in children]
            open_.discard(id(node))
            known = (
                1 + sum(count for count, _ in walked),
                1 + max((depth for _, depth in walked), default=0),
            )
        sizes[id(node)] = known
    count, depth = known
    if level + depth - 1 > MAX_DEPTH:
        raise _Refused(f"nests deeper than {MAX_DEPTH} levels", node.start_mark)
    if count > MAX_VALUES:
        raise _Refused(f"holds over {MAX_VALUES} values as its aliases expand", node.start_mark)
    return known


def parse_yaml(text: str, where: str, error: type[CamoError] = CamoError) -> object:
    """YAML text (one document) as plain data, read strictly (see the notes above); else
    `error` in one line: `WHERE is not YAML (line N): what`. An empty text is None."""
    loader = None
    try:
        loader = StrictLoader(text)
        node = loader.get_single_node()
        if node is None:
            return None
        _walk(node, 1, {}, set())
        return loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f" (line {mark.line + 1})" if mark is not None else ""
        problem = exc.problem or "not YAML"
        if "single document" in (exc.context or ""):
            problem = "it holds more than one document (---)"
        elif "duplicate anchor" in (exc.context or ""):
            problem = "an anchor (&name) is given twice"
        raise error(f"{where} is not YAML{at}: {problem}") from None
    except yaml.reader.ReaderError as exc:
        char = exc.character if isinstance(exc.character, str) else chr(exc.character)
        raise error(
            f"{where} is not YAML: it holds the character U+{ord(char):04X}, which YAML does "
            f"not allow (at character {exc.position})"
        ) from None
    except RecursionError:
        raise error(f"{where} is not YAML: it nests too deeply") from None
    except (yaml.YAMLError, ValueError, TypeError, OverflowError, MemoryError) as exc:
        raise error(f"{where} is not YAML: {type(exc).__name__.lower()}") from None
    finally:
        if loader is not None:
            loader.dispose()


def read_yaml(
    path: str | os.PathLike | None,
    what: str,
    max_bytes: int,
    error: type[CamoError] = CamoError,
) -> object:
    """The one YAML document of a file, read strictly (`parse_yaml`), the file checked first
    (`checked_file`: a regular file, at most `max_bytes`, readable, UTF-8); else `error` in
    one line naming `what` and the file."""
    path = checked_file(path, what, max_bytes, error)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"cannot read {what} {shown(path)}: {exc.strerror or exc}") from None
    if len(raw) > max_bytes:
        raise error(
            f"the {what} {shown(path)} has over {max_bytes} bytes: at most {max_bytes} are read"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"the {what} {shown(path)} is not UTF-8 text (byte {exc.start})") from None
    return parse_yaml(text, f"the {what} {shown(path)}", error)


class StrictDumper(yaml.SafeDumper):
    """PyYAML's SafeDumper writing what StrictLoader reads back as the same data: text that
    would read as something else (`1e44`, `y`, `1:00`) quoted, and no aliases (rcl refuses
    them)."""

    yaml_implicit_resolvers: ClassVar[dict] = StrictLoader.yaml_implicit_resolvers

    def ignore_aliases(self, data) -> bool:
        return True


def _represent_str(dumper: StrictDumper, value: str):
    quoted = value == "<<" or any(pattern.match(value) for pattern, _ in _AMBIGUOUS)
    return dumper.represent_scalar(_STANDARD + "str", value, style="'" if quoted else None)


StrictDumper.add_representer(str, _represent_str)


def dump_yaml(data: object) -> str:
    """`data` as YAML text that `parse_yaml` reads back as `data` (keys in their order)."""
    return yaml.dump(data, Dumper=StrictDumper, sort_keys=False, allow_unicode=True)
