"""The projector: publishes the background the swarm stands on, frame by numbered frame (latched).

What it projects: an image file (`image`), a built-in pattern (`pattern`), or a stream: whatever
arrives on a sensor_msgs/Image topic (`background_topic`, a camera driver's say: mono8, rgb8 or
bgr8, any size), a video file (`video`, at its own rate or `fps`, `loop`), image files one
after another (`images`, a glob, `period` seconds each) or a local camera (`camera`, OpenCV's
device number). A stream is projected at `max_fps` frames a second at most, its newest frame
each time; with `snapshot` only its first frame (a run without --continuous camouflages once).

Every frame it publishes is numbered (header.frame_id `arena/frame_<n>`, n counting from 0): a
round of the swarm is named after the frame it camouflages against. A name sent on
/<run>/camo/projector/load projects that instead, and ends a stream: a built-in background,
one of the backgrounds its run's parameters list (a --then switch), or `goal <n>` (the image
the run's Camouflage action wrote into `goals`, its n-th goal's). A message never names a
path: whoever can write on the topic reads no file off this machine. Setting `image` or
`pattern` while running does the same, except in a keyed run, whose parameter services
anyone in the domain could call: there the launcher's keyed messages alone choose.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_msgs.msg import String

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.modes.layouts import Layout
from camo_core.cli.options import Combination, Parser, add_options, options_of
from camo_core.exceptions import CamoError, UsageError
from camo_core.inputs.images import load_image
from camo_core.schema import check_fields, param, with_role
from camo_core.swarm.run_setup import MAX_WAIT
from camo_nodes.topics import keyed
from camo_nodes.topics.images import (
    ImageEncodingError,
    frame_id,
    image_from_msg,
    image_to_msg,
)
from camo_nodes.topics.names import RunTopics, check_topic_name
from camo_nodes.topics.parameters import (
    JoinParams,
    node_parameters,
    parameters_help,
    ros_arguments,
)
from camo_nodes.topics.qos import LATCHED_READER, history_qos
from camo_nodes.topics.runs import run_from_parameter, setup_from
from camo_nodes.topics.startup import LEAN_NODE, node_help, start_ros, wants_help
from camo_projector.sources import CameraSource, ImagesSource, Source, VideoSource

# Frames a late subscriber still gets: a process that starts while a stream plays can sense the
# frame a round started on a moment ago.
FRAMES_LATCHED = 16


def load(image_path: str, pattern: str) -> np.ndarray:
    return load_image(image_path) if image_path else background(pattern or "forest")


@dataclass(frozen=True)
class ProjectorParams:
    """What a projector shows: a file, a built-in pattern, or a stream of frames."""

    image: str = param("", "background image file (PNG, JPEG, BMP, TIFF, WebP, ...)")
    pattern: str = param("forest", "built-in background", choices=BACKGROUNDS)
    background_topic: str = param(
        "",
        "project what arrives on this sensor_msgs/Image topic (mono8, rgb8, bgr8)",
        metavar="TOPIC",
    )
    video: str = param("", "project this video file, frame by frame", metavar="FILE")
    fps: float = param(
        0.0, "frames a second of the video (0: its own rate)", low=0.0, high=1000.0, metavar="F"
    )
    loop: bool = param(False, "play the video again from the start at its end")
    images: str = param(
        "", "project the image files matching this glob pattern, in name order", metavar="GLOB"
    )
    period: float = param(
        1.0,
        "seconds each of the images is projected",
        low=0.01,
        high=MAX_WAIT,
        unit="s",
        metavar="S",
    )
    camera: int = param(
        -1,
        "project this local camera (OpenCV device number; -1: none)",
        low=-1,
        high=2**31 - 1,  # OpenCV takes the number as a C int
        metavar="N",
    )
    max_fps: float = param(
        10.0,
        "frames a second projected at most from a stream (its newest)",
        low=0.1,
        high=120.0,
        metavar="F",
    )
    snapshot: bool = param(False, "project only a stream's first frame")
    goals: str = param(
        "",
        "the folder where the run's Camouflage action writes its goals' images (goal_<n>.png)",
        metavar="FOLDER",
    )

    def __post_init__(self) -> None:
        check_fields(self)

    def streams(self) -> list[str]:
        """The stream sources given (at most one may be)."""
        given = {
            "background_topic": bool(self.background_topic),
            "video": bool(self.video),
            "images": bool(self.images),
            "camera": self.camera >= 0,
        }
        return [name for name, on in given.items() if on]


PROJECTOR_PARAMETERS = (ProjectorParams, JoinParams)
STREAMS = ("--background-topic", "--video", "--images", "--camera")
# Which of a stream's options mean nothing without which stream (`camo run` takes them too).
STREAM_COMBINATIONS = (
    Combination("--fps", needs=("--video",), why="the frame rate of a video"),
    Combination("--loop", needs=("--video",), why="a video played again"),
    Combination("--period", needs=("--images",), why="each file's time"),
    Combination("--max-fps", needs=STREAMS, why="the rate a stream's frames are projected at"),
)
PROJECTOR_COMBINATIONS = (
    *STREAM_COMBINATIONS,
    Combination("--snapshot", needs=STREAMS, why="a stream's first frame only"),
    Combination("--pattern", excludes=("--image", *STREAMS), why="one background source"),
)


def open_source(values: dict, grid: tuple[int, int] | None = None) -> Source | None:
    """The file or device stream the parameters name (a topic is the node's own), checked: an
    ImageError in one line for a missing video, an empty pattern, a camera that is not there."""
    streams = [n for n in ("background_topic", "video", "images", "camera") if _given(values, n)]
    if len(streams) > 1 or (streams and values.get("image")):
        given = [*(["image"] if values.get("image") else []), *streams]
        raise UsageError(f"the projector projects one source: {' and '.join(given)} were given")
    if _given(values, "background_topic"):
        check_topic_name(values["background_topic"], "background_topic")
        return None  # the node's own subscription
    if _given(values, "video"):
        return VideoSource(values["video"], values["fps"], values["loop"], grid=grid)
    if _given(values, "images"):
        # in turn, again and again
        return ImagesSource(values["images"], values["period"], grid=grid)
    if _given(values, "camera"):
        return CameraSource(values["camera"], grid=grid)
    return None


def _given(values: dict, name: str) -> bool:
    return values.get(name, -1) >= 0 if name == "camera" else bool(values.get(name))


class ProjectorNode(Node):
    def __init__(
        self,
        topics: RunTopics,
        first: np.ndarray | None = None,
        source: Source | None = None,
        **kwargs,
    ) -> None:
        """`first`: the still background its parameters name, when the caller has loaded it;
        `source`: the stream they name, opened."""
        super().__init__("projector", namespace=topics.robot_namespace, **kwargs)
        self.topics = topics
        values = node_parameters(self, *PROJECTOR_PARAMETERS)
        self.values = values
        self.publisher = keyed.publisher(
            self, Image, topics.background, history_qos(FRAMES_LATCHED), topics.run, sealable=True
        )
        self.frame = -1  # the number of the last frame projected
        self._last_stamp = 0
        self.rejected = 0  # stream frames not projected: undecodable, or too small
        self.source = source
        self._latest: Image | None = None  # the topic's newest frame, not projected yet
        self.add_on_set_parameters_callback(self._on_set)
        # What may be loaded: built-in backgrounds, the run's own (its parameters, latched), and
        # its goals' images; refusals are counted.
        self.listed: tuple[str, ...] = ()
        self.refused = 0
        self.layout: Layout | None = None  # the run's robots, once its setup is heard
        run = topics.run
        keyed.subscription(self, String, topics.load, self._on_load, 10, run, self._refuse)
        keyed.subscription(
            self, String, topics.params, self._on_setup, LATCHED_READER, run, self._refuse
        )
        streaming = source is not None or values["background_topic"]
        if values["background_topic"]:
            # Best effort matches a camera driver's sensor-data QoS and a reliable writer alike.
            self.create_subscription(
                Image, values["background_topic"], self._on_frame, qos_profile_sensor_data
            )
        if streaming:
            self.create_timer(1.0 / values["max_fps"], self._next_frame)
        else:
            self.publish(first if first is not None else load(values["image"], values["pattern"]))

    # ---- streams -----------------------------------------------------------------------

    def _on_frame(self, msg: Image) -> None:
        self._latest = msg

    def _next_frame(self) -> None:
        """A stream's newest frame, if it has one not projected yet (at most max_fps a second)."""
        if self.values["snapshot"] and self.frame >= 0:
            return
        if self.source is not None:
            try:
                image = self.source.frame(time.monotonic())
            except CamoError as exc:  # a file of --images that broke, a damaged video frame
                self.get_logger().error(f"frame not projected: {exc}", throttle_duration_sec=5.0)
                return
            if image is not None and self._fits(image.shape[1], image.shape[0], "a frame"):
                self.publish(image)
            return
        msg, self._latest = self._latest, None
        if msg is None:
            return
        where = f"frame from {self.values['background_topic']}"
        try:
            image_from_msg(msg)  # a frame the swarm could not decode is not projected
        except ImageEncodingError as exc:
            self._reject(f"{where} not projected: {exc}")
            return
        if self._fits(msg.width, msg.height, where):
            self._publish_msg(msg)  # as it came: its pixels are what the robots sense

    def _fits(self, width: int, height: int, what: str) -> bool:
        """Whether the run's robots can sense a frame of this size; one they cannot is counted
        and not projected: the swarm keeps the scene it has."""
        try:
            if self.layout is not None:
                self.layout.check_frame(width, height, what)
        except CamoError as exc:
            self._reject(f"not projected: {exc}")
            return False
        return True

    def _reject(self, said: str) -> None:
        self.rejected += 1
        self.get_logger().error(f"{said} ({self.rejected} so far)", throttle_duration_sec=5.0)

    def _stop_stream(self) -> None:
        if self.source is not None:
            self.source.close()
        self.source = None
        self.values = {**self.values, "background_topic": ""}
        self._latest = None

    # ---- stills ------------------------------------------------------------------------

    def _refuse(self, reason: str, gid: bytes = b"") -> None:
        self.refused += 1
        # At most once a second: anyone in the domain can send here.
        self.get_logger().warning(
            f"refused a command: {reason} ({self.refused} so far)", throttle_duration_sec=1.0
        )

    def _on_setup(self, msg: String) -> None:
        setup = setup_from(msg.data, self.topics.run)
        if setup is not None:
            self.listed = setup.backgrounds
            try:
                self.layout = modes_of(setup.params).layout
            except CamoError:  # a layout file this machine does not have: the robots judge
                self.layout = None

    def _on_load(self, msg: String) -> None:
        name = msg.data.strip()
        path = self.loadable(name)
        if path is None:
            self._refuse(f"{name[:80]!r} is none of the run's backgrounds or goals")
            return
        try:
            image = load("", name) if path == name and name in BACKGROUNDS else load(path, "")
        except CamoError as exc:
            self.get_logger().error(f"cannot project {name!r}: {exc}", throttle_duration_sec=1.0)
            return
        self._stop_stream()
        self.publish(image)

    def loadable(self, name: str) -> str | None:
        """What `name` on the load topic projects (a built-in name, or a file the run itself
        named), or None: a message never names a file of its own."""
        if name in BACKGROUNDS or name in self.listed:
            return name
        kind, _, number = name.partition(" ")
        if kind == "goal" and number.isdigit() and self.values["goals"]:
            return str(Path(self.values["goals"]) / f"goal_{int(number)}.png")
        return None

    def _on_set(self, params) -> SetParametersResult:
        values = {p.name: p.value for p in params}
        if not {"image", "pattern"} & set(values):
            return SetParametersResult(successful=True)
        if keyed.process_key() is not None:
            reason = "a keyed run's projector is told what to project by its launcher only"
            return SetParametersResult(successful=False, reason=reason)
        path = values.get("image", "")
        pattern = values.get("pattern", self.get_parameter("pattern").value)
        try:
            image = load(path, pattern)
        except CamoError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._stop_stream()
        self.publish(image)
        return SetParametersResult(successful=True)

    # ---- out ---------------------------------------------------------------------------

    def publish(self, image: np.ndarray) -> None:
        self._publish_msg(image_to_msg(image))

    def _publish_msg(self, source: Image) -> None:
        msg = Image(
            height=source.height,
            width=source.width,
            encoding=source.encoding,
            is_bigendian=source.is_bigendian,
            step=source.step,
            data=source.data,
        )
        self.frame += 1
        msg.header.frame_id = frame_id(self.frame)
        # Stamps strictly increase: a frame is told from the next by its stamp too.
        now = max(self.get_clock().now().nanoseconds, self._last_stamp + 1)
        self._last_stamp = now
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 10**9)
        self.publisher.publish(msg)
        if self.frame == 0 or (self.source is None and not self.values["background_topic"]):
            self.get_logger().info(
                f"projecting frame {self.frame}: a {msg.width}x{msg.height} {msg.encoding} image"
            )


