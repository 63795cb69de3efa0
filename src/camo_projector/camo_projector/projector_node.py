"""The projector: publishes the background image the swarm stands on (latched).

Parameters: `image` (a file) or `pattern` (desert, forest, leopard). Setting
either while running, or sending a name or path on /camo/projector/load,
publishes the new background, and the swarm camouflages again on it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import Image
from std_msgs.msg import String

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.sensing import load_image
from camo_core.exceptions import CamoError
from camo_core.schema import param
from camo_nodes.topics.images import image_to_msg
from camo_nodes.topics.names import RunTopics
from camo_nodes.topics.parameters import JoinParams, node_parameters, parameters_help
from camo_nodes.topics.qos import LATCHED
from camo_nodes.topics.runs import run_from_parameter
from camo_nodes.topics.startup import LEAN_NODE, node_help, start_ros, wants_help


def load(image_path: str, pattern: str) -> np.ndarray:
    return load_image(image_path) if image_path else background(pattern or "forest")


@dataclass(frozen=True)
class ProjectorParams:
    """The background a projector shows first: a file, else a built-in pattern."""

    image: str = param("", "background image file (PNG, JPEG, BMP, TIFF, WebP, ...)")
    pattern: str = param("forest", "built-in background", choices=BACKGROUNDS)


PROJECTOR_PARAMETERS = (ProjectorParams, JoinParams)


class ProjectorNode(Node):
    def __init__(self, topics: RunTopics, first: np.ndarray | None = None, **kwargs) -> None:
        """`first`: the background its parameters name, when the caller has loaded it."""
        super().__init__("projector", namespace=topics.robot_namespace, **kwargs)
        values = node_parameters(self, *PROJECTOR_PARAMETERS)
        self.publisher = self.create_publisher(Image, topics.background, LATCHED)
        self.image = first if first is not None else load(values["image"], values["pattern"])
        self.add_on_set_parameters_callback(self._on_set)
        # A topic as well as the parameters: data is a built-in name or an image path.
        self.create_subscription(String, topics.load, self._on_load, 10)
        self.publish()

    def _on_load(self, msg: String) -> None:
        name = msg.data.strip()
        try:
            self.image = load("", name) if name in BACKGROUNDS else load(name, "")
        except CamoError as exc:
            # At most once a second: anyone in the domain can send here.
            self.get_logger().error(f"cannot project {name!r}: {exc}", throttle_duration_sec=1.0)
            return
        self.publish()

    def publish(self) -> None:
        msg = image_to_msg(self.image)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(msg)
        self.get_logger().info(f"projecting a {msg.width}x{msg.height} {msg.encoding} background")

    def _on_set(self, params) -> SetParametersResult:
        values = {p.name: p.value for p in params}
        if not {"image", "pattern"} & set(values):
            return SetParametersResult(successful=True)
        path = values.get("image", "")
        pattern = values.get("pattern", self.get_parameter("pattern").value)
        try:
            self.image = load(path, pattern)
        except CamoError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.publish()
        return SetParametersResult(successful=True)


def main(args=None) -> int:
    if wants_help(args):
        about = "Publishes the background image projected onto the arena (latched)."
        print(node_help("projector_node", about, parameters_help(*PROJECTOR_PARAMETERS)))
        return 0
    start_ros("projector_node", args, node_options=True)
    node = None
    try:
        reader = Node("projector", **LEAN_NODE)  # its name in messages
        try:
            # Its parameters and its image are checked before it waits for a run: a missing
            # or corrupt image is one line at once, not a silent wait for a run.
            values = node_parameters(reader, *PROJECTOR_PARAMETERS)
            first = load(values["image"], values["pattern"])
            topics = run_from_parameter(reader)
        finally:
            reader.destroy_node()
        node = ProjectorNode(topics, first)
        rclpy.spin(node)
    except CamoError as exc:
        print(f"projector_node: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
