"""The variations of the algorithm, each one object chosen once from a run's parameters.

A run's `Modes` holds one object per variation: what a robot senses (grey or colour), its
threshold (fixed or auto) and descriptor (the paper's axes, a structure tensor for stripes at
any angle, or a fitted tensor on a layout), what consensus averages beside p (nothing, a grey or
a colour histogram), its palette and display (two tones, --levels, --colours), where its
robots stand (the grid, or a --layout's positions) and how far a robot's evidence reaches (the
whole swarm, or its region of the scene: --scope). `modes_of(params)` chooses them; every
driver (the simulator, the per-robot driver and so the step protocol and the robot nodes, the
Droplet bridge, results, figures and animation) asks the chosen objects instead of the flags
that chose them. Adding a mode: its declaration (a CamoParams field), its object (a class
beside its siblings here), its line in `modes_of`, its tests and docs (docs/extending.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

from camo_core.algorithm.modes.descriptors import (
    AnyOrientation,
    AutoThreshold,
    Axes,
    Descriptor,
    FittedTensor,
    FixedThreshold,
    Threshold,
)
from camo_core.algorithm.modes.layouts import Grid, Layout, Positions
from camo_core.algorithm.modes.palettes import (
    ColourHistogram,
    ColourPalette,
    GreyHistogram,
    Histogram,
    LevelPalette,
    NoHistogram,
    Palette,
    TwoTones,
)
from camo_core.algorithm.modes.scopes import GlobalScope, LocalScope, Scope
from camo_core.algorithm.modes.sensing import ColourSensing, GreySensing, Sensing
from camo_core.algorithm.params import CamoParams


@dataclass(frozen=True)
class Modes:
    sensing: Sensing
    threshold: Threshold
    descriptor: Descriptor
    histogram: Histogram
    palette: Palette
    layout: Layout
    scope: Scope = field(default_factory=GlobalScope)

    @property
    def relays(self) -> bool:
        """Robots pass on the states they received (--orientation any on the grid: the knight
        cells of the oriented kernels are two hops away)."""
        return self.descriptor.oriented and self.layout.grid

    @property
    def width(self) -> int:
        """Entries of the vector consensus averages: p, then the histogram."""
        return self.descriptor.width + self.histogram.size

    def beyond_paper(self) -> list[str]:
        """The variations that are not the paper's, as the options that chose them (what a
        Droplet's own firmware, which runs the paper's rules, lacks)."""
        chosen = (
            self.threshold.chosen_by,
            self.descriptor.chosen_by,
            self.palette.chosen_by,
            self.scope.chosen_by,
        )
        return [said for said in chosen if said]

    def with_(self, **changes: Any) -> Modes:
        return replace(self, **changes)


@lru_cache(maxsize=64)
def modes_of(params: CamoParams) -> Modes:
    """The objects a run's parameters choose."""
    threshold: Threshold = (
        AutoThreshold() if params.threshold_auto else FixedThreshold(params.threshold)
    )
    layout: Layout = Positions(params) if params.layout else Grid(params)
    descriptor: Descriptor
    if params.layout:
        descriptor = FittedTensor(threshold)
    elif params.orientation == "any":
        descriptor = AnyOrientation(threshold)
    else:
        descriptor = Axes(threshold)
    sensing: Sensing = GreySensing()
    histogram: Histogram = NoHistogram()
    palette: Palette = TwoTones()
    if params.colours:
        sensing, histogram, palette = (
            ColourSensing(),
            ColourHistogram(),
            ColourPalette(params.colours),
        )
    elif params.levels:
        histogram, palette = GreyHistogram(), LevelPalette(params.levels)
    scope: Scope = GlobalScope()
    if params.scope == "local":
        scope = LocalScope(params.scope_scale, descriptor.oriented)
    return Modes(sensing, threshold, descriptor, histogram, palette, layout, scope)


__all__ = [
    "AnyOrientation",
    "AutoThreshold",
    "Axes",
    "ColourHistogram",
    "ColourPalette",
    "ColourSensing",
    "FittedTensor",
    "FixedThreshold",
    "GlobalScope",
    "GreyHistogram",
    "GreySensing",
    "Grid",
    "LevelPalette",
    "LocalScope",
    "Modes",
    "NoHistogram",
    "Positions",
    "TwoTones",
    "modes_of",
]
