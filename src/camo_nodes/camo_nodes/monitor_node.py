"""The monitor: assembles the robots' statuses into the swarm's picture and its summary.

It publishes `/swarm/pattern` (one mono8 pixel per robot: dark = on, light =
off, grey = not reported yet) and, once every live robot has finished a round,
builds the same RunResult the reference simulator returns, for summary.json
and figure.png. A robot that stops reporting is marked dead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Image

from camo_core import cli, figures
from camo_core.params import CamoParams
from camo_core.result import RunResult, mean_p
from camo_core.simulator import select_patterns
from camo_msgs.msg import RobotStatus
from camo_projector.image_msg import from_msg, to_msg
from camo_projector.qos import BACKGROUND_TOPIC, LATCHED

from .topics import PATTERN_TOPIC, STATUS_TOPIC, status_listener_qos

PHASE_NAMES = ("discovery", "sensing", "consensus", "formation", "done")


@dataclass
class RoundRecord:
    """Everything the robots reported in one camouflage round."""

    params: CamoParams
    started: float = field(default_factory=time.monotonic)

    def __post_init__(self) -> None:
        n, steps = self.params.count, self.params.consensus_steps
        self.sensed = np.full(n, np.nan)
        self.p_trace = np.full((steps + 1, n, 3), np.nan)
        self.state_trace = np.full((self.params.formation_steps + 1, n), -1, np.int64)
        self.p_latest = np.full((n, 3), np.nan)
        self.initial = np.full(n, -1, np.int64)
        self.state = np.full(n, -1, np.int64)
        self.selected = np.full(n, -1, np.int64)
        self.phase = np.zeros(n, np.int64)
        self.step = np.zeros(n, np.int64)
        self.finished = np.zeros(n, bool)
        self.deadlines = np.zeros(n, np.int64)  # step deadlines each robot let pass

    def add(self, msg: RobotStatus) -> None:
        i = msg.sender_id
        self.phase[i] = msg.phase
        self.step[i] = msg.step
        self.sensed[i] = msg.sensed
        self.state[i] = msg.state
        self.deadlines[i] = msg.deadlines
        if msg.phase >= RobotStatus.PHASE_CONSENSUS:
            self.p_latest[i] = msg.p
        if msg.phase == RobotStatus.PHASE_CONSENSUS:
            self.p_trace[msg.step, i] = msg.p
            self.initial[i] = msg.state
        elif msg.phase == RobotStatus.PHASE_FORMATION:
            self.state_trace[msg.step, i] = msg.state
        if msg.phase == RobotStatus.PHASE_DONE:
            self.state_trace[msg.step, i] = msg.state
            self.selected[i] = msg.pattern
            self.finished[i] = True

    def timeline(self) -> list[tuple[str, np.ndarray]]:
        """The swarm at each consensus step (selected pattern, -1 unknown) and formation step (state)."""
        shape = (self.params.rows, self.params.cols)
        frames = []
        for step, p in enumerate(self.p_trace):
            unknown = np.isnan(p).any(axis=1)
            chosen = select_patterns(np.nan_to_num(p).reshape(shape + (3,))).reshape(-1)
            frames.append((f"c{step}", np.where(unknown, -1, chosen).reshape(shape)))
        frames += [
            (f"f{step}", states.reshape(shape)) for step, states in enumerate(self.state_trace)
        ]
        return frames

    def result(self, dead: np.ndarray, partial: bool = False) -> RunResult:
        """What the swarm computed, in the reference simulator's form; dead robots masked out.

        `partial`: the run was stopped early; robots still working count as alive and show
        their latest report, and the consensus trace ends where the slowest robot was.
        """
        shape = (self.params.rows, self.params.cols)
        alive = (
            ~dead & (self.phase >= RobotStatus.PHASE_CONSENSUS)
            if partial
            else self.finished & ~dead
        )
        trace = []
        for step in self.p_trace:
            if np.isnan(step[alive]).any():
                break
            trace.append(mean_p(step[alive]))
        first = self.p_trace[0]
        votes = np.where(np.isnan(first).any(axis=1), -1, np.argmax(np.nan_to_num(first), axis=1))
        return RunResult(
            params=self.params,
            sensed=self.sensed.reshape(shape),
            votes=votes.reshape(shape),
            p=self.p_latest.reshape(shape + (3,)),
            # Stopped early: a robot still in consensus shows what its current p would select.
            selected=np.where(
                self.selected < 0,
                select_patterns(np.nan_to_num(self.p_latest)[None])[0],
                self.selected,
            ).reshape(shape)
            if partial
            else self.selected.reshape(shape),
            initial=self.initial.reshape(shape),
            final=self.state.reshape(shape),
            consensus_trace=np.array(trace).reshape(-1, 3),
            elapsed_s=time.monotonic() - self.started,
            alive=None if alive.all() else alive.reshape(shape),
        )


def round_record(rounds: dict[int, RoundRecord], index: int, params: CamoParams) -> RoundRecord:
    """The record of round `index`, created on first use. Not setdefault: its default would allocate
    a record's traces (steps x robots) on every status."""
    if index not in rounds:
        rounds[index] = RoundRecord(params)
    return rounds[index]


