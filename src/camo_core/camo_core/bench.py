"""`./camo bench sim`: speed of the vectorised reference simulator.

Every figure is a ratio against a baseline measured in the same run: the time
NumPy takes to copy one p-array (rows x cols x 3 float64) once per consensus
and formation step. Also: the speed-up over the per-robot driver at 64x64.
"""

from __future__ import annotations

import time

import numpy as np

from .params import CamoParams
from .perrobot import run_per_robot
from .simulator import simulate

SIZES = (64, 256, 1024)
TARGETS = {0.0: 10.0, 0.1: 60.0}  # ratio to the copy baseline, per rho_comm


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


def run(sizes=SIZES, repeats: int = 3) -> dict:
    rows_out = []
    for n in sizes:
        reps = repeats if n <= 256 else 2
        raw = np.random.default_rng(n).uniform(0, 255, (n, n))
        base = CamoParams(rows=n, cols=n)
        steps = base.consensus_steps + base.formation_steps
        baseline = copy_baseline(n, n, steps, max(reps, 3))
        for rho in TARGETS:
            params = base.with_(rho_comm=rho)
            seconds = _best_of(lambda params=params, raw=raw: simulate(params, raw), reps)
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
    return {
        "pipeline": "descriptor + 35 consensus + 10 formation steps (paper profile)",
        "baseline": "np.copyto of one rows x cols x 3 float64 p-array per consensus and "
        "formation step",
        "results": rows_out,
        "per_robot_64x64_s": per_robot,
        "vectorised_64x64_s": vectorised,
        "speedup_over_per_robot": per_robot / vectorised,
    }


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
    return "\n".join(lines)
