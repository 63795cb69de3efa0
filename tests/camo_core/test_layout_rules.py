"""--layout: robots at positions, neighbours by range, a fitted tensor and a kernel of offsets."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import COMPUTE, PROCESS, brick_courses, run_camo

from camo_core.algorithm import orientation
from camo_core.algorithm.backgrounds import background, stripes
from camo_core.algorithm.layout import layout_for, layout_of, places_for, sense_at
from camo_core.algorithm.layout_rules import fitted_tensor, kernel
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.rules import MOTTLED
from camo_core.inputs.positions import LayoutError


def test_a_hexagonal_robot_has_six_neighbours_one_spacing_away():
    layout = layout_of("hex", 6, 6, seed=0)
    near, far = layout.neighbours()[2 * 6 + 2]  # an inner robot
    assert len(near) == 6 and len(far) == 12  # six at sqrt(3) and six at 2 spacings
    robot = layout.positions[14]
    assert all(math.isclose(np.hypot(*(layout.positions[j] - robot)), 1.0) for j in near)


def test_jitter_is_seeded_and_bounded():
    a, b = layout_of("jitter:0.3", 5, 5, seed=1), layout_of("jitter:0.3", 5, 5, seed=1)
    c = layout_of("jitter:0.3", 5, 5, seed=2)
    assert np.array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, c.positions)
    i, j = np.divmod(np.arange(25), 5)
    assert np.abs(a.positions - np.stack([j, i], axis=-1)).max() <= 0.3
    with pytest.raises(LayoutError, match=r"0 <= A < 0\.5"):
        layout_of("jitter:0.7", 5, 5, seed=0)


@pytest.mark.parametrize("amount", ["0_1", "\u0660.1", "\uff10.1", "nan", ""])
def test_jitter_reads_its_amount_as_ascii_digits_only(amount):
    with pytest.raises(LayoutError, match="jitter:A needs a number A"):
        layout_of(f"jitter:{amount}", 5, 5, seed=0)


def test_a_layout_file_is_read_or_refused_in_one_line(tmp_path):
    good = tmp_path / "swarm.csv"
    good.write_text("x,y\n0,0\n1,0\n0.5,0.9\n")
    assert layout_of(str(good), 8, 8, 0).positions.tolist() == [[0, 0], [1, 0], [0.5, 0.9]]
    cases = (("0,0\n1,nan\n", "line 2"), ("0,0\n0.3,0\n", "0.3 spacings apart"),
             ("", "no positions"), ("x,y\n0,0\n\n1,2,3\n", "line 4"),
             ("1e308,0\n-1e308,0\n", "line 1"))  # fmt: skip
    for text, said in cases:
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        with pytest.raises(LayoutError, match=said):
            layout_of(str(bad), 8, 8, 0)
    with pytest.raises(LayoutError, match="cannot read layout"):
        layout_of(str(tmp_path / "missing.csv"), 8, 8, 0)


def test_a_layout_that_crowds_a_robot_is_refused(tmp_path):
    dense = tmp_path / "dense.csv"
    dense.write_text("".join(f"{0.5 * j + 0.25 * (i % 2)},{0.45 * i}\n"
                             for i in range(14) for j in range(14)))  # fmt: skip
    params = CamoParams(rows=1, cols=196, layout="file", orientation="any",
                        positions=layout_of(str(dense), 8, 8, 0).positions.tolist())  # fmt: skip
    with pytest.raises(LayoutError, match=r"neighbours within 2\.3 spacings: at most 64"):
        places_for(params)


def test_the_fitted_tensor_of_a_ramp_lies_across_it_and_needs_three_bearings():
    offsets = [(1.0, 0.0), (0.5, 0.866), (-0.5, 0.866), (-1.0, 0.0), (-0.5, -0.866), (0.5, -0.866)]
    greys = [100.0 + 10 * dx for dx, _ in offsets]  # 10 grey levels a spacing along x
    gxx, gyy, gxy = fitted_tensor(100.0, greys, offsets)
    assert gxx == pytest.approx(100.0) and gyy == pytest.approx(0.0, abs=1e-9)
    assert gxy == pytest.approx(0.0, abs=1e-9)
    assert orientation.angle_of(orientation.choose((gxx, gyy, gxy))) == 90  # vertical stripes
    two_bearings = [greys[0], None, None, greys[3], None, None]
    assert fitted_tensor(100.0, two_bearings, offsets) is None


def test_on_square_positions_the_kernels_are_the_grids():
    layout = layout_of("jitter:0", 7, 7, seed=0)
    near, far = layout.neighbours()[3 * 7 + 3]
    slots = near + far
    offsets = [tuple(layout.positions[j] - layout.positions[24]) for j in slots]
    params = CamoParams()
    grid = dict(zip(orientation.OFFSETS, orientation.ROLES[orientation.ORIENTED], strict=True))
    roles, w2 = kernel(orientation.ORIENTED, offsets, params)
    for (dx, dy), role in zip(offsets, roles, strict=True):
        assert grid.get((round(dy), round(dx)), 0) == role
    assert w2 == params.w2_stripes
    roles, w2 = kernel(MOTTLED, offsets, params)
    assert roles.count(1) == 4 and roles.count(-1) == 8 and w2 == params.w2_mottled


def run(image, spec, **options):
    params = CamoParams(rows=32, cols=32, orientation="any", layout=spec, **options)
    raw = sense_at(image, layout_for(params)).reshape(32, 32)
    return run_per_robot(params, raw)


def test_a_layout_needs_orientation_any_and_a_file_layout_its_positions():
    with pytest.raises(ParameterError, match="--layout needs --orientation any"):
        CamoParams(layout="hex")
    with pytest.raises(ParameterError, match="one position per robot"):
        CamoParams(rows=1, cols=3, layout="file", positions=((0, 0), (1, 0)), orientation="any")
    with pytest.raises(ParameterError, match="layout must be hex, jitter:A or file"):
        CamoParams(layout="triangle", orientation="any")
    made = CamoParams(rows=1, cols=2, layout="file", positions=[[0, 0], [1, 0]], orientation="any")
    assert made.positions == ((0.0, 0.0), (1.0, 0.0)) and hash(made)  # lists become tuples


@pytest.mark.slow(COMPUTE)
def test_on_a_hexagonal_swarm_trunks_are_vertical_courses_horizontal_gravel_mottled():
    assert run(background("forest"), "hex").majority_label == "stripes at 90°"
    assert run(brick_courses(), "hex", threshold_auto=True).majority_label == "stripes at 0°"
    gravel = np.random.default_rng(2).normal(128, 40, (64, 64))
    gravel = np.clip(np.kron(gravel, np.ones((4, 4))), 0, 255).astype(np.uint8)
    assert run(gravel, "hex").majority_pattern == "mottled"


@pytest.mark.slow(COMPUTE)
def test_a_jittered_swarm_reads_45_degree_stripes_within_15_degrees():
    result = run(stripes(45, period=48, seed=3), "jitter:0.3")
    assert abs(result.orientation_deg - 45) <= 15
    assert np.mean(result.final == (result.sensed < 127)) >= 0.8


@pytest.mark.slow(PROCESS)
def test_sim_on_a_layout_writes_its_positions_and_refuses_what_it_cannot(tmp_path):
    options = ["--layout", "hex", "--orientation", "any", "--rows", "6", "--cols", "6"]
    out = run_camo("sim", *options, "--levels", "3", "--rho-comm", "0.2",
                   "--out", str(tmp_path / "a"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["layout"] == "hex" and len(summary["positions"]) == 36
    assert (tmp_path / "a" / "figure.png").exists() and (tmp_path / "a" / "run.gif").exists()
    assert "wrote" in out.stdout and "run.gif" in out.stdout
    said = run_camo("sim", "--layout", "hex", "--out", str(tmp_path / "b"))
    assert said.returncode == 2
    assert said.stderr.strip() == (
        "camo: error: --layout needs --orientation any: a layout has no grid axes"
    )
    missing = run_camo("sim", "--layout", str(tmp_path / "no.csv"), "--orientation", "any",
                       "--out", str(tmp_path / "c"))  # fmt: skip
    assert missing.returncode != 0 and len(missing.stderr.strip().splitlines()) == 1
    assert "cannot read layout" in missing.stderr


# ---- layout files: every level in one line (issue 27) ----------------------------------------


def _one_line_layout_error(path) -> str:
    with pytest.raises(LayoutError) as caught:
        CamoParams.from_options(layout=str(path))
    message = str(caught.value)
    assert message and "\n" not in message and len(message) < 300, message
    return message


@pytest.mark.parametrize(
    "content, said",
    [
        (b"x,y\n0,0\n1,nan\n", "line 3"),
        (b"0,0\n1,inf\n", "line 2"),
        (b"0,0\n1e300,0\n", "line 2"),
        (b"0,0\n1,2,3\n", "line 2"),
        (b"0,0\n1\n", "line 2"),
        (b"0,0\n0,0\n", "apart"),
        (b"x,y\n", "no positions"),
        (b"", "no positions"),
        (b"0,0\n\xff\xfe,1\n", "not a CSV"),
        (b"0,0\n" + b"1" * 200_000 + b",1\n", "not a CSV"),
        (b"0,0\n1,0\x00\n", "line 2"),
        (b"1_0,0\n2,0\n", "line 1"),  # not x=10, nor taken for a header
        ("0,0\n\u0661,0\n".encode(), "line 2"),  # an Arabic-Indic 1
        ("0,0\n\uff11,0\n".encode(), "line 2"),  # a full-width 1
        (b"x,0\n1,0\n", "line 1"),  # a number in it: data, not a header
        (b"\xef\xbb\xbfx,0\n1,0\n", "line 1"),
    ],
)
def test_a_layout_file_with_bad_numbers_or_rows_is_one_line(tmp_path, content, said):
    path = tmp_path / "layout.csv"
    path.write_bytes(content)
    assert said in _one_line_layout_error(path)


@pytest.mark.parametrize("header", [b"", b"x,y\n"])
def test_a_layout_csv_with_a_byte_order_mark_keeps_every_robot(tmp_path, header):
    from camo_core.inputs.positions import read_positions

    path = tmp_path / "layout.csv"
    rows = b"".join(b"%d,%d\n" % (c, r) for r in range(4) for c in range(4))
    path.write_bytes(b"\xef\xbb\xbf" + header + rows)  # as Excel's "CSV UTF-8" writes it
    positions = read_positions(path)
    assert len(positions) == 16 and positions[0].tolist() == [0.0, 0.0]


@pytest.mark.parametrize(
    "name, said",
    [("", "empty"), ("l" * 5000, "too long"), (".", "folder"), ("gone.csv", "not found")],
)
def test_a_layout_path_that_is_no_file_is_one_line(tmp_path, monkeypatch, name, said):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(LayoutError, match=said) as caught:
        from camo_core.inputs.positions import file_positions

        file_positions(name)
    assert "\n" not in str(caught.value)


def test_a_layout_file_too_big_to_be_one_is_refused_before_reading(tmp_path, monkeypatch):
    from camo_core.inputs import positions

    path = tmp_path / "big.csv"
    path.write_text("0,0\n1,0\n")
    monkeypatch.setattr(positions, "MAX_FILE_BYTES", 4)
    with pytest.raises(LayoutError, match="bytes"):
        positions.file_positions(str(path))


NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["", " ", "nan", "-inf", "1e309", "0x10", "1_0", "--1", "x", '"1"']),
)
ROWS = st.lists(st.lists(NUMBERS, min_size=0, max_size=3).map(",".join), max_size=6)


@given(rows=ROWS)
@settings(max_examples=80, deadline=None)
def test_a_layout_csv_of_any_numbers_is_one_line_or_positions(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("layout") / "l.csv"
    path.write_text("\n".join(rows) + "\n")
    try:
        params = CamoParams.from_options(layout=str(path))
        places_for(params)
    except (LayoutError, ParameterError) as exc:
        assert str(exc) and "\n" not in str(exc)
    else:
        positions = np.array(params.positions)
        assert np.isfinite(positions).all() and np.abs(positions).max() <= 1e6
