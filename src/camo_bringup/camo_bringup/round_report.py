"""What a round of `./camo run` leaves: its folder, summary.json, figure.png and timing.json,
and the result line; or, for a round that was stopped, what the swarm had reported."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from camo_bringup.run_config import RunConfig
from camo_core.algorithm.result import pattern_said
from camo_core.algorithm.robot_io import CONSENSUS
from camo_core.algorithm.run_setup import contiguous
from camo_nodes.monitor_node import MonitorNode


def missing_remote_cells(config: RunConfig, record) -> str:
    """The --remote-cells whose robots never reported, as FIRST-LAST ranges."""
    cells = [
        c
        for first, last in config.remote
        for c in range(first, last + 1)
        if record.phase[c] < CONSENSUS and not record.finished[c]
    ]
    return ", ".join(f"{a}-{b}" if a != b else str(a) for a, b in contiguous(cells))


def round_folder(config: RunConfig, index: int) -> Path:
    folder = config.folder if config.rounds == 1 else config.folder / f"round_{index}"
    folder.mkdir(exist_ok=True)
    return folder


def report_round(config: RunConfig, monitor: MonitorNode, index: int, times: dict) -> dict:
    """summary.json, figure.png and timing.json of a finished round, and its result line; the
    summary."""
    folder = round_folder(config, index)
    summary = monitor.write(index, folder, config.labels[index])
    params = config.params
    steps = params.consensus_steps + params.formation_steps
    missed = int(monitor.record(index).deadlines.sum())
    clocks = monitor.record(index).timing()  # the robots' own, robust to a late monitor
    if clocks is not None:
        voted, done = clocks
        launched = times["launched_wall"]
    else:
        voted, done, launched = times["voted"], times["done"], times["launched"]
    timing = {
        "startup_s": voted - launched,
        "steps": steps,
        "steps_s": done - voted,
        "steps_per_s": steps / max(done - voted, 1e-9),
        "launch_to_done_s": done - launched,
        "deadlines": missed,
        "peak_mib": times.get("peak_mib", {}),  # largest resident sets: a worker, all together
    }
    (folder / "timing.json").write_text(json.dumps(timing) + "\n")
    notes = ""
    dead = summary.get("dead", [])
    if dead:
        notes += f"; {len(dead)} dead robots {dead[:8]}{' ...' if len(dead) > 8 else ''}"
    missing = missing_remote_cells(config, monitor.record(index))
    if missing:
        notes += f"; remote cells {missing} never joined (no worker hosted them)"
    refused = summary["rejected_messages"]
    if refused["total"]:
        reasons = ", ".join(f"{n} {why}" for why, n in refused["by_reason"].items())
        notes += f"; WARNING: {refused['total']} received messages refused ({reasons})"
    if missed:
        notes += (
            f"; {missed} step deadlines passed (robots moved on without silent neighbours: "
            f"the result can differ from ./camo sim)"
        )
    print(
        f"pattern: {pattern_said(summary)}{notes}; "
        f"wrote {folder}/summary.json, figure.png and run.gif"
    )
    return summary


def write_partial(config: RunConfig, monitor: MonitorNode, index: int) -> dict | None:
    """What the swarm had reported of an unfinished round."""
    folder = round_folder(config, index)
    record = monitor.record(index)
    if not np.any(record.phase >= CONSENSUS):
        print("camo run: nothing to write yet (no robot had voted)", file=sys.stderr)
        return None
    summary = monitor.write(index, folder, config.labels[index] + " (incomplete)", partial=True)
    print(f"camo run: wrote what the swarm had reported to {folder}/", file=sys.stderr)
    return summary
