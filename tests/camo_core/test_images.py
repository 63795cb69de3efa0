"""Reading image files: every level checked, each failure one line, decoders kept quiet."""

import os
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support import PROCESS, png_bytes

from camo_core.inputs import images
from camo_core.inputs.images import ImageError


def _noise(width: int = 64, height: int = 48) -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _truncated_jpeg() -> bytes:
    ok, data = cv2.imencode(".jpg", _noise())
    assert ok
    return data.tobytes()[: len(data) // 2]


def _bmp_of_width(width: int) -> bytes:
    ok, data = cv2.imencode(".bmp", _noise())
    assert ok
    data = bytearray(data.tobytes())
    data[18:22] = width.to_bytes(4, "little", signed=True)
    return bytes(data)


def _one_line_image_error(path):
    with pytest.raises(ImageError) as caught:
        images.load_image(path)
    message = str(caught.value)
    assert message and "\n" not in message and len(message) < 300, message
    return message


def test_image_errors_are_clear(tmp_path):
    with pytest.raises(ImageError, match="not found"):
        images.load_image(tmp_path / "missing.png")
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(ImageError, match="cannot read"):
        images.load_image(corrupt)


def test_colour_alpha_and_grey_files_load(tmp_path):
    bgra = np.zeros((16, 16, 4), np.uint8)
    bgra[..., 2] = 200
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    assert images.load_image(tmp_path / "a.png").shape == (16, 16, 3)
    cv2.imwrite(str(tmp_path / "g.png"), np.full((16, 16), 7, np.uint8))
    assert images.load_image(tmp_path / "g.png").shape == (16, 16)


def test_an_image_whose_header_claims_too_many_pixels_is_refused_before_decoding(tmp_path):
    big = tmp_path / "big.png"
    big.write_bytes(png_bytes(100_000, 100_000, pixels=(8, 8)))
    assert "pixels" in _one_line_image_error(big)
    wide = tmp_path / "wide.png"  # under Pillow's own bomb limit, over ours
    wide.write_bytes(png_bytes(images.MAX_IMAGE_PIXELS // 4 + 1, 4, pixels=(8, 8)))
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
    monkeypatch.setattr(images, "MAX_IMAGE_BYTES", 10)
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
    image = images.load_image(tmp_path / "deep.png")
    assert image.dtype == np.uint8 and image.shape[:2] == (8, 8)
    (tmp_path / "tiny.png").write_bytes(png_bytes(3, 2))
    assert images.load_image(tmp_path / "tiny.png").shape == (2, 3)


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
        image = images.load_image(path)
    except ImageError as exc:
        assert str(exc) and "\n" not in str(exc)
    else:  # only a header that told the truth about its 8x8 grey 8-bit pixels loads
        assert (width, height, depth, colour) == (8, 8, 8, 0)
        assert image.shape == (8, 8) and image.dtype == np.uint8


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
        images.load_image(path)
    assert capfd.readouterr().err == ""


def test_a_png_with_only_a_harmless_libpng_warning_loads_and_writes_nothing(tmp_path, capfd):
    path = tmp_path / "short_profile.png"
    profile = b"p\0\0" + zlib.compress(b"garbage")  # "iCCP: too short"
    path.write_bytes(png_bytes(16, 16, extra=((b"iCCP", profile),)))
    assert images.load_image(path).shape == (16, 16)
    assert capfd.readouterr().err == ""


def test_a_float_tiff_opencv_cannot_bring_to_eight_bits_is_refused_with_its_reason(
    tmp_path, capfd
):
    path = tmp_path / "float.tiff"
    assert cv2.imwrite(str(path), np.random.default_rng(0).random((8, 8)).astype(np.float32))
    with pytest.raises(ImageError, match=r"the decoder says 'OpenCV TIFF: .*32-bit samples'"):
        images.load_image(path)
    assert capfd.readouterr().err == ""


def test_decoder_messages_are_matched_as_damage_or_dropped_as_harmless():
    said = images.decoder_messages(
        "[ WARN:0@0.078] global grfmt_tiff.cpp:811 readData OpenCV TIFF: Sorry, no\n\n"
        "libpng warning: iCCP: known incorrect sRGB profile\n"
    )
    assert said == ["OpenCV TIFF: Sorry, no", "libpng warning: iCCP: known incorrect sRGB profile"]
    damage = [m for m in said if images.DECODER_DAMAGE.search(m)]
    assert damage == ["OpenCV TIFF: Sorry, no"]
    for harmless in ("libpng warning: iCCP: too short", "Warning: unknown JFIF revision number"):
        assert not images.DECODER_DAMAGE.search(harmless)
    for bad in ("Corrupt JPEG data: 3 extraneous bytes before marker 0xd9", "libpng error: x"):
        assert images.DECODER_DAMAGE.search(bad)


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
        images.load_image(path)


def test_a_top_down_bmp_of_negative_height_still_loads(tmp_path):
    _, data = cv2.imencode(".bmp", _noise())
    data = bytearray(data.tobytes())
    data[22:26] = (-48).to_bytes(4, "little", signed=True)
    path = tmp_path / "top_down.bmp"
    path.write_bytes(bytes(data))
    assert images.load_image(path).shape == (48, 64, 3)


def test_a_pillow_limit_is_named_by_what_it_limits_not_pillows_internals(tmp_path):
    path = tmp_path / "text_bomb.png"
    text = b"k\0\0" + zlib.compress(b"a" * (4 * 1024 * 1024))  # zTXt of 4 MB
    path.write_bytes(png_bytes(16, 16, extra=((b"zTXt", text),)))
    with pytest.raises(ImageError, match="Pillow's limit on metadata") as error:
        images.load_image(path)
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
        images.load_image(path)
    frames[0].save(tmp_path / f"one_frame.{suffix}")
    assert images.load_image(tmp_path / f"one_frame.{suffix}").shape[:2] == (16, 16)


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

    result, text = images.captured_stderr(decode)
    assert result == "decoded" and text == said[: images.MAX_DECODER_TEXT].decode()
    assert capfd.readouterr().err == ""
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"
