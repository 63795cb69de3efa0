"""A camera-like publisher of scenes, for benchmarks and tests: scenes on a sensor_msgs/Image
topic at a frame rate, with frame-to-frame noise, switched every few seconds; with --out each
frame it sends is kept (as PNG, named by the SHA-256 of its pixels), so that the simulator can
be run on the frame a round sensed.

python -m camo_bringup.scene_stream TOPIC --scenes forest,desert --switch 6 --fps 15 --noise 6
(a scene is a built-in background or an image file; --encoding rgb8|bgr8|mono8; --seconds;
--start-when FILE holds the first scene until FILE exists).
"""

from __future__ import annotations

import argparse
import hashlib
import time
from pathlib import Path

import cv2
import numpy as np
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.inputs.images import load_image


def scene(name: str) -> np.ndarray:
    image = background(name) if name in BACKGROUNDS else load_image(name)
    return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("topic")
    parser.add_argument("--scenes", default="forest")
    parser.add_argument("--switch", type=float, default=1e9, help="seconds between scenes")
    parser.add_argument("--fps", type=float, default=15.0)
    parser.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma, grey levels")
    parser.add_argument("--encoding", default="rgb8", choices=("rgb8", "bgr8", "mono8"))
    parser.add_argument("--seconds", type=float, default=1e9)
    parser.add_argument("--size", type=int, default=160, help="frame width and height")
    parser.add_argument("--out", default=None, help="keep every frame sent here")
    parser.add_argument(
        "--start-when", default=None, help="show the first scene until this file exists"
    )
    args = parser.parse_args()
    scenes = [cv2.resize(scene(s), (args.size, args.size)) for s in args.scenes.split(",")]
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    rclpy.init()
    node = rclpy.create_node("fake_camera")
    publisher = node.create_publisher(Image, args.topic, qos_profile_sensor_data)
    generator = np.random.default_rng(0)
    start = time.monotonic()
    switching = None if args.start_when else start  # when the switches' clock started
    frame = 0
    try:
        while time.monotonic() - start < args.seconds:
            if switching is None and Path(args.start_when).exists():
                switching = time.monotonic()
            since = 0.0 if switching is None else time.monotonic() - switching
            index = min(int(since // args.switch), len(scenes) - 1)
            pixels = scenes[index].astype(np.float64)
            if args.noise:
                pixels = pixels + generator.normal(0, args.noise, pixels.shape)
            bgr = np.clip(np.round(pixels), 0, 255).astype(np.uint8)
            if args.encoding == "mono8":
                sent = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
            else:
                sent = bgr[:, :, ::-1].copy() if args.encoding == "rgb8" else bgr
            msg = Image(height=sent.shape[0], width=sent.shape[1], encoding=args.encoding)
            msg.step = sent.shape[1] * (1 if sent.ndim == 2 else 3)
            msg.data = sent.tobytes()
            msg.header.stamp = node.get_clock().now().to_msg()
            msg.header.frame_id = "camera"
            publisher.publish(msg)
            if out:
                digest = hashlib.sha256(sent.tobytes()).hexdigest()
                cv2.imwrite(str(out / f"{digest}.png"), bgr if sent.ndim == 3 else sent)
                (out / "switches.txt").open("a").write(f"{frame} {index} {time.time()}\n")
            frame += 1
            rclpy.spin_once(node, timeout_sec=0.0)
            time.sleep(max(0.0, start + frame / args.fps - time.monotonic()))
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
