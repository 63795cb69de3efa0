"""`./camo droplet-emulator`: a pseudo-terminal that behaves like a Droplet with its stock
firmware.

On the other end of a pty (reachable through a stable symlink, so that a
bridge can reconnect after a "disconnect"), it echoes each command, ends its
lines in \\r\\n and answers the stock firmware's commands: `get_id`, `get_rgb` (the
mean colour of the projected image's block at its cell), `set_led rgb R G B`
(logged, and appended to --led-log as JSON lines), `msg`/`tgt` (accepted),
anything else `\\tCommand ( WORD ) not recognized.` Faults on demand: dropped
replies, delays, garbage and over-long lines, chatter of the robot's own
program, and disconnects. No ROS here.
"""

from __future__ import annotations

import argparse
import json
import os
import pty
import random
import re
import select
import sys
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camo_core.algorithm.backgrounds import BACKGROUNDS, background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import block_means, check_covers
from camo_core.cli.options import Combination, Parser, a_path, add_options, options_of
from camo_core.exceptions import CamoError, UsageError
from camo_core.inputs.files import shown
from camo_core.inputs.images import load_image
from camo_core.inputs.numeric import integer, items
from camo_core.shutdown import interrupt_on_signals

MAX_FAULT_S = 3600.0  # s: the longest delay or disconnect an emulated fault lasts


@dataclass
class Faults:
    drop: float = 0.0  # probability that a reply (and its echo) is not sent
    delay: float = 0.0  # seconds before every reply
    garbage: float = 0.0  # probability of a garbage or over-long line before a reply
    chatter: float = 0.0  # probability of a line of the robot's own program before a reply
    disconnect_after: int = 0  # vanish after this many commands (0: never) ...
    disconnect_for: float = 2.0  # ... for this many seconds, then come back on the same link


def emulated_rgb(
    image: np.ndarray, rows: int, cols: int, row: int, col: int
) -> tuple[int, int, int]:
    """What a Droplet at (row, col) reads of the projected image: its block's mean colour,
    rounded."""
    bgr = image if image.ndim == 3 else np.repeat(image[:, :, None], 3, axis=2)
    means = block_means(bgr, rows, cols)[row, col]
    b, g, r = (int(np.clip(np.rint(v), 0, 255)) for v in means)
    return r, g, b


def _a_pty_link(path: Path) -> bool:
    """A symlink to a pseudo-terminal: an emulator's link (this one's, or a dead one's)."""
    try:
        return path.is_symlink() and os.readlink(path).startswith("/dev/pts/")
    except OSError:
        return False


class DropletEmulator:
    def __init__(
        self,
        link: str | Path,
        droplet_id: int,
        rgb: tuple[int, int, int],
        faults: Faults | None = None,
        led_log: str | Path | None = None,
        seed: int = 0,
    ) -> None:
        self.link = Path(link)
        self.droplet_id = droplet_id
        self.rgb = rgb
        self.faults = faults or Faults()
        self.led_log = Path(led_log) if led_log else None
        self.random = random.Random(seed)
        self.led: tuple[int, int, int] | None = None
        self.commands = 0
        self.disconnects = 0
        self._stop = threading.Event()
        self._master = self._slave = None
        self._thread: threading.Thread | None = None

    # ---- the pty ------------------------------------------------------------------

    def _attach(self) -> None:
        for path in (self.link, self.link.with_name(self.link.name + ".tmp")):
            if (path.exists() or path.is_symlink()) and not _a_pty_link(path):
                raise UsageError(
                    f"--link {path} is there already and is not an emulator's link to a "
                    "pseudo-terminal: it is never replaced; give another path"
                )
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)  # no line discipline: bytes pass as a UART passes them
        tmp = self.link.with_name(self.link.name + ".tmp")
        tmp.unlink(missing_ok=True)
        os.symlink(os.ttyname(self._slave), tmp)
        os.replace(tmp, self.link)

    def _detach(self) -> None:  # the link is this emulator's own (checked when made)
        self.link.unlink(missing_ok=True)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None

    def start(self) -> DropletEmulator:
        try:
            self._attach()
        except OSError as exc:
            raise CamoError(f"cannot make the pty link {self.link}: {exc.strerror}") from None
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread:
            self._thread.join(timeout=5)
        self._detach()

    # ---- the firmware -------------------------------------------------------------

    def _send(self, text: str) -> None:
        os.write(self._master, text.encode("ascii", "replace"))

    def _serve(self) -> None:
        pending = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self._master, 1024)
            except OSError:
                continue
            for byte in data:
                if byte in (10, 13):
                    if pending:
                        self._line(pending.decode("ascii", "replace").strip())
                        pending = bytearray()
                else:
                    pending.append(byte)

    def _line(self, text: str) -> None:
        self.commands += 1
        f = self.faults
        if f.disconnect_after and self.commands % f.disconnect_after == 0:
            self.disconnects += 1
            print(
                f"droplet-emulator {self.droplet_id:04X}: "
                f"disconnecting for {f.disconnect_for:g} s",
                file=sys.stderr,
            )
            self._detach()
            self._stop.wait(f.disconnect_for)
            self._attach()
            return
        if f.drop and self.random.random() < f.drop:
            return
        if f.delay:
            time.sleep(f.delay)
        self._send(text + "\r\n")  # the echo
        if f.garbage and self.random.random() < f.garbage:
            junk = bytes(self.random.randrange(128, 256) for _ in range(12))
            self._send(
                junk.decode("latin-1") + "\r\n"
                if self.random.random() < 0.5
                else "#" * 300 + "\r\n"
            )
        if f.chatter and self.random.random() < f.chatter:
            self._send(f"Px: {self.random.random():0.4f} Py: {self.random.random():0.4f}\r\n")
        words = text.split()
        if not words:
            return
        if words[0] == "get_id":
            self._send(f"My ID is: {self.droplet_id:04X}\r\n")
        elif words[0] == "get_rgb":
            r, g, b = self.rgb
            self._send(f"r: {r}, g: {g}, b: {b}\r\n")
        elif words[0] == "set_led" and len(words) == 5 and words[1] == "rgb":
            try:
                self.led = tuple(min(255, max(0, int(w))) for w in words[2:5])
            except ValueError:
                return
            if self.led_log:
                with open(self.led_log, "a") as out:
                    out.write(json.dumps({"time": time.time(), "rgb": list(self.led)}) + "\n")
        elif words[0] in ("msg", "tgt"):
            pass
        else:
            self._send(f"\tCommand ( {words[0]} ) not recognized.\r\n")


