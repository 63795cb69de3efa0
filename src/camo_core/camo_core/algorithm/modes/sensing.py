"""What a robot senses of the background: its grey (the paper's), or its colour too
(--colours: the mean sRGB of the block it covers, which its histogram and palette need).

One object, chosen once from a run's parameters (`modes.modes_of`). A robot always keeps the
colour of its reading where it has one (a grey reading's colour is its grey), for the colour
distance of its result; colour sensing is what needs it.
"""

from __future__ import annotations

import numpy as np


class GreySensing:
    name = "grey"
    colour = False  # the rules need the colours sensed (not only the greys)

    def shown(self, sensed: np.ndarray, sensed_rgb: np.ndarray | None) -> np.ndarray:
        """What a figure or a GIF shows as sensed: the greys."""
        return sensed


class ColourSensing(GreySensing):
    name = "colour"
    colour = True

    def shown(self, sensed: np.ndarray, sensed_rgb: np.ndarray | None) -> np.ndarray:
        """The colours (rows x cols x 3), where they are known."""
        return sensed if sensed_rgb is None else sensed_rgb


Sensing = GreySensing | ColourSensing
