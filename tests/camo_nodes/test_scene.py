"""The 3D scene and diagnostics: built right from what the monitor heard, and, recorded in a bag,
read by Foxglove's own libraries (@mcap/core, @foxglove/rosmsg2-serialization)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from support import BAG_COLS, BAG_ROWS, FOXGLOVE_CLIENT, SWARM
from visualization_msgs.msg import Marker

from camo_core.algorithm.params import CamoParams
from camo_core.results.record import RoundRecord
from camo_nodes import scene

PARAMS = CamoParams(rows=2, cols=3)


def record() -> RoundRecord:
    rec = RoundRecord(PARAMS)
    rec.sensed[:] = [0.0, 255.0, 51.0, np.nan, 10.0, 20.0]
    rec.state[:] = [1, 0, -1, -1, -1, -1]
    rec.phase[:] = [4, 4, 2, 0, 3, 3]
    rec.finished[:2] = True
    rec.deadlines[4] = 2
    return rec


def test_each_robot_is_a_cube_at_its_cell_in_the_grey_it_shows():
    dead = np.zeros(6, bool)
    array = scene.markers(record(), dead, set(), Time(sec=5))
    cubes, outlines, _ = array.markers
    assert cubes.type == Marker.CUBE_LIST and cubes.header.frame_id == "map"
    assert len(cubes.points) == len(cubes.colors) == 6
    right_below = cubes.points[4]  # row 1, col 1
    assert right_below.x > cubes.points[0].x and right_below.y < cubes.points[0].y
    greys = [round(c.r, 3) for c in cubes.colors]
    assert greys[:3] == [0.0, 1.0, 0.2]  # on: dark, off: light, else the sensed grey
    assert cubes.colors[3].a < 1.0  # not reported yet: faint
    assert outlines.action == Marker.DELETE  # nobody dead or bridged: nothing to outline


def test_dead_and_bridged_robots_are_outlined_in_their_colours():
    dead = np.zeros(6, bool)
    dead[3] = True
    outlines = scene.markers(record(), dead, {5}, Time()).markers[1]
    assert outlines.type == Marker.LINE_LIST and outlines.action == Marker.ADD
    assert len(outlines.points) == 16  # four edges of two squares
    assert outlines.colors[0] == scene.DEAD and outlines.colors[-1] == scene.BRIDGED


def test_diagnostics_say_ok_warn_or_error_per_robot():
    dead = np.zeros(6, bool)
    dead[3] = True
    offline = np.zeros(6, bool)
    offline[5] = True
    array = scene.diagnostics(record(), dead, {5}, offline, Time())
    levels = [s.level for s in array.status]
    ok, warn, error = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
    assert levels == [ok, ok, ok, error, warn, error]
    assert array.status[4].name == "camo/robot_1_1"
    values = {v.key: v.value for v in array.status[5].values}
    assert values == {"phase": "formation", "step": "0", "deadlines": "0", "bridged": "true"}
    assert array.status[5].hardware_id == "droplet"


@pytest.mark.slow(SWARM)
def test_a_recorded_scene_and_diagnostics_decode_in_foxglove_libraries(recorded, foxglove_client):
    bag, _ = recorded
    out = subprocess.run(
        [foxglove_client, "bag.mjs", str(bag / "bag_0.mcap"), "/swarm/markers", "/diagnostics"],
        cwd=FOXGLOVE_CLIENT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    topics = {name.split("/", 2)[2]: seen for name, seen in json.loads(out.stdout).items()}
    markers, health = topics["swarm/markers"], topics["diagnostics"]
    assert markers["schema"] == "visualization_msgs/msg/MarkerArray" and markers["count"] >= 1
    cubes = markers["last"]["markers"]["first"][0]
    assert cubes["type"] == Marker.CUBE_LIST and cubes["points"]["length"] == BAG_ROWS * BAG_COLS
    assert cubes["header"]["frame_id"] == "map"
    assert health["schema"] == "diagnostic_msgs/msg/DiagnosticArray"
    assert health["last"]["status"]["length"] == BAG_ROWS * BAG_COLS
    first = health["last"]["status"]["first"][0]
    assert first["name"] == "camo/robot_0_0"
    assert first["values"]["first"][0]["key"] == "phase"


def test_on_a_layout_each_cube_stands_at_its_position_in_its_palettes_grey():
    params = CamoParams(rows=2, cols=3, layout="hex", orientation="any", levels=3)
    rec = RoundRecord(params)
    rec.sensed[:] = 100.0
    rec.state[:] = [0b11, 0b01, 0, -1, 0b11, 0]
    rec.palette[:] = [20, 120, 230]
    cubes = scene.markers(rec, np.zeros(6, bool), set(), Time()).markers[0]
    # Row 1 is offset by half a spacing and sqrt(3)/2 down (y up in the scene).
    assert cubes.points[3].x == 0.5 * scene.SPACING
    assert np.isclose(cubes.points[3].y, -np.sqrt(3) / 2 * scene.SPACING)
    greys = [c.r for c in cubes.colors]
    assert np.allclose(greys[:3], [20 / 255, 120 / 255, 230 / 255])
    assert np.isclose(greys[3], 100 / 255)  # no state yet: its sensed grey


def test_with_colours_each_cube_shows_its_palette_colour_and_before_that_its_sensed_colour():
    params = CamoParams(rows=1, cols=3, colours=2)
    rec = RoundRecord(params)
    rec.sensed[:] = 100.0
    rec.sensed_rgb[:] = [[200.0, 50.0, 25.0]] * 3
    rec.state[:] = [1, 0, -1]
    rec.palette_rgb[:] = [[[10, 80, 20], [240, 200, 100]]] * 3
    rec.shades[:] = [0, 1]
    cubes = scene.markers(rec, np.zeros(3, bool), set(), Time()).markers[0]
    rgb = [(c.r, c.g, c.b) for c in cubes.colors]
    assert np.allclose(rgb[0], np.array([10, 80, 20]) / 255)  # on: its darker colour
    assert np.allclose(rgb[1], np.array([240, 200, 100]) / 255)  # off: its lighter colour
    assert np.allclose(rgb[2], np.array([200, 50, 25]) / 255)  # no state yet: what it sensed


def test_each_robot_carries_a_tile_in_the_colour_of_its_chosen_pattern():
    # Finished robots show their choice; one still in consensus what its p says; one that has
    # not voted nothing (a clear tile).
    from camo_core.results.snapshots import code_colours

    rec = record()
    rec.selected[:] = [1, 2, -1, -1, -1, -1]
    rec.p_latest[2] = [0.7, 0.2, 0.1]  # robot 2, in consensus: horizontal so far
    tiles = scene.markers(rec, np.zeros(6, bool), set(), Time()).markers[2]
    assert tiles.type == Marker.CUBE_LIST and tiles.ns == "camo/patterns"
    colours = code_colours()
    got = [(round(c.r, 3), round(c.g, 3), round(c.b, 3), c.a) for c in tiles.colors]
    for robot, code in ((0, 1), (1, 2), (2, 0)):
        assert got[robot][:3] == tuple(round(v, 3) for v in colours[code]) and got[robot][3] == 1
    assert all(got[robot][3] == 0.0 for robot in (3, 4, 5))
