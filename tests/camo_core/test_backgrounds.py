"""The built-in backgrounds select the patterns they are drawn for."""

import numpy as np
import pytest

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.inputs.images import ImageError


@pytest.mark.parametrize(
    "name, expected", [("desert", "horizontal"), ("forest", "vertical"), ("leopard", "mottled")]
)
@pytest.mark.parametrize("profile", ["paper", "droplet"])
def test_builtin_background_selects_its_pattern_at_8x8(name, expected, profile):
    image = background(name)
    assert image.shape == (128, 128) and image.dtype == np.uint8
    result = simulate(CamoParams(profile=profile), sense_image(image, 8, 8, profile))
    assert result.majority_pattern == expected
    assert result.selection_counts[expected] == 64


def test_backgrounds_are_deterministic_and_distinct():
    assert np.array_equal(background("forest"), background("forest"))
    assert not np.array_equal(background("forest"), background("desert"))
    with pytest.raises(ImageError, match="unknown built-in"):
        background("jungle")
