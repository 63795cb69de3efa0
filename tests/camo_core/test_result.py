"""summary.json and figure.png of large runs: the fast writer's document is json.dumps's, value for
value (floats bit for bit, NaN included), and large grids are drawn from resized copies."""

import json
import math
import struct

import cv2
import matplotlib.axes
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import COMPUTE

from camo_core.algorithm import kernels
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import SMALL_P, SUMMARY_KEYS, RunResult, mean_p, p_stats
from camo_core.algorithm.simulator import simulate
from camo_core.results import figures
from camo_core.results import summary as result
from camo_core.results.summary import write_summary

SIDE = 160  # 25600 robots: above result.INDENTED_SUMMARY_CELLS, so orjson writes the grids


def exact(value):
    """A parsed JSON document in a form whose == compares floats bit for bit (NaN equals NaN)."""
    if isinstance(value, float):
        return ("float", struct.pack("<d", value))
    if isinstance(value, dict):
        return ("dict", tuple((k, exact(v)) for k, v in value.items()))
    if isinstance(value, list):
        return ("list", tuple(exact(v) for v in value))
    return (type(value).__name__, value)


def as_json_dumps_writes_it(summary: dict) -> object:
    """The document as the writer before orjson wrote it: json.dumps of the list summary."""
    return json.loads(json.dumps(summary, indent=1))


def written(summary: dict, folder) -> object:
    return json.loads(write_summary(summary, folder).read_text())


@pytest.fixture(scope="module")
def run() -> RunResult:
    params = CamoParams(rows=SIDE, cols=SIDE, rho_meas=0.1, rho_comm=0.1, seed=3)
    raw = np.random.default_rng(1).uniform(0, 255, (SIDE, SIDE))
    return simulate(params, raw)


def test_large_summary_is_the_json_dumps_document(run, tmp_path):
    assert SIDE * SIDE > result.INDENTED_SUMMARY_CELLS
    reference = as_json_dumps_writes_it(run.summary())
    assert any(v != int(v) for row in reference["sensed"] for v in row)  # noisy, non-integer
    for arrays in (True, False):
        doc = written(run.summary(arrays=arrays), tmp_path)
        assert tuple(doc) == SUMMARY_KEYS
        assert exact(doc) == exact(reference)
    text = (tmp_path / "summary.json").read_text()
    # orjson wrote it: one top-level key a line, not one value a line.
    assert (
        text.startswith('{\n "rows": 160,\n "cols": 160,\n') and text.count("\n") == len(doc) + 2
    )


def test_large_summary_with_nan_sensed_values_keeps_nan(run, tmp_path):
    # A partial swarm run: robots that never reported their reading hold NaN.
    nan_run = RunResult(**{**vars(run), "sensed": run.sensed.copy()})
    nan_run.sensed[0, :5] = np.nan
    nan_run.sensed[77, 3] = np.nan
    reference = as_json_dumps_writes_it(nan_run.summary())
    for arrays in (True, False):
        doc = written(nan_run.summary(arrays=arrays), tmp_path)
        assert exact(doc) == exact(reference)
        assert np.isnan(doc["sensed"][77][3]) and np.isnan(doc["sensed"][0]).sum() == 5
    text = (tmp_path / "summary.json").read_text()
    assert "NaN" in text and text.count("\n") == len(doc) + 2  # as json writes NaN; a key a line
    assert math.isfinite(doc["grey_distance"])  # over the robots that sensed something


def test_large_summary_with_dead_robots_has_null_cells_and_dead_list(run, tmp_path):
    alive = np.ones((SIDE, SIDE), bool)
    alive[2, 3] = alive[150, 0] = alive[159, 159] = False
    dead_run = RunResult(**{**vars(run), "alive": alive})
    reference = as_json_dumps_writes_it(dead_run.summary())
    for arrays in (True, False):
        doc = written(dead_run.summary(arrays=arrays), tmp_path)
        assert list(doc) == [*SUMMARY_KEYS, "dead"]
        assert exact(doc) == exact(reference)
    assert doc["dead"] == [[2, 3], [150, 0], [159, 159]]
    assert doc["final"][150][0] is None and doc["initial"][2][3] is None
    assert sum(doc["votes"].values()) == SIDE * SIDE - 3


def test_small_summary_is_written_as_before(tmp_path):
    small = simulate(CamoParams(rows=8, cols=12, rho_comm=0.1), np.full((8, 12), 100.0))
    summary = small.summary()
    path = write_summary(small.summary(arrays=True), tmp_path)
    assert path.read_text() == json.dumps(summary, indent=1) + "\n"


def test_values_orjson_would_write_otherwise_go_through_json(tmp_path):
    rows = cols = 200
    summary = {
        "rows": rows,
        "cols": cols,
        "narrow": np.linspace(0, 1, 7, dtype=np.float32),  # orjson rounds float32 its own way
        "infinite": [1.0, float("inf"), -float("inf")],
        "huge": 2**70,  # beyond orjson's 64-bit integers
        "scalars": [np.float64(0.1), np.int64(3), np.float32(0.2)],
        "text": "café",
        "grid": np.arange(rows * cols, dtype=np.float64).reshape(rows, cols) / 7,
    }
    listed = {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in summary.items()}
    listed["scalars"] = [0.1, 3, float(np.float32(0.2))]
    reference = json.loads(json.dumps(listed))
    for key in summary:  # each on its own, and all together
        part = {"rows": rows, "cols": cols, key: summary[key]}
        expected = {"rows": rows, "cols": cols, key: reference[key]}
        assert exact(written(part, tmp_path)) == exact(expected), key
    assert exact(written(summary, tmp_path)) == exact(reference)


