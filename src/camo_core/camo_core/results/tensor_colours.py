"""Colours for structure tensors (--orientation any): a stripe direction's hue, a coherence's
saturation; used by figure.png, run.gif and a bag's timeline."""

from __future__ import annotations

import numpy as np


def tensor_rgb(p: np.ndarray) -> np.ndarray:
    """Tensors (... x 3) as colours: the hue is the stripe direction (0 to 180 degrees round
    the colour wheel), the saturation the coherence (white: no direction)."""
    jxx, jyy, jxy = p[..., 0], p[..., 1], p[..., 2]
    x, y = jxx - jyy, 2 * jxy
    with np.errstate(divide="ignore", invalid="ignore"):
        coherence = np.nan_to_num(np.sqrt(x * x + y * y) / (jxx + jyy))
    hue = ((90 - np.degrees(np.arctan2(y, x)) / 2) % 180) / 180
    hsv = np.stack([hue, np.clip(coherence / 0.5, 0, 1), np.full(hue.shape, 0.95)], axis=-1)
    import matplotlib.colors  # imported by what draws (a simulator's frames need not draw)

    return matplotlib.colors.hsv_to_rgb(hsv)


def direction_legend() -> list:
    """Legend patches for tensor_rgb's colours."""
    import matplotlib.patches

    angles = (0, 45, 90, 135)
    # matplotlib takes an RGB array as a colour, though its ColorType stub lists only tuples.
    patches = [
        matplotlib.patches.Patch(color=tensor_rgb(np.array(tensor_at(a))), label=f"{a}°")  # type: ignore[arg-type]
        for a in angles
    ]
    return [*patches, matplotlib.patches.Patch(facecolor="white", edgecolor="grey",
                                                label="no direction")]  # fmt: skip


def tensor_at(degrees: float) -> tuple[float, float, float]:
    """A fully coherent tensor of stripes at `degrees` (double angle 180 - 2 degrees)."""
    double = np.radians(180 - 2 * degrees)
    return 0.5 + 0.5 * np.cos(double), 0.5 - 0.5 * np.cos(double), 0.5 * np.sin(double)
