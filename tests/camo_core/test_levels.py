"""--levels K: the swarm's own K greys, from a histogram it averages, shown in layers."""

import json

import numpy as np
import pytest
from support import COMPUTE, PROCESS, Bus, assert_drivers_agree, brick_courses, run_camo

from camo_core.algorithm import levels
from camo_core.algorithm.backgrounds import background, stripes
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.robot_io import DONE, Message
from camo_core.swarm.validation import message_problem

FIELDS = ("sensed", "votes", "p", "selected", "initial", "final", "palette", "display")


@pytest.mark.slow(COMPUTE)
@pytest.mark.parametrize("k", [2, 3, 4, 8])
@pytest.mark.parametrize("rho", [0.0, 0.3])
def test_the_drivers_agree_with_levels(k, rho):
    generator = np.random.default_rng(k + int(rho * 10))
    for rows, cols, orientation in [(1, 1, "axes"), (1, 5, "any"), (6, 5, "axes"), (9, 9, "any")]:
        profile = "droplet" if k == 3 else "paper"
        params = CamoParams(rows=rows, cols=cols, seed=3, rho_meas=rho, rho_comm=rho, levels=k,
                            orientation=orientation, profile=profile)  # fmt: skip
        raw = generator.uniform(0, 255, (rows, cols))
        assert_drivers_agree(params, raw, FIELDS, (rows, cols))


@pytest.mark.slow(COMPUTE)
def test_one_robots_palette_is_the_grids_bit_for_bit():
    generator = np.random.default_rng(0)
    vectors = []
    for _ in range(200):
        shares = generator.dirichlet(np.full(16, 0.3))
        shares[generator.random(16) < 0.4] = 0.0  # empty bins, and classes with nobody
        shares = shares / shares.sum() if shares.sum() else np.eye(16)[3]
        greys = 16 * np.arange(16) + 16 * generator.random(16)
        vectors.append(np.concatenate([shares, shares * greys]))
    vectors = np.array(vectors)
    for k in (2, 3, 5):
        cuts, greys = levels.palettes(vectors, k)
        for v, c, g in zip(vectors, cuts, greys, strict=True):
            assert levels.palette(tuple(v.tolist()), k) == (tuple(c), tuple(g))


def test_the_cuts_part_the_histograms_peaks_and_the_greys_are_their_means():
    greys = np.array([20.0] * 30 + [30.0] * 30 + [200.0] * 40)
    vector = np.mean([levels.start_vector(g) for g in greys], axis=0)
    cuts, palette = levels.palette(tuple(vector), 2)
    assert 32 <= cuts[0] <= 192  # between the dark and the light peak
    assert palette == (25, 200)
    # 20 and 30 share a bin: three classes leave one empty, shown at its bins' middle.
    assert levels.palette(tuple(vector), 3)[1][1:] == (25, 200)
    greys = np.array([20.0] * 30 + [100.0] * 30 + [200.0] * 40)
    vector = np.mean([levels.start_vector(g) for g in greys], axis=0)
    cuts, palette = levels.palette(tuple(vector), 3)
    # Every cut between the bins of 20, 100 and 200 scores the same: the first is taken.
    assert palette == (20, 100, 200) and cuts == (32, 112)
    # A robot with its layers on shows the darkest grey; with none, the lightest.
    assert levels.initial_layers(25.0, cuts) == 0b11 and levels.initial_layers(210.0, cuts) == 0
    assert levels.shown(0b11, palette) == 20 and levels.shown(0, palette) == 200


def mean_distance(images, k):
    distances = []
    for image in images:
        params = CamoParams(rows=32, cols=32, levels=k, threshold_auto=True)
        distances.append(simulate(params, sense_image(image, 32, 32, "paper")).grey_distance)
    return float(np.mean(distances))


def test_more_levels_show_the_background_more_closely():
    images = [background(n) for n in ("desert", "forest", "leopard")]
    images += [brick_courses(), stripes(60, period=48), stripes(0, period=64, noise=60)]
    paper, two, four = (mean_distance(images, k) for k in (0, 2, 4))
    assert paper > 2 * two and two > four


@pytest.mark.slow(PROCESS)
def test_the_paper_shows_black_and_white_and_summary_json_says_how_far_that_is(tmp_path):
    result = simulate(CamoParams(), sense_image(background("forest"), 8, 8, "paper"))
    assert np.array_equal(result.display, np.where(result.final == 1, 0, 255))
    shown, sensed = np.sort(result.display.ravel()), np.sort(result.sensed.ravel())
    assert result.grey_distance == pytest.approx(np.mean(np.abs(shown - sensed)))
    out = run_camo("sim", "--levels", "3", "--pattern", "leopard", "--out", str(tmp_path / "a"))
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    again = simulate(CamoParams(levels=3), sense_image(background("leopard"), 8, 8, "paper"))
    assert summary["display"] == again.display.tolist()
    assert summary["grey_distance"] == round(again.grey_distance, 6) > 0
    # Each robot shows a grey of its own palette (the robots' palettes differ a little where
    # consensus has not quite converged).
    assert all(again.display[i, j] in again.palette[i, j] for i in range(8) for j in range(8))
    bad = run_camo("sim", "--levels", "9", "--out", str(tmp_path / "b"))
    assert bad.returncode == 2
    assert bad.stderr.strip() == "camo: error: levels must be an integer in 2..8 (got 9)"


def test_levels_must_be_2_to_8():
    for bad in (1, 9, -2, True):
        with pytest.raises(ParameterError, match=r"levels must be an integer in 2\.\.8"):
            CamoParams(levels=bad)


def test_the_step_protocol_in_any_delivery_order_equals_the_simulator_with_levels():
    for rows, cols, rho, k, orientation in [(4, 5, 0.0, 3, "axes"), (6, 6, 0.3, 4, "any")]:
        params = CamoParams(rows=rows, cols=cols, rho_comm=rho, rho_meas=rho, seed=2, levels=k,
                            orientation=orientation)  # fmt: skip
        grid = np.random.default_rng(k).uniform(0, 255, (rows, cols))
        bus = Bus(params, grid, seed=k)
        bus.run()
        assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots.values())
        reference = simulate(params, grid)
        robots = [bus.robots[i].core for i in range(params.count)]
        for name, field in (("state", "final"), ("display", "display")):
            got = np.reshape([getattr(r, name) for r in robots], (rows, cols))
            assert np.array_equal(got, getattr(reference, field)), (rows, cols, name)


def test_states_and_histograms_are_checked_against_the_runs_levels():
    params = CamoParams(rows=4, cols=4, levels=4, formation_steps=6)
    assert message_problem(Message("state", 3, 0, 0, 0b111), params) is None
    assert message_problem(Message("state", 3, 0, 0, 0b1000), params) == "state out of range"
    assert message_problem(Message("state", 3, 0, 0, 2), CamoParams()) == "state out of range"
    vote = (*(0.2, 0.3, 0.5), *levels.start_vector(100.0))
    assert message_problem(Message("vote", 3, 0, 0, (vote, 3)), params) is None
    assert message_problem(Message("vote", 3, 0, 0, (vote[:3], 3)), params) == "vote out of range"
    wrong_bin = list(vote)
    wrong_bin[3 + 16 + 6] = 20.0  # a grey of 20 in the bin of 96-111
    assert message_problem(Message("vote", 3, 0, 0, (wrong_bin, 3)), params) == "vote out of range"
