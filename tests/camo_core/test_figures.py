"""The figures a user reads: every line labelled, the consensus spread across robots, marked
robots, and the error figure in the paper's form (a band that cannot go below zero, the
correct-pattern rate, the paper's colours and reported values)."""

import matplotlib.colors
import matplotlib.pyplot as plt
import numpy as np
import pytest

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.results import figures


@pytest.fixture(scope="module")
def noisy_forest():
    params = CamoParams(rows=8, cols=8, rho_meas=0.15, rho_comm=0.1)
    image = background("forest")
    return simulate(params, sense_image(image, 8, 8, "paper")), image


def test_the_simulator_keeps_the_least_and_greatest_p_around_the_mean(noisy_forest):
    result, _ = noisy_forest
    spread = result.consensus_range
    assert spread.shape == (len(result.consensus_trace), 3, 2)
    assert np.all(spread[:, :, 0] <= result.consensus_trace + 1e-12)
    assert np.all(result.consensus_trace <= spread[:, :, 1] + 1e-12)
    # One-hot votes at step 0, then averaging narrows the spread.
    assert spread[0, :, 0].tolist() == [0, 0, 0] and spread[0, 1, 1] == 1
    assert np.ptp(spread[-1], axis=1).max() < np.ptp(spread[0], axis=1).max()


def test_every_consensus_line_is_labelled_and_the_spread_is_drawn(noisy_forest):
    result, image = noisy_forest
    fig = figures.run_plot(result, image, title="built-in forest")
    consensus = fig.axes[2]
    labels = [line.get_label() for line in consensus.get_lines()]
    assert labels and not any(label.startswith("_") for label in labels), labels
    threshold = [line for line in consensus.get_lines() if line.get_ydata()[0] == 0.5]
    assert [line.get_label() for line in threshold] == ["p = 0.5: half of the weight"]
    bands = [c for c in consensus.collections if len(c.get_paths())]
    assert len(bands) == 3  # one per pattern
    assert "band" in " ".join(t.get_text() for t in consensus.get_legend().get_texts())
    plt.close(fig)


def test_dead_bridged_and_real_reading_robots_are_marked(noisy_forest):
    result, image = noisy_forest
    alive = np.ones((8, 8), bool)
    alive[3, 4] = False
    result = type(result)(**{**result.__dict__, "alive": alive})
    bridged = np.zeros((8, 8), bool)
    bridged[0, 1] = True
    silent = np.zeros((8, 8), bool)
    fig = figures.run_plot(result, image, marks={"bridged": bridged, "silent": silent})
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    styles = figures.MARK_STYLES
    assert legend == [styles["bridged"]["label"], styles["dead"]["label"]]
    final = fig.axes[4]
    points = {tuple(p) for c in final.collections for p in c.get_offsets().tolist()}
    assert points == {(1.0, 0.0), (4.0, 3.0)}  # (col, row) of the bridged and the dead robot
    plt.close(fig)


def test_an_unmarked_run_has_no_marks_legend(noisy_forest):
    result, image = noisy_forest
    fig = figures.run_plot(result, image)
    assert not fig.legends and not fig.axes[4].collections
    plt.close(fig)


@pytest.fixture(scope="module")
def error_rows():
    # What ./camo errors draws: mean, spread and correct rate per mode and rho; a spread of
    # several trials, some of them above zero.
    rng = np.random.default_rng(3)
    rows = []
    for mode in ("measurement", "communication", "both"):
        for rho in (0.0, 0.3, 0.5):
            diffs = rng.integers(0, 40, 6) * (rho > 0)
            rows.append(
                {
                    "mode": mode,
                    "rho": rho,
                    "mean_diff": float(np.mean(diffs)),
                    "p10_diff": float(np.percentile(diffs, 10)),
                    "p90_diff": float(np.percentile(diffs, 90)),
                    "correct_rate": float(rng.uniform()),
                }
            )
    return rows


def test_the_error_figure_has_a_band_above_zero_a_rate_panel_and_the_paper(error_rows):
    fig = figures.errors_plot(error_rows, 32, cells=64)
    diff_ax, rate_ax = fig.axes
    assert diff_ax.get_ylim()[0] == 0
    for band in diff_ax.collections:
        for path in band.get_paths():
            assert path.vertices[:, 1].min() >= 0
    colors = {line.get_label(): line.get_color() for line in diff_ax.get_lines()}
    assert matplotlib.colors.to_hex(colors["measurement error only"]) == "#d62728"  # red
    assert matplotlib.colors.to_hex(colors["communication error only"]) == "#1f77b4"  # blue
    rates = {line.get_label(): line.get_ydata() for line in rate_ax.get_lines()}
    both = [r["correct_rate"] for r in error_rows if r["mode"] == "both"]
    assert list(rates["both, equal probability"]) == both
    legend = " ".join(t.get_text() for t in diff_ax.get_legend().get_texts())
    assert "paper: robust up to 0.15-0.2" in legend and "differs by 32" in legend
    assert any("arXiv 1709.07051" in t.get_text() for t in fig.texts)
    plt.close(fig)


def test_the_paper_random_level_is_only_drawn_for_the_paper_swarm_size(error_rows):
    fig = figures.errors_plot(error_rows, 128, cells=256)
    legend = " ".join(t.get_text() for t in fig.axes[0].get_legend().get_texts())
    assert "random 8x8" not in legend and "differs by 128" in legend
    plt.close(fig)


def test_a_swarm_round_marks_its_bridged_robots_and_those_given_up_on():
    from camo_core.results.record import RoundRecord

    record = RoundRecord(CamoParams(rows=2, cols=3))
    record.given_up = {0: frozenset({4, 5})}  # robot 0 gave up on 4 and 5 for a while
    dead = np.zeros(6, bool)
    dead[5] = True  # 5 never finished: dead, not merely silent
    marks = record.marks(dead, bridged={2, 99})  # 99: not a robot of this swarm
    assert np.flatnonzero(marks["silent"]).tolist() == [4]
    assert np.flatnonzero(marks["bridged"]).tolist() == [2]


def test_the_error_figure_draws_the_grey_distance_when_the_rows_have_it(error_rows):
    rows = [{**r, "mean_grey_distance": 10 + 100 * r["rho"]} for r in error_rows]
    fig = figures.errors_plot(rows, 32, cells=64)
    assert len(fig.axes) == 3
    lines = {line.get_label(): list(line.get_ydata()) for line in fig.axes[2].get_lines()}
    measured = [r["mean_grey_distance"] for r in rows if r["mode"] == "measurement"]
    assert lines["measurement error only"] == measured
    plt.close(fig)
