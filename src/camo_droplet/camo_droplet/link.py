"""A Droplet's serial link (its USB serial commands): no ROS here.

The robot echoes every command, ends its lines in \\r\\n and prints lines of its
own program at any time. A command is sent, its echo awaited, then the line
that answers it; anything else that arrives meanwhile is kept as an
asynchronous line (monitor mode reads them). Bytes that are not printable
text and over-long lines are discarded and counted. A missing or slow reply is
retried; `\\tCommand ( X ) not recognized.` is an error naming the command; a
port that disappears raises DropletDisconnected, and reconnect() opens it
again.
"""

from __future__ import annotations

import logging
import re
import time
from collections import deque
from collections.abc import Callable

from camo_core.exceptions import CamoError

BAUD = 115200
REFUSAL_WAIT = 0.05  # seconds to listen for "not recognized" after a command without reply
MAX_LINE = 200  # longer lines are noise: the firmware's longest print is ~60 bytes
NOT_RECOGNIZED = re.compile(r"^\s*Command \( (.*) \) not recognized\.\s*$")
ID_REPLY = re.compile(r"^My ID is: ([0-9A-Fa-f]{4})$")
RGB_REPLY = re.compile(r"^r: (\d+), g: (\d+), b: (\d+)$")

log = logging.getLogger("camo.droplet")


class DropletError(CamoError):
    """The Droplet did not do what was asked (after retries), or refused the command."""


class DropletDisconnected(DropletError):
    """The serial port went away."""


class LineReader:
    """Splits a byte stream into printable lines; counts what it throws away."""

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.skipping = False
        self.discarded = 0  # garbage lines and over-long lines
        self._warned = False

    def feed(self, data: bytes) -> list[str]:
        lines = []
        for byte in data:
            if byte in (10, 13):  # \r or \n ends a line; \r\n gives one empty line
                if self.buffer:
                    lines.extend(self._finish())
                self.skipping = False
                continue
            if self.skipping:  # the rest of an over-long line
                continue
            self.buffer.append(byte)
            if len(self.buffer) > MAX_LINE:
                self._discard(f"a line longer than {MAX_LINE} bytes")
                self.skipping = True
        return lines

    def _finish(self) -> list[str]:
        raw, self.buffer = bytes(self.buffer), bytearray()
        if all(32 <= b < 127 or b == 9 for b in raw):
            return [raw.decode("ascii")]
        self._discard("bytes that are not text")
        return []

    def _discard(self, what: str) -> None:
        self.buffer = bytearray()
        self.discarded += 1
        if not self._warned:
            self._warned = True
            log.warning("discarding %s from the Droplet (further discards are only counted)", what)


class DropletLink:
    """Commands over one serial port. `opener(path)` returns a pyserial-like port
    (read/write/close)."""

    def __init__(
        self,
        path: str,
        opener: Callable[[str], object] | None = None,
        timeout: float = 0.5,
        retries: int = 3,
    ) -> None:
        self.path = path
        self.opener = opener or open_serial
        self.timeout = timeout
        self.retries = retries
        self.reader = LineReader()
        self.lines: deque[str] = deque()
        self.asynchronous: deque[str] = deque(
            maxlen=10_000
        )  # the robot's own prints, for monitor mode
        self.port = None

    # ---- connection -------------------------------------------------------------

    def open(self) -> None:
        try:
            self.port = self.opener(self.path)
        except (OSError, ValueError) as exc:  # serial.SerialException is an OSError
            self.port = None
            raise DropletDisconnected(f"cannot open {self.path}: {exc}") from None
        self.lines.clear()
        self.reader.buffer = bytearray()

    @property
    def connected(self) -> bool:
        return self.port is not None

    def close(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except OSError:
                pass
        self.port = None

    def _lost(self, exc: Exception) -> DropletDisconnected:
        self.close()
        return DropletDisconnected(f"{self.path} went away: {exc}")

    # ---- bytes and lines --------------------------------------------------------

    def _write(self, text: str) -> None:
        if self.port is None:
            raise DropletDisconnected(f"{self.path} is not open")
        try:
            self.port.write(text.encode("ascii"))
        except (OSError, ValueError) as exc:
            raise self._lost(exc) from None

    def _read_line(self, deadline: float) -> str | None:
        while not self.lines:
            if time.monotonic() >= deadline:
                return None
            if self.port is None:
                raise DropletDisconnected(f"{self.path} is not open")
            try:
                data = self.port.read(256)
            except (OSError, ValueError, TypeError) as exc:
                raise self._lost(exc) from None
            if data:
                self.lines.extend(self.reader.feed(data))
        return self.lines.popleft()

    def poll(self, seconds: float = 0.0) -> list[str]:
        """Lines that arrived unasked (the robot's own prints), waiting up to `seconds` for one."""
        deadline = time.monotonic() + seconds
        while True:
            line = self._read_line(deadline)
            if line is None:
                break
            self.asynchronous.append(line)
            deadline = time.monotonic()  # take what is there, do not wait again
        out = list(self.asynchronous)
        self.asynchronous.clear()
        return out

    # ---- commands ---------------------------------------------------------------

    def command(self, text: str, reply: re.Pattern | None) -> re.Match | None:
        """Send one command; wait for its echo and (if `reply`) the line matching it. Retries on
        silence."""
        for attempt in range(1 + self.retries):
            self._write(text + "\r")
            deadline = time.monotonic() + self.timeout
            echoed = False
            while True:
                line = self._read_line(deadline)
                if line is None:
                    if echoed and reply is None:
                        return None
                    break  # silence: try again
                refused = NOT_RECOGNIZED.match(line)
                if refused:
                    raise DropletError(
                        f"the Droplet on {self.path} does not know the command "
                        f"'{refused.group(1)}' (old firmware?)"
                    )
                if not echoed and line.strip() == text:
                    echoed = True
                    if reply is None:
                        # No answer expected: only a refusal would follow, right after the echo.
                        deadline = min(deadline, time.monotonic() + REFUSAL_WAIT)
                    continue
                match = reply.match(line.strip()) if (echoed and reply is not None) else None
                if match:
                    return match
                self.asynchronous.append(line)
            log.debug("no answer to %r from %s (attempt %d)", text, self.path, attempt + 1)
        raise DropletError(
            f"the Droplet on {self.path} did not answer '{text}' "
            f"({1 + self.retries} tries, {self.timeout:g} s each)"
        )

    def get_id(self) -> int:
        return int(self.command("get_id", ID_REPLY).group(1), 16)

    def get_rgb(self) -> tuple[int, int, int]:
        match = self.command("get_rgb", RGB_REPLY)
        rgb = tuple(int(match.group(k)) for k in (1, 2, 3))
        if max(rgb) > 255:
            raise DropletError(f"the Droplet on {self.path} read an impossible colour {rgb}")
        return rgb

    def set_led(self, r: int, g: int, b: int) -> None:
        self.command(f"set_led rgb {int(r)} {int(g)} {int(b)}", None)


def open_serial(path: str):
    """115200 8N1 with a short read timeout, as the Droplets talk."""
    import serial

    return serial.Serial(
        path,
        BAUD,
        bytesize=serial.EIGHTBITS,
        parity=serial.PARITY_NONE,
        stopbits=serial.STOPBITS_ONE,
        timeout=0.05,
        write_timeout=1.0,
    )
