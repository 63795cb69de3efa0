"""The parameters of one camouflage run, as one validated, typed object."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

from camo_core.inputs.positions import MAX_COORDINATE, file_positions
from camo_core.schema import ParameterError, check_fields, declared, param, to_dict

PROFILES = ("paper", "droplet")
# --scope: one pattern for the whole swarm (the paper's), or each region of the scene its own.
SCOPES = ("global", "local")
# --orientation: the paper's two stripe directions (axes), or stripes at any angle (any).
ORIENTATIONS = ("axes", "any")

# docs/algorithm.md §2: steps per phase and Young's inhibitor weight, per profile.
PROFILE_DEFAULTS: dict[str, dict[str, Any]] = {
    "paper": {
        "consensus_steps": 35,
        "formation_steps": 10,
        "w2_stripes": -0.75,
        "w2_mottled": -0.75,
    },
    "droplet": {
        "consensus_steps": 10,
        "formation_steps": 20,
        "w2_stripes": -0.75,
        "w2_mottled": -0.60,
    },
}

MAX_LEVELS = 8  # --levels: K - 1 layers fit a state's uint8 and leave 255 (not received) free
MAX_COLOURS = 8  # --colours: a palette of at most 8, as --levels
MAX_SIDE = 8192  # robots per row or column; ids stay far inside uint32
MAX_STEPS = 100_000
AUTO = "auto"
PAPER_DIAMETER = 7  # hops across the paper's 8x8 swarm, for which its step counts were chosen


@dataclass(frozen=True)
class CamoParams:
    """One run's parameters, each declared once (camo_core.schema): the command-line options,
    the robot nodes' ROS parameters, params.yaml, the run's setup and summary.json's parameter
    fields all come from these fields. Those declared with a default of None take the profile's
    (once made, every field holds its value)."""

    rows: int = param(8, "robot rows", low=1, high=MAX_SIDE, unit="robots", summary=True)
    cols: int = param(8, "robot columns", low=1, high=MAX_SIDE, unit="robots", summary=True)
    profile: str = param("paper", "paper or droplet rules", choices=PROFILES, summary=True)
    seed: int = param(0, "seed of every random draw", low=0, high=2**64 - 1, summary=True)
    rho_meas: float = param(
        0.0, "measurement error probability", low=0.0, high=1.0, summary=True, noise=True
    )
    rho_comm: float = param(
        0.0, "message loss probability", low=0.0, high=1.0, summary=True, noise=True
    )
    threshold: float = param(
        50.0,
        "descriptor threshold T; auto: each robot's from the swarm's mean texture energy",
        low=0.0,
        high=1020.0,
        keyword=AUTO,
        metavar="T|auto",
    )
    # --threshold auto: each robot's threshold from the swarm's texture energy
    # (docs/algorithm.md, "Threshold auto"); `threshold` is then not used.
    threshold_auto: bool = param(False, "the threshold is auto (--threshold auto)", cli=False)
    # --orientation any: a structure tensor instead of the vote, stripes at multiples of 15
    # degrees (docs/algorithm.md, "Orientation any").
    orientation: str = param(
        "axes",
        "axes: the paper's horizontal and vertical stripes; any: stripes at any multiple of 15 "
        "degrees",
        choices=ORIENTATIONS,
    )
    # --levels K: K greys of the swarm's choosing instead of black and white (0: the paper's);
    # docs/algorithm.md, "Levels".
    levels: int = param(
        0,
        "show K greys (2 to 8) the swarm chooses from its averaged histogram, instead of black "
        "and white",
        low=2,
        high=MAX_LEVELS,
        off=0,
        metavar="K",
        none_means="0, the paper's two",
    )
    # --colours K: K colours of the swarm's choosing, from its averaged colour histogram, each
    # robot showing one of the two that bracket its own colour (0: the paper's black and
    # white); docs/algorithm.md, "Colours".
    colours: int = param(
        0,
        "show the background's colours: a K-colour palette (2 to 8) the swarm chooses from its "
        "averaged colour histogram, the pattern choosing between the two that bracket each "
        "robot's colour",
        low=2,
        high=MAX_COLOURS,
        off=0,
        metavar="K",
        none_means="0, the paper's black and white",
    )
    # --layout: "" (the grid), "hex", "jitter:A", or "file" with the robots' x, y in
    # `positions` (spacings, y down, one pair per robot id); docs/algorithm.md, "Layout".
    layout: str = param(
        "",
        "robots at hexagonal positions, at grid positions jittered by up to A spacings, or at a "
        "CSV file's x,y positions (spacings; a file's robots make one row); needs "
        "--orientation any",
        metavar="hex|jitter:A|FILE",
        none_means="the grid",
    )
    positions: tuple[tuple[float, float], ...] = param(
        (), "a file layout's x, y per robot", cli=False, ros=False
    )
    # --scope local: each robot chooses from the evidence of its own region of the scene
    # (docs/algorithm.md, "Scope local"); scope_scale is the smallest region, in robots.
    scope: str = param(
        "global",
        "global: the paper's, one pattern the whole swarm agrees on; local: each region of the "
        "scene its own pattern, chosen from its robots' evidence",
        choices=SCOPES,
        summary=True,
    )
    scope_scale: float = param(
        2.0,
        "--scope local's length scale L: regions narrower than about 2L robots join their "
        "surroundings (larger: fewer, larger regions)",
        low=0.5,
        high=50.0,
        unit="robots",
        metavar="L",
    )
    consensus_steps: int = param(
        None,
        "consensus steps; auto: the profile's, scaled with the square of the grid's diameter "
        "over 8x8's",
        low=0,
        high=MAX_STEPS,
        keyword=AUTO,
        metavar="N|auto",
        unit="steps",
        none_means="35 paper, 10 droplet",
    )
    formation_steps: int = param(
        None,
        "formation steps",
        low=0,
        high=MAX_STEPS,
        unit="steps",
        none_means="10 paper, 20 droplet",
    )
    w2_stripes: float = param(
        None,
        "inhibitor weight W2 of the horizontal and vertical stripes kernels",
        low=-100.0,
        high=100.0,
        none_means="the profile's",
    )
    w2_mottled: float = param(
        None,
        "inhibitor weight W2 of the mottled kernels",
        low=-100.0,
        high=100.0,
        none_means="the profile's",
    )
    w1: float = field(default=1.0, init=False)

    def __post_init__(self) -> None:
        if self.profile in PROFILES:
            for name, value in PROFILE_DEFAULTS[self.profile].items():
                if getattr(self, name) is None:
                    object.__setattr__(self, name, value)
        check_fields(self)
        self._check_layout()
        if self.colours and self.levels:
            raise ParameterError(
                "--colours and --levels are two palettes: give one (--colours K shows colours, "
                "--levels K greys)"
            )

    @classmethod
    def from_options(cls, **options: Any) -> CamoParams:
        """The parameters from options as a command line or a node's ROS parameters give them:
        `auto` for --threshold and --consensus-steps, a layout FILE for --layout (its positions
        read, its robots one row), None for what is left to the defaults."""
        options = {k: v for k, v in options.items() if v is not None}
        if options.get("threshold") == AUTO:
            options["threshold"], options["threshold_auto"] = THRESHOLD_DEFAULT, True
        layout = options.get("layout") or ""
        if layout and layout != "hex" and not layout.startswith("jitter:") and layout != "file":
            positions = file_positions(layout)
            options.update(rows=1, cols=len(positions), layout="file", positions=positions)
        if options.get("consensus_steps") == AUTO:
            options["consensus_steps"] = auto_steps_for(options)
        return cls(**options)

    def _check_layout(self) -> None:
        layout = self.layout
        positions = tuple((float(x), float(y)) for x, y in self.positions)
        object.__setattr__(self, "positions", positions)  # hashable, from lists too
        if not layout:
            if positions:
                raise ParameterError("positions are a file layout's: give layout file too")
            return
        if layout.startswith("jitter:"):
            try:
                amount = float(layout.split(":", 1)[1])
            except ValueError:
                amount = math.nan
            if not 0.0 <= amount < 0.5:
                raise ParameterError(f"jitter:A needs 0 <= A < 0.5 spacings (got {layout!r})")
        elif layout == "file":
            if len(positions) != self.rows * self.cols or self.rows != 1:
                raise ParameterError(
                    f"a file layout has rows 1 and one position per robot (got {len(positions)} "
                    f"positions for {self.rows}x{self.cols})"
                )
            if not all(abs(v) <= MAX_COORDINATE for xy in positions for v in xy):  # NaN too
                raise ParameterError(
                    f"a file layout's positions must be numbers within +-{MAX_COORDINATE:g}"
                )
        elif layout != "hex":
            raise ParameterError(f"layout must be hex, jitter:A or file (got {layout!r})")
        if self.orientation != "any":
            raise ParameterError("--layout needs --orientation any: a layout has no grid axes")

    @property
    def orientation_any(self) -> bool:
        return self.orientation == "any"

    @property
    def count(self) -> int:
        return self.rows * self.cols

    def with_(self, **changes: Any) -> CamoParams:
        return replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        return to_dict(self)


THRESHOLD_DEFAULT = declared(CamoParams)["threshold"].default


def auto_steps_for(options: dict[str, Any]) -> int:
    """--consensus-steps auto for options: the grid's diameter, or a file layout's extent."""
    rows, cols = options.get("rows", 8), options.get("cols", 8)
    if options.get("positions"):  # a file's robots: their extent, not one long row
        xy = [v for xy in options["positions"] for v in xy]
        extent = max(max(xy[0::2]) - min(xy[0::2]), max(xy[1::2]) - min(xy[1::2]))
        rows = cols = math.ceil(float(extent)) + 1
    return auto_consensus_steps(options.get("profile", "paper"), rows, cols)


def auto_consensus_steps(profile: str, rows: int, cols: int) -> int:
    """`--consensus-steps auto`: the profile's steps, scaled with the square of the grid's
    diameter D = max(rows, cols) - 1 (hops between its farthest robots) over the paper's 8x8
    (D = 7), never fewer. Consensus by averaging with neighbours spreads an opinion about one
    hop a step, and evens it out in about D^2 steps (docs/algorithm.md, "Consensus steps")."""
    if profile not in PROFILES:
        raise ParameterError(f"profile must be one of {', '.join(PROFILES)} (got {profile!r})")
    base = PROFILE_DEFAULTS[profile]["consensus_steps"]
    diameter = max(rows, cols) - 1
    steps = max(base, math.ceil(base * diameter**2 / PAPER_DIAMETER**2))
    if steps > MAX_STEPS:
        raise ParameterError(
            f"--consensus-steps auto would be {steps} steps for a {rows}x{cols} grid, above "
            f"{MAX_STEPS}: give the number of steps"
        )
    return steps
