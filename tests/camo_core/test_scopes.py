"""--scope local: each region of a scene its own pattern, by a rule both drivers and the step
protocol compute alike (docs/algorithm.md §2.9)."""

import json
import sys

import numpy as np
import pytest
from scipy import ndimage
from support import COMPUTE, PROCESS, ROOT, Bus, run_camo

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.change import params_of_round
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.modes.palettes import GridPalette
from camo_core.algorithm.modes.scopes import (
    ROUNDS,
    LocalScope,
    Previous,
    strict_argmax,
    strict_argmax_all,
)
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.sensing import sense_colours, sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.robot_io import DONE, Message
from camo_core.swarm.validation import message_problem

sys.path.insert(0, str(ROOT / "tools"))
from scenes import disc_scene, make_scene, robot_truth

FIELDS = ("votes", "p", "selected", "initial", "final", "consensus_trace")


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"rho_comm": 0.2, "rho_meas": 0.1, "seed": 3},
        {"profile": "droplet", "rho_comm": 0.3, "seed": 5},
        {"orientation": "any", "rho_comm": 0.1},
        {"levels": 3, "rho_comm": 0.1, "consensus_steps": 50},
        {"threshold": "auto", "scope_scale": 1.2},
        {"consensus_steps": 0},
    ],
)
def test_both_drivers_compute_scope_local_alike(options):
    params = CamoParams.from_options(rows=9, cols=8, scope="local", **options)
    grid = np.random.default_rng(7).uniform(0, 255, (9, 8))
    vectorised, robots = simulate(params, grid), run_per_robot(params, grid)
    for name in FIELDS:
        assert np.array_equal(getattr(vectorised, name), getattr(robots, name)), name


def test_both_drivers_compute_scope_local_alike_with_colours():
    params = CamoParams(rows=7, cols=6, scope="local", colours=3, rho_comm=0.1, seed=2)
    image = np.random.default_rng(3).integers(0, 256, (56, 48, 3), dtype=np.uint8)
    grey, rgb = sense_image(image, 7, 6, "paper"), sense_colours(image, 7, 6)
    vectorised = simulate(params, grey, raw_colours=rgb)
    robots = run_per_robot(params, grey, raw_colours=rgb)
    for name in (*FIELDS, "palette_rgb", "shades"):
        assert np.array_equal(getattr(vectorised, name), getattr(robots, name)), name


@pytest.mark.parametrize("shared_link", [False, True])
def test_step_protocols_in_any_delivery_order_equal_the_simulator_in_scope_local(shared_link):
    params = CamoParams(rows=6, cols=7, scope="local", rho_comm=0.2, rho_meas=0.1, seed=4)
    grid = np.random.default_rng(1).uniform(0, 255, (6, 7))
    bus = Bus(params, grid, seed=2, shared_link=shared_link)
    bus.run()
    assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots.values())
    reference = simulate(params, grid)
    robots = [bus.robots[i].core for i in range(params.count)]
    assert np.array_equal(np.reshape([r.pattern for r in robots], (6, 7)), reference.selected)
    assert np.array_equal(np.reshape([r.state for r in robots], (6, 7)), reference.final)


def test_a_local_round_takes_its_segmentation_steps_before_the_paper_s_consensus():
    params = CamoParams(scope="local", scope_scale=2)
    scope = modes_of(params).scope
    assert isinstance(scope, LocalScope)
    assert (scope.evidence, scope.cleanup) == (4, 6)  # round(L^2), round(1.5 L^2)
    assert scope.steps(params) == 4 + ROUNDS * 6 + params.consensus_steps
    assert modes_of(CamoParams()).scope.steps(CamoParams()) == 35  # the paper's: unchanged


def test_ties_for_the_largest_go_to_the_last_class():
    assert strict_argmax((0.2, 0.5, 0.3), 2) == 1
    assert strict_argmax((0.5, 0.5, 0.0), 2) == 2
    values = np.array([[0.2, 0.5, 0.3], [0.5, 0.5, 0.0], [0.1, 0.1, 0.8]])
    assert strict_argmax_all(values, 2).tolist() == [1, 2, 2]


