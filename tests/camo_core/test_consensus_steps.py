"""--consensus-steps auto: the paper's steps scaled with the square of the grid's diameter."""

import json

import numpy as np
import pytest
import yaml
from support import PROCESS, run_camo

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import ParameterError, auto_consensus_steps
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.cli.options import Parser, add_run_options, params_from


def test_auto_keeps_the_profiles_steps_at_8x8_and_grows_with_the_diameter_squared():
    assert auto_consensus_steps("paper", 8, 8) == 35
    assert auto_consensus_steps("droplet", 8, 8) == 10
    assert auto_consensus_steps("paper", 2, 3) == 35  # never fewer than the profile's
    assert auto_consensus_steps("paper", 16, 16) == 161  # ceil(35 * 15^2 / 7^2)
    assert auto_consensus_steps("paper", 4, 32) == auto_consensus_steps("paper", 32, 32) == 687
    with pytest.raises(ParameterError, match="above 100000"):
        auto_consensus_steps("paper", 1000, 1000)


def spread_after(side: int, steps: str) -> float:
    parser = Parser()
    add_run_options(parser)
    params = params_from(parser.parse_args(["--rows", str(side), "--cols", str(side)]
                                           + ["--consensus-steps", steps]))  # fmt: skip
    result = simulate(params, sense_image(background("forest"), side, side, params.profile))
    least, greatest = result.consensus_range[-1, :, 0], result.consensus_range[-1, :, 1]
    return float(np.max(greatest - least))


def test_auto_steps_bring_a_large_swarm_close_to_agreement_where_35_do_not():
    assert spread_after(32, "35") > 0.3
    assert spread_after(32, "auto") < 0.05


@pytest.mark.slow(PROCESS)
def test_sim_with_auto_runs_the_scaled_steps_and_its_params_file_repeats_it(tmp_path):
    out = run_camo("sim", "--rows", "16", "--cols", "16", "--consensus-steps", "auto",
                   "--out", str(tmp_path / "a"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert len(summary["consensus_trace"]) == 161 + 1  # p before the first step, then each
    written = yaml.safe_load((tmp_path / "a" / "params.yaml").read_text())
    assert written["/**"]["ros__parameters"]["consensus_steps"] == "auto"
    again = run_camo("sim", "--params-file", str(tmp_path / "a" / "params.yaml"),
                     "--out", str(tmp_path / "b"))  # fmt: skip
    assert again.returncode == 0, again.stderr
    repeated = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert {k: v for k, v in repeated.items() if k != "elapsed_s"} == {
        k: v for k, v in summary.items() if k != "elapsed_s"
    }


@pytest.mark.slow(PROCESS)
def test_a_parameters_file_with_steps_that_are_not_whole_is_one_line(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"consensus_steps": 2.5}}}))
    out = run_camo("sim", "--params-file", str(path), "--out", str(tmp_path / "o"))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "consensus_steps must be an integer (got 2.5)" in out.stderr
