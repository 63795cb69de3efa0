"""Parameters files (--params-file): the usual mistakes named in one line, good files let through,
and anything at all fed to the reader (and then to rcl) ends in a one-line error or a start."""

from __future__ import annotations

import json
import os
import re
from unittest import mock

import pytest
import yaml
from hypothesis import event, given, settings
from hypothesis import strategies as st
from support import PROCESS, SWARM

from camo_core.cli.params_file import ParamsFileError, check_params_file, check_ros_args
from camo_core.exceptions import UsageError
from camo_core.inputs.files import shown

GOOD = """\
/**:
  ros__parameters:
    rows: 8
    cols: 8
robot_parameters:
  ros__parameters:
    row: 2
    profile: desert
    rho: [0.1, 0.2]
    nested:
      deeper: true
"""


def write(tmp_path, text: str | bytes):
    path = tmp_path / "params.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


def test_a_good_file_and_an_empty_one_pass(tmp_path):
    check_params_file(write(tmp_path, GOOD))
    check_params_file(write(tmp_path, ""))


@pytest.mark.parametrize(
    "text, said",
    [
        ("robot: [1,\n", "is not YAML (line 2)"),
        ("ros__parameters:\n  rows: 8\n", "must be under a node name"),
        ("robot:\n  rows: 8\n", "robot/rows is a value outside ros__parameters"),
        ("robot:\n  ros__parameters: 8\n", "must map names to values"),
        ("robot:\n  ros__parameters:\n    rho: [1, 0.5]\n", "rho mixes kinds of values"),
        ("robot:\n  ros__parameters:\n    rho: [[1]]\n", "rho is a list of lists"),
        ("- robot\n", "a parameters file maps NODE"),
    ],
)
def test_the_usual_mistakes_are_named(tmp_path, text, said):
    with pytest.raises(ParamsFileError, match=re.escape(said)):
        check_params_file(write(tmp_path, text))


def test_a_missing_or_binary_file_is_named(tmp_path):
    with pytest.raises(ParamsFileError, match="cannot read parameters file"):
        check_params_file(tmp_path / "nope.yaml")
    with pytest.raises(ParamsFileError, match="UTF-8"):
        check_params_file(write(tmp_path, bytes(range(256))))


NODE = "/**:\n  ros__parameters:\n"


@pytest.mark.parametrize(
    ("values", "said"),
    [
        ("    seed: " + "9" * 5000, "(line 3): an integer of 5000 digits"),
        ("    formation_steps: 30:00:00", "(line 3): '30:00:00' is a base-60 number"),
        ("    rows: 4\n    rows: 5", "(line 4): the key 'rows' is given twice (lines 3 and 4)"),
        ("    rows: 4\n---\n" + NODE + "    rows: 9", "(line 4): it holds more than one document"),
        ("    rows: 0x4", "(line 3): '0x4' is a number in another base"),
        ("    image: 2001-12-14", "(line 3): '2001-12-14' is a date"),
        ("    image: !!binary AAAA", "(line 3): the tag !!binary is not read"),
        ("    ~: 4", "/**: a parameter name is text (got nothing)"),
    ],
)
def test_what_yaml_1_1_would_read_otherwise_in_a_params_file_is_one_line(tmp_path, values, said):
    path = write(tmp_path, NODE + values + "\n")
    with pytest.raises(ParamsFileError) as caught:
        check_params_file(path)
    message = str(caught.value)  # the path as messages show one (longer than 80: shortened)
    assert message.startswith(f"the parameters file {shown(path)} is not YAML") or (
        str(path) in message
    )
    assert said in message and "\n" not in message
    with pytest.raises(ParamsFileError, match=re.escape(said)):  # robot: --ros-args --params-file
        check_ros_args(["--ros-args", "--params-file", str(path)])


@pytest.mark.parametrize(
    ("value", "said"),
    [
        ("", "rows must be a number or text (got nothing)"),
        ("'2001-12-14'", "rows must be an integer (got '2001-12-14')"),
        ("[1]", "rows must be a number or text (got a list)"),
    ],
)
def test_a_wrong_value_for_an_option_is_said_in_user_words(tmp_path, value, said):
    from camo_core.cli.commands import add_sim_arguments
    from camo_core.cli.options import Parser
    from camo_core.cli.params_file import options_from_file
    from camo_core.exceptions import UsageError

    path = write(tmp_path, f"{NODE}    rows: {value}\n")
    with pytest.raises(UsageError, match=re.escape(said)):
        options_from_file(add_sim_arguments(Parser(prog="camo sim")), path, "camo_sim")


def test_every_params_file_of_a_command_line_is_checked(tmp_path):
    good = write(tmp_path, GOOD)
    check_ros_args(["x", "--ros-args", "--params-file", str(good), "-p", "a:=1"])
    check_ros_args(["--params-file", "not-ros-args.yaml"])  # before --ros-args: not ROS's
    with pytest.raises(ParamsFileError, match="cannot read"):
        check_ros_args(["--ros-args", "--params-file", str(good), "--params-file", "gone.yaml"])
    with pytest.raises(ParamsFileError, match="needs a FILE"):
        check_ros_args(["--ros-args", "--params-file"])


