"""docs/extending.md's worked example: a mode of one's own, a threshold from each robot's own
texture energy (no averaging), run by both drivers of the reference simulator."""

import numpy as np

from camo_core.algorithm import rules
from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.modes import Axes, modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate


class OwnEnergyThreshold:
    """Each robot's threshold T = max(5, share x its own texture energy): --threshold auto
    without averaging the energy over the swarm first."""

    averages_energy = False  # the energy is the robot's own: no averaging steps
    chosen_by = "own-energy threshold"  # not the paper's (a Droplet's firmware lacks it)

    def __init__(self, share: float = 0.5) -> None:
        self.share = share

    def of(self, energy: float) -> float:  # one robot
        return max(rules.MIN_THRESHOLD, self.share * energy)

    def of_grid(self, energy: np.ndarray) -> np.ndarray:  # every robot: the same arithmetic
        return np.maximum(rules.MIN_THRESHOLD, self.share * energy)

    def regulariser(self, energy: float) -> float:  # --orientation any's, as auto's
        scale = self.of(energy) / rules.MIN_THRESHOLD
        return 16.0 * scale * scale

    def regulariser_grid(self, threshold: np.ndarray) -> np.ndarray:
        scale = threshold / rules.MIN_THRESHOLD
        return 16.0 * scale * scale


params = CamoParams(rows=16, cols=16, rho_comm=0.1, seed=3)
threshold = OwnEnergyThreshold(0.5)
modes = modes_of(params).with_(threshold=threshold, descriptor=Axes(threshold))
sensed = sense_image(background("forest"), params.rows, params.cols, params.profile)

grid = simulate(params, sensed, modes=modes)  # the whole grid at once
robots = run_per_robot(params, sensed, modes=modes)  # robot by robot, as the nodes run it
for name in ("votes", "p", "selected", "final"):
    assert np.array_equal(getattr(grid, name), getattr(robots, name)), name
paper = simulate(params, sensed)
print(f"own-energy threshold: {grid.majority_label} {grid.selection_counts}")
print(f"the paper's T = 50:   {paper.majority_label} {paper.selection_counts}")
print(f"votes for stripes: {np.count_nonzero(grid.votes != 2)} of {params.count} robots "
      f"(the paper's threshold: {np.count_nonzero(paper.votes != 2)})")
