"""The swarm as ROS tools draw robots: a 3D scene (visualization_msgs) and a health report per
robot (diagnostic_msgs), both built from what the monitor has heard.

The scene is three markers in the frame `map` (RViz's default fixed frame; Foxglove's 3D panel
follows it): a cube per robot at its grid position (column along x, row down along -y, one
`SPACING` apart), coloured as it shows (its state once it draws the pattern, in its
palette's grey or colour with --levels or --colours; what it sensed before; mid-grey and faint
until it reports), a red outline around each dead
robot and a blue one around each robot that is a real Droplet, and on each robot a small tile in
the colour of its chosen pattern. Two cube lists and a line list keep it three markers at any
swarm size.

Diagnostics follow rqt_robot_monitor's and Foxglove's conventions: one DiagnosticStatus per
robot, named `camo/robot_<row>_<col>`, OK, WARN when it let a step deadline pass, ERROR when it
is dead (silent) or its Droplet is offline; its values say phase, step, deadlines and whether
it is bridged.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.results.record import RoundRecord
from camo_core.results.snapshots import code_colours
from camo_core.swarm.robot_io import PHASE_NAMES

FRAME = "map"
SPACING = 0.1  # m between robot centres (a Droplet is 4.4 cm across)
SIZE = 0.08  # m, a robot's cube
HEIGHT = 0.02  # m
DEAD = ColorRGBA(r=0.9, g=0.1, b=0.1, a=1.0)
BRIDGED = ColorRGBA(r=0.1, g=0.4, b=1.0, a=1.0)


def position(robot: int, params: CamoParams, z: float = 0.0) -> Point:
    """A robot's place in the scene: its grid cell, or on a --layout its position."""
    positions = modes_of(params).layout.positions
    if positions is not None:
        x, y = positions[robot]
        return Point(x=float(x) * SPACING, y=-float(y) * SPACING, z=z)
    row, col = divmod(robot, params.cols)
    return Point(x=col * SPACING, y=-row * SPACING, z=z)


def shown_colour(record: RoundRecord) -> tuple[np.ndarray, np.ndarray]:
    """Each robot's colour (robots x 3, 0..1) and opacity: what its state shows once it has one
    (on = dark; with --levels its palette's grey, with --colours its palette's colour), what it
    sensed before (its colour with --colours, else its grey), a faint mid-grey until it
    reports."""
    state, modes = record.state, record.modes
    n, shape = len(state), (record.params.rows, record.params.cols)
    sensed = np.nan_to_num(record.sensed, nan=128.0)
    sensed_rgb = np.repeat(sensed[:, None], 3, axis=1)
    if modes.sensing.colour:  # the colours robots sensed
        known = ~np.isnan(record.sensed_rgb).any(axis=1)
        sensed_rgb[known] = record.sensed_rgb[known]
    states = np.maximum(state, 0).reshape(shape)
    shown = modes.palette.shown_grid(states, record.grid_palette()).reshape(n, -1)
    if shown.shape[1] == 1:  # greys
        shown = np.repeat(shown, 3, axis=1)
    rgb = np.where((state >= 0)[:, None], shown, sensed_rgb)
    alpha = np.where(np.isnan(record.sensed) & (state < 0), 0.3, 1.0)
    return rgb / 255.0, alpha


def _outline(robot: int, params: CamoParams) -> list[Point]:
    """The four edges of a robot's square, as line-list point pairs."""
    centre = position(robot, params, HEIGHT)
    half = SPACING * 0.48
    corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
    points = [Point(x=centre.x + dx, y=centre.y + dy, z=centre.z) for dx, dy in corners]
    return [p for k in range(4) for p in (points[k], points[(k + 1) % 4])]


