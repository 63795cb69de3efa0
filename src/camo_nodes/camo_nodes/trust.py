"""Who may speak for which robots, and the count of what was refused.

Any process in a run's domain can publish on its topics. DDS tells a message's
writer by its GID, whose first 12 bytes name the writer's process (its
participant): so a robot message is accepted only from the process that hosts
its sender, and a process hosts the tiles it announced first (trust on first
use: the run's own processes announce as they start, and only tiles of the
run's layout count). A background is taken only if its pixels are one of the
run's backgrounds (their digests are in the run's setup); without a setup that
lists them (a robot alone, a background replayed from a bag) the first writer
of the background is trusted. Everything refused is counted by reason and
logged once per sender.

A stranger that announces a tile before its real host does takes it in every
process that heard it first: they no longer hear the real host, and which one
each process heard first, no other can tell. So a tile of the run's own
processes announced by a process its launcher did not start is a conflict the
launcher ends the run on (`held_by_others`), and a worker started by hand
refuses, or leaves, cells another process announces. What this cannot stop: a
process that forges DDS packets with another process's GUID, or announces
under the name of one of the launcher's own (DDS Security stops both; see
docs/security.md).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from rclpy.serialization import deserialize_message

from camo_core.swarm.run_setup import RunSetup
from camo_msgs.msg import Host
from camo_nodes.rcl_take import PREFIX

# The reason a process reports (in its host announcement) for another process announcing
# tiles it hosts itself: its launcher ends the run on it even before hearing that process.
OWN_TILES_CLAIMED = "announcement of tiles this process hosts"


class Rejections:
    """Messages refused, by reason; the first from each writing process is logged."""

    def __init__(self, logger) -> None:
        self.logger = logger
        self.counts: Counter = Counter()
        self._logged: set[bytes] = set()

    def refuse(self, reason: str, gid: bytes, about: str = "") -> None:
        """`gid`: the writer's; `about`: what the message claimed to be (`robot 7`, say)."""
        self.counts[reason] += 1
        process = gid[:PREFIX]
        if process not in self._logged:
            self._logged.add(process)
            claimed = f" ({about})" if about else ""
            self.logger.warning(
                f"refused a message{claimed} from the process with GUID prefix {process.hex()}: "
                f"{reason}; further ones from it are only counted"
            )

    def decoded(self, data: bytes, msg_type, gid: bytes, what: str):
        """The message `data` holds, or None, refused as `what` that does not decode (bytes a
        stranger wrote on the topic)."""
        try:
            return deserialize_message(data, msg_type)
        except Exception:  # noqa: BLE001 - rclpy's deserializer raises several kinds
            self.refuse(f"{what} that does not decode", gid)
            return None

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def as_dict(self) -> dict:
        return {"total": self.total, "by_reason": dict(sorted(self.counts.items()))}


def merged(*reports: dict) -> dict:
    """The sum of several as_dict() reports."""
    counts: Counter = Counter()
    for report in reports:
        counts.update(report.get("by_reason", {}))
    return {"total": sum(counts.values()), "by_reason": dict(sorted(counts.items()))}