# ---- fuzzed ------------------------------------------------------------------------------

keys = st.sampled_from(["ros__parameters", "robot", "/**", "ns", "rows", "rho", "1", ""])
scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=8), st.dates()
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(keys, inner, max_size=3)),
    max_leaves=12,
)


def spliced(parts: tuple[str, bytes, float]) -> bytes:
    text, garbage, where = parts
    at = int(where * len(text))
    return text.encode()[:at] + garbage + text.encode()[at:]


def texts():
    """Parameters-file-shaped YAML, as text, sometimes cut or with bytes of garbage."""
    trees = st.one_of(
        st.dictionaries(keys, values, max_size=3),
        st.dictionaries(keys, values, max_size=4).map(lambda p: {"robot": {"ros__parameters": p}}),
    )
    shaped = trees.map(lambda tree: yaml.safe_dump(tree, allow_unicode=True))
    return st.one_of(
        shaped,
        st.tuples(shaped, st.floats(0, 1)).map(lambda t: t[0][: int(t[1] * len(t[0]))]),
        st.tuples(shaped, st.binary(max_size=6), st.floats(0, 1)).map(
            lambda t: (
                t[0].encode()[: int(t[2] * len(t[0]))]
                + t[1]
                + t[0].encode()[int(t[2] * len(t[0])) :]
            )
        ),
        st.text(max_size=40),
    )


@pytest.mark.slow(SWARM)
@given(text=texts())
def test_anything_in_a_params_file_ends_in_one_line_or_a_start(tmp_path_factory, capsys, text):
    """Whatever the reader lets through, rcl accepts, or start_ros says why not in one line
    and exits 2: never a traceback."""
    import rclpy

    from camo_nodes.topics.startup import start_ros

    path = write(tmp_path_factory.mktemp("params"), text)
    try:
        check_params_file(path)
    except ParamsFileError as exc:
        assert "\n" not in str(exc)
        event("refused by the reader")
        return
    try:
        with mock.patch.dict(os.environ):  # start_ros sets ROS's network settings here
            start_ros("robot_node", ["robot_node", "--ros-args", "--params-file", str(path)])
    except SystemExit as exc:
        event("refused by rcl")
        assert exc.code == 2
        said = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        ours = [line for line in said if line.startswith("robot_node: error: ")]
        assert len(ours) == 1 and "Traceback" not in "".join(said), said
    else:
        event("started")
        rclpy.shutdown()


# ---- options from a parameters file -------------------------------------------------------


def test_a_node_takes_its_own_keys_over_the_general_ones(tmp_path):
    from camo_core.cli.params_file import parameters_for

    path = write(
        tmp_path,
        "/**:\n  ros__parameters:\n    rows: 4\n    cols: 4\n"
        "/lab/camo_sim:\n  ros__parameters:\n    rows: 6\n    nested: {a: 1}\n"
        "camo_run:\n  ros__parameters:\n    rows: 9\n",
    )
    assert parameters_for(path, "camo_sim") == {"rows": 6, "cols": 4, "nested.a": 1}
    assert parameters_for(path, "camo_run") == {"rows": 9, "cols": 4}
    assert parameters_for(path, "other") == {"rows": 4, "cols": 4}


def test_a_file_for_other_nodes_only_is_one_line_naming_its_sections(tmp_path):
    from camo_core.cli.params_file import parameters_for

    path = write(
        tmp_path,
        "camo_smi:\n  ros__parameters:\n    rows: 4\n"
        "/lab/projector:\n  ros__parameters:\n    image: a.png\n",
    )
    with pytest.raises(UsageError) as refused:
        parameters_for(path, "camo_sim")
    said = str(refused.value)
    assert "no section for camo_sim (it has /camo_smi, /lab/projector)" in said
    assert "/**/camo_sim" in said and "\n" not in said
    assert parameters_for(path, "projector") == {"image": "a.png"}  # a node it names: read
    wild = write(tmp_path, "/lab/**:\n  ros__parameters:\n    rows: 4\n")
    assert parameters_for(wild, "camo_sim") == {}  # a namespace's wildcard: not refused


