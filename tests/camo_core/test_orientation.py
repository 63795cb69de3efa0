"""--orientation any: a structure tensor, stripes at multiples of 15 degrees, relayed states."""

import json

import numpy as np
import pytest
from support import (
    COMPUTE,
    PROCESS,
    Bus,
    assert_drivers_agree,
    brick_courses,
    drawn_direction,
    run_camo,
)

from camo_core.algorithm import orientation, rules
from camo_core.algorithm.backgrounds import stripes
from camo_core.algorithm.orientation import ORIENTED, ROLES, choose, raw_tensor
from camo_core.algorithm.params import CamoParams, ParameterError
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.swarm.robot_io import DONE

FIELDS = ("sensed", "votes", "p", "selected", "initial", "final", "consensus_trace")


@pytest.mark.parametrize("profile", ["paper", "droplet"])
@pytest.mark.parametrize("rho", [0.0, 0.3])
@pytest.mark.parametrize("auto", [False, True])
def test_the_drivers_agree_with_orientation_any(profile, rho, auto):
    generator = np.random.default_rng(int(rho * 10) + auto)
    for rows, cols in [(1, 1), (1, 6), (2, 2), (5, 4), (9, 9)]:
        params = CamoParams(profile=profile, rows=rows, cols=cols, seed=7, rho_meas=rho,
                            rho_comm=rho, threshold_auto=auto, orientation="any")  # fmt: skip
        raw = generator.uniform(0, 255, (rows, cols))
        assert_drivers_agree(params, raw, FIELDS, (rows, cols))


@pytest.mark.slow(COMPUTE)
def test_the_drivers_agree_on_stripes_at_every_angle_with_loss():
    # Random greys seldom agree on a direction: stripes do, so every oriented kernel (and its
    # relayed knight cells, lost or not) is exercised.
    for degrees in range(0, 180, 15):
        params = CamoParams(rows=12, cols=12, rho_comm=0.25, seed=degrees, orientation="any")
        raw = sense_image(stripes(degrees, period=100, noise=10), 12, 12, "paper")
        fast, _ = assert_drivers_agree(params, raw, FIELDS, (degrees,))
        assert (fast.selected >= ORIENTED).any(), degrees


def test_the_oriented_kernels_at_0_and_90_degrees_are_the_papers_stripe_kernels():
    assert np.array_equal(ROLES[ORIENTED], ROLES[rules.HORIZONTAL])
    assert np.array_equal(ROLES[ORIENTED + 6], ROLES[rules.VERTICAL])
    params = CamoParams(profile="droplet")
    w2 = orientation.inhibitor_weights(params)
    assert w2[ORIENTED] == w2[ORIENTED + 6] == params.w2_stripes
    # And the rule itself: the same new state from any neighbourhood, missing slots included.
    generator = np.random.default_rng(3)
    for _ in range(300):
        received = [None if generator.random() < 0.3 else int(generator.integers(2))
                    for _ in range(12)]  # fmt: skip
        knights = [int(generator.integers(2)) for _ in range(8)]
        state = int(generator.integers(2))
        for paper, oriented in ((rules.HORIZONTAL, ORIENTED), (rules.VERTICAL, ORIENTED + 6)):
            expected = rules.formation_step(state, paper, received, params)
            got = orientation.formation_step(state, oriented, received, knights, params, w2)
            assert got == expected


def test_the_45_degree_kernel_runs_along_the_diagonal_and_weighs_its_inhibitors():
    roles = dict(zip(orientation.OFFSETS, ROLES[ORIENTED + 3], strict=True))
    assert sorted(o for o, r in roles.items() if r > 0) == [(-1, 1), (1, -1)]  # up-right
    assert sum(r < 0 for r in roles.values()) == 10
    w2 = orientation.inhibitor_weights(CamoParams())[ORIENTED + 3]
    assert w2 == pytest.approx(-0.75 * 3 / 5 * 6 / 10)


