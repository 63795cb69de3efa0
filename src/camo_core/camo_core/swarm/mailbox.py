"""Where delivered messages wait for their step: one robot's, or shared by a process's robots.

A robot takes a step's messages all at once, when every neighbour it waits for
has sent (protocol.py). A process hosting thousands of robots keeps each message
once, by sender, in one mailbox its robots read from, and wakes the robots that
hear the sender, instead of handing every message to every robot that hears it:
a vote heard by eight robots costs one insertion and a few set operations, not
eight calls (docs/swarm.md). A robot driven message by message (`deliver`, the
tests' in-memory buses) has a mailbox of its own.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from camo_core.algorithm.link import LinkBook

Key = tuple[int, str, int]  # (round, kind, step)
EMPTY: Mapping[Any, Any] = MappingProxyType({})


class Mailbox:
    """Messages by (round, kind, step), then by sender. `readers`: the robots that take each
    step's messages; a step's messages are forgotten once all of them have taken it, and a
    message that comes after that (a late one nobody waits for any more) is not kept."""

    def __init__(self, readers: int = 1, link: LinkBook | None = None) -> None:
        self.readers = readers
        # The link's draws for the robots that read it, made for all of them at once (None: each
        # robot draws its own).
        self.link = link
        self.boxes: dict[Key, dict[int, Any]] = {}
        self.spoke: dict[int, int] = {}  # messages put, per sender: a silent one speaks again
        self._taken: dict[Key, int] = {}  # readers that took each step (a few keys a round)
        # Rounds whose hellos came (ascending), and the latest: a robot hearing a neighbour's
        # hello of a later round than its own joins it (protocol.py).
        self.hello_rounds: list[int] = []
        self.newest = -1

    def put(self, key: Key, sender: int, value: Any) -> None:
        self.spoke[sender] = self.spoke.get(sender, 0) + 1
        box = self.boxes.get(key)
        if box is not None:
            box[sender] = value
        elif not self.finished(key):
            self.boxes[key] = {sender: value}
            if key[1] == "hello" and key[0] not in self.hello_rounds:
                self.hello_rounds.append(key[0])
                self.hello_rounds.sort()
                self.newest = self.hello_rounds[-1]

    # A step's messages by sender; read with any key (a robot looks up None for a slot
    # without a neighbour, and finds nothing).
    def box(self, key: Key) -> Mapping[Any, Any]:
        """What has come for this step so far, by sender."""
        return self.boxes.get(key, EMPTY)

    def take(self, key: Key) -> Mapping[Any, Any]:
        """This step's messages, for one reader."""
        taken = self._taken.get(key, 0) + 1
        self._taken[key] = taken
        if taken >= self.readers:
            return self.boxes.pop(key, EMPTY)
        return self.boxes.get(key, EMPTY)

    def finished(self, key: Key) -> bool:
        """Whether every reader has taken this step: what comes for it now is kept by no one."""
        return self._taken.get(key, 0) >= self.readers

    def hello_rounds_after(self, round_: int) -> list[int]:
        """The rounds later than `round_` that hellos came for, latest first."""
        return [r for r in reversed(self.hello_rounds) if r > round_]

    def forget_before(self, round_: int) -> None:
        """Drop what was kept of rounds before `round_`: none of the readers is in them any more
        (a superseded round's messages are never all taken)."""
        self.boxes = {k: v for k, v in self.boxes.items() if k[0] >= round_}
        self._taken = {k: v for k, v in self._taken.items() if k[0] >= round_}
        self.hello_rounds = [r for r in self.hello_rounds if r >= round_]
