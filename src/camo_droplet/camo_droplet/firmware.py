"""Reading the camouflage firmware's own printouts (SPEC section 5) as a robot's status: no ROS
here.

Our reading of the three lines SPEC names (the firmware's source is not part of
SPEC, so this is documented in docs/hardware.md):
- `Px: %0.4f Py: %0.4f`: the robot's current p_horizontal and p_vertical;
  p_mottled is what is left, 1 - Px - Py (clipped at 0).
- `Pre-pattern: [a b c] Cur-pattern: [a b c]`: p before and after one
  consensus step; each such line is one step, and Cur-pattern is the new p.
- `%hu[%04X] Color: %hu`: a colour value and the id of the robot it belongs
  to; the robot's own id gives its sensed value, other ids are neighbours'.
Every other line is ignored (and counted).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from camo_core.rules import select_pattern

PX_PY = re.compile(r"^Px:\s*(-?[\d.]+)\s+Py:\s*(-?[\d.]+)$")
PATTERNS = re.compile(r"^Pre-pattern:\s*\[([^\]]*)\]\s*Cur-pattern:\s*\[([^\]]*)\]$")
COLOR = re.compile(r"^(\d+)\[([0-9A-Fa-f]{4})\]\s*Color:\s*(\d+)$")


@dataclass
class FirmwareState:
    """What the firmware has told about its robot so far."""

    droplet_id: int
    sensed: float = math.nan
    p: tuple[float, float, float] | None = None
    steps: int = 0  # consensus steps seen (Pre/Cur-pattern lines)
    neighbour_colors: dict[int, int] = field(default_factory=dict)
    ignored: int = 0

    @property
    def pattern(self) -> int | None:
        """The pattern the current p selects (strictly largest, else mottled)."""
        return None if self.p is None else select_pattern(self.p)

    def feed(self, line: str) -> bool:
        """Take one line; True when it changed what the robot reports."""
        line = line.strip()
        if match := PX_PY.match(line):
            px, py = float(match.group(1)), float(match.group(2))
            self.p = (px, py, max(0.0, 1.0 - px - py))
            return True
        if match := PATTERNS.match(line):
            try:
                current = tuple(float(x) for x in match.group(2).replace(",", " ").split())
            except ValueError:
                current = ()
            if len(current) != 3:
                self.ignored += 1
                return False
            self.p = current
            self.steps += 1
            return True
        if match := COLOR.match(line):
            owner, value = int(match.group(2), 16), int(match.group(3))
            if owner == self.droplet_id:
                self.sensed = float(value)
                return True
            self.neighbour_colors[owner] = value
            return False
        self.ignored += 1
        return False
