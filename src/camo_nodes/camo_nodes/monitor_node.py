"""The monitor: assembles the robots' statuses into the swarm's picture and its summary.

It publishes `/swarm/pattern` (one mono8 pixel per robot: dark = on, grey =
not reported yet) and, once every live robot is done, builds the same
RunResult the reference simulator returns, for summary.json and figure.png.
"""
from __future__ import annotations

import time

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Image

from camo_core.params import CamoParams
from camo_core.result import RunResult, mean_p
from camo_msgs.msg import RobotStatus
from camo_projector.image_msg import from_msg, to_msg
from camo_projector.qos import BACKGROUND_TOPIC, LATCHED

from .topics import PATTERN_TOPIC, STATUS_TOPIC, status_listener_qos


class MonitorNode(Node):
    def __init__(self, params: CamoParams, silence_timeout: float = 30.0, **kwargs) -> None:
        super().__init__("monitor", namespace="/swarm", **kwargs)
        self.params = params
        self.silence_timeout = silence_timeout
        n = params.count
        steps = params.consensus_steps
        self.sensed = np.full(n, np.nan)
        self.p_trace = np.full((steps + 1, n, 3), np.nan)
        self.initial = np.full(n, -1, np.int64)
        self.state = np.full(n, -1, np.int64)
        self.selected = np.full(n, -1, np.int64)
        self.phase = np.zeros(n, np.int64)
        self.step = np.zeros(n, np.int64)
        self.finished = np.zeros(n, bool)
        self.last_heard = np.full(n, time.monotonic())
        self.image = None
        self.create_subscription(RobotStatus, STATUS_TOPIC, self._on_status, status_listener_qos())
        self.create_subscription(Image, BACKGROUND_TOPIC, self._on_background, LATCHED)
        self.pattern_pub = self.create_publisher(Image, PATTERN_TOPIC, 10)
        self.create_timer(0.2, self._publish_pattern)
        self.started = time.monotonic()

    def _on_background(self, msg: Image) -> None:
        self.image = from_msg(msg)

    def _on_status(self, msg: RobotStatus) -> None:
        i = msg.sender_id
        if i >= self.params.count:
            return
        self.last_heard[i] = time.monotonic()
        self.phase[i], self.step[i] = msg.phase, msg.step
        self.sensed[i] = msg.sensed
        self.state[i] = msg.state
        if msg.phase == RobotStatus.PHASE_CONSENSUS:
            self.p_trace[msg.step, i] = msg.p
        elif msg.phase == RobotStatus.PHASE_FORMATION and msg.step == 0:
            self.initial[i] = msg.state
            self.p_trace[self.params.consensus_steps, i] = msg.p
        elif msg.phase == RobotStatus.PHASE_DONE:
            self.selected[i] = msg.pattern
            self.finished[i] = True
            if self.params.formation_steps == 0:
                self.initial[i] = msg.state

    # ---- views ------------------------------------------------------------------

    def silent(self) -> np.ndarray:
        return ~self.finished & (time.monotonic() - self.last_heard > self.silence_timeout)

    @property
    def complete(self) -> bool:
        return bool(np.all(self.finished | self.silent()))

    def progress_line(self) -> str:
        names = ("discovery", "sensing", "consensus", "formation", "done")
        counts = np.bincount(self.phase, minlength=5)
        busy = ", ".join(f"{names[k]} {counts[k]}" for k in range(4) if counts[k])
        return (f"robots done {int(self.finished.sum())}/{self.params.count}"
                f"{', ' + busy if busy else ''}; silent {int(self.silent().sum())}")

    def _publish_pattern(self) -> None:
        shape = (self.params.rows, self.params.cols)
        pixels = np.where(self.state < 0, 128, np.where(self.state == 1, 0, 255)).astype(np.uint8).reshape(shape)
        msg = to_msg(pixels, frame_id="swarm")
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pattern_pub.publish(msg)

    def result(self) -> RunResult:
        """What the swarm computed, in the reference simulator's form; dead robots masked out."""
        shape = (self.params.rows, self.params.cols)
        alive = self.finished.copy()
        trace_p = self.p_trace[:, alive]
        p_final = self.p_trace[-1]
        votes = np.where(np.isnan(self.p_trace[0]).any(axis=1), -1, np.argmax(np.nan_to_num(self.p_trace[0]), axis=1))
        return RunResult(
            params=self.params,
            sensed=self.sensed.reshape(shape),
            votes=votes.reshape(shape),
            p=p_final.reshape(shape + (3,)),
            selected=self.selected.reshape(shape),
            initial=self.initial.reshape(shape).astype(np.uint8) if alive.all() else self.initial.reshape(shape),
            final=self.state.reshape(shape).astype(np.uint8) if alive.all() else self.state.reshape(shape),
            consensus_trace=np.array([mean_p(trace_p[k]) for k in range(trace_p.shape[0])]),
            elapsed_s=time.monotonic() - self.started,
            alive=None if alive.all() else alive.reshape(shape),
        )