def neighbourhood(rows_of_greys):
    """A robot's grey and slots 0-7's from a 3x3 block (rows top to bottom)."""
    (tl, t, tr), (lf, m, r), (bl, b, br) = rows_of_greys
    return m, [t, r, b, lf, tr, br, bl, tl]


@pytest.mark.parametrize(
    "block, angle",
    [
        ([[0, 0, 0], [200, 200, 200], [0, 0, 0]], 0),  # a horizontal line
        ([[0, 200, 0], [0, 200, 0], [0, 200, 0]], 90),
        ([[0, 0, 200], [0, 200, 0], [200, 0, 0]], 45),  # bottom-left to top-right
        ([[200, 0, 0], [0, 200, 0], [0, 0, 200]], 135),
    ],
)
def test_a_robot_reads_the_direction_of_a_line_through_it(block, angle):
    own, around = neighbourhood(block)
    tensor = orientation.normalised(*raw_tensor(own, around), orientation.REGULARISER)
    assert orientation.angle_of(choose(tensor)) == angle


def test_flat_or_isotropic_neighbourhoods_are_mottled_and_missing_ones_filled():
    assert choose((0.0, 0.0, 0.0)) == rules.MOTTLED
    assert choose((0.4, 0.4, 0.0)) == rules.MOTTLED  # coherence 0
    assert choose((0.5, 0.4, 0.0)) == rules.MOTTLED  # coherence 0.11 < 0.15
    assert choose((0.5, 0.3, 0.0)) == ORIENTED + 6  # 0.25: across x, so vertical stripes
    # A lone robot fills every neighbour with its own grey: no texture at all.
    assert raw_tensor(90.0, [None] * 8) == (0.0, 0.0, 0.0)
    # A missing neighbour takes the opposite one (a corner too: the pair measures one line),
    # else the robot's own grey.
    filled = raw_tensor(0.0, [None, 10.0, None, 10.0, 4.0, None, None, None])
    assert filled == raw_tensor(0.0, [0.0, 10.0, 0.0, 10.0, 4.0, 0.0, 4.0, 0.0])


def test_a_knight_cell_comes_from_the_first_neighbour_that_relays_it_else_its_mirror():
    k = orientation.KNIGHTS.index((1, 2))  # one down, two right
    (ahead, ahead_sub), (diag, diag_sub) = orientation.RELAY_PATHS[k]
    assert (ahead, ahead_sub) == (1, 5) and (diag, diag_sub) == (5, 1)
    relays = [None] * 8
    relays[diag] = (None, 1, None, None, None, None, None, None)
    assert orientation.knight_states(relays)[k] == 1
    relays[ahead] = (None, None, None, None, None, 0, None, None)
    assert orientation.knight_states(relays)[k] == 0  # the one straight ahead comes first
    assert orientation.STAND_INS[12 + k] == tuple(
        12 + orientation.KNIGHTS.index(m) for m in ((-1, 2), (1, -2), (-1, -2))
    )


def test_a_missing_cell_takes_the_first_stand_in_of_its_own_role():
    params = CamoParams()
    w2 = orientation.inhibitor_weights(params)
    at_45 = ORIENTED + 3
    # Slot 4 (up-right, an activator at 45 degrees) is missing; its mirror across the row, slot
    # 5, lies across the stripe (an inhibitor) and is on: it must not stand in, the
    # point-opposite slot 6 (off) does. With slot 5 standing in, 1 + 1 activators against one
    # inhibitor would switch the robot on.
    received = [0, 0, 0, 0, None, 1, 0, 0, 0, 0, 0, 0]
    assert orientation.formation_step(1, at_45, received, [0] * 8, params, w2) == 1
    received[6] = 1
    assert orientation.formation_step(0, at_45, received, [0] * 8, params, w2) == 1
    received = [0, 0, 0, 0, None, 1, 0, 0, 0, 0, 0, 0]
    assert orientation.formation_step(0, at_45, received, [0] * 8, params, w2) == 0


