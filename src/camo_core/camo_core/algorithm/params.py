"""The parameters of one camouflage run, as one validated, typed object."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from camo_core.exceptions import CamoError

PROFILES = ("paper", "droplet")
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
MAX_COORDINATE = 1e6  # spacings: a file layout's positions stay within this
MAX_SIDE = 8192  # robots per row or column; ids stay far inside uint32
MAX_STEPS = 100_000
AUTO = "auto"
PAPER_DIAMETER = 7  # hops across the paper's 8x8 swarm, for which its step counts were chosen


class ParameterError(CamoError):
    """A parameter outside its allowed range; the message names it and the range."""


@dataclass(frozen=True)
class CamoParams:
    """One run's parameters. Fields left as None take the profile's defaults."""

    profile: str = "paper"
    rows: int = 8
    cols: int = 8
    threshold: float = 50.0
    consensus_steps: int | None = None
    formation_steps: int | None = None
    w2_stripes: float | None = None
    w2_mottled: float | None = None
    seed: int = 0
    rho_meas: float = 0.0
    rho_comm: float = 0.0
    # --threshold auto: each robot's threshold from the swarm's texture energy
    # (docs/algorithm.md, "Threshold auto"); `threshold` is then not used.
    threshold_auto: bool = False
    # --orientation any: a structure tensor instead of the vote, stripes at multiples of 15
    # degrees (docs/algorithm.md, "Orientation any").
    orientation: str = "axes"
    # --levels K: K greys of the swarm's choosing instead of black and white (0: the paper's);
    # docs/algorithm.md, "Levels".
    levels: int = 0
    # --layout: "" (the grid), "hex", "jitter:A", or "file" with the robots' x, y in
    # `positions` (spacings, y down, one pair per robot id); docs/algorithm.md, "Layout".
    layout: str = ""
    positions: tuple[tuple[float, float], ...] = ()
    w1: float = field(default=1.0, init=False)

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ParameterError(
                f"profile must be one of {', '.join(PROFILES)} (got {self.profile!r})"
            )
        for name, value in PROFILE_DEFAULTS[self.profile].items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        if self.orientation not in ORIENTATIONS:
            raise ParameterError(
                f"orientation must be one of {', '.join(ORIENTATIONS)} (got {self.orientation!r})"
            )
        if self.levels != 0:
            _int_in("levels", self.levels, 2, MAX_LEVELS)
        _int_in("rows", self.rows, 1, MAX_SIDE)
        _int_in("cols", self.cols, 1, MAX_SIDE)
        _int_in("consensus_steps", self.consensus_steps, 0, MAX_STEPS)
        _int_in("formation_steps", self.formation_steps, 0, MAX_STEPS)
        _int_in("seed", self.seed, 0, 2**64 - 1)
        _float_in("threshold", self.threshold, 0.0, 1020.0)
        _float_in("rho_meas", self.rho_meas, 0.0, 1.0)
        _float_in("rho_comm", self.rho_comm, 0.0, 1.0)
        _float_in("w2_stripes", self.w2_stripes, -100.0, 100.0)
        _float_in("w2_mottled", self.w2_mottled, -100.0, 100.0)
        if not isinstance(self.threshold_auto, bool):
            raise ParameterError(
                f"threshold_auto must be true or false (got {self.threshold_auto!r})"
            )
        for name in ("threshold", "rho_meas", "rho_comm", "w2_stripes", "w2_mottled"):
            object.__setattr__(self, name, float(getattr(self, name)))
        self._check_layout()

    def _check_layout(self) -> None:
        layout = self.layout
        if not isinstance(layout, str):
            raise ParameterError(f"layout must be text (got {layout!r})")
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
        data = asdict(self)
        data.pop("w1")
        return data


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


def _int_in(name: str, value: Any, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ParameterError(f"{name} must be an integer in {low}..{high} (got {value!r})")


def _float_in(name: str, value: Any, low: float, high: float) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or not low <= value <= high:
        raise ParameterError(f"{name} must be a number in [{low:g}, {high:g}] (got {value!r})")
