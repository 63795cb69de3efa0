"""A projector's stream sources without ROS: a video behind its time catches up a bounded number
of frames a call, in order."""

import cv2
import numpy as np
import pytest

from camo_projector.sources import SKIPPED_PER_CALL, VideoSource

FRAMES = 2 * SKIPPED_PER_CALL + 10


def numbered_video(path, fps: float = 25.0) -> str:
    """A video whose frame k says k in two greys, 40 + 10 x its base-16 digits: the left half's
    the high digit, the right half's the low one (MJPG keeps a uniform grey within a level or
    two)."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (32, 16))
    for k in range(FRAMES):
        image = np.full((16, 32, 3), 40 + 10 * (k // 16), np.uint8)
        image[:, 16:] = 40 + 10 * (k % 16)
        writer.write(image)
    writer.release()
    return str(path)


def number(frame: np.ndarray | None) -> int | None:
    if frame is None:
        return None
    high, low = (round((float(frame[4:12, x : x + 8].mean()) - 40) / 10) for x in (4, 20))
    return 16 * high + low


def test_a_video_behind_its_time_skips_a_bounded_number_of_frames_a_call_in_order(tmp_path):
    video = VideoSource(numbered_video(tmp_path / "clip.avi"), fps=25.0)
    assert number(video.frame(0.0)) == 0
    late = (FRAMES - 5) / 25.0  # the source was not asked for that long: frames are due
    shown = [number(video.frame(late)) for _ in range(4)]
    assert shown == [SKIPPED_PER_CALL + 1, 2 * SKIPPED_PER_CALL + 2, FRAMES - 5, None]
    assert number(video.frame(late + 1 / 25.0)) == FRAMES - 4  # caught up: frame by frame
    video.close()


def test_a_video_plays_each_frame_in_its_time_and_a_looped_one_starts_again(tmp_path):
    path = numbered_video(tmp_path / "clip.avi")
    for loop, after in ((False, [None, None]), (True, [0, 1])):
        video = VideoSource(path, fps=25.0, loop=loop)
        shown = [number(video.frame(0.0))]
        shown += [number(video.frame((k + 0.5) / 25.0)) for k in range(1, FRAMES + 2)]
        assert shown == [*range(FRAMES), *after] and video.ended is not loop
        video.close()


def test_opening_a_video_or_a_missing_camera_leaves_opencvs_log_level_as_it_was(tmp_path):
    """OpenCV's log level is the process's: a projector silenced it for good when it opened a
    video, and then a damaged image it loaded no longer said what its decoder reported."""
    import pytest

    from camo_core.inputs.images import ImageError, load_image
    from camo_projector.sources import CameraSource

    logging = cv2.utils.logging
    before = logging.getLogLevel()
    VideoSource(numbered_video(tmp_path / "numbered.avi")).close()
    with pytest.raises(ImageError):
        CameraSource(57)
    assert logging.getLogLevel() == before
    path = tmp_path / "float.tiff"
    assert cv2.imwrite(str(path), np.random.default_rng(0).random((8, 8)).astype(np.float32))
    with pytest.raises(ImageError, match=r"the decoder says 'OpenCV TIFF: .*32-bit samples'"):
        load_image(path)


def test_every_file_of_images_is_checked_before_any_is_shown(tmp_path):
    """Kinds, multi-frame files and sizes against the grid: the whole sequence up front, the
    first bad file named in one line."""
    import pytest
    from PIL import Image

    from camo_core.inputs.images import ImageError
    from camo_projector.sources import ImagesSource

    for name, side in (("a.png", 32), ("b.png", 32)):
        cv2.imwrite(str(tmp_path / name), np.zeros((side, side), np.uint8))
    assert ImagesSource(str(tmp_path / "*.png"), 1.0, grid=(32, 32)).files
    cv2.imwrite(str(tmp_path / "c.png"), np.zeros((8, 40), np.uint8))  # 40 wide, 8 high
    with pytest.raises(ImageError, match=r"c.png of 40x8 pixels is smaller than the 32x32 robot"):
        ImagesSource(str(tmp_path / "*.png"), 1.0, grid=(32, 32))
    (tmp_path / "c.png").unlink()
    frames = [Image.new("L", (32, 32), k) for k in (0, 255)]
    frames[0].save(tmp_path / "d.gif", save_all=True, append_images=frames[1:])
    with pytest.raises(ImageError, match="more than one frame"):
        ImagesSource(str(tmp_path / "*"), 1.0, grid=(32, 32))
    (tmp_path / "d.gif").unlink()
    (tmp_path / "e.png").write_bytes(b"not an image at all")
    with pytest.raises(ImageError, match=r"e\.png") as refused:
        ImagesSource(str(tmp_path / "*.png"), 1.0)
    assert "\n" not in str(refused.value)


def test_a_damaged_video_frame_is_skipped_counted_and_its_decoder_kept_quiet(tmp_path, capfd):
    """FFmpeg decodes a damaged MJPG frame to something, saying so on stderr: that frame is
    refused in one line (the projector logs it and projects nothing), the others come."""
    import pytest

    from camo_core.inputs.images import ImageError

    mjpg = cv2.VideoWriter_fourcc(*"MJPG")
    writer = cv2.VideoWriter(str(tmp_path / "v.avi"), mjpg, 25, (64, 32))
    for k in range(20):
        writer.write(np.full((32, 64, 3), 10 * k, np.uint8))  # frame k: grey 10 k
    writer.release()
    data = bytearray((tmp_path / "v.avi").read_bytes())
    starts = [k for k in range(len(data) - 1) if data[k : k + 2] == b"\xff\xd8"]

    def damage(frame: int) -> None:  # its scan's bytes, from its start-of-scan to its end
        scan = data.index(b"\xff\xda", starts[frame]) + 14
        end = data.index(b"\xff\xd9", scan)
        data[scan:end] = bytes(range(end - scan))

    damage(10)
    (tmp_path / "bad.avi").write_bytes(bytes(data))
    clean = VideoSource(str(tmp_path / "v.avi"), fps=10.0)
    greys = [float(clean.frame(k / 10.0).mean()) for k in range(19)]  # as this FFmpeg decodes
    video = VideoSource(str(tmp_path / "bad.avi"), fps=10.0)
    seen, refused = [], []
    for k in range(19):  # FFmpeg gives this file's last frame as none
        try:
            grey = float(video.frame(k / 10.0).mean())
            seen.append(min(range(19), key=lambda j: abs(greys[j] - grey)))  # its frame
        except ImageError as exc:
            refused.append(str(exc))
    assert seen == [*range(10), *range(11, 19)] and video.damaged == 1, (seen, refused)
    (said,) = refused
    assert "frame 10 is damaged (the decoder says" in said and "1 so far" in said
    assert "mjpeg" not in capfd.readouterr().err  # quoted in the line, not on the terminal
    damage(0)
    (tmp_path / "first.avi").write_bytes(bytes(data))
    with pytest.raises(ImageError, match="first frame is damaged"):
        VideoSource(str(tmp_path / "first.avi"))


def test_a_video_smaller_than_the_grid_is_refused_before_it_plays(tmp_path):
    from camo_core.inputs.images import ImageError

    path = numbered_video(tmp_path / "small.avi")  # 32x16 pixels
    VideoSource(path, grid=(16, 32)).close()  # a pixel each: enough
    with pytest.raises(ImageError, match=r"small.avi of 32x16 pixels is smaller than the 32x20"):
        VideoSource(path, grid=(20, 32))


@pytest.mark.parametrize(
    "options, said",
    [
        (["--fps", "5"], "--fps needs --video"),
        (["--loop", "--images", "a*.png"], "--loop needs --video"),
        (["--period", "2", "--video", "v.mp4"], "--period needs --images"),
        (["--max-fps", "2"], "--max-fps needs --background-topic or --video"),
        (["--snapshot", "--image", "a.png"], "--snapshot needs --background-topic"),
        (["--pattern", "desert", "--camera", "0"], "--pattern and --camera do not go together"),
    ],
)
def test_a_projector_option_that_means_nothing_with_the_others_is_one_line(options, said):
    from camo_core.exceptions import UsageError
    from camo_projector.projector_node import options_to_ros_args

    with pytest.raises(UsageError, match=said):
        options_to_ros_args(["projector_node", *options])
    assert "-p" in options_to_ros_args(["projector_node", "--fps", "5", "--video", "v.mp4"])


def test_a_truncated_video_is_one_line_with_what_its_decoder_said(tmp_path, capfd):
    # FFmpeg wrote "moov atom not found" on the terminal above camo's own line.
    from camo_core.inputs.images import ImageError

    path = tmp_path / "cut.mp4"
    path.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 8)
    with pytest.raises(ImageError) as caught:
        VideoSource(str(path))
    assert str(caught.value) == (
        f"video {path}: OpenCV cannot read it (not a video it knows): the decoder says "
        "'moov atom not found'"
    )
    assert capfd.readouterr().err == ""