def markers(record: RoundRecord, dead: np.ndarray, bridged: set[int], stamp: Time) -> MarkerArray:
    rgb, alpha = shown_colour(record)
    cubes = Marker(ns="camo/robots", id=0, type=Marker.CUBE_LIST, action=Marker.ADD)
    cubes.header.frame_id, cubes.header.stamp = FRAME, stamp
    cubes.pose.orientation.w = 1.0
    cubes.scale.x = cubes.scale.y = SIZE
    cubes.scale.z = HEIGHT
    cubes.points = [position(i, record.params, HEIGHT / 2) for i in range(record.params.count)]
    cubes.colors = [
        ColorRGBA(r=r, g=g, b=b, a=a)
        for (r, g, b), a in zip(rgb.tolist(), alpha.tolist(), strict=True)
    ]
    outlines = Marker(ns="camo/outlines", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
    outlines.header.frame_id, outlines.header.stamp = FRAME, stamp
    outlines.pose.orientation.w = 1.0
    outlines.scale.x = SPACING * 0.06  # line width
    for robot in sorted(set(np.flatnonzero(dead)) | bridged):
        colour = DEAD if dead[robot] else BRIDGED
        edges = _outline(int(robot), record.params)
        outlines.points += edges
        outlines.colors += [colour] * len(edges)
    if not outlines.points:
        outlines.action = Marker.DELETE  # an empty line list is not drawable
    return MarkerArray(markers=[cubes, outlines, patterns(record, stamp)])


def chosen_codes(record: RoundRecord) -> np.ndarray:
    """Each robot's pattern code: its choice once it has finished consensus, before that the
    pattern its latest p says, -1 before it votes."""
    codes = record.selected.copy()
    voting = (codes < 0) & ~np.isnan(record.p_latest).any(axis=1)
    if voting.any():
        codes[voting] = record.select(record.p_latest[voting])
    return codes


def patterns(record: RoundRecord, stamp: Time) -> Marker:
    """A small tile on each robot in the colour of its chosen pattern (figure.png's "chosen
    pattern" colours): the regions of a --scope local swarm, at a glance."""
    colours = code_colours(record.modes.descriptor.oriented)
    codes = chosen_codes(record)
    none = (codes < 0) | (codes >= len(colours) - 1)
    tiles = Marker(ns="camo/patterns", id=2, type=Marker.CUBE_LIST, action=Marker.ADD)
    tiles.header.frame_id, tiles.header.stamp = FRAME, stamp
    tiles.pose.orientation.w = 1.0
    tiles.scale.x = tiles.scale.y = SIZE * 0.4
    tiles.scale.z = HEIGHT / 2
    tiles.points = [position(i, record.params, HEIGHT * 1.25) for i in range(record.params.count)]
    rgb = colours[np.where(none, -1, codes)]
    tiles.colors = [
        ColorRGBA(r=r, g=g, b=b, a=0.0 if unknown else 1.0)
        for (r, g, b), unknown in zip(rgb.tolist(), none.tolist(), strict=True)
    ]
    return tiles


def diagnostics(
    record: RoundRecord,
    dead: np.ndarray,
    bridged: set[int],
    offline: np.ndarray,
    stamp: Time,
) -> DiagnosticArray:
    cols = record.params.cols
    array = DiagnosticArray()
    array.header.stamp = stamp
    for robot in range(record.params.count):
        row, col = divmod(robot, cols)
        deadlines = int(record.deadlines[robot])
        if dead[robot]:
            level, message = DiagnosticStatus.ERROR, "silent: its neighbours gave up on it"
        elif offline[robot]:
            level, message = DiagnosticStatus.ERROR, "its Droplet is offline"
        elif deadlines:
            level, message = DiagnosticStatus.WARN, f"let {deadlines} step deadlines pass"
        elif record.finished[robot]:
            level, message = DiagnosticStatus.OK, "done"
        else:
            level, message = DiagnosticStatus.OK, PHASE_NAMES[int(record.phase[robot])]
        array.status.append(
            DiagnosticStatus(
                level=level,
                name=f"camo/robot_{row}_{col}",
                message=message,
                hardware_id="droplet" if robot in bridged else "simulated",
                values=[
                    KeyValue(key="phase", value=PHASE_NAMES[int(record.phase[robot])]),
                    KeyValue(key="step", value=str(int(record.step[robot]))),
                    KeyValue(key="deadlines", value=str(deadlines)),
                    KeyValue(key="bridged", value=str(robot in bridged).lower()),
                ],
            )
        )
    return array
