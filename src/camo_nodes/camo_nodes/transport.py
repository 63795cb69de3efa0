"""How a process's robots exchange messages: memory between themselves, tile topics for the world.

A process hosts one or more *tiles* of robots (contiguous ranges of robot ids,
row-major: bands of the grid). Each tile publishes on eight topics, one per
message kind for its *edge* robots (those with a neighbour hosted elsewhere)
and one per kind for the rest (its *core*), every message carrying its
sender's id (`RunTopics.tile`). What a tile's robots send on one topic between
two writes goes out as one DDS message, their columns (`camo_msgs/Votes`, ...,
`robot_messages.py`): a DDS write costs many times what packing one more robot
message into it does (docs/swarm.md). Edge topics are written between generations of
deliveries (`pump`), core topics once per turn of the host's loop. A robot
hosted by the same process as its neighbour gets the message handed over in
memory, as rclcpp's intra-process communication does. A process subscribes
only to the edge topics of the tiles that hold its robots' neighbours, which it
learns from the tiles' hosts' announcements (`camo_msgs/Host`, latched); a
recorder or a viewer subscribes to all of them. So the DDS endpoints of a run
grow with its processes, not with robots x neighbours, and a process takes only
the messages its robots need (a tile's two boundary rows, not the whole band).

The edge subscriptions (and the hosts', and the background's) are not spun by
the executor: `poll()` takes their messages with their publisher's GID
(`rcl_take.py`), so that a message is accepted only from its sender's host
(`trust.py`), and only once it passes camo_core's checks (`validation.py`).
Every take and every pump is bounded: a poll takes a few arrays per topic, a
pump hands messages over for PUMP_BUDGET seconds, and the rest waits for the
host loop's next turn, so that its timers, stop flag and heartbeats keep up
whatever the load. The transport also judges its neighbours' processes by
their heartbeats (`heartbeat.py`, `camo_core.swarm.liveness`): `alive()`
is what a robot asks before it gives up on a late neighbour.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Callable, Iterable

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from camo_core.algorithm.layout import slot_ids
from camo_core.algorithm.link import LinkBook
from camo_core.algorithm.params import CamoParams
from camo_core.swarm.liveness import Liveness
from camo_core.swarm.mailbox import Key, Mailbox
from camo_core.swarm.robot_io import (
    CONSENSUS,
    DONE,
    NOTHING,
    Message,
    Output,
    Report,
    kinds_of,
    messages_per_round,
)
from camo_core.swarm.run_setup import RunSetup
from camo_core.swarm.status_rows import StatusRows
from camo_core.swarm.validation import message_problem, phase_problem
from camo_msgs.msg import Heartbeat, Host, StatusArray
from camo_nodes.heartbeat import HeartbeatThread
from camo_nodes.polled import PolledTopics
from camo_nodes.rcl_take import PREFIX, publisher_gid
from camo_nodes.topics import keyed
from camo_nodes.topics.names import RunTopics, tile_name
from camo_nodes.topics.qos import HEARTBEAT_READER, LATCHED, LATCHED_READER, history_qos
from camo_nodes.topics.robot_messages import COLUMN_TYPES, Columns, RaggedColumns, stamp, unpack
from camo_nodes.trust import OWN_TILES_CLAIMED, Conflict, Hosts, Rejections

# Robot messages in one array at most: a process's pump can send several steps of thousands of
# robots, and a DDS message past Fast DDS's shared-memory segment (512 KB) is slow.
MAX_BATCH = 256
# A process's statuses go out as one array a STATUS_PERIOD (s), of MAX_STATUS_BYTES at most: an
# array past Fast DDS's shared-memory segment (512 KB) goes out in UDP fragments, slowly (eight
# stopping 256x256 workers, each sending its robots' last reports as two arrays of 4096 rows,
# took more than 5 s).
STATUS_PERIOD = 0.2
MAX_STATUS_BYTES = 256 * 1024
STATUS_ROW_BYTES = 128  # a status row's fixed fields, about; its traces and lists on top
CLOSE_ACK_WAIT = 1.0  # s a closing process waits for its last statuses to be acknowledged
# Arrays taken from one edge topic per poll at most (each up to MAX_BATCH robot messages).
EDGE_TAKE = 4
# Seconds a pump hands messages to robots per call at most: the rest is handed over on the
# host loop's next turn, after its timers, heartbeat and stop flag have had theirs.
PUMP_BUDGET = 0.02
Wake = Callable[[float], Output]  # a robot's protocol, told at `now` that messages came for it
Emit = Callable[[Output, float], None]  # what a robot does with its protocol's output at `now`
Tile = tuple[int, int]  # first and last robot id, inclusive


def messages_per_robot(params: CamoParams, kind: str) -> int:
    """History a topic keeps per robot on it: a whole phase, so that a process (or a recorder)
    that joins late still gets every message of the round."""
    return messages_per_round(params)[kind] + 4


def status_depth(params: CamoParams) -> int:
    """Statuses one robot sends in a round (one per step and phase change)."""
    return messages_per_round(params)["vote"] + params.formation_steps + 8


def listener_qos() -> QoSProfile:
    """A reader of a tile's edge: everything, in order (a late joiner gets the history)."""
    return QoSProfile(
        depth=1,
        history=HistoryPolicy.KEEP_ALL,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def edge_of(params: CamoParams, hosted: set[int], robots: Iterable[int]) -> set[int]:
    """Robots with a neighbour (any of the 12 slots, or a layout's) this process does not
    host."""
    edge = set()
    for robot in robots:
        if any(n is not None and n not in hosted for n in slot_ids(params, robot)):
            edge.add(robot)
    return edge


def times_a_round(report: Report) -> bool:
    """A report that says when its robot voted (entered consensus) or finished: what a run's
    timing is measured by, so it goes out at the end of the turn, not the period."""
    return report.phase == DONE or (report.phase == CONSENSUS and report.step == 0)


def row_bytes(report: Report) -> int:
    """A report's size in a StatusArray, about."""
    traces = 8 * len(report.p_trace) + len(report.state_trace)
    lists = 4 * len(report.silent) + len(report.palette) + 8 * len(report.sensed_rgb)
    return STATUS_ROW_BYTES + traces + lists + len(report.palette_rgb) + len(report.shades)


class Statuses:
    """What a process's robots reported since the last write: one StatusArray per STATUS_PERIOD
    (or MAX_STATUS_BYTES of reports), and at the end of a turn in which a robot voted or
    finished (the array's stamp is when its robots said so), not a message per report."""

    def __init__(self, writer, name: str) -> None:
        self.writer = writer
        self.name = name
        self.reports: list[Report] = []
        self.size = 0  # bytes of `reports` as a StatusArray, about
        self.written = time.monotonic()
        self.timed = False  # a report that times the round waits in `reports`

    def add(self, report: Report) -> None:
        size = row_bytes(report)
        if self.reports and self.size + size > MAX_STATUS_BYTES:
            self.flush()
        self.reports.append(report)
        self.size += size
        self.timed = self.timed or times_a_round(report)

    def flush(self, now: float | None = None) -> None:
        """Write what was reported (with `now`: only once STATUS_PERIOD has passed, or a report
        times the round)."""
        if not self.reports:
            return
        if now is not None and not self.timed and now - self.written < STATUS_PERIOD:
            return
        reports, self.reports, self.timed, self.size = self.reports, [], False, 0
        msg = StatusArray(name=self.name, **StatusRows.from_reports(reports).message_fields())
        stamp(msg)
        self.writer.publish(msg)
        self.written = time.monotonic()


class Batch(Columns):
    """What a tile's robots send on one topic, until the next flush: one message of columns."""

    def __init__(self, writer, kind: str, edge: bool) -> None:
        super().__init__(kind)
        self.writer = writer
        self.edge = edge  # read by other processes' robots (else by recorders and viewers only)

    def flush(self) -> None:
        if self.sender:
            self.writer.publish(self.take())


class Transport:
    """The DDS endpoints of one process's robots, owned by one node (the process's own)."""

    def __init__(
        self,
        node: Node,
        params: CamoParams,
        topics: RunTopics,
        tiles: list[Tile],
        setup: RunSetup | None = None,
        step_timeout: float = 30.0,
    ) -> None:
        """`setup`: the run's parameters message, whose layout says which tiles may be hosted;
        `step_timeout`: a process silent that long is dead (`liveness.py`)."""
        self.node = node
        self.setup = setup
        self.params = params
        self.topics = topics
        self.tiles = tiles
        self.hosted = {r for first, last in tiles for r in range(first, last + 1)}
        self.edge = edge_of(params, self.hosted, self.hosted)
        self.kinds = kinds_of(params)  # the kinds of message this run's robots send
        self.batches: dict[tuple[int, str], Batch] = {}  # (robot, kind) -> its topic's batch
        self._unsent: list[Batch] = []  # batches holding messages, to publish at the next flush
        self._unsent_edges: list[Batch] = []  # those of them other processes' robots wait for
        for first, last in tiles:
            self._create_writers(first, last)
        status_pub = keyed.publisher(
            node,
            StatusArray,
            topics.status,
            history_qos(status_depth(params) * len(self.hosted)),
            topics.run,
        )
        self.statuses = Statuses(status_pub, node.get_name())
        self.status_pub = status_pub
        # Each message is kept once, in the mailbox the hosted robots share, and wakes the
        # robots that hear its sender (by robot id; `_robots`: their wake and emit).
        # The simulated link's draws are made for all of them at once (a lossy swarm steps as
        # fast as a loss-free one).
        self.mailbox = Mailbox(readers=len(self.hosted), link=LinkBook(sorted(self.hosted)))
        self.targets: dict[tuple[int, str], list[int]] = defaultdict(list)
        self._robots: dict[int, tuple[Wake, Emit]] = {}
        self.needed: set[int] = set()  # neighbours hosted elsewhere
        self.remote: set[tuple[int, int]] = set()  # tiles subscribed to
        self.rejected = Rejections(node.get_logger())
        self.trusted = Hosts(params.count, self.rejected, setup)
        # Each message taken from another process, once, by step (round, kind, step) then
        # sender: a second, different one for the same step is refused. A step is let go once
        # every hosted robot took it (`flush`), a round whole (`forget_before`), so that a long
        # round keeps only the steps under way.
        self._seen: dict[Key, dict[int, object]] = {}
        # Robots to wake: those that heard something since the generation being woken began,
        # and what is left of that generation.
        self._woken: set[int] = set()
        self._generation: list[int] = []
        self._announced_rejections = 0
        self.polled = PolledTopics(
            f"{node.get_name()}_edges",
            node.get_namespace(),
            node.context,
            topics.run,
            self.rejected.refuse,
        )
        self.host_pub = keyed.publisher(node, Host, topics.hosts, LATCHED, topics.run)
        self.own = publisher_gid(self.host_pub)[:PREFIX]  # this process, as DDS names it
        # This process's tiles as another process announced them too: wherever that one was
        # heard first, this one's robots go unheard (trust.py).
        self.conflict: Conflict | None = None
        self.listen(Host, topics.hosts, LATCHED_READER, self._on_host)
        # Which processes are alive, by their heartbeats; this one's own beats from now on (its
        # robot nodes are still to be created: a neighbour waits for them meanwhile).
        self.liveness = Liveness(step_timeout, self.trusted.owner.get, time.monotonic)
        self.offline: frozenset[int] = frozenset()  # hosted robots whose hardware is off
        self.listen(Heartbeat, topics.heartbeat, HEARTBEAT_READER, self._on_heartbeat, 256)
        self.announce()
        self.heartbeat = HeartbeatThread(node, topics)
        self.heartbeat.start()

    def _create_writers(self, first: int, last: int) -> None:
        robots = range(first, last + 1)
        edge = [r for r in robots if r in self.edge]
        parts = {"edge": edge, "core": [r for r in robots if r not in self.edge]}
        name = tile_name(first, last)
        for part, members in parts.items():
            if not members:
                continue
            for kind in self.kinds:
                # An array holds at least one message: at most as many arrays as messages.
                depth = len(members) * messages_per_robot(self.params, kind)
                writer = keyed.publisher(
                    self.node,
                    COLUMN_TYPES[kind],
                    self.topics.tile(name, part, kind),
                    history_qos(depth),
                    self.topics.run,
                    sealable=True,
                )
                batch = Batch(writer, kind, part == "edge")
                for robot in members:
                    self.batches[(robot, kind)] = batch

    def listen(self, msg_type, topic: str, qos: QoSProfile, handle, limit: int = 64) -> None:
        """Poll this topic: `handle(CDR bytes, publisher GID)` for each message, `limit` a turn
        at most."""
        self.polled.listen(msg_type, topic, qos, handle, limit)

    def alive(self, robot: int) -> bool:
        """Whether a robot is running: one of this process's, or one whose process beats (and
        whose hardware is on). A robot is never given up on while this holds."""
        if robot in self.hosted:
            return robot not in self.offline
        return self.liveness.robot_alive(robot)

    def _on_heartbeat(self, data: bytes, gid: bytes) -> None:
        msg = self.rejected.decoded(data, Heartbeat, gid, "a heartbeat")
        if msg is None:
            return
        offline = frozenset(int(r) for r in msg.offline[:1024])
        if not self.liveness.heard(gid[:PREFIX], offline):
            self.rejected.refuse("heartbeat of one process too many", gid, msg.name)

    def set_offline(self, robots: frozenset[int]) -> None:
        """This process's robots whose hardware is off: said in its heartbeats."""
        self.offline = robots
        self.heartbeat.offline = tuple(sorted(robots))

    def add(self, robot: int, hears: Iterable[tuple[int, str]], wake: Wake, emit: Emit) -> None:
        """A hosted robot (reading this transport's `mailbox`): what it hears from whom (`hears`:
        (sender, kind)), how it is told messages came (`wake`) and what it does with the answer
        (`emit`, unless NOTHING)."""
        if robot not in self.hosted:
            raise ValueError(f"robot {robot} is not hosted by this process")
        self._robots[robot] = (wake, emit)
        for sender, kind in hears:
            self.targets[(sender, kind)].append(robot)
            if sender not in self.hosted:
                self.needed.add(sender)

    def forget_before(self, round_: int) -> None:
        """What was kept of rounds before `round_`, which none of the hosted robots is in any
        more (continuous camouflage: a superseded round's messages are never all taken)."""
        self.mailbox.forget_before(round_)
        for old in [key for key in self._seen if key[0] < round_]:
            del self._seen[old]

    def check_hosted(self) -> None:
        """Every hosted robot was added: the mailbox forgets a step's messages once each of them
        (its `readers`) took the step, and one never added would keep every step in memory."""
        missing = len(self.hosted) - len(self._robots)
        if missing:
            raise ValueError(f"{missing} hosted robots were not added to the transport")

    def announce(self) -> None:
        """Say which tiles this process hosts, and what it has refused (latched)."""
        msg = Host(name=self.node.get_name(), first=[f for f, _ in self.tiles])
        msg.last = [last for _, last in self.tiles]
        counts = self.rejected.counts
        msg.rejected_reasons = list(counts)
        msg.rejected_counts = [counts[r] for r in msg.rejected_reasons]
        self._announced_rejections = self.rejected.total
        stamp(msg)
        self.host_pub.publish(msg)

    def announce_rejections(self) -> None:
        """Called now and then: a new announcement once more was refused."""
        if self.rejected.total != self._announced_rejections:
            self.announce()

    def _on_host(self, data: bytes, gid: bytes) -> None:
        msg = deserialize_message(data, Host)
        new = self.trusted.learn(msg, gid)
        if self.conflict is None and gid[:PREFIX] != self.own:
            self.conflict = self.trusted.held_by_others(self.tiles, lambda p: p == self.own)
            if self.conflict is not None:
                # Said at once: the launcher may not have heard that process yet (discovery
                # under load takes seconds), and a small run can end before it does.
                self.rejected.refuse(OWN_TILES_CLAIMED, gid, msg.name)
                self.announce()
        for first, last in new:
            if first in self.hosted or not any(first <= n <= last for n in self.needed):
                continue  # ours, or nothing there that this process's robots hear
            self.remote.add((first, last))
            name = tile_name(first, last)
            for kind in self.kinds:
                topic = self.topics.tile(name, "edge", kind)
                handle = self._robot_messages(kind)
                self.listen(COLUMN_TYPES[kind], topic, listener_qos(), handle, EDGE_TAKE)

    def _robot_messages(self, kind: str):
        cls = COLUMN_TYPES[kind]

        def handle(data: bytes, gid: bytes) -> None:
            msg = self.rejected.decoded(data, cls, gid, f"a tile's {kind} messages")
            if msg is None:
                return
            problem = phase_problem(kind, msg.phase)
            try:
                messages = [] if problem else unpack(kind, msg)
            except RaggedColumns as exc:
                problem = str(exc)
            if problem:  # the whole message: none of its columns can be trusted
                self.rejected.refuse(problem, gid, f"a tile's {kind} messages")
                return
            for message in messages:
                self._robot_message(message, gid)  # queued: poll() hands them over

        return handle

    def _robot_message(self, message: Message, gid: bytes) -> None:
        sender, kind = message.sender, message.kind
        if not self.trusted.speaks_for(gid, sender):
            self.rejected.refuse("not from the process hosting its sender", gid, f"robot {sender}")
            return
        problem = message_problem(message, self.params)
        if problem is not None:
            self.rejected.refuse(problem, gid, f"robot {sender}")
            return
        key = (message.round, kind, message.step)
        seen = self._seen.get(key)
        if seen is None:
            if self.mailbox.finished(key):
                return  # late: every hosted robot took its step, and nobody reads it
            seen = self._seen[key] = {}
        elif sender in seen:
            if seen[sender] != message.value:
                problem = "a second, different message for the same step"
                self.rejected.refuse(problem, gid, f"robot {sender}")
            return  # the same message again, or refused
        seen[sender] = message.value
        self._put(key, message)

    # ---- out ----------------------------------------------------------------------

    def send(self, message: Message) -> None:
        """To this process's robots at once; to the world at the next `flush()`."""
        key = (message.sender, message.kind)
        batch = self.batches[key]
        if not batch.sender:
            (self._unsent_edges if batch.edge else self._unsent).append(batch)
        batch.add(message)
        if len(batch.sender) >= MAX_BATCH:
            batch.flush()
        targets = self.targets.get(key)  # _put, written out: a robot's every step
        if targets:
            self.mailbox.put(
                (message.round, message.kind, message.step), message.sender, message.value
            )
            self._woken.update(targets)  # woken by the next pump: the host loop's

    def flush(self) -> None:
        """Publish what was sent since the last flush: one array per topic (the host's loop calls
        this after each turn)."""
        self._flush_edges()
        unsent, self._unsent = self._unsent, []
        for batch in unsent:
            batch.flush()
        self.statuses.flush(time.monotonic())
        self._forget_taken_steps()

    def _forget_taken_steps(self) -> None:
        """Let go of the steps every hosted robot took (a few keys: the steps under way)."""
        finished = self.mailbox.finished
        for key in [key for key in self._seen if finished(key)]:
            del self._seen[key]

    def _flush_edges(self) -> None:
        unsent, self._unsent_edges = self._unsent_edges, []
        for batch in unsent:
            batch.flush()

    def report(self, report: Report) -> None:
        """To monitors and recorders, in the process's next status array."""
        self.statuses.add(report)

    # ---- in -----------------------------------------------------------------------

    def poll(self) -> int:
        """Take what came from other processes (a bounded batch) and hand what is queued to the
        robots (for PUMP_BUDGET at most); how many messages were taken."""
        taken = self.polled.poll()
        self.pump()
        return taken

    @property
    def busy(self) -> bool:
        """Work is left for the next turn: robots to wake or messages waiting in a reader."""
        return bool(self._woken or self._generation) or self.polled.more

    def _put(self, key: Key, message: Message) -> None:
        """Into the mailbox under its step's `key`, once; the hosted robots that listen to its
        sender, to be woken."""
        targets = self.targets.get((message.sender, message.kind))
        if targets:
            self.mailbox.put(key, message.sender, message.value)
            self._woken.update(targets)

    def pump(self, budget: float = PUMP_BUDGET) -> None:
        """Wake the robots that heard something, in generations: first those woken by what came
        in, then those woken by what they sent, and so on; for `budget` seconds at most (the
        rest wait for the next turn). Between generations the edge topics are flushed, so that
        another process's robots get what they wait for before this process goes on with robots
        they do not hear."""
        robots, generation = self._robots, self._generation
        now = time.monotonic()
        end = now + budget
        woken = 0
        while generation or self._woken:
            if not generation:
                self._flush_edges()
                generation.extend(self._woken)
                self._woken.clear()
            wake, emit = robots[generation.pop()]
            out = wake(now)
            if out is not NOTHING:  # most wakes find a message still missing
                emit(out, now)
            woken += 1
            if not woken % 16:  # the clock a few times per batch of robots, not per robot
                now = time.monotonic()
                if now >= end:
                    break
        self._flush_edges()

    def close(self) -> None:
        """Before the node is destroyed: the takers use its subscriptions' handles, the
        heartbeat thread its publisher."""
        self.heartbeat.close()
        self.flush()
        self.statuses.flush()
        # The last statuses reach the monitor and the recorder before the process goes.
        self.status_pub.wait_for_all_acked(Duration(seconds=CLOSE_ACK_WAIT))
        self.polled.close()
