"""What a round of `./camo run` leaves: its folder, summary.json, figure.png and timing.json,
and the result line; or, for a round that was stopped, what the swarm had reported."""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from camo_bringup.run_config import RunConfig
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.result import pattern_said
from camo_core.results.record import round_fields
from camo_core.swarm.robot_io import CONSENSUS
from camo_core.swarm.run_setup import contiguous
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
    writing = time.monotonic()
    summary = monitor.write(index, folder, config.labels[index])
    written = time.monotonic()
    params = config.params
    steps = modes_of(params).scope.steps(params) + params.formation_steps
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
        # From the last robot done (this process's clock) to summary.json, figure.png and
        # run.gif written: what the user waits for after the swarm's last step.
        "done_to_written_s": written - times["done"],
        "writing_s": written - writing,
        "deadlines": missed,
        "peak_mib": times.get("peak_mib", {}),  # largest resident sets: a worker, all together
        # When the round's frame was projected and when its last robot was done (ROS time, s
        # since the epoch): what a switch of background costs (./camo bench dynamic).
        "projected_at": monitor.images.times.get(index),
        "done_at": clocks[1] if clocks is not None else None,
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


ROUNDS_CSV = (
    "round", "frame", "seed", "pattern", "background_sha256", "changed_at", "noticed_at",
    "noticed_by", "done_at", "noticed_s", "done_s", "complete",
)  # fmt: skip


def continuous_round(
    config: RunConfig, monitor: MonitorNode, index: int, round_: int, partial: bool = False
) -> dict:
    """A round of a continuous run (the `index`-th, on frame `round_`): round_<index>/ with
    summary.json (its seed, the SHA-256 of its frame, when the scene changed, when and by whom
    that was noticed, when every robot was done: ROS time, s since the epoch), figure.png,
    run.gif and background.png; its line of rounds.csv; run.gif of the rounds so far. `partial`:
    a round the run stopped in, as far as the swarm had reported it (its line says complete 0).
    The summary."""
    folder = config.folder / f"round_{index}"
    folder.mkdir(exist_ok=True)
    record = monitor.record(round_)
    noticed = monitor.notices.get(round_)
    extra = round_fields(index, round_, monitor.images, monitor.notices, record, partial)
    done_at = extra["done_at"]
    label = f"{config.labels[0]}, frame {round_}" + (" (incomplete)" if partial else "")
    summary = monitor.write(round_, folder, label, partial=partial, extra=extra)
    image = monitor.images.get(round_)
    if image is not None:
        cv2.imwrite(str(folder / "background.png"), image)  # lossless: `sim --image` takes it
    row = {key: summary.get(key) for key in ROUNDS_CSV}
    row["complete"] = int(not partial)
    changed = summary["changed_at"]
    for key, at in (("noticed_s", summary["noticed_at"]), ("done_s", done_at)):
        row[key] = None if at is None or changed is None else round(at - changed, 3)
    # The run's GIF: every round so far, one after another.
    from camo_core.results.animation import join_animations  # matplotlib: by what draws

    join_animations(
        [config.folder / f"round_{k}" for k in range(index + 1)], config.folder / "run.gif"
    )
    with open(config.folder / "rounds.csv", "a", newline="") as file:
        writer = csv.DictWriter(file, ROUNDS_CSV)
        if file.tell() == 0:
            writer.writeheader()
        writer.writerow(row)
    dead = summary.get("dead", [])
    notes = f"; {len(dead)} dead robots" if dead else ""
    by = f"noticed by robot {noticed[0]}" if noticed else "noticed"
    after = f" {row['noticed_s']:.2f} s after the change" if row["noticed_s"] is not None else ""
    if partial:
        print(
            f"camo run: round {index} (frame {round_}, {by}{after}) was under way: wrote what "
            f"the swarm had reported of it to {folder}/ (incomplete)",
            file=sys.stderr,
        )
    else:
        print(
            f"round {index} (frame {round_}, {by}{after}): pattern {pattern_said(summary)}"
            f"{notes}; wrote {folder}/"
        )
    return summary
