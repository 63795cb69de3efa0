"""--threshold auto: each robot's threshold from the swarm's averaged texture energy."""

import numpy as np
import pytest
from support import PROCESS, Bus, assert_drivers_agree, brick_courses, run_camo

from camo_core.algorithm import rules
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate

FIELDS = ("sensed", "votes", "p", "selected", "initial", "final", "consensus_trace")


@pytest.mark.parametrize("profile", ["paper", "droplet"])
@pytest.mark.parametrize("rho", [0.0, 0.3])
def test_the_drivers_agree_with_threshold_auto(profile, rho):
    generator = np.random.default_rng(int(rho * 10))
    for rows, cols in [(1, 1), (1, 6), (5, 4), (8, 8)]:
        params = CamoParams(profile=profile, rows=rows, cols=cols, seed=7, rho_meas=rho,
                            rho_comm=rho, threshold_auto=True)  # fmt: skip
        raw = generator.uniform(0, 255, (rows, cols))
        assert_drivers_agree(params, raw, FIELDS, (rows, cols))


def test_the_energy_is_averaged_as_p_is_and_sets_each_robots_threshold():
    # A lone robot keeps its own energy; two neighbours meet halfway in one step (degree 1:
    # weight 1/2 each), and a threshold never falls below the minimum.
    assert rules.energy_step(8.0, 0, [None] * 8) == 8.0
    assert rules.energy_step(8.0, 1, [(2.0, 1), *[None] * 7]) == 5.0
    assert rules.auto_threshold(40.0) == 20.0 and rules.auto_threshold(3.0) == 5.0
    horizontal, vertical, energy = rules.descriptor(100.0, [140.0, 100.0, 160.0, 100.0], "paper")
    assert (horizontal, vertical, energy) == (100.0, -100.0, 50.0)  # |Py| = 100, |Px| = 0


def pattern_of(image: np.ndarray, auto: bool) -> str:
    params = CamoParams(rows=32, cols=32, threshold_auto=auto)
    return simulate(params, sense_image(image, 32, 32, params.profile)).majority_pattern


def test_faint_courses_are_striped_with_auto_where_the_fixed_threshold_sees_nothing():
    bricks = brick_courses()
    assert pattern_of(bricks, auto=False) == "mottled"
    assert pattern_of(bricks, auto=True) == "horizontal"
    assert pattern_of(np.ascontiguousarray(bricks.T), auto=True) == "vertical"
    gravel = np.random.default_rng(2).normal(128, 40, (64, 64))
    gravel = np.clip(np.kron(gravel, np.ones((4, 4))), 0, 255).astype(np.uint8)
    assert pattern_of(gravel, auto=True) == "mottled"


def test_the_step_protocol_in_any_delivery_order_equals_the_simulator_with_auto():
    from camo_core.swarm.protocol import DONE

    for rows, cols, rho, order in [(3, 4, 0.0, 1), (5, 5, 0.3, 2), (1, 1, 0.0, 0)]:
        params = CamoParams(rows=rows, cols=cols, rho_comm=rho, rho_meas=rho, seed=4,
                            threshold_auto=True, consensus_steps=12)  # fmt: skip
        grid = np.random.default_rng(order).uniform(0, 255, (rows, cols))
        bus = Bus(params, grid, seed=order)
        bus.run()
        assert all(p.phase == DONE and p.deadlines == 0 for p in bus.robots.values())
        reference = simulate(params, grid)
        robots = [bus.robots[i].core for i in range(params.count)]
        assert np.array_equal(np.reshape([r.vote for r in robots], (rows, cols)), reference.votes)
        assert np.array_equal(np.reshape([r.state for r in robots], (rows, cols)), reference.final)


@pytest.mark.slow(PROCESS)
def test_sim_takes_threshold_auto_and_its_params_file_repeats_it(tmp_path):
    out = run_camo("sim", "--threshold", "auto", "--rho-comm", "0.2", "--out", str(tmp_path / "a"))
    assert out.returncode == 0, out.stderr
    assert "threshold: auto" in (tmp_path / "a" / "params.yaml").read_text()
    again = run_camo("sim", "--params-file", str(tmp_path / "a" / "params.yaml"),
                     "--out", str(tmp_path / "b"))  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "a" / "summary.json").read_text().split('"elapsed_s"')[0] == (
        (tmp_path / "b" / "summary.json").read_text().split('"elapsed_s"')[0]
    )
    bad = run_camo("sim", "--threshold", "high", "--out", str(tmp_path / "c"))
    assert bad.returncode == 2
    assert bad.stderr.strip() == "camo: error: argument --threshold: a number or auto (got 'high')"
