"""Sensing: images, grey values, block means, measurement noise, real readings, calibration."""

import json
import os
import threading
import zlib

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from support import COMPUTE, PROCESS, png_bytes

from camo_core.algorithm import sensing
from camo_core.algorithm.params import ParameterError
from camo_core.algorithm.sensing import Calibration, ImageError, rgb_to_gray, to_gray


def test_block_means_are_unrounded_area_averages():
    gray = np.zeros((4, 4), np.uint8)
    gray[0, 0] = 1  # block (0, 0) mean is 0.25, which a uint8 resize would round away
    gray[2:, 2:] = 200
    means = sensing.block_means(gray, 2, 2)
    assert means.dtype == np.float64
    assert means.tolist() == [[0.25, 0.0], [0.0, 200.0]]


def test_paper_grey_is_opencv_luma_and_droplet_grey_is_red_green_mean():
    bgr = np.zeros((2, 2, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 10, 101, 250  # B, G, R
    assert np.array_equal(
        sensing.to_gray(bgr, "paper"), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(float)
    )
    assert sensing.to_gray(bgr, "droplet")[0, 0] == 0.5 * 250 + 0.5 * 101


def test_grey_image_is_used_as_is_by_both_profiles():
    gray = np.arange(16, dtype=np.uint8).reshape(4, 4)
    assert np.array_equal(sensing.to_gray(gray, "paper"), sensing.to_gray(gray, "droplet"))


def test_noise_replaces_about_rho_of_the_robots_with_whole_grey_levels():
    sensed = np.full((100, 100), 0.5)
    noisy = sensing.apply_noise(sensed, seed=3, rho_meas=0.2)
    replaced = noisy != 0.5
    assert abs(replaced.mean() - 0.2) < 0.02
    assert np.all(noisy[replaced] == np.floor(noisy[replaced])) and noisy.max() <= 255
    assert sensing.noisy_value(3, 42, 0.5, 0.2) == noisy.ravel()[42]


def test_image_errors_are_clear(tmp_path):
    with pytest.raises(ImageError, match="not found"):
        sensing.load_image(tmp_path / "missing.png")
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(ImageError, match="cannot read"):
        sensing.load_image(corrupt)
    with pytest.raises(ImageError, match="smaller"):
        sensing.block_means(np.zeros((5, 5)), 8, 8)


def test_colour_alpha_and_grey_files_load(tmp_path):
    bgra = np.zeros((16, 16, 4), np.uint8)
    bgra[..., 2] = 200
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    assert sensing.load_image(tmp_path / "a.png").shape == (16, 16, 3)
    cv2.imwrite(str(tmp_path / "g.png"), np.full((16, 16), 7, np.uint8))
    assert sensing.load_image(tmp_path / "g.png").shape == (16, 16)


def _one_line_image_error(path):
    with pytest.raises(ImageError) as caught:
        sensing.load_image(path)
    message = str(caught.value)
    assert message and "\n" not in message and len(message) < 300, message
    return message


def test_an_image_whose_header_claims_too_many_pixels_is_refused_before_decoding(tmp_path):
    big = tmp_path / "big.png"
    big.write_bytes(png_bytes(100_000, 100_000, pixels=(8, 8)))
    assert "pixels" in _one_line_image_error(big)
    wide = tmp_path / "wide.png"  # under Pillow's own bomb limit, over ours
    wide.write_bytes(png_bytes(sensing.MAX_IMAGE_PIXELS // 4 + 1, 4, pixels=(8, 8)))
    assert "more than" in _one_line_image_error(wide)


def test_an_image_whose_data_is_not_what_its_header_says_is_refused(tmp_path):
    short = tmp_path / "short.png"
    short.write_bytes(png_bytes(64, 64, pixels=(8, 8)))
    _one_line_image_error(short)


@pytest.mark.parametrize(
    "name, expected",
    [
        ("", "empty"),
        ("a" * 5000, "too long"),
        ("d/" + "b" * 300 + ".png", "too long"),
        ("folder", "folder"),
        ("missing.png", "not found"),
        ("nul\0.png", "NUL"),
    ],
)
def test_a_bad_image_path_is_one_line(tmp_path, name, expected):
    (tmp_path / "folder").mkdir()
    path = "" if name == "" else str(tmp_path / name)
    assert expected in _one_line_image_error(path)


def test_an_image_that_is_not_a_regular_file_or_too_big_on_disk_is_refused(tmp_path, monkeypatch):
    assert "regular file" in _one_line_image_error("/dev/null")
    image = tmp_path / "ok.png"
    image.write_bytes(png_bytes(8, 8))
    monkeypatch.setattr(sensing, "MAX_IMAGE_BYTES", 10)
    assert "bytes" in _one_line_image_error(image)


def test_an_image_we_may_not_read_is_one_line(tmp_path):
    image = tmp_path / "secret.png"
    image.write_bytes(png_bytes(8, 8))
    image.chmod(0)
    try:
        if os.access(image, os.R_OK):
            pytest.skip("running as root: every file is readable")
        assert "permission" in _one_line_image_error(image)
    finally:
        image.chmod(0o600)


def test_a_file_that_is_no_image_format_is_one_line(tmp_path):
    text = tmp_path / "notes.png"
    text.write_text("hello\n" * 10)
    assert "not a known image format" in _one_line_image_error(text)


def test_sixteen_bit_and_grey_pngs_load_as_eight_bit(tmp_path):
    cv2.imwrite(str(tmp_path / "deep.png"), np.full((8, 8), 40000, np.uint16))
    image = sensing.load_image(tmp_path / "deep.png")
    assert image.dtype == np.uint8 and image.shape[:2] == (8, 8)
    (tmp_path / "tiny.png").write_bytes(png_bytes(3, 2))
    assert sensing.load_image(tmp_path / "tiny.png").shape == (2, 3)


@given(
    width=st.one_of(st.integers(0, 64), st.integers(2**14, 2**31 - 1)),
    height=st.one_of(st.integers(0, 64), st.integers(2**14, 2**31 - 1)),
    depth=st.sampled_from([0, 1, 2, 4, 7, 8, 16, 255]),
    colour=st.sampled_from([0, 1, 2, 3, 4, 5, 6, 7, 255]),
)
@settings(max_examples=60, deadline=None)
def test_a_png_with_any_header_fields_loads_or_is_refused_in_one_line(
    tmp_path_factory, width, height, depth, colour
):
    path = tmp_path_factory.mktemp("png") / "fuzz.png"
    path.write_bytes(png_bytes(width, height, depth=depth, colour=colour, pixels=(8, 8)))
    try:
        image = sensing.load_image(path)
    except ImageError as exc:
        assert str(exc) and "\n" not in str(exc)
    else:  # only a header that told the truth about its 8x8 grey 8-bit pixels loads
        assert (width, height, depth, colour) == (8, 8, 8, 0)
        assert image.shape == (8, 8) and image.dtype == np.uint8


@pytest.mark.parametrize("profile", ["paper", "droplet"])
def test_a_grey_reading_gives_its_own_value_in_both_profiles(profile):
    for v in (0, 1, 77, 128, 254, 255):
        assert rgb_to_gray(v, v, v, profile) == v


def test_a_colour_reading_is_grey_as_the_image_pixel_would_be():
    for r, g, b in ((200, 10, 30), (0, 255, 7), (13, 14, 250)):
        pixel = np.array([[[b, g, r]]], np.uint8)
        assert rgb_to_gray(r, g, b, "paper") == to_gray(pixel, "paper")[0, 0]
        assert rgb_to_gray(r, g, b, "droplet") == 0.5 * r + 0.5 * g
    with pytest.raises(ValueError):
        rgb_to_gray(256, 0, 0, "paper")


def test_calibration_is_identity_by_default_and_reads_yaml(tmp_path):
    assert Calibration().apply(123.5) == 123.5
    path = tmp_path / "cal.yaml"
    path.write_text("gain: 1.1\noffset: -5\n")
    cal = Calibration.from_yaml(path)
    assert (
        cal.apply(100) == pytest.approx(105.0) and cal.apply(250) == 255.0 and cal.apply(1) == 0.0
    )
    path.write_text("gain: [1\n")
    with pytest.raises(ParameterError, match="not YAML"):
        Calibration.from_yaml(path)
    path.write_text("gain: 0\n")
    with pytest.raises(ParameterError, match=r"gain must be in \(0, 1e\+06\]"):
        Calibration.from_yaml(path)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ('gain: "1"\n', "gain must be a number (got '1')"),
        ("gain: true\n", "gain must be a number (got true)"),
        ("gain: 1e44\n", "gain must be in (0, 1e+06] (got 1e+44)"),
        ("offset: -1e300\n", "offset must be within +-1e+06"),
        ("gain: 1:00\n", "(line 1): '1:00' is a base-60 number"),
        ("gain: 1\noffset: 0\ngain: 5\n", "(line 3): the key 'gain' is given twice"),
        ("gain: " + "9" * 5000 + "\n", "an integer of 5000 digits"),
        ("gain: 2\n---\ngain: 3\n", "more than one document"),
    ],
)
def test_a_calibration_takes_numbers_in_range_read_strictly(tmp_path, text, said):
    path = tmp_path / "cal.yaml"
    path.write_text(text)
    with pytest.raises(ParameterError) as caught:
        Calibration.from_yaml(path)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize("special", ["/dev/zero", "/dev/urandom", "fifo"])
def test_a_calibration_that_is_a_device_or_a_fifo_is_refused_not_a_hang(tmp_path, special):
    if special == "fifo":
        special = str(tmp_path / "cal.yaml")
        os.mkfifo(special)
    said: list[str] = []

    def read():
        try:
            Calibration.from_yaml(special)
        except ParameterError as exc:
            said.append(str(exc))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(10)
    assert said == [f"the calibration {special} is not a regular file"]


@pytest.mark.slow(COMPUTE)
@given(
    content=st.one_of(
        st.binary(max_size=64),
        st.dictionaries(
            st.sampled_from(["gain", "offset", "other"]),
            st.one_of(
                st.none(), st.booleans(), st.floats(), st.text(max_size=5), st.lists(st.integers())
            ),
            max_size=3,
        ).map(lambda d: yaml.safe_dump(d).encode()),
    )
)
def test_any_calibration_file_reads_or_is_refused_in_one_line(tmp_path_factory, content):
    path = tmp_path_factory.mktemp("cal") / "calibration.yaml"
    path.write_bytes(content)
    try:
        cal = Calibration.from_yaml(path)
    except ParameterError as exc:
        assert "\n" not in str(exc)
    else:
        assert 0.0 <= cal.apply(128.0) <= 255.0


def test_contrast_pulls_every_value_toward_the_images_mean():
    image = np.array([[0, 100], [200, 100]], np.uint8)  # mean 100
    assert np.array_equal(sensing.with_contrast(image, 1.0), image)
    assert np.array_equal(sensing.with_contrast(image, 0.5), [[50, 100], [150, 100]])
    for bad in (0.0, 1.5):
        with pytest.raises(ImageError, match=r"--contrast must be in \(0, 1\]"):
            sensing.with_contrast(image, bad)


@pytest.mark.slow(PROCESS)
def test_sim_at_a_contrast_senses_what_it_senses_on_that_image_written_out(tmp_path):
    from support import run_camo

    from camo_core.algorithm.backgrounds import background

    faint = tmp_path / "faint.png"
    cv2.imwrite(str(faint), sensing.with_contrast(background("leopard"), 0.4))
    runs = {
        "option": ["--pattern", "leopard", "--contrast", "0.4"],
        "file": ["--image", str(faint)],
    }
    summaries = {}
    for name, args in runs.items():
        out = run_camo("sim", *args, "--rho-meas", "0.2", "--out", str(tmp_path / name))
        assert out.returncode == 0, out.stderr
        summaries[name] = json.loads((tmp_path / name / "summary.json").read_text())
    assert summaries["option"]["sensed"] == summaries["file"]["sensed"]
    assert summaries["option"]["final"] == summaries["file"]["final"]
    out = run_camo("sim", "--contrast", "2", "--out", str(tmp_path / "bad"))
    assert (
        out.returncode == 2
        and out.stderr.strip() == "camo: error: --contrast must be in (0, 1] (got 2)"
    )


# ---- what the native decoders say (issue 27) -------------------------------------------------


def _noise(width: int = 64, height: int = 48) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _truncated_jpeg() -> bytes:
    ok, data = cv2.imencode(".jpg", _noise())
    assert ok
    return data.tobytes()[: len(data) // 2]


@pytest.mark.parametrize(
    "name, content, said",
    [
        ("bad_filter.png", png_bytes(16, 16, filter_byte=9), "libpng error: bad adaptive filter"),
        ("few_rows.png", png_bytes(16, 16, pixels=(16, 4)), "libpng error: Not enough image data"),
        ("truncated.jpg", _truncated_jpeg(), "Premature end of JPEG file"),
    ],
    ids=["bad_filter", "few_rows", "truncated_jpeg"],
)
def test_an_image_the_decoder_calls_damaged_is_refused_quoting_it_and_nothing_else_is_written(
    tmp_path, capfd, name, content, said
):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ImageError, match=f"cannot decode image .*: the decoder says '{said}"):
        sensing.load_image(path)
    assert capfd.readouterr().err == ""


def test_a_png_with_only_a_harmless_libpng_warning_loads_and_writes_nothing(tmp_path, capfd):
    path = tmp_path / "short_profile.png"
    profile = b"p\0\0" + zlib.compress(b"garbage")  # "iCCP: too short"
    path.write_bytes(png_bytes(16, 16, extra=((b"iCCP", profile),)))
    assert sensing.load_image(path).shape == (16, 16)
    assert capfd.readouterr().err == ""


def test_a_float_tiff_opencv_cannot_bring_to_eight_bits_is_refused_with_its_reason(
    tmp_path, capfd
):
    path = tmp_path / "float.tiff"
    assert cv2.imwrite(str(path), np.random.default_rng(0).random((8, 8)).astype(np.float32))
    with pytest.raises(ImageError, match=r"the decoder says 'OpenCV TIFF: .*32-bit samples'"):
        sensing.load_image(path)
    assert capfd.readouterr().err == ""


def test_decoder_messages_are_matched_as_damage_or_dropped_as_harmless():
    said = sensing.decoder_messages(
        "[ WARN:0@0.078] global grfmt_tiff.cpp:811 readData OpenCV TIFF: Sorry, no\n\n"
        "libpng warning: iCCP: known incorrect sRGB profile\n"
    )
    assert said == ["OpenCV TIFF: Sorry, no", "libpng warning: iCCP: known incorrect sRGB profile"]
    damage = [m for m in said if sensing.DECODER_DAMAGE.search(m)]
    assert damage == ["OpenCV TIFF: Sorry, no"]
    for harmless in ("libpng warning: iCCP: too short", "Warning: unknown JFIF revision number"):
        assert not sensing.DECODER_DAMAGE.search(harmless)
    for bad in ("Corrupt JPEG data: 3 extraneous bytes before marker 0xd9", "libpng error: x"):
        assert sensing.DECODER_DAMAGE.search(bad)


def _bmp_of_width(width: int) -> bytes:
    ok, data = cv2.imencode(".bmp", _noise())
    assert ok
    data = bytearray(data.tobytes())
    data[18:22] = width.to_bytes(4, "little", signed=True)
    return bytes(data)


@pytest.mark.parametrize(
    "name, content, said",
    [
        ("zero_width.png", png_bytes(0, 16, pixels=(16, 16)), "PNG header says width 0"),
        ("zero_height.png", png_bytes(16, 0, pixels=(16, 16)), "PNG header says height 0"),
        ("negative.png", png_bytes(2**32 - 64, 16, pixels=(16, 16)), "says width -64"),
        ("negative_width.bmp", _bmp_of_width(-64), "BMP header says width -64"),
        ("zero_width.bmp", _bmp_of_width(0), "BMP header says width 0"),
    ],
    ids=["png_width_0", "png_height_0", "png_width_2**32-64", "bmp_width_-64", "bmp_width_0"],
)
def test_a_header_of_zero_or_negative_width_or_height_is_refused_naming_it(
    tmp_path, name, content, said
):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ImageError, match=f"{said}, not at least 1"):
        sensing.load_image(path)


def test_a_top_down_bmp_of_negative_height_still_loads(tmp_path):
    _, data = cv2.imencode(".bmp", _noise())
    data = bytearray(data.tobytes())
    data[22:26] = (-48).to_bytes(4, "little", signed=True)
    path = tmp_path / "top_down.bmp"
    path.write_bytes(bytes(data))
    assert sensing.load_image(path).shape == (48, 64, 3)


def test_a_pillow_limit_is_named_by_what_it_limits_not_pillows_internals(tmp_path):
    path = tmp_path / "text_bomb.png"
    text = b"k\0\0" + zlib.compress(b"a" * (4 * 1024 * 1024))  # zTXt of 4 MB
    path.write_bytes(png_bytes(16, 16, extra=((b"zTXt", text),)))
    with pytest.raises(ImageError, match="Pillow's limit on metadata") as error:
        sensing.load_image(path)
    assert "ImagePlugin" not in str(error.value) and "MAX_" not in str(error.value)


@pytest.mark.parametrize(
    "suffix, kind", [("gif", "GIF"), ("png", "PNG"), ("webp", "WEBP"), ("tiff", "TIFF")]
)
def test_an_animation_or_multi_page_image_is_refused_not_read_as_its_first_frame(
    tmp_path, suffix, kind
):
    from PIL import Image

    frames = [Image.fromarray(np.full((16, 16), value, np.uint8)) for value in (0, 255)]
    path = tmp_path / f"two_frames.{suffix}"
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=100)
    with pytest.raises(ImageError, match=f"a {kind} of more than one frame"):
        sensing.load_image(path)
    frames[0].save(tmp_path / f"one_frame.{suffix}")
    assert sensing.load_image(tmp_path / f"one_frame.{suffix}").shape[:2] == (16, 16)


@pytest.mark.slow(PROCESS)
def test_a_damaged_image_given_to_the_command_line_is_exactly_one_line_on_stderr(tmp_path):
    from support import run_camo

    for name, content in (
        ("bad.png", png_bytes(16, 16, filter_byte=9)),
        ("cut.jpg", _truncated_jpeg()),
    ):
        path = tmp_path / name
        path.write_bytes(content)
        out = run_camo("sim", "--image", str(path), "--out", str(tmp_path / name / "out"))
        assert out.returncode == 2, out.stderr
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("camo: error: cannot decode image"), lines


def test_what_native_code_writes_to_fd_2_while_decoding_is_kept_whole_and_off_stderr(capfd):
    said = b"libpng warning: iCCP: known incorrect sRGB profile\n" * 4000  # 200 kB, > a pipe

    def decode():
        for start in range(0, len(said), 4096):
            os.write(2, said[start : start + 4096])
        return "decoded"

    result, text = sensing._captured_stderr(decode)
    assert result == "decoded" and text == said[: sensing.MAX_DECODER_TEXT].decode()
    assert capfd.readouterr().err == ""
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"