@pytest.mark.slow(PROCESS)
def test_sim_writes_params_yaml_that_repeats_it_and_the_command_line_wins(tmp_path):
    from support import run_camo

    first = run_camo(
        "sim",
        "--pattern",
        "desert",
        "--rows",
        "6",
        "--cols",
        "5",
        "--seed",
        "3",
        "--rho-comm",
        "0.1",
        "--out",
        str(tmp_path / "a"),
    )
    assert first.returncode == 0, first.stderr
    params = tmp_path / "a" / "params.yaml"
    again = run_camo("sim", "--params-file", str(params), "--out", str(tmp_path / "b"))
    assert again.returncode == 0, again.stderr
    summary = lambda run: {  # noqa: E731
        k: v
        for k, v in json.loads((tmp_path / run / "summary.json").read_text()).items()
        if k != "elapsed_s"
    }
    assert summary("a") == summary("b")
    assert yaml.safe_load(params.read_text()) == yaml.safe_load(
        (tmp_path / "b" / "params.yaml").read_text()
    )
    over = run_camo(
        "sim", "--params-file", str(params), "--rows", "4", "--out", str(tmp_path / "c")
    )
    assert over.returncode == 0, over.stderr
    written = yaml.safe_load((tmp_path / "c" / "params.yaml").read_text())["/**"]
    assert written["ros__parameters"]["rows"] == 4 and written["ros__parameters"]["cols"] == 5


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "text, said",
    [
        ("/**:\n  ros__parameters:\n    rows: eight\n", "rows must be an integer (got 'eight')"),
        ("camo_sim:\n  ros__parameters:\n    rowz: 8\n", "camo sim has no parameter rowz"),
        ("camo_smi:\n  ros__parameters:\n    rows: 8\n", "no section for camo_sim (it has /c"),
        (
            "/**:\n  ros__parameters:\n    profile: fancy\n",
            "profile must be one of paper, droplet",
        ),
        ("/**:\n  ros__parameters:\n    rho_comm: [0.1]\n", "rho_comm must be a number or text"),
        ("/**:\n  ros__parameters:\n    seed: " + "9" * 5000, "an integer of 5000 digits"),
        ("/**:\n  ros__parameters:\n    rows: 4\n---\n", "more than one document"),
        (
            "/**:\n  ros__parameters:\n    pattern:\n",
            "pattern must be a number or text (got nothing)",
        ),
    ],
)
def test_a_wrong_parameter_in_the_file_is_one_line(tmp_path, text, said):
    from support import run_camo

    out = run_camo(
        "sim", "--params-file", str(write(tmp_path, text)), "--out", str(tmp_path / "x")
    )
    assert out.returncode == 2 and said in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


# ---- structured bad values, through `camo sim --params-file` in process (issue 27) ---------

SIM_KEYS = ("rows", "cols", "seed", "rho_comm", "threshold", "profile", "image", "pattern")
SIM_KEYS += ("layout", "contrast", "sensed", "consensus_steps", "no_such_option")
WRONG = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["", "auto", "nan", "-1", "1e300", "x" * 300, "0,0=1", "hex", "paper"]),
    st.lists(st.integers(-3, 3), max_size=2),
    st.dictionaries(st.sampled_from(["a", "ros__parameters"]), st.integers(), max_size=2),
)
SIM_FILES = st.one_of(
    st.dictionaries(st.sampled_from(SIM_KEYS), WRONG, min_size=1, max_size=3).map(
        lambda values: {"/**": {"ros__parameters": values}}
    ),
    st.builds(lambda v: {"camo_sim": {"ros__parameters": v}}, WRONG),
    st.builds(lambda v: {"/**": v}, WRONG),
    WRONG,
)


@given(tree=SIM_FILES)
@settings(max_examples=80, deadline=None)
def test_a_params_file_of_wrong_types_and_ranges_is_one_line_or_runs(
    tmp_path_factory, monkeypatch, capsys, tree
):
    from support import Validated, validated

    from camo_core.algorithm import perrobot, simulator
    from camo_core.cli import commands

    folder = tmp_path_factory.mktemp("pf")
    path = folder / "p.yaml"
    path.write_text(yaml.safe_dump(tree))
    monkeypatch.setattr(simulator, "simulate", validated)  # as cmd_sim imports it
    monkeypatch.setattr(perrobot, "run_per_robot", validated)
    argv = ["sim", "--params-file", str(path), "--out", str(folder / "out"), "--force"]
    try:
        code = commands.main(argv)
    except Validated:
        return
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("camo: error: "), err


def test_an_image_on_the_command_line_overrides_a_parameters_files_pattern(tmp_path):
    # A run's params.yaml names its pattern: repeated with --image, the image is the background.
    import cv2
    import numpy as np

    from camo_core.cli.commands import build_parser
    from camo_core.cli.options import image_from

    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    pattern: desert\n")
    image = tmp_path / "a.png"
    cv2.imwrite(str(image), np.full((16, 16), 90, np.uint8))
    args = build_parser().parse_args(["sim", "--params-file", str(params), "--image", str(image)])
    shown, label = image_from(args)
    assert label == str(image) and shown.shape[:2] == (16, 16)


def test_a_scope_scale_without_a_local_scope_is_one_line_from_a_file_too(tmp_path):
    from camo_core.cli.commands import build_parser

    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    scope_scale: 3.0\n")
    for argv in (["--params-file", str(params)], ["--scope-scale", "3"]):
        with pytest.raises(UsageError, match="--scope-scale needs --scope: the size of"):
            build_parser().parse_args(["sim", *argv])
        build_parser().parse_args(["sim", *argv, "--scope", "local"])