def test_a_vote_of_each_phase_is_checked_as_that_phase_sends_it():
    params = CamoParams(rows=4, cols=4, scope="local")
    scope = modes_of(params).scope

    def problem(step, vector):
        return message_problem(Message("vote", 1, 0, step, (vector, 3)), params)

    assert problem(0, (0.5, 0.25, 0.25)) is None  # evidence: p
    assert problem(0, (0.5, 0.25, 0.25, 1.0)) is not None
    assert problem(scope.evidence, (0.5, 0.5, 0.0)) is None  # clean-up: classes' shares
    assert problem(scope.evidence, (0.5, 0.6, 0.0)) is not None
    assert problem(scope.segmented, (0.5, 0.25, 0.25, 2.0)) is None  # segment: p and class
    assert problem(scope.segmented, (0.5, 0.25, 0.25, 3.0)) is not None  # no such class
    assert problem(scope.segmented, (0.5, 0.25, 0.25)) is not None  # no class at all
    assert problem(scope.steps(params), (0.5, 0.25, 0.25, 2.0)) is not None  # past the phase


def region_accuracy(scene, params):
    truth, _, distance = robot_truth(scene, params.rows, params.cols)
    grey = sense_image(scene.image, params.rows, params.cols, params.profile)
    chosen = simulate(params, grey).selected
    far = distance >= 2
    return float(np.mean(chosen[far] == truth[far]))


@pytest.mark.parametrize("seed", [11, 12, 13, 14])
def test_each_region_of_a_composite_scene_shows_its_own_pattern(seed):
    scene = make_scene(seed, cells=32)
    local = region_accuracy(scene, CamoParams(rows=32, cols=32, scope="local"))
    everywhere = region_accuracy(scene, CamoParams(rows=32, cols=32, consensus_steps=300))
    assert local >= 0.95, local
    assert local > everywhere  # consensus to completion shows the majority's pattern


def test_a_disc_of_horizontal_stripes_in_vertical_ones_keeps_its_stripes():
    scene = disc_scene(3, cells=32, radius=7.0, inner=0, outer=1)
    params = CamoParams(rows=32, cols=32, scope="local")
    assert region_accuracy(scene, params) >= 0.95
    truth, _, distance = robot_truth(scene, 32, 32)
    chosen = simulate(params, sense_image(scene.image, 32, 32, "paper")).selected
    disc = (truth == 0) & (distance >= 2)
    assert np.mean(chosen[disc] == 0) >= 0.95


@pytest.mark.parametrize("name", ["desert", "forest", "leopard"])
def test_on_a_single_texture_local_chooses_what_global_chooses(name):
    for side in (8, 16):
        grey = sense_image(background(name), side, side, "paper")
        local = simulate(CamoParams(rows=side, cols=side, scope="local"), grey)
        paper = simulate(CamoParams(rows=side, cols=side), grey)
        assert np.mean(local.selected == paper.selected) >= 0.95, (name, side)


def changed_scene(seed: int, cells: int, region: int, other: int):
    """A composite scene, and the same scene with one region's texture another scene's."""
    before = make_scene(seed, cells=cells)
    after = before.image.copy()
    inside = before.region == region
    after[inside] = make_scene(other, cells=cells).image[inside]
    return before, after


def previous_of(result, raw) -> Previous:
    return Previous(raw, result.selected, result.final, GridPalette(result.palette))