def build_parser() -> Parser:
    parser = Parser(
        prog="camo droplet-emulator",
        description="a Droplet with stock firmware on a pseudo-terminal",
    )
    parser.add_argument(
        "--link",
        required=True,
        type=a_path,
        help="path of the symlink to the pty (the bridge's PORT)",
    )
    parser.add_argument(
        "--id", default="1A2B", help="the Droplet's id, 4 hex digits (default 1A2B)"
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--image", help="projected image file")
    source.add_argument(
        "--pattern", choices=BACKGROUNDS, default=None, help="built-in background (default forest)"
    )
    add_options(parser, CamoParams, only=("rows", "cols"))  # the arena's grid of robots
    parser.add_argument("--cell", default="0,0", help="ROW,COL of this Droplet in the arena")
    parser.add_argument(
        "--led-log", type=a_path, default=None, help="append every LED setting here (JSON lines)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the injected faults")
    for name, kind, text in (
        ("drop", float, "probability of a dropped reply"),
        ("delay", float, "seconds per reply"),
        ("garbage", float, "probability of a garbage line"),
        ("chatter", float, "probability of an unasked line"),
        ("disconnect-after", int, "disconnect after this many commands (0: never)"),
        ("disconnect-for", float, "seconds a disconnect lasts"),
    ):
        parser.add_argument(
            f"--{name}",
            type=kind,
            default=Faults.__dataclass_fields__[name.replace("-", "_")].default,
            help=text,
        )
    parser.combine(
        Combination("--disconnect-for", needs=("--disconnect-after",), why="how long each lasts")
    )
    return parser


def emulator_from(args: argparse.Namespace) -> DropletEmulator:
    arena = CamoParams.from_options(**options_of(args, CamoParams))
    if not re.fullmatch(r"[0-9A-Fa-f]{4}", args.id, re.ASCII):
        raise UsageError(f"--id takes 4 hex digits, 0000..FFFF (got {args.id!r})")
    droplet_id = int(args.id, 16)
    try:
        row, col = (integer(x) for x in items(args.cell, "--cell"))
    except ValueError:
        raise UsageError(f"--cell takes ROW,COL (got {args.cell!r})") from None
    if not (0 <= row < arena.rows and 0 <= col < arena.cols):
        raise UsageError(f"--cell {args.cell}: outside the {arena.rows}x{arena.cols} arena")
    for name in ("drop", "garbage", "chatter"):
        if not 0 <= getattr(args, name) <= 1:
            raise UsageError(f"--{name} is a probability in 0..1")
    for name in ("delay", "disconnect_for"):  # not NaN, which `< 0` lets through
        if not 0 <= getattr(args, name) <= MAX_FAULT_S:
            flag = "--" + name.replace("_", "-")
            raise UsageError(f"{flag} must be seconds in 0..{MAX_FAULT_S:g}")
    if args.disconnect_after < 0:
        raise UsageError("--disconnect-after must not be negative")
    image = (
        load_image(args.image) if args.image is not None else background(args.pattern or "forest")
    )
    what = f"image {shown(args.image)}" if args.image is not None else "the built-in image"
    check_covers(image.shape[1], image.shape[0], arena.rows, arena.cols, what)  # as sim says it
    if args.led_log is not None:  # appended to at every LED command: a folder would fail then
        log = Path(args.led_log)
        if log.exists() and not log.is_file():
            raise UsageError(f"--led-log {shown(log)} is not a file: give a file to append to")
        if not log.parent.is_dir():
            raise UsageError(f"--led-log {shown(log)}: {shown(log.parent)} is not a folder")
    faults = Faults(
        args.drop,
        args.delay,
        args.garbage,
        args.chatter,
        args.disconnect_after,
        args.disconnect_for,
    )
    return DropletEmulator(
        args.link,
        droplet_id,
        emulated_rgb(image, arena.rows, arena.cols, row, col),
        faults,
        args.led_log,
        args.seed,
    )


def main(argv: list[str] | None = None) -> int:
    try:
        emulator = emulator_from(build_parser().parse_args(argv))
        emulator.start()
    except CamoError as exc:
        print(f"camo droplet-emulator: error: {exc}", file=sys.stderr)
        return 2
    interrupt_on_signals()  # Ctrl-C and SIGTERM stop it cleanly
    r, g, b = emulator.rgb
    print(
        f"droplet-emulator {emulator.droplet_id:04X}: on {emulator.link}, reads r {r} g {g} b {b} "
        f"(Ctrl-C to stop)",
        file=sys.stderr,
        flush=True,
    )
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        emulator.stop()
        print(
            f"droplet-emulator {emulator.droplet_id:04X}: {emulator.commands} commands, last LED "
            f"{emulator.led}",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
