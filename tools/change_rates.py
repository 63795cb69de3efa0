"""The change rule's false-alarm and detection rates (docs/algorithm.md §6), by simulation of
camo_core.algorithm.change.Watch, the vectorised rule the robots' processes run.

    .venv/bin/python tools/change_rates.py [--robots 4096] [--readings 2500]

False alarms: robots on an unchanged scene (greys spread over 20..235) reading it with
measurement noise (rho_meas) and reading noise (a camera's, sigma grey levels); every notice
counts. Detection: the scene moves by a step of so many grey levels; readings until a robot
notices (a robot that does not within 50 readings counts as not noticing).
"""

from __future__ import annotations

import argparse

import numpy as np

from camo_core.algorithm.change import Watch, false_alarm_rate
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.run_setup import ProtocolParams

DEFAULTS = ProtocolParams()


def watch(robots: int, rho: float, seed: int) -> Watch:
    params = CamoParams(rows=1, cols=robots, rho_meas=rho, seed=seed)
    return Watch(np.arange(robots), params, DEFAULTS.change_window, DEFAULTS.change_threshold)


def false_alarms(robots: int, readings: int, rho: float, sigma: float, seed: int) -> int:
    generator = np.random.default_rng(seed)
    w = watch(robots, rho, seed)
    scene = np.linspace(20, 235, robots).reshape(1, robots)
    w.reset(np.arange(robots), scene, 0)
    count = 0
    for k in range(readings):
        noisy = scene + generator.normal(0, sigma, scene.shape) if sigma else scene
        judged = w.read(noisy, k)
        count += len(judged.robots)
        w.reset(judged.robots, noisy, k)
    return count


def delays(robots: int, step: float, rho: float, sigma: float, seed: int) -> np.ndarray:
    generator = np.random.default_rng(seed)
    w = watch(robots, rho, seed)
    scene = np.full((1, robots), 100.0)
    for k in range(2 * DEFAULTS.change_window):
        w.read(scene, k)
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
    print("| rho_meas | reading noise sigma | notices | per reading | estimate |")
    print("|---|---|---|---|---|")
    for rho, sigma in ((0.0, 0.0), (0.15, 0.0), (0.3, 0.0), (0.15, 4.0), (0.15, 10.0)):
        count = false_alarms(args.robots, args.readings, rho, sigma, seed=1)
        rate = f"{count / total:.1e}" if count else f"< {3 / total:.0e} (95%)"
        window, threshold = DEFAULTS.change_window, DEFAULTS.change_threshold
        estimate = false_alarm_rate(rho, window, threshold)
        print(f"| {rho} | {sigma:g} | {count} | {rate} | {estimate:.1e} |")
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