def test_the_step_protocol_in_any_delivery_order_equals_the_simulator_with_orientation_any():
    for rows, cols, rho, auto, order in [(4, 5, 0.0, False, 1), (6, 6, 0.3, True, 2),
                                         (1, 1, 0.0, False, 0)]:  # fmt: skip
        params = CamoParams(rows=rows, cols=cols, rho_comm=rho, rho_meas=rho, seed=4,
                            threshold_auto=auto, orientation="any")  # fmt: skip
        grid = sense_image(stripes(30 * order, period=40), rows, cols, "paper")
        bus = Bus(params, grid, seed=order)
        bus.run()
        assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots.values())
        reference = simulate(params, grid)
        robots = [bus.robots[i].core for i in range(params.count)]
        for name, field in (("vote", "votes"), ("pattern", "selected"), ("state", "final")):
            got = np.reshape([getattr(r, name) for r in robots], (rows, cols))
            assert np.array_equal(got, getattr(reference, field)), (rows, cols, name)
        assert np.array_equal(np.reshape([r.p for r in robots], (rows, cols, 3)), reference.p)


def run_32(image: np.ndarray, **options) -> tuple:
    params = CamoParams(rows=32, cols=32, **options)
    result = simulate(params, sense_image(image, 32, 32, params.profile))
    return result, float(np.mean(result.final == (result.sensed < 127)))


@pytest.mark.parametrize("degrees", [45, 135])
def test_diagonal_stripes_are_drawn_as_they_are(degrees):
    image = stripes(degrees, seed=degrees)
    result, agreement = run_32(image, orientation="any")
    assert result.majority_label == f"stripes at {degrees}°"
    assert agreement >= 0.85
    # The paper's two directions cannot draw them (mottled, or stripes along an axis).
    _, agreement_axes = run_32(image)
    assert agreement_axes < agreement - 0.2


def test_stripes_at_30_degrees_are_chosen_and_drawn_near_30():
    result, agreement = run_32(stripes(30, seed=5), orientation="any")
    assert abs(result.orientation_deg - 30) <= 15
    assert abs(drawn_direction(result.final.astype(float)) - 30) <= 20
    assert agreement >= 0.65


def test_orientation_any_with_threshold_auto_keeps_textures_apart():
    bricks = brick_courses()
    both = {"orientation": "any", "threshold_auto": True}
    assert run_32(bricks, **both)[0].majority_label == "stripes at 0°"
    assert run_32(np.ascontiguousarray(bricks.T), **both)[0].majority_label == "stripes at 90°"
    gravel = np.random.default_rng(2).normal(128, 40, (64, 64))
    gravel = np.clip(np.kron(gravel, np.ones((4, 4))), 0, 255).astype(np.uint8)
    assert run_32(gravel, **both)[0].majority_pattern == "mottled"


def test_orientation_must_be_axes_or_any():
    with pytest.raises(ParameterError, match="orientation must be one of axes, any"):
        CamoParams(orientation="diagonal")


@pytest.mark.slow(PROCESS)
def test_sim_writes_stripes_and_their_direction_to_summary_json(tmp_path):
    image = tmp_path / "stripes.png"
    import cv2

    cv2.imwrite(str(image), stripes(135))
    out = run_camo("sim", "--image", str(image), "--rows", "16", "--cols", "16",
                   "--orientation", "any", "--out", str(tmp_path / "a"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert (summary["pattern"], summary["orientation_deg"]) == ("stripes", 135)
    assert summary["votes"]["stripes_135"] > 128 and "horizontal" not in summary["votes"]
    assert "orientation: any" in (tmp_path / "a" / "params.yaml").read_text()
    assert "pattern: stripes at 135°" in out.stdout
    paper = run_camo("sim", "--out", str(tmp_path / "b"))
    assert paper.returncode == 0, paper.stderr
    assert "orientation_deg" not in json.loads((tmp_path / "b" / "summary.json").read_text())
