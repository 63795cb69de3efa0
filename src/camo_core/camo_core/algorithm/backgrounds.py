"""Built-in 128 x 128 grey backgrounds, drawn by code (no downloads).

desert: horizontal dunes; forest: vertical trunks; leopard: rosettes. Each is
deterministic, so a run on a built-in background is reproducible.
"""

from __future__ import annotations

import cv2
import numpy as np

from camo_core.inputs.images import ImageError

SIZE = 128
BACKGROUNDS = ("desert", "forest", "leopard")


def desert(size: int = SIZE) -> np.ndarray:
    """Bright sand with dark, gently wavy dune shadows running left to right."""
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    wobble = 3.0 * np.sin(2 * np.pi * x / 97.0) + 2.0 * np.sin(2 * np.pi * x / 41.0 + 1.0)
    dunes = np.sin(2 * np.pi * (y + wobble) / 32.0)
    ripples = 0.15 * np.sin(2 * np.pi * (y + 0.5 * wobble) / 5.0)
    image = 140.0 + 95.0 * dunes + 12.0 * ripples + rng.normal(0.0, 6.0, (size, size))
    return _to_uint8(cv2.GaussianBlur(image, (3, 3), 0))


def forest(size: int = SIZE) -> np.ndarray:
    """Dark trunks standing on a light, misty background."""
    rng = np.random.default_rng(7)
    image = np.full((size, size), 200.0)
    image += 15.0 * np.sin(
        2 * np.pi * np.arange(size)[:, None] / 128.0
    )  # light mist, top to bottom
    for centre in range(8, size, 32):
        width = rng.uniform(11.0, 15.0)
        left = round(centre + rng.uniform(-2.0, 2.0) - width / 2)
        shade = rng.uniform(30.0, 55.0)
        cv2.rectangle(image, (left, 0), (left + int(width), size - 1), shade, thickness=-1)
    image += rng.normal(0.0, 8.0, (size, size))  # bark and leaves
    return _to_uint8(cv2.GaussianBlur(image, (3, 3), 0))


def leopard(size: int = SIZE) -> np.ndarray:
    """Tawny fur with small dark rosettes, finer than a robot's 16 x 16 block."""
    rng = np.random.default_rng(5)
    image = np.full((size, size), 170.0)
    spacing = 11.0
    for gy in np.arange(-spacing, size + spacing, spacing):
        for gx in np.arange(-spacing, size + spacing, spacing):
            cy = int(gy + rng.uniform(-2.5, 2.5))
            cx = int(gx + (spacing / 2 if int(gy / spacing) % 2 else 0) + rng.uniform(-2.5, 2.5))
            axes = (int(rng.integers(3, 5)), int(rng.integers(3, 5)))
            angle = float(rng.uniform(0, 180))
            cv2.ellipse(image, (cx, cy), axes, angle, 0, 360, 45.0, thickness=2)  # dark ring
            cv2.ellipse(image, (cx, cy), (axes[0] - 2, axes[1] - 2), angle, 0, 360, 120.0, -1)
    image += rng.normal(0.0, 6.0, (size, size))
    return _to_uint8(cv2.GaussianBlur(image, (3, 3), 0))


def stripes(
    degrees: float, period: float = 32, size: int = 256, noise: float = 40, seed: int = 0
) -> np.ndarray:
    """Noisy square-wave stripes running at `degrees` (counter-clockwise from horizontal, y up,
    as --orientation any counts them), `period` pixels from one dark band to the next: the test
    card of the orientation figures and tests."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    t = np.radians(degrees)
    across = -x * np.sin(t) - y * np.cos(t)  # distance across the stripes (rows point down)
    image = np.where((across / period) % 1 < 0.5, 60.0, 200.0)
    image += np.random.default_rng(seed).normal(0, noise, image.shape)
    return _to_uint8(image)


def background(name: str) -> np.ndarray:
    try:
        return {"desert": desert, "forest": forest, "leopard": leopard}[name]()
    except KeyError:
        raise ImageError(
            f"unknown built-in background {name!r} (choose from {', '.join(BACKGROUNDS)})"
        ) from None


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)
