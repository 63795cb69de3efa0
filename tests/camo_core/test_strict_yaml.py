"""The one strict YAML reading of outside input (`camo_core.inputs.strict_yaml.parse_yaml`,
`read_yaml`): YAML 1.2 scalars, one document, no key twice; anything else one line naming the
line."""

from __future__ import annotations

import datetime
import os
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camo_core.exceptions import CamoError
from camo_core.inputs.strict_yaml import MAX_DEPTH, described, dump_yaml, parse_yaml, read_yaml


def refused(text: str) -> str:
    with pytest.raises(CamoError) as caught:
        parse_yaml(text, "F")
    message = str(caught.value)
    assert "\n" not in message and message.startswith("F is not YAML")
    return message


def test_yaml_1_2_scalars_load_as_numbers_booleans_null_and_text():
    text = (
        "a: 12\nb: -0.5\nc: 1e44\nd: true\ne: False\nf: ~\ng:\nh: '1:00'\ni: 12:30 pm\nj: .inf\n"
    )
    assert parse_yaml(text, "F") == {
        "a": 12,
        "b": -0.5,
        "c": 1e44,
        "d": True,
        "e": False,
        "f": None,
        "g": None,
        "h": "1:00",
        "i": "12:30 pm",
        "j": float("inf"),
    }
    assert parse_yaml("", "F") is None and parse_yaml("---\n", "F") is None


def test_a_key_given_twice_is_refused_naming_the_key_and_both_lines():
    assert "the key 'rows' is given twice (lines 1 and 3)" in refused(
        "rows: 4\ncols: 2\nrows: 5\n"
    )
    assert "given twice" in refused("a:\n  b: 1\n  b: 1\n")


@pytest.mark.parametrize("text", ["1:5:1", "30:00:00", "1:00", "-1:30.5"])
def test_base_60_numbers_are_refused_not_read_as_seconds(text):
    assert "is a base-60 number to YAML 1.1" in refused(f"formation_steps: {text}\n")


def test_an_integer_of_thousands_of_digits_is_one_line_not_a_traceback():
    assert "(line 2): an integer of 5000 digits" in refused("a: 1\nseed: " + "9" * 5000)
    assert "too large" in refused("gain: 1e400\n")


def test_more_than_one_document_is_refused_not_the_first_dropped():
    assert "(line 2): it holds more than one document" in refused("rows: 4\n---\n\nrows: 9\n")


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("rows: 0x4", "'0x4' is a number in another base"),
        ("rows: 010", "'010' is an octal number"),
        ("rows: 1_000", "'1_000' is a number"),
        ("flag: yes", "'yes' is true or false"),
        ("when: 2001-12-14", "'2001-12-14' is a date"),
        ("data: !!binary AAAA", "the tag !!binary is not read"),
        ("when: !!timestamp 2001-12-14", "the tag !!timestamp is not read"),
        ("s: !!set {a}", "the tag !!set is not read"),
        ("x: !!python/object:os.system a", "the tag !!python/object:os.system is not read"),
        ("rows: !!int 0x4", "'0x4' is not a decimal integer"),
        ("b: &b {x: 1}\nc: {<<: *b}", "merge keys (<<) are not read"),
        ("a: &a [*a]", "an alias refers to a node that holds it"),
        ("a: &a 1\nb: &a 2", "an anchor (&name) is given twice"),
        ("? [1]\n: 2", "a key is a list or mapping"),
        ("a: \0", "the character U+0000"),
    ],
)
def test_what_yaml_1_1_reads_otherwise_is_refused_in_user_words(text, said):
    assert said in refused(text)


def test_aliases_are_read_but_a_billion_laughs_is_refused_quickly():
    assert parse_yaml("a: &x [1]\nb: *x\n", "F") == {"a": [1], "b": [1]}
    lines = ["a: &a [" + ", ".join(["x"] * 10) + "]"]
    lines += [
        f"{c}: &{c} [" + ", ".join([f"*{p}"] * 10) + "]"
        for p, c in zip("abcdefgh", "bcdefghi", strict=True)
    ]
    assert "values as its aliases expand" in refused("\n".join(lines))


