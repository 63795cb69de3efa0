"""The Droplet emulator: what it reads of the projected image, and its command line."""

import subprocess
import sys

import numpy as np

from camo_droplet.emulator import emulated_rgb


def test_emulator_reads_the_mean_colour_of_its_block():
    image = np.zeros((16, 16, 3), np.uint8)
    image[8:, 8:] = (10, 20, 30)  # BGR: bottom-right block
    image[8:12, 8:] = (10, 20, 40)
    assert emulated_rgb(image, 2, 2, 1, 1) == (35, 20, 10)
    assert emulated_rgb(image, 2, 2, 0, 0) == (0, 0, 0)


def test_emulator_command_line_rejects_bad_options(tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "camo_droplet.emulator",
            "--link",
            str(tmp_path / "x"),
            "--cell",
            "9,9",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "inside the 8x8 arena" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
