"""run.gif: a round of the swarm step by step (drawn by matplotlib, written by Pillow).

Left, what the robots sensed (grey). Right, each consensus step with every robot coloured by
its p-vector (the mix of the three pattern colours it currently holds; with --orientation any
the direction its tensor says, pale where it says little), then each formation
step with every robot's state (dark = on). Dead, silent and bridged robots carry the marks
of figure.png.

Both drivers feed it the same way: the reference simulator calls a `Snapshots` at every step,
and the swarm's record is read into one afterwards. A long round is sampled (MAX_FRAMES) and a
large swarm shown by every k-th robot (MAX_SIDE), so the GIF stays small and quick to write.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, cast

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors
import matplotlib.patches
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

if TYPE_CHECKING:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

from camo_core.algorithm.patterns import PATTERN_COLORS
from camo_core.results.figures import draw_discs, mark
from camo_core.results.snapshots import Snapshots
from camo_core.results.tensor_colours import direction_legend

FRAME_S = 0.15
TITLE_CHARS = 84  # a title line at most, in the GIF's width


def write_animation(
    snapshots: Snapshots,
    sensed: np.ndarray,
    dead: np.ndarray,
    path: str | Path,
    title: str = "",
    marks: dict[str, np.ndarray] | None = None,
) -> Path:
    """run.gif of a round; `sensed` (greys, or colours x 3) and `dead` per robot, `marks` (name -> rows x cols, as
    figures.run_figure takes them) say which robots carry a mark, with their legend."""
    frames = snapshots.shown()
    sensed = np.asarray(sensed)
    coloured = sensed.size == 3 * snapshots.params.count
    # Only the cells a frame shows (a large grid's every few robots): greys, or colours (x 3).
    grey = np.nan_to_num(np.asarray(snapshots.cells(sensed), float), nan=128.0)
    fig, (left, right) = plt.subplots(1, 2, figsize=(6.4, 3.9), dpi=80)
    params = snapshots.params
    positions = snapshots.modes.layout.positions
    if positions is None:
        frames = [(text, _rgba_bytes(rgb)) for text, rgb in frames]
        if coloured:
            left.imshow(grey / 255.0, interpolation="nearest")
        else:
            left.imshow(grey, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        shown = right.imshow(frames[0][1], interpolation="nearest", animated=True)
    else:  # each robot a disc at its position, recoloured frame by frame
        draw_discs(left, positions, grey)
        shown = draw_discs(right, positions, np.zeros(len(positions)))
        shown.set_array(None)
        shown.set_animated(True)
    left.set_title("sensed colour" if coloured else "sensed grey", fontsize=9)
    caption = right.set_title(frames[0][0], fontsize=9)
    all_marks = {**(marks or {}), "dead": np.asarray(dead, bool)}
    all_marks = {name: snapshots.cells(mask) for name, mask in all_marks.items()}
    handles = []
    for ax in (left, right):
        ax.set_xticks([])
        ax.set_yticks([])
        handles = mark(ax, all_marks, positions)
    on_top = [caption, *(c for c in right.collections if c is not shown)]  # drawn over the frame
    for artist in on_top:
        artist.set_animated(True)
    if snapshots.modes.descriptor.oriented:
        handles += direction_legend()
    else:
        handles += [matplotlib.patches.Patch(color=c, label=n) for n, c in PATTERN_COLORS.items()]
    handles += [
        matplotlib.patches.Patch(facecolor="black", edgecolor="grey", label="formation: on"),
        matplotlib.patches.Patch(facecolor="white", edgecolor="grey", label="formation: off"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7)
    fig.suptitle("\n".join(textwrap.wrap(title, TITLE_CHARS)), fontsize=9)  # long labels too
    fig.tight_layout(rect=(0, 0.16, 1, 0.95))
    # Everything that does not change is drawn once; each frame redraws only the right panel's
    # image, caption and marks over it (matplotlib's blitting), 10x quicker than whole figures.
    canvas = cast("FigureCanvasAgg", fig.canvas)  # matplotlib.use("Agg") above
    canvas.draw()
    still = canvas.copy_from_bbox(fig.bbox)
    size = canvas.get_width_height()
    images = []
    for text, rgb in frames:
        canvas.restore_region(still)
        if positions is None:
            shown.set_data(rgb)
        else:
            shown.set_facecolor(rgb.reshape(-1, 3))
        caption.set_text(text)
        for artist in (shown, *on_top):
            fig.draw_artist(artist)
        # RGBA to RGB by PIL, from the canvas's own buffer: no copy of a strided array.
        frame = Image.frombuffer("RGBA", size, canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
        images.append(
            frame.convert("RGB").quantize(colors=255, method=Image.Quantize.FASTOCTREE)
        )
    plt.close(fig)
    path = Path(path)
    duration = round(FRAME_S * 1000)
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0)
    return path


def _rgba_bytes(rgb: np.ndarray) -> np.ndarray:
    """A frame's RGB (0..1) as the bytes matplotlib would make of it (clipped to 0..1, x 255,
    truncated), with alpha: an image of bytes is drawn without matplotlib's passes over
    floats, frame by frame."""
    rgba = np.empty((*rgb.shape[:-1], 4), np.uint8)
    np.multiply(np.clip(rgb, 0.0, 1.0), 255, out=rgba[..., :3], casting="unsafe")
    rgba[..., 3] = 255
    return rgba


MAX_JOINED = 20  # rounds a joined GIF shows at most: the latest
CARD_S = 1.5  # s a round's card (its frame and what it was) is shown


def round_card(folder: Path, size: tuple[int, int]) -> Image.Image | None:
    """A round's card: the frame it camouflaged (background.png), fitted in, and a caption
    from its summary.json (which round, which frame, who noticed the change, how soon)."""
    picture = folder / "background.png"
    if not picture.exists():
        return None
    from PIL import ImageDraw, ImageFont, ImageOps

    summary = json.loads((folder / "summary.json").read_text())
    card = Image.new("RGB", size, "white")
    with Image.open(picture) as frame:
        fitted = ImageOps.contain(frame.convert("RGB"), (size[0] - 20, size[1] - 60))
    card.paste(fitted, ((size[0] - fitted.width) // 2, 40))
    text = f"round {summary.get('round')}: frame {summary.get('frame')}"
    noticed, changed = summary.get("noticed_at"), summary.get("changed_at")
    if summary.get("noticed_by") is not None and noticed is not None and changed is not None:
        text += f", noticed by robot {summary['noticed_by']} {noticed - changed:.2f} s after it"
    ImageDraw.Draw(card).text((10, 10), text, fill="black", font=ImageFont.load_default(14))
    return card


def join_animations(folders: list[Path], path: str | Path) -> Path:
    """One GIF of several rounds (each folder's run.gif, after a card with the frame it
    camouflaged), one after another, the latest MAX_JOINED: a continuous run's scenes and how
    the swarm followed each."""
    images: list[Image.Image] = []
    durations: list[int] = []
    for folder in folders[-MAX_JOINED:]:
        with Image.open(folder / "run.gif") as gif:
            card = round_card(folder, gif.size)
            if card is not None:
                images.append(card.quantize(colors=255, method=Image.Quantize.FASTOCTREE))
                durations.append(round(CARD_S * 1000))
            for k in range(getattr(gif, "n_frames", 1)):
                gif.seek(k)
                frame = gif.convert("RGB")
                images.append(frame.quantize(colors=255, method=Image.Quantize.FASTOCTREE))
                durations.append(round(FRAME_S * 1000))
    path = Path(path)
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0)
    return path
