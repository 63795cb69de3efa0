"""Reading an image file, checked level by level (`load_image`): every background, video
frame and calibration picture camo reads from disk comes through here, and a file that
cannot be used is one ImageError line, never a traceback nor a decoder's noise on stderr.
"""

from __future__ import annotations

import os
import re
import struct
import sys
import threading
import warnings
from pathlib import Path

import cv2
import numpy as np

from camo_core.exceptions import CamoError
from camo_core.inputs.files import checked_file, shown


class ImageError(CamoError):
    """An image that cannot be used: missing, unreadable, too big, of an odd kind or too small."""


MAX_IMAGE_BYTES = 512 * 1024 * 1024  # on disk: a 2**27-pixel BMP is 400 MB
MAX_IMAGE_PIXELS = 2**27  # 16384 x 8192: a 8192 x 8192 grid's image and more, 400 MB as BGR
DEPTHS = (np.uint8, np.uint16, np.float32)  # what OpenCV's codecs decode to


# Pillow's limits name its internals ("Decompressed data too large for
# PngImagePlugin.MAX_TEXT_CHUNK"): say what they limit instead.
_PILLOW_LIMITS = re.compile(r"\b\w+ImagePlugin\.MAX_\w+")


def _check_raw_dimensions(path: Path) -> None:
    """ImageError for a PNG or BMP header whose width or height is zero or negative. Pillow
    does not say so: a PNG of width 0 is "not a known image format" to it, and a BMP of width
    -64 one of 4294967232 pixels, "more than MAX_IMAGE_PIXELS"."""
    try:
        with open(path, "rb") as file:
            head = file.read(26)
    except OSError:
        return  # Pillow, next, says what is wrong
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        kind, (width, height) = "PNG", struct.unpack(">ii", head[16:24])  # at most 2**31 - 1
    elif head[:2] == b"BM" and len(head) >= 26 and struct.unpack("<I", head[14:18])[0] >= 40:
        kind, (width, height) = "BMP", struct.unpack("<ii", head[18:26])
        height = abs(height)  # a negative height is a top-down BMP
    else:
        return
    for name, value in (("width", width), ("height", height)):
        if value < 1:
            raise ImageError(
                f"image {shown(path)}: its {kind} header says {name} {value}, not at least 1"
            )


def image_header(path: Path) -> tuple[int, int, str, str]:
    """(width, height, format, mode) from the file's header alone (Pillow reads no pixels), or
    ImageError: not an image Pillow recognises, or one that claims more than MAX_IMAGE_PIXELS."""
    from PIL import Image  # only here: Pillow is matplotlib's, we read headers with it

    _check_raw_dimensions(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as header:
                width, height = header.size
                kind, mode = header.format or "?", header.mode
                # MPO (a JPEG with previews or a stereo pair's second view) counts as one.
                animated = kind != "MPO" and bool(getattr(header, "is_animated", False))
    except Image.DecompressionBombError:
        raise ImageError(
            f"image {shown(path)}: its header claims more than {MAX_IMAGE_PIXELS} pixels"
        ) from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error, MemoryError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, Image.UnidentifiedImageError):
            detail = "not a known image format (PNG, JPEG, BMP, TIFF, WebP, ...)"
        detail = _PILLOW_LIMITS.sub("Pillow's limit on metadata", detail)
        raise ImageError(f"cannot read image {shown(path)}: {detail}") from None
    if width < 1 or height < 1:
        raise ImageError(f"image {shown(path)}: its header says {width}x{height} pixels")
    if width * height > MAX_IMAGE_PIXELS:
        raise ImageError(
            f"image {shown(path)}: its header claims {width}x{height} pixels, more than "
            f"{MAX_IMAGE_PIXELS} are not decoded"
        )
    if animated:
        raise ImageError(
            f"image {shown(path)}: a {kind} of more than one frame (an animation or a "
            "multi-page file); camo reads still images: save the one frame as its own file"
        )
    return width, height, kind, mode


# What the native decoders write to file descriptor 2 while they decode, as lines. Those that
# mean damaged or unreadable data refuse the image, quoting the first; the rest are dropped as
# harmless: libpng's warnings (about ancillary chunks: iCCP and sRGB colour profiles, text,
# gamma; common in valid PNGs, and none changes the pixels read), libjpeg's other warnings
# (an unknown JFIF revision, a thumbnail's size) and OpenCV's notes on a decoded image.
DECODER_DAMAGE = re.compile(
    r"libpng error|Premature end of JPEG|Corrupt JPEG data|JPEG datastream contains no image"
    r"|Invalid (SOS|JPEG)|Bogus|TIFF.*\b([Ee]rror|Sorry|[Cc]annot|can ?not)\b|\[\s*ERROR:"
)
_OPENCV_LOG = re.compile(r"^\[\s*\w+:[^\]]*\]\s+(?:global\s+)?\S+:\d+\s+\S+\s+(.*)$")
_STDERR = threading.Lock()  # fd 2 is the process's: one capture at a time
MAX_DECODER_TEXT = 64 * 1024  # read of what was written
MAX_QUOTED = 200  # characters of a decoder's message in camo's one line


