"""A Droplet's serial link against the emulator: replies, garbage, silence, disconnects."""

import json
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st
from support import COMPUTE

from camo_droplet.emulator import Faults
from camo_droplet.link import (
    DropletDisconnected,
    DropletError,
    DropletLink,
    LineReader,
)


def connected(em, **kwargs) -> DropletLink:
    link = DropletLink(str(em.link), **kwargs)
    link.open()
    return link


def test_line_reader_splits_crlf_and_discards_garbage_and_long_lines():
    reader = LineReader()
    lines = reader.feed(b"My ID is: 00C3\r\nr: 1, g: 2,") + reader.feed(
        b" b: 3\r\n\xff\xfe\x01junk\r\n"
    )
    lines += reader.feed(b"#" * 500 + b"\r\nok\n")
    assert lines == ["My ID is: 00C3", "r: 1, g: 2, b: 3", "ok"]
    assert reader.discarded == 2


@pytest.mark.slow(COMPUTE)
def test_link_reads_id_and_colour_and_sets_the_led(emulator):
    em = emulator(rgb=(200, 100, 50), droplet_id=0x00C3)
    link = connected(em)
    assert link.get_id() == 0x00C3
    assert link.get_rgb() == (200, 100, 50)
    link.set_led(255, 0, 0)
    assert em.led == (255, 0, 0)
    assert json.loads((em.led_log).read_text().splitlines()[-1])["rgb"] == [255, 0, 0]


@pytest.mark.slow(COMPUTE)
def test_unknown_command_is_an_error_naming_it(emulator):
    link = connected(emulator())
    with pytest.raises(DropletError, match="does not know the command 'blink'"):
        link.command("blink", None)
    assert link.get_rgb() == (10, 20, 30)  # and the link still works


@pytest.mark.slow(COMPUTE)
def test_link_survives_garbage_chatter_and_dropped_replies(emulator):
    em = emulator(faults=Faults(drop=0.3, garbage=0.5, chatter=0.5))
    link = connected(em, timeout=0.2, retries=8)
    for _ in range(15):
        assert link.get_rgb() == (10, 20, 30)
    assert link.reader.discarded > 0
    assert any(line.startswith("Px:") for line in link.poll())


@pytest.mark.slow(COMPUTE)
def test_a_robot_that_never_answers_gives_a_clear_error(emulator):
    link = connected(emulator(faults=Faults(drop=1.0)), timeout=0.1, retries=2)
    with pytest.raises(DropletError, match="did not answer 'get_rgb' \\(3 tries"):
        link.get_rgb()


@pytest.mark.slow(COMPUTE)
def test_a_port_that_disappears_raises_and_can_be_reopened(emulator):
    em = emulator(faults=Faults(disconnect_after=2, disconnect_for=0.5))
    link = connected(em)
    assert link.get_rgb() == (10, 20, 30)
    with pytest.raises(DropletDisconnected):
        link.get_rgb()
    assert not link.connected
    deadline = time.monotonic() + 10
    while True:
        try:
            link.open()
            break
        except DropletDisconnected:
            assert time.monotonic() < deadline
            time.sleep(0.1)
    assert link.get_rgb() == (10, 20, 30)


# ---- fuzzed: whatever a serial port sends -----------------------------------------------------


class ScriptedPort:
    """A port that answers every read with the next chunk of a script, then silence."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks = list(chunks)

    def read(self, size: int) -> bytes:
        return self.chunks.pop(0)[:size] if self.chunks else b""

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


@given(st.lists(st.binary(max_size=300), max_size=20))
def test_any_bytes_split_into_printable_bounded_lines(chunks):
    reader = LineReader()
    lines = [line for chunk in chunks for line in reader.feed(chunk)]
    assert all(len(line) <= 200 for line in lines)
    assert all(32 <= ord(c) < 127 or c == "\t" for line in lines for c in line)


REPLIES = [b"get_rgb\r\n", b"r: 1, g: 2, b: 3\r\n", b"r: 999, g: 0, b: 0\r\n", b"get_id\r\n"]
REPLIES += [b"My ID is: 00C3\r\n", b"\tCommand ( get_rgb ) not recognized.\r\n", b"\xff\x00"]


@pytest.mark.slow(COMPUTE)
@given(st.lists(st.one_of(st.sampled_from(REPLIES), st.binary(max_size=80)), max_size=12))
def test_a_command_answered_with_anything_returns_or_raises_a_droplet_error(chunks):
    link = DropletLink("/dev/fuzz", opener=lambda path: ScriptedPort(chunks), timeout=0.01)
    link.open()
    for command in (link.get_rgb, link.get_id):
        try:
            value = command()
        except DropletError as exc:
            assert "\n" not in str(exc)
        else:
            assert value == (1, 2, 3) or value == 0x00C3


def test_nul_bytes_and_a_line_one_byte_too_long_are_discarded_and_counted():
    reader = LineReader()
    lines = reader.feed(b"a\x00b\r\n" + b"x" * 201 + b"\r\n" + b"y" * 200 + b"\r\n")
    assert lines == ["y" * 200] and reader.discarded == 2


@pytest.mark.parametrize(
    "reply", [b"r: nan, g: 0, b: 0\r\n", b"r: -1, g: 0, b: 0\r\n", b"r: 1e3, g: 0, b: 0\r\n"]
)
def test_a_colour_reply_that_is_no_number_in_range_is_one_droplet_error(reply):
    chunks = [b"get_rgb\r\n", reply] * 3
    link = DropletLink("/dev/fuzz", opener=lambda path: ScriptedPort(chunks), timeout=0.01)
    link.open()
    with pytest.raises(DropletError) as caught:
        link.get_rgb()
    assert "\n" not in str(caught.value)