class Hosts:
    """Which process (by GID prefix) hosts which robots: the first to announce a tile. With the
    run's layout (its setup's `tiles` and `remote` ranges), only a tile of the layout, or one
    inside the cells left to remote workers, can be announced at all. Every process that
    announced a tile is kept (`claims`), first or not."""

    def __init__(self, count: int, rejections: Rejections, setup: RunSetup | None = None) -> None:
        self.count = count
        self.rejections = rejections
        self.layout: set[tuple[int, int]] | None = None
        if setup is not None and setup.tiles:
            self.layout = set(setup.tiles)
            self.remote = list(setup.remote)
        self.owner: dict[int, bytes] = {}  # robot -> the prefix of its host
        self.tiles: dict[tuple[int, int], bytes] = {}
        self.refused: dict[bytes, dict] = {}  # host prefix -> what it reported refusing
        self.names: dict[bytes, str] = {}  # host prefix -> the name it announced first
        self.claims: dict[tuple[int, int], set[bytes]] = {}  # tile -> every prefix announcing it

    def learn(self, msg: Host, gid: bytes) -> list[tuple[int, int]]:
        """An announcement: the tiles it gives its writer's process for the first time."""
        prefix = gid[:PREFIX]
        self.names.setdefault(prefix, msg.name)
        self.refused[prefix] = {
            "by_reason": dict(zip(msg.rejected_reasons, msg.rejected_counts, strict=False))
        }
        new = []
        for first, last in zip(msg.first, msg.last, strict=False):
            if not 0 <= first <= last < self.count or len(msg.first) != len(msg.last):
                self.rejections.refuse("host announcement out of range", gid, msg.name)
                continue
            if self.layout is not None and not self._planned(first, last):
                self.rejections.refuse("host announcement of a tile not in the run", gid, msg.name)
                continue
            self.claims.setdefault((first, last), set()).add(prefix)
            claimed = {self.owner.get(r) for r in range(first, last + 1)} - {None}
            if claimed - {prefix}:
                self.rejections.refuse("tile already hosted by another process", gid, msg.name)
                continue
            if (first, last) not in self.tiles:
                self.tiles[(first, last)] = prefix
                for robot in range(first, last + 1):
                    self.owner[robot] = prefix
                new.append((first, last))
        return new

    def _planned(self, first: int, last: int) -> bool:
        return (first, last) in self.layout or any(
            a <= first and last <= b for a, b in self.remote
        )

    def speaks_for(self, gid: bytes, robot: int) -> bool:
        return self.owner.get(robot) == gid[:PREFIX]

    def held_by_others(self, tiles, ours: Callable[[bytes], bool]) -> Conflict | None:
        """Of `tiles`, those a process not one of `ours` (by GUID prefix) announced, or announced
        cells of, first or not (which announcement another process heard first, this one cannot
        know), with that process: the tiles of the first such process, or None."""
        found: dict[bytes, list[tuple[int, int]]] = {}
        for (a, b), prefixes in self.claims.items():
            strangers = [p for p in prefixes if not ours(p)]
            for tile in tiles if strangers else ():
                if a <= tile[1] and tile[0] <= b:
                    for prefix in strangers:
                        if tile not in found.setdefault(prefix, []):
                            found[prefix].append(tile)
        if not found:
            return None
        prefix = min(found)
        return Conflict(sorted(found[prefix]), self.names.get(prefix, ""), prefix)


@dataclass(frozen=True)
class Conflict:
    """Tiles a process announced that are not its to host: wherever its announcement was heard
    first, nobody hears their rightful host. `name` is the node name the process gave itself
    (anything it likes), `prefix` its GUID prefix (what DDS says of it)."""

    tiles: list[tuple[int, int]]
    name: str
    prefix: bytes

    @property
    def cells(self) -> str:
        return ", ".join(f"{a}-{b}" if a != b else str(a) for a, b in self.tiles)

    @property
    def process(self) -> str:
        return f"node {self.name or '(unnamed)'}, GUID prefix {self.prefix.hex()}"


class FirstWriter:
    """A topic with one rightful writer: the first one heard."""

    def __init__(self) -> None:
        self.gid: bytes | None = None

    def allows(self, gid: bytes) -> bool:
        if self.gid is None:
            self.gid = gid
        return gid == self.gid


class BackgroundCheck:
    """Whether a background may be used. With the run's digests: only the next of the run's
    backgrounds, in order (the current one again is a repeat, not a new round). Without them:
    whatever its first writer sends."""

    REPEAT = ""  # problem() for the background in use, heard again: ignore it quietly

    def __init__(self, setup: RunSetup | None) -> None:
        self.digests = list(setup.background_digests if setup is not None else ())
        self.taken = 0
        self.first = FirstWriter()

    def problem(self, digest: str, gid: bytes) -> str | None:
        """None to take it, REPEAT to ignore it, else why it is refused."""
        if not self.digests:
            return None if self.first.allows(gid) else "a background from a second writer"
        if self.taken < len(self.digests) and digest == self.digests[self.taken]:
            self.taken += 1
            return None
        if self.taken and digest == self.digests[self.taken - 1]:
            return self.REPEAT
        return "a background that is not the run's next one"
