"""The run's Camouflage action (camo_msgs/action/Camouflage on /<run>/swarm/camouflage).

A goal with an image: the launcher writes it into the run's folder (goals/goal_<n>.png) and has
the projector load it (/<run>/camo/projector/load, as a --then switch does); the swarm
notices the change by itself (--continuous) and the goal's result is the first round written
on a frame projected after it; an image that reads as the latest round's frame (no robot would
notice it) gets that round. A goal without an image: the round under way, or if none is,
the latest one written. Feedback, twice a second: the robots per phase of the round being
followed and the slowest robot's consensus step. A run without --continuous starts no round for
a goal: it refuses goals with an image. Goals still open when the run ends are aborted.

At most MAX_OPEN goals are open at once: one more is accepted and aborted at once, its result's
message saying why (a refused goal tells its client nothing). What a turn of the launcher's loop
does for the goals is bounded with them: one goal's image written and sent to the projector a
turn at most (a large image takes a while to write).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String

from camo_core.algorithm.sensing import sense_image
from camo_core.exceptions import CamoError
from camo_core.inputs.images import MAX_IMAGE_PIXELS
from camo_core.swarm.robot_io import CONSENSUS
from camo_msgs.action import Camouflage
from camo_nodes.topics import keyed
from camo_nodes.topics.images import image_from_msg

FEEDBACK_PERIOD = 0.5  # s
SPINS = 8  # turns of the action's executor per turn of the launcher's loop
GOAL_WAIT = 120.0  # s a goal's image may take to start a round before the goal is aborted
MAX_OPEN = 16  # goals open at once
# Rounds written that are kept for goals: a goal is met by the first round written after its
# frame, found the turn it is written, or by the latest (a summary of 256x256 robots is MBs).
DONE_KEPT = 16


@dataclass
class OpenGoal:
    handle: object  # rclpy's ServerGoalHandle
    future: Future
    image: np.ndarray | None
    accepted: float = field(default_factory=time.monotonic)
    after: int | None = None  # the goal is met by a round on a frame later than this
    sent: int | None = None  # its image went to the projector when this was the newest frame
    digest: str = ""  # SHA-256 of its image's pixels, as the projector will publish them
    fed: float = 0.0


class CamouflageAction:
    """Serves the action from the launcher's node; `update()` each turn of the launcher's loop,
    `written()` for each round it writes."""

    def __init__(self, session) -> None:
        self.session = session
        config = session.config
        self.continuous = config.continuous
        self.folder: Path = config.folder / "goals"
        self.open: list[OpenGoal] = []
        # (index, frame, summary) of the latest rounds written
        self.done: deque[tuple[int, int, dict]] = deque(maxlen=DONE_KEPT)
        self._grids: dict[int, np.ndarray | None] = {}  # frame -> its greys, of rounds in `done`
        self._numbers = itertools.count()
        self.keys = keyed.GoalCheck(config.topics.run)
        # A node and executor of its own: a result sent after its request's callback returned
        # fails from rclpy's EventsExecutor, which the launcher's other nodes spin ("Failed to
        # send result response"); rclpy's own executor keeps the request for later.
        context = session.node.context
        self.node = Node("camouflage", namespace=config.topics.swarm_namespace, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.server = ActionServer(
            self.node,
            Camouflage,
            config.topics.camouflage,
            execute_callback=self._execute,
            goal_callback=self._goal,
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
        )

    # ---- the server's callbacks ------------------------------------------------------------

    def _goal(self, request) -> GoalResponse:
        refused = self.keys.problem(request)  # a keyed run takes its key holders' goals only
        if refused:
            self.session.monitor.rejected.refuse(refused, b"", "a Camouflage goal")
            self.session.node.get_logger().warning(f"Camouflage goal refused: {refused}")
            return GoalResponse.REJECT
        if len(self.open) >= MAX_OPEN:
            return GoalResponse.ACCEPT  # aborted at once, saying why (`_execute`), not decoded
        problem = self._problem(request.image)
        if problem:
            self.session.node.get_logger().warning(f"Camouflage goal refused: {problem}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _problem(self, image) -> str | None:
        if not image.width:
            return None
        if not self.continuous:
            return "this run has no --continuous: it camouflages its own backgrounds only"
        if image.width * image.height > MAX_IMAGE_PIXELS:
            return f"an image of {image.width}x{image.height}: more than {MAX_IMAGE_PIXELS} pixels"
        try:
            pixels = image_from_msg(image)
            params = self.session.config.params
            sense_image(pixels, params.rows, params.cols, params.profile)
        except CamoError as exc:
            return str(exc)
        return None

    async def _execute(self, handle):
        if len(self.open) >= MAX_OPEN:
            handle.abort()
            message = f"{MAX_OPEN} goals are open already: send it again once one has its result"
            return Camouflage.Result(success=False, message=message)
        image = handle.request.image
        pixels = image_from_msg(image) if image.width else None
        goal = OpenGoal(handle, Future(), pixels)
        if pixels is not None:
            goal.digest = hashlib.sha256(np.ascontiguousarray(pixels).tobytes()).hexdigest()
        self.open.append(goal)
        result = await goal.future
        if handle.is_cancel_requested:
            handle.canceled()
        elif result.success:
            handle.succeed()
        else:
            handle.abort()
        return result

    # ---- what the launcher's loop tells it ---------------------------------------------------

    def written(self, index: int, frame: int, summary: dict) -> None:
        self.done.append((index, frame, summary))
        # Its frame as the robots read it, for goals that show its scene again (the frame is let
        # go once the round is written).
        self._grids[frame] = self._grid(self.session.monitor.images.get(frame))
        for old in [r for r in self._grids if r not in {d[1] for d in self.done}]:
            del self._grids[old]

    def update(self) -> None:
        for _ in range(SPINS):  # the goals' requests, their execution, feedback and results
            self.executor.spin_once(timeout_sec=0.0)
        monitor = self.session.monitor
        now = time.monotonic()
        projected = False  # one image a turn: the next goal's waits for the next turn
        feedback = None  # the same for every goal: computed once a turn at most
        for goal in list(self.open):
            if goal.handle.is_cancel_requested:
                self._finish(goal, Camouflage.Result(success=False, message="cancelled"))
                continue
            if goal.image is not None and goal.sent is None and not projected:
                projected = self._project(goal, monitor)
            met = self._round_for(goal)
            if met is not None:
                self._finish(goal, result_of(*met))
            elif now - goal.accepted > GOAL_WAIT and not self._under_way(goal):
                message = f"no round began on the goal's scene within {GOAL_WAIT:g} s"
                self._finish(goal, Camouflage.Result(success=False, message=message))
            elif now - goal.fed >= FEEDBACK_PERIOD:
                goal.fed = now
                if feedback is None:
                    feedback = feedback_of(monitor)
                goal.handle.publish_feedback(feedback)

    def close(self) -> None:
        """The run ends: goals its last rounds met get their results, the others are aborted."""
        self.update()
        for goal in list(self.open):
            self._finish(goal, Camouflage.Result(success=False, message="the run ended"))
        for _ in range(SPINS):
            self.executor.spin_once(timeout_sec=0.01)
        self.server.destroy()
        self.executor.shutdown()
        self.node.destroy_node()

    # ---- helpers ------------------------------------------------------------------------------

    def _project(self, goal: OpenGoal, monitor) -> bool:
        """Its image into the run's folder, and the projector told to project it (once it
        listens: the load topic is volatile); whether it was."""
        if not self.session.loader.get_subscription_count():
            return False
        self.folder.mkdir(exist_ok=True)
        number = next(self._numbers)
        cv2.imwrite(str(self.folder / f"goal_{number}.png"), goal.image)
        goal.sent = max(monitor.images, default=-1)
        self.session.loader.publish(String(data=f"goal {number}"))  # never a path (projector)
        return True

    def _under_way(self, goal: OpenGoal) -> bool:
        """A round that will meet the goal has begun: it is waited for, however long it takes."""
        return goal.after is not None and any(r > goal.after for r in self.session.monitor.heard)

    def _round_for(self, goal: OpenGoal) -> tuple[int, int, dict] | None:
        """The round that meets the goal, once it is written."""
        if goal.image is not None:
            if goal.after is None and goal.sent is not None:  # its frame, once projected
                digests = self.session.monitor.images.digests
                frames = [n for n, d in digests.items() if d == goal.digest and n > goal.sent]
                goal.after = min(frames) - 1 if frames else None
                if frames:  # the scene it shows may be on already: no robot notices it then
                    same = self._scene_round(min(frames))
                    goal.after = goal.after if same is None else same - 1
            if goal.after is None:
                return None
            later = [d for d in self.done if d[1] > goal.after]
            return later[0] if later else None
        monitor = self.session.monitor
        under_way = sorted(monitor.heard - monitor.closed)
        if goal.after is None:  # the round to wait for, fixed when the goal came
            goal.after = (
                under_way[-1] - 1 if under_way else (self.done[-1][1] - 1 if self.done else -1)
            )
        later = [d for d in self.done if d[1] > goal.after]
        return later[0] if later else None

    def _scene_round(self, frame: int) -> int | None:
        """The round on the scene a goal's frame (number `frame`) shows already, if there is one:
        the latest round begun or written before it, when its frame reads the same grey in every
        cell (no robot notices a frame that reads as its round's)."""
        monitor = self.session.monitor
        rounds = [r for r in monitor.heard - monitor.closed if r < frame]
        rounds += [r for _, r, _ in self.done if r < frame]
        latest = max(rounds, default=None)
        if latest is None:
            return None
        grid = self._grids.get(latest)
        if grid is None:
            grid = self._grid(monitor.images.get(latest))
        shown = self._grid(monitor.images.get(frame))
        same = grid is not None and shown is not None and np.array_equal(grid, shown)
        return latest if same else None

    def _grid(self, image: np.ndarray | None) -> np.ndarray | None:
        if image is None:
            return None
        params = self.session.config.params
        return sense_image(image, params.rows, params.cols, params.profile)

    def _finish(self, goal: OpenGoal, result) -> None:
        self.open.remove(goal)
        goal.future.set_result(result)


def feedback_of(monitor) -> Camouflage.Feedback:
    """The robots per phase of the latest round robots report in, its slowest consensus step."""
    under_way = sorted(monitor.heard - monitor.closed)
    if not under_way:
        return Camouflage.Feedback(robots_per_phase=[0] * 5)
    frame = under_way[-1]
    record = monitor.record(frame)
    counts = np.bincount(record.phase, minlength=5)
    in_consensus = record.step[record.phase == CONSENSUS]
    step = int(in_consensus.min()) if len(in_consensus) else 0
    return Camouflage.Feedback(
        frame=frame, robots_per_phase=[int(c) for c in counts[:5]], consensus_step=step
    )


def result_of(index: int, frame: int, summary: dict) -> Camouflage.Result:
    votes = summary.get("votes", {})
    return Camouflage.Result(
        success=True,
        pattern=str(summary.get("pattern", "")),
        patterns=list(votes),
        votes=[int(v) for v in votes.values()],
        round=index,
        frame=frame,
        summary_json=json.dumps(summary),
    )
