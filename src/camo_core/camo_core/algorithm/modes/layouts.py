"""Where robots stand and who their neighbours are: the paper's grid, or positions (--layout
hex, jitter:A or a file; docs/algorithm.md §2.7).

Each is one object chosen once from a run's parameters (`modes.modes_of`). A layout gives each
robot its neighbour slots, senses an image for its robots, draws no grid lines where it has
none, and forms patterns with kernels of its own where its robots have no grid slots.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from camo_core.algorithm import layout_rules, orientation, rules
from camo_core.algorithm.grid import CONSENSUS_SLOTS, NUM_SLOTS, neighbor_ids
from camo_core.algorithm.layout import (
    MAX_SLOTS,
    Place,
    colours_at,
    layout_for,
    places_for,
    sense_at,
)
from camo_core.algorithm.orientation import ORIENTED
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import check_covers, sense_colours, sense_image

# A robot's formation step: (state, pattern code, states by slot, knight cells) -> next state.
Former = Callable[[int, int, Sequence[int | None], Sequence[int | None]], int]


class Grid:
    """The paper's grid: robot (i, j) has the twelve slots of docs/algorithm.md §1."""

    name = ""  # as --layout names it: the grid is no layout
    grid = True
    max_degree = len(CONSENSUS_SLOTS)  # consensus neighbours a robot can count
    positions: np.ndarray | None = None  # robots x 2 (x, y down, spacings); the grid has none

    def __init__(self, params: CamoParams) -> None:
        self.rows, self.cols = params.rows, params.cols

    def slots(self, robot: int) -> tuple[list[int | None], int, Place | None]:
        """A robot's neighbours by slot (None where there is none), how many of the first
        slots are its near (consensus) ones, and its place on a layout (None on the grid)."""
        return neighbor_ids(*divmod(robot, self.cols), self.rows, self.cols), 8, None

    def listen(self, colour_slots: int, near: int = 8, slots: int = NUM_SLOTS) -> dict[str, int]:
        """How many slots each kind of message is heard from (docs/algorithm.md §1: the vote's
        colours from slots 0-3, or 0-7 for a tensor; consensus from 0-7; states from all)."""
        return {
            "hello": NUM_SLOTS,
            "color": colour_slots,
            "energy": 8,
            "vote": 8,
            "state": NUM_SLOTS,
            "relay": 8,
        }

    def sense(self, image: np.ndarray, profile: str) -> tuple[np.ndarray, np.ndarray]:
        """Every robot's grey and colour (rows x cols, rows x cols x 3), before noise."""
        return (
            sense_image(image, self.rows, self.cols, profile),
            sense_colours(image, self.rows, self.cols),
        )

    def check_frame(self, width: int, height: int, what: str = "frame") -> None:
        """ImageError if robots could not sense a frame of this size (a pixel each at least)."""
        check_covers(width, height, self.rows, self.cols, what)

    def former(self, place: Place | None, params: CamoParams) -> Former:
        """A robot's formation rule, (state, pattern code, states received by slot, relayed
        knight cells) -> its next state: Young's rule with its pattern's kernel, the paper's
        regions or, for stripes at an angle, the oriented kernel over its slots and relayed
        knight cells."""
        weights = orientation.inhibitor_weights(params)

        def form(state: int, code: int, received, knights) -> int:
            if code < ORIENTED:
                return rules.formation_step(state, code, received, params)
            return orientation.formation_step(state, code, received, knights, params, weights)

        return form

    def summary(self) -> dict:
        """What summary.json says of where the robots stood (the grid: nothing)."""
        return {}


class Positions(Grid):
    """--layout: robots at positions, each with the neighbours within reach as its slots (the
    near ones first) and kernels of its own from its neighbours' offsets (its descriptor is
    descriptors.FittedTensor)."""

    grid = False
    max_degree = MAX_SLOTS

    def __init__(self, params: CamoParams) -> None:
        super().__init__(params)
        self.params = params
        self.name = params.layout
        self.layout = layout_for(params)
        self.positions = self.layout.positions

    def slots(self, robot: int) -> tuple[list[int | None], int, Place | None]:
        place = places_for(self.params)[robot]
        return list(place.neighbors), place.near, place

    def listen(self, colour_slots: int, near: int = 8, slots: int = NUM_SLOTS) -> dict[str, int]:
        return {"hello": slots, "color": near, "energy": near, "vote": near, "state": slots}

    def sense(self, image: np.ndarray, profile: str) -> tuple[np.ndarray, np.ndarray]:
        return self.sense_greys(image, profile), self.sense_colours(image)

    def check_frame(self, width: int, height: int, what: str = "frame") -> None:
        """Any frame with pixels: each robot takes the mean round its own position."""

    def sense_greys(self, image: np.ndarray, profile: str) -> np.ndarray:
        """Each robot's grey (rows x cols): the image's mean round its position."""
        return sense_at(image, self.layout, profile).reshape(self.params.rows, self.params.cols)

    def sense_colours(self, image: np.ndarray) -> np.ndarray:
        """Each robot's colour (rows x cols x 3), likewise."""
        rows, cols = self.params.rows, self.params.cols
        return colours_at(image, self.layout).reshape(rows, cols, 3)

    def former(self, place: Place | None, params: CamoParams) -> Former:
        """Young's rule with a kernel of the robot's own, from its neighbours' offsets (built
        once it knows its pattern)."""
        assert place is not None
        kernels: dict[int, tuple[list[int], float]] = {}

        def form(state: int, code: int, received, knights) -> int:
            kernel = kernels.get(code)
            if kernel is None:
                kernel = kernels[code] = layout_rules.kernel(code, place.offsets, params)
            roles, w2 = kernel
            return layout_rules.formation_step(state, roles, w2, received, params)

        return form

    def summary(self) -> dict:
        positions = self.layout.positions.tolist()
        return {"layout": self.name, "positions": [list(xy) for xy in positions]}


Layout = Grid | Positions
