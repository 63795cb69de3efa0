"""The Droplet emulator: what it reads of the projected image, and its command line."""

import subprocess
import sys

import numpy as np
import pytest
from support import bad_value_outcomes, validated, value_options

from camo_droplet import emulator
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
    assert out.returncode == 2 and "--cell 9,9: outside the 8x8 arena" in out.stderr
    assert "--id" not in out.stderr  # the --cell at fault only, not --id too
    assert len(out.stderr.strip().splitlines()) == 1


def test_an_image_smaller_than_the_arena_is_said_as_sim_says_it(tmp_path):
    import cv2
    import numpy as np

    from camo_core.inputs.images import ImageError

    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((6, 40), np.uint8))  # 40 wide, 6 high
    args = emulator.build_parser().parse_args(
        ["--link", str(tmp_path / "x"), "--image", str(small)]
    )
    with pytest.raises(ImageError, match=r"small.png of 40x6 pixels is smaller than the 8x8 rob"):
        emulator.emulator_from(args)


@pytest.mark.parametrize(
    "options, said",
    [
        (["--id", "12"], "--id takes 4 hex digits, 0000..FFFF (got '12')"),
        (["--id", "0x1A"], "--id takes 4 hex digits"),
        (["--cell", "1_0,0"], "--cell takes ROW,COL (got '1_0,0')"),
        (["--cell", "\uff11,0"], "--cell takes ROW,COL"),
        (["--cell", "1,"], "--cell takes ROW,COL"),
    ],
)
def test_a_bad_id_or_cell_names_only_the_option_at_fault(tmp_path, options, said):
    from camo_core.exceptions import UsageError

    args = emulator.build_parser().parse_args(["--link", str(tmp_path / "x"), *options])
    with pytest.raises(UsageError) as caught:
        emulator.emulator_from(args)
    assert said in str(caught.value)
    assert ("--id" in str(caught.value)) == (options[0] == "--id")


# ---- every option with bad values (issue 27) -------------------------------------------------


@pytest.mark.parametrize("option", value_options(emulator.build_parser()))
def test_every_option_of_the_emulator_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line is checked: making the pty is replaced.
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(emulator, "DropletEmulator", validated)
    argv = [] if option == "--link" else ["--link", str(tmp_path / "pty")]
    assert bad_value_outcomes(emulator.main, argv, option, capsys, emulator.build_parser()) == []


@pytest.mark.parametrize("option", ["--delay", "--disconnect-for"])
@pytest.mark.parametrize("value", ["nan", "1e300", "inf"])
def test_a_fault_of_no_finite_duration_is_refused(option, value, tmp_path, capsys):
    argv = ["--link", str(tmp_path / "pty"), option, value]
    argv += ["--disconnect-after", "1"] if option == "--disconnect-for" else []
    assert emulator.main(argv) == 2
    err = capsys.readouterr().err  # nan and inf are no numbers to a Parser's type=float
    assert "must be seconds in 0..3600" in err or f"invalid float value: '{value}'" in err


@pytest.mark.parametrize("there", ["file", "folder", "tmp file", "pty link"])
def test_a_link_path_that_is_not_an_emulators_is_never_replaced(tmp_path, there):
    """A file, a folder, or a file where the link's temporary name goes: one line, kept.
    An emulator's old link to a pseudo-terminal is taken over."""
    import os

    from camo_core.exceptions import UsageError

    link = tmp_path / "droplet"
    if there == "file":
        link.write_text("mine")
    elif there == "folder":
        link.mkdir()
    elif there == "tmp file":
        (tmp_path / "droplet.tmp").write_text("mine")
    else:
        os.symlink("/dev/pts/999", link)
    args = emulator.build_parser().parse_args(["--link", str(link), "--cell", "0,0"])
    made = emulator.emulator_from(args)
    if there == "pty link":
        made.start()
        try:
            target = os.readlink(link)
            assert target.startswith("/dev/pts/") and target != "/dev/pts/999"
        finally:
            made.stop()
        return
    with pytest.raises(UsageError, match="is never replaced") as refused:
        made.start()
    assert "\n" not in str(refused.value)
    kept = tmp_path / ("droplet.tmp" if there == "tmp file" else "droplet")
    assert kept.is_dir() if there == "folder" else kept.read_text() == "mine"


def test_a_disconnects_length_without_disconnects_is_one_line_naming_both(tmp_path):
    from camo_core.exceptions import UsageError

    link = ["--link", str(tmp_path / "x")]
    emulator.build_parser().parse_args([*link, "--disconnect-after", "3", "--disconnect-for", "1"])
    with pytest.raises(UsageError, match="--disconnect-for needs --disconnect-after"):
        emulator.build_parser().parse_args([*link, "--disconnect-for", "1"])


@pytest.mark.parametrize("where", ["folder", "under a file"])
def test_an_led_log_that_cannot_be_appended_to_is_one_line_at_start(tmp_path, where):
    # A folder failed only at the first LED command, in the serving thread: no more replies.
    from camo_core.exceptions import UsageError

    (tmp_path / "file").write_text("")
    log = tmp_path if where == "folder" else tmp_path / "file" / "led.log"
    args = emulator.build_parser().parse_args(
        ["--link", str(tmp_path / "x"), "--led-log", str(log)]
    )
    with pytest.raises(UsageError, match="--led-log"):
        emulator.emulator_from(args)
