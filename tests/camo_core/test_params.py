"""CamoParams: profile defaults, and one-line errors for values out of range."""

import pytest

from camo_core.algorithm.params import CamoParams, ParameterError


def test_profile_defaults_fill_steps_and_weights():
    paper = CamoParams()
    assert (paper.consensus_steps, paper.formation_steps, paper.w2_stripes, paper.w2_mottled) == (
        35,
        10,
        -0.75,
        -0.75,
    )
    droplet = CamoParams(profile="droplet")
    assert (
        droplet.consensus_steps,
        droplet.formation_steps,
        droplet.w2_stripes,
        droplet.w2_mottled,
    ) == (10, 20, -0.75, -0.60)
    assert CamoParams(profile="droplet", consensus_steps=3).consensus_steps == 3


@pytest.mark.parametrize(
    "changes, named, allowed",
    [
        ({"rows": 0}, "rows", "1..8192"),
        ({"cols": 10**6}, "cols", "1..8192"),
        ({"rho_meas": -0.1}, "rho_meas", "[0, 1]"),
        ({"rho_comm": 1.5}, "rho_comm", "[0, 1]"),
        ({"rho_comm": float("nan")}, "rho_comm", "[0, 1]"),
        ({"threshold": -1}, "threshold", "[0, 1020]"),
        ({"seed": -3}, "seed", "0.."),
        ({"consensus_steps": 2.5}, "consensus_steps", "0..100000"),
        ({"profile": "firmware"}, "profile", "paper, droplet"),
    ],
)
def test_bad_values_are_errors_naming_parameter_and_range(changes, named, allowed):
    with pytest.raises(ParameterError) as info:
        CamoParams(**changes)
    assert named in str(info.value) and allowed in str(info.value)
