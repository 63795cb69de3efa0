"""Reading the camouflage firmware's own printouts (docs/algorithm.md §5) as a robot's status:
no ROS here.

Our reading of the three lines docs/algorithm.md §5 names (what they mean is ours to read,
and docs/hardware.md says how):
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

from camo_core.algorithm.rules import select_pattern
from camo_core.swarm.validation import REPORT_TOLERANCE, probability_vector

PX_PY = re.compile(r"^Px:\s*(-?[\d.]+)\s+Py:\s*(-?[\d.]+)$")
PATTERNS = re.compile(r"^Pre-pattern:\s*\[([^\]]*)\]\s*Cur-pattern:\s*\[([^\]]*)\]$")
# ASCII digits only (\d takes any script's), and few of them: a 5000-digit value is no colour
# (and beyond int()'s 4300-digit limit).
COLOR = re.compile(r"^([0-9]+)\[([0-9A-Fa-f]{4})\]\s*Color:\s*([0-9]{1,9})$", re.ASCII)


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
        """Take one line; True when it changed what the robot reports. A line that does not
        parse, or says what no robot can (p that is not a probability vector, a colour above
        255), is ignored and counted."""
        line = line.strip()
        p = None
        if match := PX_PY.match(line):
            xy = numbers(f"{match.group(1)} {match.group(2)}")
            p = (xy[0], xy[1], max(0.0, 1.0 - xy[0] - xy[1])) if xy and len(xy) == 2 else None
        elif match := PATTERNS.match(line):
            p = numbers(match.group(2))
        elif match := COLOR.match(line):
            owner, value = int(match.group(2), 16), int(match.group(3))
            if value > 255:
                self.ignored += 1
                return False
            if owner == self.droplet_id:
                self.sensed = float(value)
                return True
            self.neighbour_colors[owner] = value
            return False
        if p is None or not probability_vector(p, REPORT_TOLERANCE):
            self.ignored += 1
            return False
        self.p = p
        if match.re is PATTERNS:
            self.steps += 1  # each Pre/Cur-pattern line is one consensus step
        return True


def numbers(text: str) -> tuple[float, ...] | None:
    """Numbers separated by spaces or commas; None if one is not a number."""
    try:
        return tuple(float(x) for x in text.replace(",", " ").split())
    except ValueError:
        return None
