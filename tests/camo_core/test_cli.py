"""The reference tools from the command line: outputs, and one-line errors on bad input."""

import json
import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import (
    PROCESS,
    Validated,
    bad_value_outcomes,
    run_camo,
    validated,
    value_options,
)

from camo_core.algorithm import perrobot, simulator
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import SUMMARY_KEYS
from camo_core.cli import commands
from camo_core.schema import with_role


@pytest.mark.slow(PROCESS)
def test_sim_writes_summary_and_figure(tmp_path):
    out = run_camo(
        "sim",
        "--pattern",
        "desert",
        "--rows",
        "8",
        "--cols",
        "12",
        "--seed",
        "4",
        "--rho-comm",
        "0.1",
        "--out",
        str(tmp_path),
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert tuple(summary) == SUMMARY_KEYS
    assert summary["pattern"] == "horizontal" and summary["rows"] == 8 and summary["cols"] == 12
    assert sum(summary["votes"].values()) == 96
    assert np.array(summary["final"]).shape == (8, 12) and np.array(summary["sensed"]).shape == (
        8,
        12,
    )
    assert len(summary["consensus_trace"]) == 36 and summary["rho_comm"] == 0.1
    figure = cv2.imread(str(tmp_path / "figure.png"))
    assert figure is not None and figure.shape[1] > 3 * figure.shape[0]  # one row of five panels


@pytest.mark.slow(PROCESS)
def test_sim_accepts_a_colour_image_file(tmp_path):
    image = np.zeros((64, 64, 3), np.uint8)
    image[:, ::16] = (0, 0, 255)
    image[:, 1::16] = (0, 0, 255)
    path = tmp_path / "stripes.jpg"
    cv2.imwrite(str(path), image)
    out = run_camo(
        "sim", "--image", str(path), "--profile", "droplet", "--out", str(tmp_path / "o")
    )
    assert out.returncode == 0, out.stderr
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["profile"] == "droplet"


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "args, message",
    [
        (["--image", "/no/such/file.png"], "cannot read image /no/such/file.png: not found"),
        (["--rows", "0"], "rows must be"),
        (["--rho-meas", "-0.5"], "rho_meas must be"),
        (["--rows", "200", "--cols", "200"], "smaller than"),
        (["--profile", "nope"], "invalid choice"),
        (["--seed", "abc"], "invalid int value"),
        (["--consensus-steps", "2.5"], "a whole number of steps or auto"),
        (["--consensus-steps", "auto", "--rows", "400", "--cols", "400"], "above 100000"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, message, tmp_path):
    out = run_camo("sim", *args, "--out", str(tmp_path / "o"))
    assert out.returncode == 2
    assert message in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


@pytest.mark.slow(PROCESS)
def test_corrupt_image_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png at all")
    out = run_camo("sim", "--image", str(bad), "--out", str(tmp_path / "o"))
    assert out.returncode == 2 and "cannot read image" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow(PROCESS)
def test_bench_prints_json_with_ratios():
    out = run_camo("bench", "sim", "--json", "--sizes", "16,32")
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert {r["robots"] for r in report["results"]} == {"16x16", "32x32"}
    assert all(r["ratio"] > 0 and r["baseline_s"] > 0 for r in report["results"])
    assert report["speedup_over_per_robot"] > 1
    assert "whole_process" not in report  # only with --whole


@pytest.mark.slow(PROCESS)
def test_sim_takes_real_readings_without_noise(tmp_path):
    out = run_camo("sim", "--rho-meas", "1.0", "--sensed", "2,3=201.5", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    sensed = json.loads((tmp_path / "summary.json").read_text())["sensed"]
    assert sensed[2][3] == 201.5
    assert (
        sum(v == int(v) for row in sensed for v in row) == 64 - 1
    )  # the others are noise: integers
    for bad in ("2,3", "9,9=4", "1,1=300"):
        out = run_camo("sim", "--sensed", bad, "--out", str(tmp_path))
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr


@pytest.mark.slow(PROCESS)
def test_bench_whole_process_times_camo_sim_in_a_subprocess():
    from camo_core.cli import bench

    whole = bench.whole_process(repeats=1, side=32)  # --whole runs it at 1024x1024
    assert whole["command"].startswith("python -m camo_core.cli sim --image BIG --rows 32 ")
    assert len(whole["runs_s"]) == 1 and whole["seconds"] == whole["runs_s"][0] > 0
    assert whole["baseline_s"] > 0 and whole["ratio"] == whole["seconds"] / whole["baseline_s"]
    assert whole["target_ratio"] is None  # the target is for 1024x1024
    report = {"pipeline": "", "baseline": "", "results": [], "whole_process": whole}
    report |= {"per_robot_64x64_s": 1.0, "vectorised_64x64_s": 0.1, "speedup_over_per_robot": 10}
    assert "whole process: python -m camo_core.cli sim" in bench.format_table(report)


@pytest.mark.parametrize("force", [[], ["--force"]])
@pytest.mark.parametrize("where", ["file", "file/below", "/dev/null"])
def test_an_output_folder_that_is_a_file_is_one_line_and_the_file_is_kept(
    tmp_path, capsys, where, force
):
    """A file (or a device) where a folder should be, or above it: never replaced, --force
    or not."""
    mine = tmp_path / "file"
    mine.write_text("keep me")
    out = where if where.startswith("/") else str(tmp_path / where)
    assert commands.main(["sim", "--rows", "2", "--cols", "2", "--out", out, *force]) == 2
    err = capsys.readouterr().err
    assert "not a folder" in err and len(err.strip().splitlines()) == 1, err
    assert mine.read_text() == "keep me" and sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.slow(PROCESS)
def test_an_output_folder_that_holds_something_is_refused_unless_forced(tmp_path):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    refused = run_camo("sim", "--rows", "4", "--cols", "4", "--out", str(out))
    assert refused.returncode == 2 and "already exists and is not empty" in refused.stderr
    assert "--force" in refused.stderr and sorted(p.name for p in out.iterdir()) == ["mine.txt"]
    forced = run_camo("sim", "--rows", "4", "--cols", "4", "--out", str(out), "--force")
    assert forced.returncode == 0, forced.stderr
    assert (out / "summary.json").exists() and (out / "mine.txt").read_text() == "keep me"


@pytest.mark.slow(PROCESS)
def test_an_abbreviated_option_is_refused():
    out = run_camo("sim", "--row", "8", "--out", "unused")
    assert out.returncode == 2 and "unrecognized arguments: --row" in out.stderr


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "module, args",
    [
        ("camo_nodes.monitor_node", ["--run-i", "x"]),
        ("camo_bringup.worker", ["--cells", "0-3", "--run-i", "x"]),
        ("camo_bag.view_node", ["--prt", "9001"]),
        ("camo_bag.recorder_node", ["B", "--topic", "x"]),
    ],
)
def test_a_misspelt_option_of_a_node_command_is_an_error_not_a_ros_argument(
    tmp_path, module, args
):
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert out.returncode == 2, out.stderr
    assert "unrecognized arguments" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []  # no results folder, no bag


@pytest.mark.slow(PROCESS)
def test_output_into_a_pipe_nobody_reads_ends_quietly(tmp_path):
    import signal
    import subprocess
    import sys

    argv = [sys.executable, "-m", "camo_core.cli", "sim", "--rows", "4", "--cols", "4"]
    proc = subprocess.Popen(
        [*argv, "--out", str(tmp_path / "sim")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()  # as `| head` does once it has what it wants
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == -signal.SIGPIPE
    assert "Traceback" not in err and "BrokenPipeError" not in err


def _sim_parser():
    return commands.add_sim_arguments(commands.Parser(prog="camo sim"))


@pytest.mark.parametrize("option", value_options(_sim_parser()))
def test_every_option_of_sim_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line runs: the simulation itself is replaced by Validated (where a
    # value is fine: -1 for a weight, a folder named nan).
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(simulator, "simulate", validated)  # as cmd_sim imports it
    monkeypatch.setattr(perrobot, "run_per_robot", validated)
    argv = ["sim", "--rows", "2", "--cols", "2"]
    if option != "--out":
        argv += ["--out", str(tmp_path / "out"), "--force"]
    assert bad_value_outcomes(commands.main, argv, option, capsys, _sim_parser()) == []


def _out_of_range(d) -> st.SearchStrategy[str]:
    """Values of a declared parameter's option on either side of its range, and beyond."""
    s = d.spec
    edges = [st.sampled_from(["nan", "inf", "-inf", "1e300", str(10**30), "", "-1"])]
    if s.low is not None:
        edges.append(st.just(repr(s.low - 1 if d.kind is int else s.low - 1e-9)))
    if s.high is not None:
        edges.append(st.just(repr(s.high + 1 if d.kind is int else s.high * (1 + 1e-9) + 1e-9)))
    if s.choices:
        edges.append(st.just(s.choices[0] + "x"))
    return st.one_of(*edges)


SIM_OPTIONS = list(with_role(CamoParams, "cli").values())
ARGVS = st.lists(
    st.sampled_from(SIM_OPTIONS).flatmap(
        lambda d: st.tuples(st.just(d.option), st.none() if d.kind is bool else _out_of_range(d))
    ),
    min_size=1,
    max_size=3,
)


@given(pairs=ARGVS)
@settings(max_examples=60, deadline=None)
def test_sim_with_declared_options_out_of_range_is_one_line_or_runs(
    tmp_path_factory, monkeypatch, capsys, pairs
):
    folder = tmp_path_factory.mktemp("sim")
    monkeypatch.setattr(simulator, "simulate", validated)  # as cmd_sim imports it
    monkeypatch.setattr(perrobot, "run_per_robot", validated)
    argv = ["sim", "--rows", "2", "--cols", "2", "--out", str(folder / "o"), "--force"]
    for option, value in pairs:
        argv += [option] if value is None else [option, value]  # a flag takes no value
    try:
        code = commands.main(argv)
    except Validated:
        return
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("camo: error: "), err


# ---- numbers in outside text: one grammar (camo_core.inputs) ---------------------------------

NUMBER_CHARS = st.sampled_from(list("0123456789+-.eE_ ") + ["\u0661", "\uff11", "\u00b2", "x"])
NUMBER_TEXT = st.one_of(
    st.text(NUMBER_CHARS, max_size=12),
    st.sampled_from(["nan", "-inf", "Infinity", "1e309", "1_000", "\u0661\u0662", "\uff15"]),
)


def _by_the_grammar(text: str, special: bool) -> float | None:
    """The documented grammar, spelt out by hand: the number `text` means, or None."""
    bare = text.strip(" \t")
    if (
        special
        and bare.lstrip("+-").lower() in ("nan", "inf", "infinity")
        and (len(bare) - len(bare.lstrip("+-")) <= 1)
    ):
        return float(bare)
    body = bare[1:] if bare[:1] in ("+", "-") else bare
    mantissa, e, exponent = body.replace("E", "e").partition("e")
    whole, _, fraction = mantissa.partition(".")
    digits = set("0123456789")
    if not (whole or fraction) or not set(whole + fraction) <= digits:
        return None
    if e:
        exponent = exponent[1:] if exponent[:1] in ("+", "-") else exponent
        if not exponent or not set(exponent) <= digits:
            return None
    value = float(bare)
    return value if special or math.isfinite(value) else None


@given(text=NUMBER_TEXT, special=st.booleans())
@settings(max_examples=400, deadline=None)
def test_a_number_parses_by_the_documented_grammar_or_is_a_one_line_error(text, special):
    from camo_core.inputs.numeric import NumberError, integer, number

    want = _by_the_grammar(text, special)
    try:
        got = number(text, special=special)
    except NumberError as exc:
        assert want is None, (text, want)
        assert "\n" not in str(exc) and str(exc).startswith("want a number")
    else:
        assert want is not None and (got == want or (math.isnan(got) and math.isnan(want)))
    bare = text.strip(" \t")
    whole = bare[1:] if bare[:1] in ("+", "-") else bare
    if whole and set(whole) <= set("0123456789"):
        assert integer(text) == int(bare)
    else:
        with pytest.raises(NumberError, match="want a whole number"):
            integer(text)


def test_a_list_with_an_empty_item_is_refused_not_shortened():
    from camo_core.inputs.numeric import NumberError, items

    assert items("0, 1 ,2", "--x") == ["0", "1", "2"]
    for text in ("0,,1", "0,1,", ",0", ""):
        with pytest.raises(NumberError, match="--x has an empty item"):
            items(text, "--x")


@pytest.mark.parametrize("value", ["1_0", "\u0661", "\uff11", "\u00b2", "1e999", "nan", "0x1"])
def test_int_and_float_options_refuse_what_python_alone_would_take(value):
    from camo_core.cli.options import Parser
    from camo_core.exceptions import UsageError

    parser = Parser(prog="p")
    parser.add_argument("--n", type=int)
    parser.add_mutually_exclusive_group().add_argument("--x", type=float)
    sub = parser.add_subparsers(dest="cmd").add_parser("sub")
    sub.add_argument("--m", type=int)
    assert parser.parse_args(["--n", " 12", "--x=-1.5e3"]).x == -1500.0
    for argv in (["--n", value], ["--x", value], ["sub", "--m", value]):
        with pytest.raises(UsageError, match=r"invalid (int|float) value"):
            parser.parse_args(argv)


@pytest.mark.parametrize("text", ["1,1=1_00", "\uff11,1=5", "1,1=\u0665", "1,=5", "1,1=inf"])
def test_sensed_refuses_numbers_python_would_take(text):
    from camo_core.exceptions import UsageError

    with pytest.raises(UsageError, match="--sensed takes ROW,COL=VALUE"):
        commands.sensed_overrides([text], 4, 4)


def test_a_value_beginning_with_a_dash_says_how_to_give_it():
    from camo_core.cli.options import Parser
    from camo_core.exceptions import UsageError

    parser = Parser(prog="p")
    parser.add_argument("--sensed", action="append")
    with pytest.raises(
        UsageError,
        match=r"--sensed: expected one argument \(a value that begins with '-' is given as "
        r"--sensed=VALUE\)$",
    ):
        parser.parse_args(["--sensed", "-1,1=5"])
    assert parser.parse_args(["--sensed=-1,1=5"]).sensed == ["-1,1=5"]
    with pytest.raises(UsageError, match="outside the 4x4 grid"):
        commands.sensed_overrides(["-1,1=5"], 4, 4)


@pytest.mark.parametrize("sizes", ["-5", "100000", "4", "abc", ""])
def test_bench_sizes_out_of_range_are_one_line_before_anything_is_timed(sizes, capsys):
    # -5 reached numpy's seeding, 100000 a 75 GiB allocation, "" the default sizes.
    assert commands.main(["bench", "sim", "--sizes", sizes]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "--sizes" in said[0], said