def decoder_messages(text: str) -> list[str]:
    """What native decoders wrote, one message a line, OpenCV's log prefix taken off."""
    lines = (line.strip() for line in text.splitlines())
    return [(_OPENCV_LOG.sub(r"\1", line)).strip() for line in lines if line]


def captured_stderr(decode):
    """decode()'s result and what native code wrote to file descriptor 2 meanwhile (libpng,
    libjpeg and OpenCV's logging write there, around camo's one line of error), through a
    pipe a thread drains (no disk needed, no writer blocked on a full pipe). Anything another
    thread writes to fd 2 in that window is taken too: decoding is short."""
    with _STDERR:
        sys.stderr.flush()
        try:
            saved = os.dup(2)
        except OSError:  # no fd 2 (started with 2>&-): nothing to keep apart
            return decode(), ""
        try:
            read_end, write_end = os.pipe()
        except OSError:  # out of file descriptors: decode as OpenCV alone would
            os.close(saved)
            return decode(), ""
        chunks: list[bytes] = []

        def drain() -> None:
            kept = 0
            while block := os.read(read_end, 65536):
                if kept < MAX_DECODER_TEXT:
                    chunks.append(block)
                    kept += len(block)
            os.close(read_end)

        drainer = threading.Thread(target=drain, name="decoder-stderr", daemon=True)
        drainer.start()
        try:
            os.dup2(write_end, 2)
            try:
                result = decode()
            finally:
                os.dup2(saved, 2)
        finally:
            os.close(write_end)  # the drainer reads to its end
            os.close(saved)
            drainer.join()
    return result, b"".join(chunks)[:MAX_DECODER_TEXT].decode("utf-8", "replace")


def _decoded(path: Path, flags: int) -> np.ndarray | None:
    """cv2.imread, with what the decoders write to fd 2 kept from the terminal: an image they
    say is damaged (a truncated JPEG decodes, half grey, with only a warning) is an
    ImageError quoting their first word on it."""
    try:
        image, text = captured_stderr(lambda: cv2.imread(str(path), flags))
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1].strip() if str(exc).strip() else "cv2.error"
        raise ImageError(f"cannot decode image {shown(path)}: {detail}") from None
    messages = decoder_messages(text)
    damage = [m for m in messages if DECODER_DAMAGE.search(m)]
    if damage or (image is None and messages):
        said = (damage or messages)[0][:MAX_QUOTED]
        raise ImageError(f"cannot decode image {shown(path)}: the decoder says {said!r}")
    return image


def load_image(path: str | Path) -> np.ndarray:
    """Read an image as uint8, grey (H x W) or BGR (H x W x 3); alpha is dropped.

    Checked level by level, each failure an ImageError in one line: the path (empty, too long,
    missing, a folder, unreadable), the size on disk (MAX_IMAGE_BYTES), the header's dimensions
    before any pixel is decoded (at least 1, MAX_IMAGE_PIXELS in all) and its frames (one: an
    animation or a multi-page file is refused), the decoding (refused if the decoder says the
    data is damaged, see DECODER_DAMAGE; nothing it writes reaches stderr), and what it decoded
    to (dimensions as the header said, 1, 3 or 4 channels of 8 or 16 bits or float)."""
    path = checked_file(path, "image", MAX_IMAGE_BYTES, ImageError)
    width, height, kind, _ = image_header(path)
    image = _decoded(path, cv2.IMREAD_UNCHANGED)
    if image is None or image.size == 0:
        raise ImageError(
            f"cannot read image (not an image OpenCV understands, or corrupt): {shown(path)}"
        )
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise ImageError(f"image {shown(path)}: {image.shape} is not 1, 3 or 4 channels")
    if image.dtype not in DEPTHS:
        raise ImageError(f"image {shown(path)}: pixels of {image.dtype} are not read")
    if image.shape[0] * image.shape[1] != width * height:
        raise ImageError(
            f"image {shown(path)}: decoded as {image.shape[1]}x{image.shape[0]} pixels, its "
            f"{kind} header says {width}x{height}"
        )
    if image.dtype != np.uint8:
        # 16-bit or float images: bring to 0..255 the way OpenCV's IMREAD_COLOR does.
        image = _decoded(path, cv2.IMREAD_COLOR)
        if image is None or image.dtype != np.uint8:
            raise ImageError(f"cannot convert image {shown(path)} to 8 bits")
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    return image