@pytest.mark.slow(COMPUTE)
def test_without_orjson_the_summary_goes_through_json(run, tmp_path, monkeypatch):
    monkeypatch.setattr(result, "orjson", None)
    nan_run = RunResult(**{**vars(run), "sensed": run.sensed.copy()})
    nan_run.sensed[5, 5] = np.nan
    for case in (run, nan_run):
        reference = as_json_dumps_writes_it(case.summary())
        assert exact(written(case.summary(arrays=True), tmp_path)) == exact(reference)


def drawn_panels(monkeypatch) -> list[tuple[tuple, dict]]:
    """Record the shape and keyword arguments of every array imshow draws."""
    calls = []
    imshow = matplotlib.axes.Axes.imshow

    def spy(self, values, *args, **kwargs):
        calls.append((np.shape(values), kwargs))
        return imshow(self, values, *args, **kwargs)

    monkeypatch.setattr(matplotlib.axes.Axes, "imshow", spy)
    return calls


def synthetic_run(rows: int, cols: int, dead: bool = False) -> RunResult:
    rng = np.random.default_rng(rows)
    states = rng.integers(0, 2, (rows, cols)).astype(np.uint8)
    alive = None
    if dead:
        alive = np.ones((rows, cols), bool)
        alive[: rows // 3, : cols // 3] = False
    return RunResult(
        params=CamoParams(rows=rows, cols=cols),
        sensed=rng.uniform(0, 255, (rows, cols)),
        votes=np.zeros((rows, cols), int),
        p=np.full((rows, cols, 3), 1 / 3),
        selected=np.zeros((rows, cols), int),
        initial=states,
        final=1 - states,
        consensus_trace=np.full((36, 3), 1 / 3),
        alive=alive,
    )


@pytest.mark.slow(COMPUTE)
def test_large_grid_figure_is_drawn_from_resized_grids(tmp_path, monkeypatch):
    rows, cols = 1100, 400
    calls = drawn_panels(monkeypatch)
    image = np.random.default_rng(0).integers(0, 256, (2200, 1200, 3), dtype=np.uint8)
    path = figures.run_figure(synthetic_run(rows, cols, dead=True), image, tmp_path / "big.png")
    figure = cv2.imread(str(path))
    assert figure.shape == (390, 2040, 3)  # figsize 20.4 x 3.9 inches at 100 dpi
    assert len(calls) == 5  # input image, sensed, chosen patterns, initial, final
    cap = figures.MAX_PANEL_PX
    assert calls[0][0] == (cap, cap, 3)  # each side on its own
    assert calls[0][1]["extent"] == (-0.5, 1199.5, 2199.5, -0.5)
    assert calls[2][0] == (cap, cols, 3)  # the chosen patterns, in their colours
    for shape, kwargs in calls[1:]:
        assert shape[:2] == (cap, cols)  # 1100 rows drawn as 512, 400 columns as they are
        assert kwargs["extent"] == (-0.5, cols - 0.5, rows - 0.5, -0.5)
    assert len(np.unique(figure)) > 2  # the panels hold something


def test_small_grid_figure_is_drawn_as_before(tmp_path, monkeypatch):
    rows, cols = 64, 96
    calls = drawn_panels(monkeypatch)
    image = np.random.default_rng(0).integers(0, 256, (128, 192), dtype=np.uint8)
    path = figures.run_figure(synthetic_run(rows, cols), image, tmp_path / "small.png")
    assert cv2.imread(str(path)).shape == (390, 2040, 3)
    shapes = [shape for shape, _ in calls]
    assert shapes == [(128, 192), (rows, cols), (rows, cols, 3), (rows, cols), (rows, cols)]
    assert not any("extent" in kwargs for _, kwargs in calls)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 300), st.integers(1, 8), st.integers(0, 2**32 - 1), st.booleans())
def test_p_stats_sums_in_robot_order_and_keeps_the_first_robots_nan(n, width, seed, holes):
    # The mean is the sum in robot-id order (as every driver sums it), the spread the least and
    # greatest; a NaN in the first robot's p stays, a later one is passed over.
    rng = np.random.default_rng(seed)
    p = rng.random((n, width)) * rng.choice([1e-9, 1.0, 1e9], (n, width))
    if holes:
        p[rng.random((n, width)) < 0.1] = np.nan
    mean, spread = p_stats(p)
    in_order = np.cumsum(p, axis=0)[-1] / n  # cumsum adds one robot after another
    assert np.array_equal(mean, in_order, equal_nan=True)
    for k in range(width):
        column = p[:, k]
        if np.isnan(column[0]):
            assert np.isnan(spread[k]).all()
        else:
            assert spread[k, 0] == np.nanmin(column) and spread[k, 1] == np.nanmax(column)


@pytest.mark.parametrize("robots", [1, 7, SMALL_P // 3, SMALL_P // 3 + 1])
def test_p_stats_of_small_and_large_swarms_are_the_kernels_bits(robots):
    """Small swarms' p statistics skip numba (its start costs more than they do): the same bits
    as the compiled kernels on either side of the limit."""
    p = np.random.default_rng(robots).random((robots, 3)) * 1e3
    mean, spread = p_stats(p)
    assert np.array_equal(mean, kernels.mean_p(p)) and np.array_equal(mean, mean_p(p))
    expected_mean, expected_spread = kernels.p_stats(p)
    assert np.array_equal(mean, expected_mean) and np.array_equal(spread, expected_spread)
