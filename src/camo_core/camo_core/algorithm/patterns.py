"""The patterns a swarm can draw, as one table (docs/algorithm.md §2.4).

Every list, range and colour of patterns is derived from `PATTERNS`: the pattern codes and
names, the width of the vote p (one entry per pattern), the formation kernels' regions, which
inhibitor weight W2 each takes, the figures' colours, the columns of a sweep's table. Adding a
pattern is a row here, its kernels' regions in the same row, a way for the descriptor to vote
for it (descriptors.py), its tests and its docs (docs/extending.md, "A fourth pattern").
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Pattern:
    code: int  # its index in p, and RobotStatus.PATTERN_<NAME>
    name: str
    activators: tuple[int, ...]  # slots (docs/algorithm.md §1) that excite; the robot itself too
    inhibitors: tuple[int, ...]  # slots that inhibit
    w2: str  # the CamoParams field holding its inhibitor weight W2
    colour: str  # its colour in figures and GIFs, #rrggbb (matplotlib's tab10 for the three)


PATTERNS: tuple[Pattern, ...] = (
    Pattern(0, "horizontal", (1, 3, 9, 11), (0, 2, 4, 5, 6, 7), "w2_stripes", "#1f77b4"),
    Pattern(1, "vertical", (0, 2, 8, 10), (1, 3, 4, 5, 6, 7), "w2_stripes", "#2ca02c"),
    Pattern(2, "mottled", (0, 1, 2, 3), (4, 5, 6, 7, 8, 9, 10, 11), "w2_mottled", "#ff7f0e"),
)
WIDTH = len(PATTERNS)  # entries of a vote p
PATTERN_NAMES = tuple(p.name for p in PATTERNS)
CODE_OF = {p.name: p.code for p in PATTERNS}
HORIZONTAL, VERTICAL, MOTTLED = CODE_OF["horizontal"], CODE_OF["vertical"], CODE_OF["mottled"]
TIE = MOTTLED  # a tie for the largest entry of p goes to it (fw changeColor)
ACTIVATORS = {p.code: p.activators for p in PATTERNS}
INHIBITORS = {p.code: p.inhibitors for p in PATTERNS}
PATTERN_COLORS = {p.name: p.colour for p in PATTERNS}


def _check() -> None:
    """Codes are the table's order, names unique, regions within the twelve slots and apart."""
    assert [p.code for p in PATTERNS] == list(range(WIDTH)), "codes are 0, 1, ... in order"
    assert len(set(PATTERN_NAMES)) == WIDTH, "pattern names are unique"
    for p in PATTERNS:
        slots = set(p.activators) | set(p.inhibitors)
        assert slots <= set(range(12)), f"{p.name}: regions are slots 0-11"
        assert not set(p.activators) & set(p.inhibitors), f"{p.name}: a slot has one role"


_check()