def add_background(images: list[np.ndarray], stamps: list[tuple[int, int]], msg: Image) -> None:
    """Keep each new background once (by its stamp): round k camouflaged images[k]."""
    stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
    if stamp not in stamps:
        stamps.append(stamp)
        images.append(from_msg(msg))


def write_round(
    result: RunResult,
    image: np.ndarray | None,
    folder: Path,
    label: str,
    incomplete: str | None = None,
) -> dict:
    """summary.json and figure.png of one round, as `./camo sim` writes them."""
    summary = result.summary()
    if incomplete is not None:
        summary["incomplete"] = incomplete
    cli.write_summary(summary, folder)
    params = result.params
    figures.run_figure(
        result,
        image,
        folder / "figure.png",
        title=f"{label}: {params.rows}x{params.cols} robot nodes, {params.profile} profile, "
        f"seed {params.seed}, rho_meas {params.rho_meas:g}, rho_comm {params.rho_comm:g}",
    )
    return summary


class MonitorNode(Node):
    def __init__(
        self,
        params: CamoParams,
        silence_timeout: float = 30.0,
        startup_timeout: float = 600.0,
        **kwargs,
    ) -> None:
        super().__init__("monitor", namespace="/swarm", **kwargs)
        self.params = params
        self.silence_timeout = silence_timeout
        self.startup_timeout = startup_timeout
        self.rounds: dict[int, RoundRecord] = {0: RoundRecord(params)}
        self.images: list[np.ndarray] = []  # background of round k is images[k]
        self._image_stamps: list[tuple[int, int]] = []
        self.last_heard = np.zeros(params.count)
        self.heard = np.zeros(params.count, bool)
        self.offline = np.zeros(params.count, bool)
        self.statuses_heard = 0  # a recording of the run must hold at least these
        self.started = time.monotonic()
        self.create_subscription(RobotStatus, STATUS_TOPIC, self._on_status, status_listener_qos())
        self.create_subscription(Image, BACKGROUND_TOPIC, self._on_background, LATCHED)
        self.pattern_pub = self.create_publisher(Image, PATTERN_TOPIC, 10)
        self.create_timer(0.2, self._publish_pattern)

    def _on_background(self, msg: Image) -> None:
        add_background(self.images, self._image_stamps, msg)

    def _on_status(self, msg: RobotStatus) -> None:
        self.statuses_heard += 1
        if msg.sender_id >= self.params.count:
            return
        self.last_heard[msg.sender_id] = time.monotonic()
        self.heard[msg.sender_id] = True
        self.offline[msg.sender_id] = not msg.alive  # a bridged Droplet whose port went away
        self.record(msg.round).add(msg)

    # ---- views ------------------------------------------------------------------

    def dead(self, round_index: int = 0) -> np.ndarray:
        """Robots that stopped reporting before finishing this round (or never reported at all)."""
        now = time.monotonic()
        quiet = np.where(
            self.heard,
            now - self.last_heard > self.silence_timeout,
            now - self.started > self.startup_timeout,
        )
        return ~self.record(round_index).finished & quiet

    def all_voted(self, round_index: int = 0) -> bool:
        """Every live robot has voted and entered consensus."""
        record = self.record(round_index)
        return bool(np.all((record.phase >= RobotStatus.PHASE_CONSENSUS) | self.dead(round_index)))

    def record(self, round_index: int) -> RoundRecord:
        return round_record(self.rounds, round_index, self.params)

    def complete(self, round_index: int = 0) -> bool:
        record = self.record(round_index)
        return bool(np.all(record.finished | self.dead(round_index)))

    def progress_line(self, round_index: int = 0) -> str:
        record = self.record(round_index)
        counts = np.bincount(record.phase, minlength=5)
        parts = []
        for k in range(4):
            if counts[k]:
                steps = record.step[record.phase == k]
                where = (
                    f" (step {steps.min()}-{steps.max()})"
                    if k >= RobotStatus.PHASE_CONSENSUS
                    else ""
                )
                parts.append(f"{PHASE_NAMES[k]} {counts[k]}{where}")
        busy = ", ".join(parts)
        offline = f"; hardware offline {int(self.offline.sum())}" if self.offline.any() else ""
        if record.deadlines.any():
            offline += f"; step deadlines passed {int(record.deadlines.sum())}"
        return (
            f"round {round_index}: robots done {int(record.finished.sum())}/{self.params.count}"
            f"{', ' + busy if busy else ''}; silent {int(self.dead(round_index).sum())}{offline}"
        )

    def result(self, round_index: int = 0, partial: bool = False) -> RunResult:
        return self.record(round_index).result(self.dead(round_index), partial)

    def _publish_pattern(self) -> None:
        latest = self.rounds[max(self.rounds)]
        shape = (self.params.rows, self.params.cols)
        pixels = np.where(latest.state < 0, 128, np.where(latest.state == 1, 0, 255)).astype(
            np.uint8
        )
        msg = to_msg(pixels.reshape(shape), frame_id="swarm")
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pattern_pub.publish(msg)