def options_to_ros_args(argv: list[str]) -> list[str]:
    """`./camo projector --video FILE --fps 5 ...`: the projector's options as ROS parameters
    (`-p video:=FILE ...`, before any --ros-args given), the rest as they were."""
    ours, ros = argv, []
    if "--ros-args" in argv:
        at = argv.index("--ros-args")
        ours, ros = argv[:at], argv[at + 1 :]
    parser = Parser(prog="projector_node", add_help=False)
    add_options(parser, ProjectorParams)
    parser.combine(*PROJECTOR_COMBINATIONS)
    options, rest = parser.parse_known_args(ours[1:])
    declared = with_role(ProjectorParams, "cli")
    # Only what the command line names: the rest is left to ROS (a parameters file, -p).
    given = {
        name: value
        for name, value in options_of(options, ProjectorParams).items()
        if any(
            a == d.option or a.startswith(d.option + "=") for a in ours for d in [declared[name]]
        )
    }
    if not given:
        return argv
    left = {name: None for name in declared if name not in given}
    params = ros_arguments(ProjectorParams(**given), **left)
    return [ours[0], *rest, "--ros-args", *params, *ros]


def main(args=None) -> int:
    if wants_help(args):
        about = (
            "Publishes the background projected onto the arena (latched, numbered frames). "
            "Options --image, --pattern, --background-topic, --video, --fps, --loop, "
            "--images, --period, --camera, --max-fps, --snapshot set its parameters."
        )
        print(node_help("projector_node", about, parameters_help(*PROJECTOR_PARAMETERS)))
        return 0
    try:
        args = options_to_ros_args(list(sys.argv if args is None else args))
    except CamoError as exc:
        print(f"projector_node: error: {exc}", file=sys.stderr)
        return 2
    start_ros("projector_node", args, node_options=True)
    node = None
    source = None
    try:
        reader = Node("projector", **LEAN_NODE)  # its name in messages
        try:
            # Its parameters and its image or stream are checked before it waits for a run: a
            # missing or corrupt image, a video OpenCV cannot read, a camera that is not there
            # are one line at once, not a silent wait for a run.
            values = node_parameters(reader, *PROJECTOR_PARAMETERS)
            source = open_source(values)
            still = source is None and not values["background_topic"]
            first = load(values["image"], values["pattern"]) if still else None
            topics = run_from_parameter(reader)
        finally:
            reader.destroy_node()
        node = ProjectorNode(topics, first, source)
        rclpy.spin(node)
    except CamoError as exc:
        print(f"projector_node: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if source is not None:
            source.close()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
