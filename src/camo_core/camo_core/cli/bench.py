"""`./camo bench sim`: speed of the vectorised reference simulator.

Every figure is a ratio against a baseline measured in the same run: the time
NumPy takes to copy one p-array (rows x cols x 3 float64) once per consensus
and formation step. Also: the speed-up over the per-robot driver at 64x64, and (--whole) the
whole `camo sim` process at 1024x1024, image to summary.json, figure.png and run.gif.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.simulator import simulate

SIZES = (64, 256, 1024)
MAX_SIZE = 2048  # a side's p-arrays and copies take about 1 GB; 4096 would take 4
TARGETS = {0.0: 10.0, 0.1: 60.0}  # ratio to the copy baseline, per rho_comm
WHOLE_SIDE = 1024  # robots per side of the whole-process run
WHOLE_IMAGE_SIDE = 2048  # its input image, pixels per side
WHOLE_TARGET = 40.0  # ratio of the whole process to the copy baseline


def _best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def copy_baseline(rows: int, cols: int, steps: int, repeats: int) -> float:
    p = np.random.default_rng(0).random((rows, cols, 3))
    out = np.empty_like(p)

    def copies() -> None:
        for _ in range(steps):
            np.copyto(out, p)

    return _best_of(copies, repeats)


def whole_process(repeats: int = 3, side: int = WHOLE_SIDE) -> dict:
    """Wall time of `python -m camo_core.cli sim --image BIG --rows 1024 --cols 1024 --out TMP`
    (side 1024 unless given), start to exit: imports, image, simulation, summary.json,
    figure.png and run.gif. The best of `repeats` runs after an untimed one, against the best
    of the copy baselines (45 copies of a side x side x 3 array) measured before each run.
    BIG: a built-in background resized to twice the grid's side."""
    params = CamoParams(rows=side, cols=side)
    steps = params.consensus_steps + params.formation_steps
    pixels = WHOLE_IMAGE_SIDE * side // WHOLE_SIDE
    with tempfile.TemporaryDirectory(prefix="camo-bench-") as tmp:
        image = Path(tmp) / "big.png"
        big = cv2.resize(background("leopard"), (pixels, pixels), interpolation=cv2.INTER_CUBIC)
        cv2.imwrite(str(image), big)
        command = [sys.executable, "-m", "camo_core.cli", "sim", "--image", str(image)]
        command += ["--rows", str(side), "--cols", str(side), "--out"]
        runs, baselines = [], []
        for k in range(repeats + 1):
            baselines.append(copy_baseline(side, side, steps, 3))
            start = time.perf_counter()
            done = subprocess.run(
                [*command, str(Path(tmp) / f"out{k}")], capture_output=True, text=True
            )
            seconds = time.perf_counter() - start
            if done.returncode != 0:
                raise RuntimeError(f"camo sim failed ({done.returncode}): {done.stderr[-2000:]}")
            if k > 0:  # the first run warms the file cache (and numba's cache, if it has none)
                runs.append(seconds)
    seconds, baseline = min(runs), min(baselines)
    return {
        "command": f"python -m camo_core.cli sim --image BIG --rows {side} --cols {side} "
        f"--out TMP (BIG: {pixels}x{pixels} PNG)",
        "seconds": seconds,
        "runs_s": runs,
        "baseline_s": baseline,
        "ratio": seconds / baseline,
        "target_ratio": WHOLE_TARGET if side == WHOLE_SIDE else None,
    }


def run(sizes=SIZES, repeats: int = 3, whole: bool = False) -> dict:
    rows_out = []
    for n in sizes:
        reps = repeats if n <= 256 else 2
        raw = np.random.default_rng(n).uniform(0, 255, (n, n))
        base = CamoParams(rows=n, cols=n)
        steps = base.consensus_steps + base.formation_steps
        baseline = copy_baseline(n, n, steps, max(reps, 3))
        for rho in TARGETS:
            params = base.with_(rho_comm=rho)
            seconds = _best_of(partial(simulate, params, raw), reps)
            rows_out.append(
                {
                    "robots": f"{n}x{n}",
                    "rho_comm": rho,
                    "seconds": seconds,
                    "baseline_s": baseline,
                    "ratio": seconds / baseline,
                    "target_ratio": TARGETS[rho] if n == 1024 else None,
                }
            )
    n = 64
    raw = np.random.default_rng(n).uniform(0, 255, (n, n))
    params = CamoParams(rows=n, cols=n)
    vectorised = _best_of(lambda: simulate(params, raw), repeats)
    per_robot = _best_of(lambda: run_per_robot(params, raw), 1)
    report = {
        "pipeline": "descriptor + 35 consensus + 10 formation steps (paper profile)",
        "baseline": "np.copyto of one rows x cols x 3 float64 p-array per consensus and "
        "formation step",
        "results": rows_out,
        "per_robot_64x64_s": per_robot,
        "vectorised_64x64_s": vectorised,
        "speedup_over_per_robot": per_robot / vectorised,
    }
    if whole:
        report["whole_process"] = whole_process(repeats)
    return report


def format_table(report: dict) -> str:
    lines = [
        f"pipeline: {report['pipeline']}",
        f"baseline: {report['baseline']}",
        "",
        f"{'robots':>10} {'rho_comm':>8} {'seconds':>9} {'baseline s':>11} {'ratio':>8} "
        f"{'target':>7}",
    ]
    for r in report["results"]:
        target = f"<= {r['target_ratio']:g}" if r["target_ratio"] else ""
        lines.append(
            f"{r['robots']:>10} {r['rho_comm']:>8g} {r['seconds']:>9.3f} {r['baseline_s']:>11.4f} "
            f"{r['ratio']:>8.1f} {target:>7}"
        )
    lines.append("")
    lines.append(
        f"64x64: per-robot driver {report['per_robot_64x64_s']:.3f} s, vectorised "
        f"{report['vectorised_64x64_s']:.4f} s, speed-up {report['speedup_over_per_robot']:.0f}x"
    )
    if "whole_process" in report:
        w = report["whole_process"]
        runs = ", ".join(f"{s:.3f}" for s in w["runs_s"])
        lines += [
            "",
            f"whole process: {w['command']}",
            f"  best {w['seconds']:.3f} s (runs {runs}), baseline {w['baseline_s']:.4f} s, "
            f"ratio {w['ratio']:.1f}"
            + (f" (target <= {w['target_ratio']:g})" if w["target_ratio"] else ""),
        ]
    return "\n".join(lines)
