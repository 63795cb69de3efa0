"""Driver (a): the whole run as the swarm computes it, one RobotCore per cell.

Slow (a Python loop over robots and slots) but built from exactly the calls a
robot node makes, so it is the bridge between the nodes and the vectorised
simulator: tests require all three to agree bit for bit.
"""

from __future__ import annotations

import time

import numpy as np

from camo_core.algorithm.modes import Modes, modes_of
from camo_core.algorithm.modes.palettes import GridPalette, RobotPalette
from camo_core.algorithm.modes.scopes import Previous
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import RunResult, mean_p
from camo_core.algorithm.robot import RobotCore
from camo_core.algorithm.simulator import Observer


def run_per_robot(
    params: CamoParams,
    raw_sensed: np.ndarray,
    exempt: np.ndarray | None = None,
    observe: Observer | None = None,
    raw_colours: np.ndarray | None = None,
    modes: Modes | None = None,
    previous: Previous | None = None,
) -> RunResult:
    """`raw_sensed`: rows x cols block means before noise; `exempt`: real readings (no noise);
    `observe` is shown every step as the simulator shows it (`simulator.Observer`);
    `raw_colours`: the blocks' mean colours (rows x cols x 3; colour sensing needs them);
    `modes`: the run's variations (modes.modes_of(params) unless given); `previous`: the
    grid's last round (`simulator.simulate`'s)."""
    modes = modes or modes_of(params)
    if raw_colours is None and modes.sensing.colour:
        raise ValueError(f"{modes.sensing.name} sensing needs the sensed colours (raw_colours)")
    shown = observe or (lambda phase, step, values: None)
    start = time.perf_counter()
    rows, cols = params.rows, params.cols
    robots = [
        RobotCore(params, i, j, modes, previous=_previous_of(previous, i, j))
        for i in range(rows)
        for j in range(cols)
    ]

    for robot in robots:
        robot.discover([n is not None for n in robot.neighbors])
    for robot in robots:
        robot.sense(
            raw_sensed[robot.row, robot.col],
            bool(exempt[robot.row, robot.col]) if exempt is not None else False,
            None if raw_colours is None else raw_colours[robot.row, robot.col],
        )
    for robot in robots:
        robot.describe([None if n is None else robots[n].sensed for n in robot.neighbors])
    if modes.threshold.averages_energy:
        for step in range(params.consensus_steps):
            energies = [(r.energy, r.degree) for r in robots]
            for robot in robots:
                robot.average_energy(
                    step, [None if n is None else energies[n] for n in robot.neighbors]
                )
    for robot in robots:
        robot.cast_vote()
    votes = np.array([r.vote for r in robots]).reshape(rows, cols)

    trace = [mean_p(np.array([r.pattern_p for r in robots]))]
    shown("consensus", 0, np.array([r.pattern_p for r in robots]))
    for step in range(modes.scope.steps(params)):
        sent = [(r.p, r.degree) for r in robots]
        for robot in robots:
            robot.consensus(step, [None if n is None else sent[n] for n in robot.neighbors])
        trace.append(mean_p(np.array([r.pattern_p for r in robots])))
        shown("consensus", step + 1, np.array([r.pattern_p for r in robots]))
    for robot in robots:
        robot.finish_consensus()
    shown("chosen", 0, np.array([r.pattern for r in robots]))
    initial = np.array([r.state for r in robots], dtype=np.uint8).reshape(rows, cols)
    palette = _palette(modes, robots, rows, cols)

    def formation_view() -> np.ndarray:
        """What the robots show, robot by robot (modes.palette.frame)."""
        states = np.array([r.state for r in robots]).reshape(rows, cols)
        frame = modes.palette.frame(states, palette)
        return frame.reshape(len(robots), *frame.shape[2:])

    shown("formation", 0, formation_view())
    for step in range(params.formation_steps):
        sent_states = [r.state for r in robots]
        heard = [[None if n is None else sent_states[n] for n in r.neighbors] for r in robots]
        relays = [
            r.relay(step, h) if modes.relays else None for r, h in zip(robots, heard, strict=True)
        ]
        for robot, states in zip(robots, heard, strict=True):
            from_relays = [None if n is None else relays[n] for n in robot.neighbors[:8]]
            robot.form(step, states, from_relays)
        shown("formation", step + 1, formation_view())

    return RunResult(
        params=params,
        sensed=np.array([r.sensed for r in robots]).reshape(rows, cols),
        votes=votes,
        p=np.array([r.pattern_p for r in robots]).reshape(rows, cols, modes.descriptor.width),
        selected=np.array([r.pattern for r in robots]).reshape(rows, cols),
        initial=initial,
        final=np.array([r.state for r in robots], dtype=np.uint8).reshape(rows, cols),
        consensus_trace=np.array(trace),
        elapsed_s=time.perf_counter() - start,
        palette=palette.greys,
        positions=modes.layout.positions,
        sensed_rgb=np.array([r.sensed_rgb for r in robots]).reshape(rows, cols, 3)
        if raw_colours is not None
        else None,
        palette_rgb=palette.colours,
        shades=palette.shades,
    )


def _previous_of(previous: Previous | None, row: int, col: int) -> Previous | None:
    """One robot's part of the grid's last round (None: no last round)."""
    if previous is None:
        return None
    palette = previous.palette

    def of(values, convert):
        return () if values is None else convert(values[row, col])

    return Previous(
        float(np.asarray(previous.raw)[row, col]),
        int(np.asarray(previous.pattern)[row, col]),
        int(np.asarray(previous.final)[row, col]),
        RobotPalette(
            greys=of(palette.greys, lambda g: tuple(int(v) for v in g)),
            colours=of(palette.colours, lambda c: tuple(tuple(int(v) for v in rgb) for rgb in c)),
            shades=of(palette.shades, lambda s: (int(s[0]), int(s[1]))) or (0, 0),
        ),
    )


def _palette(modes: Modes, robots: list[RobotCore], rows: int, cols: int) -> GridPalette:
    """The robots' palettes as the whole grid's (what the simulator's palette.grid gives)."""
    shows = [r.shows for r in robots]
    greys = colours = shades = None
    if shows and shows[0].greys:
        greys = np.array([s.greys for s in shows]).reshape(rows, cols, -1)
    if shows and shows[0].colours:
        colours = np.array([s.colours for s in shows]).reshape(rows, cols, -1, 3)
        shades = np.array([s.shades for s in shows]).reshape(rows, cols, 2)
    return GridPalette(greys=greys, colours=colours, shades=shades)
