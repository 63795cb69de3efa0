"""The change rule's false-alarm and detection rates (docs/algorithm.md §6), by simulation of
camo_core.algorithm.change.Watch, the vectorised rule the robots' processes run.

    .venv/bin/python tools/change_rates.py [--robots 4096] [--readings 2500]

False alarms: robots on an unchanged scene (greys spread over 20..235) reading it with
measurement noise (rho_meas), from a run's start (robots in no round, which notice the scene
and start one), through a camera whose every frame adds noise of its own (sigma
grey levels on a cell's grey), as a run meets it: a new frame every reading or every few readings
(a camera slower than the sense period), and every robot joining a round every so many readings
(it reads the round's frame a window's worth of times, as a host has it do). A robot that
notices starts a round and reads its frame the same way; every notice counts. Detection: the
scene moves by a step of so many grey levels; readings until a robot notices (a robot that does
not within 50 readings counts as not noticing).
"""

from __future__ import annotations

import argparse

import numpy as np

from camo_core.algorithm.change import Watch, false_alarm_rate
from camo_core.algorithm.params import CamoParams
from camo_core.swarm.run_setup import ProtocolParams

DEFAULTS = ProtocolParams()
# (rho_meas, frame noise sigma, readings a frame, readings between joins; 0: none)
FALSE_ALARM_CASES = (
    (0.0, 0.0, 1, 0),
    (0.15, 0.0, 1, 0),
    (0.3, 0.0, 1, 0),
    (0.15, 4.0, 1, 0),
    (0.15, 10.0, 1, 0),
    (0.15, 10.0, 3, 0),
    (0.15, 4.0, 1, 50),
    (0.15, 10.0, 1, 50),
    (0.15, 10.0, 3, 50),
)


def watch(robots: int, rho: float, seed: int) -> Watch:
    params = CamoParams(rows=1, cols=robots, rho_meas=rho, seed=seed)
    return Watch(np.arange(robots), params, DEFAULTS.change_window, DEFAULTS.change_threshold)


def false_alarms(
    robots: int, readings: int, rho: float, sigma: float, every: int, joins: int, seed: int
) -> int:
    generator = np.random.default_rng(seed)
    w = watch(robots, rho, seed)
    scene = np.linspace(20, 235, robots).reshape(1, robots)
    idle = np.ones(robots, bool)  # in no round yet: a run's start, where noticing is no alarm
    frame, count = -1, 0
    for k in range(readings):
        if k % every == 0:
            frame += 1
            noisy = scene + generator.normal(0, sigma, scene.shape) if sigma else scene
        judged = w.read(noisy, frame, idle)
        count += int((~idle[judged.robots]).sum())
        idle[judged.robots] = False
        w.reset(judged.robots, noisy, frame)
        if joins and k % joins == joins - 1:
            w.reset(np.flatnonzero(~idle), noisy, frame)
    return count


def delays(robots: int, step: float, rho: float, sigma: float, seed: int) -> np.ndarray:
    generator = np.random.default_rng(seed)
    w = watch(robots, rho, seed)
    scene = np.full((1, robots), 100.0)
    for k in range(4 * DEFAULTS.change_window):  # frames of the scene before, and a round of it
        w.read(scene + generator.normal(0, sigma, scene.shape) if sigma else scene, k)
    w.reset(np.arange(robots), scene, 0)
    moved = scene + step
    noticed = np.full(robots, np.inf)
    for k in range(50):
        noisy = moved + generator.normal(0, sigma, moved.shape) if sigma else moved
        judged = w.read(noisy, 100 + k)
        fresh = judged.robots[np.isinf(noticed[judged.robots])]
        noticed[fresh] = k + 1
    return noticed


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--robots", type=int, default=4096)
    parser.add_argument("--readings", type=int, default=2500)
    args = parser.parse_args()
    total = args.robots * args.readings
    print(f"false notices on an unchanged scene, {args.robots} robots x {args.readings} readings")
    print("| rho_meas | frame noise sigma | readings a frame | joins | notices | per reading |")
    print("|---|---|---|---|---|---|")
    for rho, sigma, every, joins in FALSE_ALARM_CASES:
        count = false_alarms(args.robots, args.readings, rho, sigma, every, joins, seed=1)
        rate = f"{count / total:.1e}" if count else f"< {3 / total:.0e} (95%)"
        joined = f"every {joins} readings" if joins else "none"
        print(f"| {rho} | {sigma:g} | {every} | {joined} | {count} | {rate} |")
    window, threshold = DEFAULTS.change_window, DEFAULTS.change_threshold
    for rho in (0.15, 0.3):
        estimate = false_alarm_rate(rho, window, threshold)
        print(f"estimate without frame noise, rho_meas {rho}: {estimate:.1e} a reading")
    print()
    print("readings until a robot notices a step (rho_meas 0.15)")
    print("| step (grey levels) | sigma | median | 90th percentile | noticed within 50 |")
    print("|---|---|---|---|---|")
    for step, sigma in ((30, 0.0), (60, 0.0), (120, 0.0), (60, 4.0), (60, 10.0)):
        seen = delays(args.robots, step, 0.15, sigma, seed=2)
        found = seen[np.isfinite(seen)]
        median = f"{np.median(found):.0f}" if len(found) else "-"
        p90 = f"{np.percentile(found, 90):.0f}" if len(found) else "-"
        print(f"| {step} | {sigma:g} | {median} | {p90} | {100 * len(found) / len(seen):.1f}% |")


if __name__ == "__main__":
    main()
