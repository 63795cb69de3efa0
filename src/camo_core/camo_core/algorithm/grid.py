"""docs/algorithm.md §1: the grid, robot ids and the 12 neighbour slots."""

from __future__ import annotations

# Slot k sits at offset NEIGHBOR_OFFSETS[k] = (d_row, d_col) from the robot.
NEIGHBOR_OFFSETS: tuple[tuple[int, int], ...] = (
    (-1, 0),
    (0, 1),
    (1, 0),
    (0, -1),  # 0-3: top, right, bottom, left
    (-1, 1),
    (1, 1),
    (1, -1),
    (-1, -1),  # 4-7: the diagonals
    (-2, 0),
    (0, 2),
    (2, 0),
    (0, -2),  # 8-11: two cells away
)
NUM_SLOTS = 12
DESCRIPTOR_SLOTS = range(4)
CONSENSUS_SLOTS = range(8)


def robot_id(row: int, col: int, cols: int) -> int:
    return row * cols + col


def neighbor_cell(row: int, col: int, slot: int, rows: int, cols: int) -> tuple[int, int] | None:
    """The cell in `slot` of (row, col), or None when it is off the grid."""
    di, dj = NEIGHBOR_OFFSETS[slot]
    r, c = row + di, col + dj
    if 0 <= r < rows and 0 <= c < cols:
        return r, c
    return None


def neighbor_ids(row: int, col: int, rows: int, cols: int) -> list[int | None]:
    """Ids of the robots in slots 0..11 (None where the grid ends)."""
    cells = (neighbor_cell(row, col, s, rows, cols) for s in range(NUM_SLOTS))
    return [None if cell is None else robot_id(cell[0], cell[1], cols) for cell in cells]
