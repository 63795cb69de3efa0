"""A real Droplet as a robot's sensor and display: its colour sensor and its LED. No ROS here.

Both share one serial link and one Reconnector: a port that goes away is
reopened with backoff; meanwhile the sensor gives no reading (the robot waits
and its neighbours treat it as silent) and the LED change waits until the port
is back.
"""

from __future__ import annotations

import logging
import time

from camo_core.algorithm.params import ParameterError
from camo_core.algorithm.sensing import Calibration, Reading, rgb_to_gray
from camo_core.exceptions import CamoError
from camo_droplet.link import DropletDisconnected, DropletError, DropletLink

MAX_BACKOFF = 8.0
log = logging.getLogger("camo.droplet")


def parse_rgb(text: str) -> tuple[int, int, int]:
    try:
        rgb = tuple(int(x) for x in text.replace(",", " ").split())
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(0 <= c <= 255 for c in rgb):
        raise ParameterError(
            f"an LED colour is three integers 0..255, e.g. '255 0 0' (got {text!r})"
        )
    return rgb


class Reconnector:
    """Opens the link again after it went away, waiting longer after each failure."""

    def __init__(self, link: DropletLink, logger: logging.Logger = log) -> None:
        self.link = link
        self.logger = logger
        self.backoff = 0.5
        self.next_try = 0.0

    def ensure(self) -> bool:
        if self.link.connected:
            return True
        now = time.monotonic()
        if now < self.next_try:
            return False
        try:
            self.link.open()
        except DropletDisconnected as exc:
            self.next_try = now + self.backoff
            self.logger.warning(f"{exc}; next try in {self.backoff:g} s")
            self.backoff = min(MAX_BACKOFF, self.backoff * 2)
            return False
        self.backoff = 0.5
        if self.next_try:  # an earlier open failed or the port went away
            self.logger.info(f"reconnected to {self.link.path}")
        return True

    def failed(self, exc: DropletError) -> None:
        if isinstance(exc, DropletDisconnected):
            self.logger.warning(f"{exc}: the robot is offline until the port is back")
            self.next_try = time.monotonic() + self.backoff


class DropletSensor:
    """get_rgb, as the profile's grey, then the calibration. A real reading: no simulated
    measurement noise."""

    def __init__(
        self, link: DropletLink, reconnector: Reconnector, profile: str, calibration: Calibration
    ) -> None:
        self.link, self.reconnector = link, reconnector
        self.profile, self.calibration = profile, calibration

    def read(self) -> Reading | None:
        if not self.reconnector.ensure():
            return None
        try:
            r, g, b = self.link.get_rgb()
        except DropletDisconnected as exc:
            self.reconnector.failed(exc)
            return None
        except DropletError as exc:
            self.reconnector.logger.warning(f"{exc}; reading again")
            return None
        grey = self.calibration.apply(rgb_to_gray(r, g, b, self.profile))
        self.reconnector.logger.info(f"read r {r} g {g} b {b}: grey {grey:g}")
        # Its colour, calibrated channel by channel as its grey is (--colours shows it).
        rgb = (self.calibration.apply(r), self.calibration.apply(g), self.calibration.apply(b))
        return Reading(grey, real=True, rgb=rgb)

    def next_round(self, frame: int) -> None:
        """The projector changed what the Droplet sees: nothing to do here."""

    def ok(self) -> bool:
        return self.link.connected


class DropletLed:
    """The formation state on the LED (`on` when the state is 1; with --colours the palette
    colour the robot shows). keep() is called periodically: it learns the Droplet's id once and
    sets a colour that could not be set earlier."""

    def __init__(
        self,
        link: DropletLink,
        reconnector: Reconnector,
        on: tuple[int, int, int] = (255, 0, 0),
        off: tuple[int, int, int] = (255, 255, 255),
        cell: tuple[int, int] = (0, 0),
    ) -> None:
        self.link, self.reconnector = link, reconnector
        self.colors = {1: on, 0: off}
        self.cell = cell
        self.shown: tuple[int, int, int] | None = None
        self.wanted: tuple[int, int, int] | None = None
        self.droplet_id: int | None = None

    def keep(self) -> None:
        if not self.reconnector.ensure():
            return
        try:
            if self.droplet_id is None:
                self.droplet_id = self.link.get_id()
                self.reconnector.logger.info(
                    f"Droplet {self.droplet_id:04X} on {self.link.path} is robot {self.cell}"
                )
            if self.wanted is not None and self.wanted != self.shown:
                self.link.set_led(*self.wanted)
                self.shown = self.wanted
        except DropletDisconnected as exc:
            self.reconnector.failed(exc)
        except CamoError as exc:
            self.reconnector.logger.warning(str(exc))

    def show(self, state: int, colour: tuple[int, int, int] | None = None) -> None:
        self.wanted = self.colors[int(state)] if colour is None else colour
        if self.wanted != self.shown:
            self.keep()

    def ready(self) -> bool:
        if self.wanted != self.shown:
            self.keep()
        return self.wanted == self.shown

    def ok(self) -> bool:
        return self.link.connected
