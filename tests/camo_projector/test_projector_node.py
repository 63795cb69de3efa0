"""The projector started alone: its image is checked before it waits for a run."""

import itertools
import os
import subprocess
import sys
import time

import pytest
import rclpy
from support import (
    PROCESS,
    SWARM,
    assert_like_sim,
    domain,
    finished,
    png_bytes,
    ros_context,
    ros_node,
    run_camo,
    start_run,
)


def projector(*ros_args: str) -> subprocess.CompletedProcess:
    # No run in its domain: a projector that waited for one would outlast the timeout.
    return ros_node("camo_projector.projector_node", *ros_args, timeout=30)


@pytest.mark.slow(PROCESS)
def test_a_projector_with_a_missing_or_damaged_image_exits_at_once_with_one_line(tmp_path):
    damaged = tmp_path / "damaged.png"
    damaged.write_bytes(png_bytes(16, 16, filter_byte=9))
    cases = {
        str(tmp_path / "missing.png"): "not found",
        str(damaged): "the decoder says 'libpng error: bad adaptive filter value'",
    }
    for image, said in cases.items():
        out = projector("-p", f"image:={image}")
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1, out.stderr
        assert lines[0].startswith("projector_node: error: ") and said in lines[0]


@pytest.mark.slow(PROCESS)
def test_a_projector_given_a_parameter_it_has_not_exits_at_once_naming_itself():
    out = projector("-p", "bogus:=1")
    assert out.returncode == 2
    assert out.stderr.strip() == (
        "projector_node: error: projector has no parameter bogus (it has: image, pattern, "
        "background_topic, video, fps, loop, images, period, camera, max_fps, snapshot, goals, "
        "run_id)"
    )


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "args, said",
    [
        (["--camera", "57"], "camera 57: there is none"),
        (["--images", "/nonexistent/*.png"], "no file matches it"),
        (["--video", "/nonexistent/clip.mp4"], "not found"),
        (["--video", "x.mp4", "--camera", "0"], "one source: video and camera"),
        (["--fps", "-3", "--video", "x.mp4"], "fps must be a number in [0, 1000]"),
    ],
)
def test_a_projector_without_its_stream_exits_at_once_with_one_line(args, said):
    out = subprocess.run(
        [sys.executable, "-m", "camo_projector.projector_node", *args],
        capture_output=True,
        text=True,
        timeout=30,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and said in lines[0], out.stderr


def frames_of(run_id: str, domain_id: int, count: int, timeout: float = 30.0) -> list:
    """The first `count` frames a projector publishes on /<run>/camo/background."""
    from sensor_msgs.msg import Image

    from camo_nodes.topics.qos import LATCHED_READER

    got: list = []
    with ros_context(domain_id) as context:
        node = rclpy.create_node("frames_listener", context=context)
        node.create_subscription(Image, f"/{run_id}/camo/background", got.append, LATCHED_READER)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + timeout
        while len(got) < count and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        node.destroy_node()
    return got


@pytest.mark.slow(SWARM)
def test_a_projector_plays_a_video_as_numbered_frames(tmp_path):
    import cv2
    import numpy as np

    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (64, 48))
    for k in range(12):
        writer.write(np.full((48, 64, 3), 20 * k, np.uint8))
    writer.release()
    domain_id = domain()
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_projector.projector_node", "--video", str(video),
         "--max-fps", "50", "--ros-args", "-p", "run_id:=clipped"],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        frames = frames_of("clipped", domain_id, 12)
    finally:
        proc.terminate()
        proc.wait(10)
    numbers = [int(f.header.frame_id.removeprefix("arena/frame_")) for f in frames]
    assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers) >= 8, numbers
    greys = [int(np.frombuffer(bytes(f.data), np.uint8).mean()) for f in frames]
    assert greys == sorted(greys) and greys[-1] - greys[0] >= 120  # played in order, to its end
    assert {(f.width, f.height, f.encoding) for f in frames} == {(64, 48, "bgr8")}


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("encoding, size", [("rgb8", 97), ("mono8", 64), ("bgr8", 160)])
def test_a_frame_from_an_image_topic_gives_the_readings_the_same_picture_gives(
    tmp_path, encoding, size
):
    # Without --continuous the swarm camouflages once, on the first frame that came.
    domain_id = domain()
    frames = tmp_path / "frames"
    camera = subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.scene_stream", "/cam/image_raw", "--scenes",
         "leopard", "--encoding", encoding, "--size", str(size), "--out", str(frames)],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        proc = start_run(
            "--background-topic", "/cam/image_raw", "--rows", "8", "--cols", "8",
            "--out", str(tmp_path / "run"), domain_id=domain_id,
        )  # fmt: skip
        _, err = finished(proc, 120)
    finally:
        camera.terminate()
        camera.wait(10)
    assert proc.returncode == 0, err[-2000:]
    (frame,) = {p.name for p in frames.glob("*.png")}  # no noise: every frame the same
    sim = run_camo("sim", "--image", str(frames / frame), "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


def projector_stream(domain_id: int, run_id: str, *args: str) -> subprocess.Popen:
    """A projector of a stream, alone, for run `run_id` in `domain_id`."""
    return subprocess.Popen(
        [sys.executable, "-m", "camo_projector.projector_node", *args,
         "--ros-args", "-p", f"run_id:={run_id}"],
        env={**os.environ, "ROS_DOMAIN_ID": str(domain_id)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def shown(frames: list) -> tuple[list[int], list[float]]:
    """Each frame's grey (its pixels' mean, to the nearest 50) and its stamp (s)."""
    import numpy as np

    greys = [50 * round(np.frombuffer(bytes(f.data), np.uint8).mean() / 50) for f in frames]
    return greys, [f.header.stamp.sec + f.header.stamp.nanosec * 1e-9 for f in frames]


@pytest.mark.slow(SWARM)
def test_a_projector_shows_images_in_name_order_each_for_its_period_again_and_again(tmp_path):
    import cv2
    import numpy as np

    for name, grey in (("b.png", 100), ("a.png", 50), ("c.png", 150)):
        cv2.imwrite(str(tmp_path / name), np.full((48, 64), grey, np.uint8))
    domain_id = domain()
    images = str(tmp_path / "*.png")
    proc = projector_stream(domain_id, "shown", "--images", images, "--period", "0.4")
    try:
        frames = frames_of("shown", domain_id, 7)
    finally:
        proc.terminate()
        proc.wait(10)
    greys, stamps = shown(frames)
    assert greys == [50, 100, 150, 50, 100, 150, 50]  # by name, in turn, from the first again
    gaps = np.diff(stamps)
    assert 0.3 <= np.median(gaps) <= 0.5 and gaps.min() > 0.2, gaps  # one each 0.4 s


@pytest.mark.slow(SWARM)
def test_a_projector_plays_a_video_at_the_rate_given_and_loops_it(tmp_path):
    import cv2
    import numpy as np

    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25, (64, 48))
    for grey in (0, 50, 100, 150, 200):
        writer.write(np.full((48, 64, 3), grey, np.uint8))
    writer.release()
    domain_id = domain()
    proc = projector_stream(
        domain_id, "looped", "--video", str(video), "--fps", "5", "--loop", "--max-fps", "50"
    )
    try:
        frames = frames_of("looped", domain_id, 12)
    finally:
        proc.terminate()
        proc.wait(10)
    greys, stamps = shown(frames)
    # To its end, then from its start (a frame whose time passed while the projector was held
    # up is skipped, not shown late).
    steps = [(b - a) % 250 for a, b in itertools.pairwise(greys)]
    assert set(steps) <= {50, 100} and steps.count(50) >= 9 and greys.count(0) >= 2, greys
    gaps = np.diff(stamps)
    assert 0.15 <= np.median(gaps) <= 0.25, gaps  # 5 frames a second, not the file's 25


class Frames:
    """A stream that gives the frames it holds, one a call."""

    ended = False

    def __init__(self, *frames) -> None:
        self.frames = list(frames)

    def frame(self, now: float):
        return self.frames.pop(0) if self.frames else None

    def close(self) -> None:
        pass


@pytest.mark.parametrize("from_topic", [False, True])
def test_a_stream_frame_too_small_for_the_runs_robots_is_counted_and_not_projected(from_topic):
    # The run's setup says 8x8 robots on the grid: a 4x6 frame would give some none of its
    # pixels; a stream's frame (a camera's, a video's) is judged as --image is, the scene kept.
    import numpy as np
    from sensor_msgs.msg import Image
    from std_msgs.msg import String

    from camo_core.algorithm.params import CamoParams
    from camo_core.swarm.run_setup import RunSetup
    from camo_nodes.topics.images import image_to_msg
    from camo_nodes.topics.names import RunTopics
    from camo_projector.projector_node import ProjectorNode

    small, fits = np.zeros((4, 6), np.uint8), np.full((8, 8), 90, np.uint8)
    with ros_context() as context:
        args = ["--ros-args", "-p", "background_topic:=/cam/image_raw"] if from_topic else []
        source = None if from_topic else Frames(small, fits)
        node = ProjectorNode(RunTopics("sized"), source=source, context=context, cli_args=args)
        projected: list[Image] = []
        node.publisher.publish = projected.append  # what it would send to the swarm
        try:
            setup = RunSetup(run="sized", params=CamoParams(rows=8, cols=8))
            node._on_setup(String(data=setup.to_json()))
            for frame in (small, fits):
                if from_topic:
                    node._on_frame(image_to_msg(frame))
                node._next_frame()
        finally:
            node.destroy_node()
    assert node.rejected == 1
    assert [(m.width, m.height, m.header.frame_id) for m in projected] == [(8, 8, "arena/frame_0")]