def test_nesting_deeper_than_the_limit_is_one_line_and_up_to_it_loads():
    assert parse_yaml("[" * MAX_DEPTH + "]" * MAX_DEPTH, "F") is not None
    assert f"nests deeper than {MAX_DEPTH}" in refused(
        "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1)
    )
    assert "nests deeper" in refused("[" * 100_000)
    deep_by_alias = "a: &a " + "[" * 40 + "]" * 40 + "\nb: " + "[" * 40 + "*a" + "]" * 40
    assert "nests deeper" in refused(deep_by_alias)


def test_values_are_described_in_user_words_not_python_reprs():
    assert described(None) == "nothing"
    assert described(True) == "true"
    assert described(datetime.date(2001, 12, 14)) == "a date"
    assert described(b"\0\0\0") == "binary data"
    assert described([1]) == "a list" and described({}) == "a mapping"
    assert described(12) == "12" and described("x") == "'x'"
    assert described(10**5000) == "an integer too long to show"


@pytest.mark.parametrize("special", ["/dev/zero", "/dev/urandom", "fifo"])
def test_a_device_or_a_fifo_is_refused_without_being_read(tmp_path, special):
    if special == "fifo":
        special = tmp_path / "f.yaml"
        os.mkfifo(special)
    said: list[str] = []

    def read():
        try:
            read_yaml(special, "calibration", 1024)
        except CamoError as exc:
            said.append(str(exc))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(10)
    assert said and "is not a regular file" in said[0]


# ---- any document built of the constructs above: one line of camo's error, or plain data ----

REFUSED = {
    "twice": "k: 1\nk: 2",
    "base60": "k: 1:5:1",
    "huge": "k: " + "9" * 4400,
    "documents": "k: 1\n---\nk: 2",
    "date": "k: 2001-12-14",
    "timestamp": "k: 2001-12-14T21:59:43.10-05:00",
    "binary": "k: !!binary AAAA",
    "deep": "k: " + "[" * 200 + "]" * 200,
    "hex": "k: 0x1F",
    "yes": "k: on",
}
FINE = {
    "int": "k: 4",
    "float": "k: 1.5e3",
    "bool": "k: false",
    "null": "k: null",
    "text": "k: forest",
    "quoted": "k: '1:5:1'",
    "list": "k: [1, 2.5, a]",
    "alias": "k: &x {a: 1}\nl: *x",
    "nested": "k: {a: {b: [c]}}",
}
PLAIN = (type(None), bool, int, float, str, list, dict)


def plain(value) -> bool:
    if isinstance(value, list):
        return all(plain(v) for v in value)
    if isinstance(value, dict):
        return all(plain(k) and plain(v) for k, v in value.items())
    return isinstance(value, PLAIN)


@settings(max_examples=200, deadline=None)
@given(
    parts=st.lists(st.sampled_from(sorted({**REFUSED, **FINE})), min_size=1, max_size=4),
    indent=st.sampled_from(["", "top:\n  "]),
)
def test_any_document_of_these_constructs_loads_as_plain_data_or_is_one_line(parts, indent):
    # each part under its own key, so that only "twice" repeats a key
    pieces = []
    for n, name in enumerate(parts):
        body = {**REFUSED, **FINE}[name].replace("k:", f"k{n}:").replace("l:", f"l{n}:")
        body = body.replace("&x", f"&x{n}").replace("*x", f"*x{n}")
        if name == "twice":
            body = body.replace(f"k{n}:", "kk:")
        pieces.append(body)
    text = "\n".join(pieces)
    if indent and "---" not in text:
        text = "top:\n" + "\n".join("  " + line for line in text.splitlines())
    twice = parts.count("twice") > 0
    documents = "documents" in parts
    must_fail = twice or documents or any(name in REFUSED for name in parts)
    try:
        value = parse_yaml(text, "F")
    except CamoError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("F is not YAML")
        assert must_fail, str(exc)
    else:
        assert not must_fail and plain(value)


PLAIN_DATA = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**30), 10**30)
    | st.floats(allow_nan=False)
    | st.text(max_size=12)
    | st.sampled_from(["1e44", "y", "1:5:1", "0x4", "on", "2001-12-14", "<<", "~", "010"]),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=12,
)


@settings(max_examples=200, deadline=None)
@given(data=PLAIN_DATA)
def test_what_camo_writes_as_yaml_it_reads_back_as_the_same_data(data):
    shared = [data, data]  # a value repeated: written out twice, not as an alias rcl refuses
    text = dump_yaml(shared)
    assert "*id" not in text
    assert parse_yaml(text, "F") == shared