@pytest.mark.slow(COMPUTE)  # the per-robot driver over 32x32 robots: seconds each
@pytest.mark.parametrize("options", [{}, {"rho_comm": 0.1}, {"levels": 3, "rho_comm": 0.1}])
def test_a_change_in_one_region_re_camouflages_that_region_and_only_it(options):
    before, after = changed_scene(1010, 32, 1, 1017)
    params = CamoParams(rows=32, cols=32, scope="local", **options)
    first_raw = sense_image(before.image, 32, 32, "paper")
    first = simulate(params, first_raw)
    later = params_of_round(params, 1)
    raw = sense_image(after, 32, 32, "paper")
    kept = simulate(later, raw, previous=previous_of(first, first_raw))
    fresh = simulate(later, raw)
    _, region, _ = robot_truth(before, 32, 32)
    changed = region == 1
    outside = ~ndimage.binary_dilation(changed, iterations=2)  # two cells clear of the change
    moved = kept.display != first.display
    assert moved[outside].mean() <= 0.05 < (fresh.display != first.display)[outside].mean()
    assert moved[changed].mean() > 0.3  # the changed region shows its new camouflage
    robots = run_per_robot(later, raw, previous=previous_of(first, first_raw))
    for name in ("selected", "initial", "final", "display"):
        assert np.array_equal(getattr(kept, name), getattr(robots, name)), name


def test_the_paper_s_swarm_re_camouflages_whole_whatever_its_last_round():
    params = CamoParams(rows=8, cols=8, rho_comm=0.1)
    grey = sense_image(background("forest"), 8, 8, "paper")
    first = simulate(params, grey)
    again = simulate(params, grey, previous=previous_of(first, grey))
    assert np.array_equal(again.final, simulate(params, grey).final)


def test_step_protocols_keep_what_they_showed_where_a_later_frame_did_not_change():
    before, after = changed_scene(1024, 12, 0, 1003)
    params = CamoParams(rows=12, cols=12, scope="local", rho_comm=0.1)
    first_raw = sense_image(before.image, 12, 12, "paper")
    raw = sense_image(after, 12, 12, "paper")
    bus = Bus(params, first_raw, seed=5, shared_link=True)
    bus.run()
    bus.show(raw, 1)
    assert all(p.phase == DONE and p.round == 1 for p in bus.robots.values())
    first = simulate(params, first_raw)
    expected = simulate(params_of_round(params, 1), raw, previous=previous_of(first, first_raw))
    robots = [bus.robots[i].core for i in range(params.count)]
    assert np.array_equal(np.reshape([r.state for r in robots], (12, 12)), expected.final)
    assert any(r.kept for r in robots) and not all(r.kept for r in robots)


@pytest.mark.slow(PROCESS)
def test_sim_after_a_round_folder_is_that_round_s_next(tmp_path):
    # A continuous run's round_<k>/ holds summary.json and background.png: ./camo sim --after
    # it, on the next round's frame and seed, is the next round.
    import cv2

    before, after = changed_scene(1010, 16, 1, 1017)
    first, second = tmp_path / "first.png", tmp_path / "second.png"
    cv2.imwrite(str(first), before.image)
    cv2.imwrite(str(second), after)
    options = ["--rows", "16", "--cols", "16", "--scope", "local", "--levels", "3"]
    ran = run_camo("sim", "--image", str(first), *options, "--out", str(tmp_path / "r0"))
    assert ran.returncode == 0, ran.stderr
    cv2.imwrite(str(tmp_path / "r0" / "background.png"), before.image)
    out = tmp_path / "r1"
    ran = run_camo("sim", "--image", str(second), *options, "--after", str(tmp_path / "r0"),
                   "--seed", "1", "--out", str(out))  # fmt: skip
    assert ran.returncode == 0, ran.stderr
    params = CamoParams(rows=16, cols=16, scope="local", levels=3)
    first_raw = sense_image(before.image, 16, 16, "paper")
    r0 = simulate(params, first_raw)
    expected = simulate(
        params.with_(seed=1),
        sense_image(after, 16, 16, "paper"),
        previous=previous_of(r0, first_raw),
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["final"] == expected.final.tolist()
    assert summary["display"] == expected.display.tolist()
    bad = run_camo("sim", "--image", str(second), *options, "--after", str(tmp_path))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
