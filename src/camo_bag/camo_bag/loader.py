"""The one way into a bag: every level is checked before it is used, and a level that fails
gives one line (BagError), never a traceback.

1. The path: not empty, not too long, an existing, readable bag folder (or a lone .mcap
   file), holding metadata.yaml or an .mcap file.
2. metadata.yaml, when the folder has one: YAML, then rosbag2's bag information as camo
   writes and reads it (types, ranges, the files it names present), and each topic's
   offered QoS profiles (`qos_yaml.check_profiles`).
3. The MCAP file: its magic, then its records read with the `mcap` library, chunk CRCs
   checked. Without a summary (a recorder killed, a file cut) it is refused, unless opened
   `partial`: then it is read up to where it breaks (`bag repair`, `render --partial`).
   Each channel's QoS metadata is checked as metadata.yaml's is, and metadata.yaml must
   list the topics the file holds.
4. Schemas: a channel whose schema is not ros2msg text of a message type installed here,
   or whose text does not parse, is left out, and counted.
5. Messages: a reader that cannot decode a message's CDR as its type calls `reject`; the
   message is left out and counted. `note()` sums up what was left out in one line.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema

from camo_bag import msgdefs
from camo_bag.checks import (
    INT64_MAX,
    integer,
    listed,
    mapping,
    optional,
    shown,
    text,
)
from camo_bag.container import (
    DAMAGE,
    MAGIC,
    ROSBAG2_VERSION,
    BagError,
    BagMessage,
    BagSummary,
    BagWriter,
    TopicInfo,
    damaged,
)
from camo_bag.qos_yaml import check_profiles
from camo_bag.salvage import salvage
from camo_core.inputs.files import checked_path
from camo_core.inputs.strict_yaml import read_yaml
from camo_core.swarm.keys import Opener, RunKey, sealed, strip
from camo_nodes.topics.keyed import process_key, run_of

METADATA = "metadata.yaml"
METADATA_MAX = 64 * 1024 * 1024  # a metadata.yaml larger than this is not one camo wrote


# ---- level 1: the path ----------------------------------------------------------------


def bag_path(path: str | Path) -> Path:
    """The path, checked to name something that could be a bag (BagError otherwise)."""
    raw = os.fspath(path)
    if not raw.strip():
        raise BagError("no bag given (the path is empty)")
    if not raw.isprintable():
        raise BagError(f"{shown(raw)} is not a usable path: it holds a control character")
    path = checked_path(raw, "bag", BagError)  # too long for the system
    try:
        if not path.exists():
            raise BagError(f"{path}: no such bag")
        if path.is_dir():
            if not os.access(path, os.R_OK | os.X_OK):
                raise BagError(f"cannot read the bag folder {path}: permission denied")
        elif not path.is_file():
            raise BagError(f"{path} is neither a bag folder nor an .mcap file")
        elif path.suffix != ".mcap":
            raise BagError(f"{path} is neither a bag folder nor an .mcap file")
    except OSError as exc:
        raise BagError(f"cannot read {path}: {exc.strerror}") from None
    return path


# ---- level 2: metadata.yaml -----------------------------------------------------------

NANOSECONDS = mapping({"nanoseconds": integer(0, INT64_MAX)}, required=("nanoseconds",))
SINCE_EPOCH = mapping(
    {"nanoseconds_since_epoch": integer(0, INT64_MAX)}, required=("nanoseconds_since_epoch",)
)
COUNT = integer(0, INT64_MAX)


def topic_problem(name: str) -> str:
    """Why a topic name from a bag cannot be one ("" when it can)."""
    if not name.startswith("/") or not name.isprintable() or any(c.isspace() for c in name):
        return f"not a topic name starting with / ({shown(name)})"
    return ""


def _topic_name(value: Any, where: str) -> str:
    name = text(nonempty=True)(value, where)
    if topic_problem(name):
        raise BagError(f"{where} must be a topic name starting with / (got {shown(name)})")
    return name


def _type_name(value: Any, where: str) -> str:
    name = text(nonempty=True)(value, where)
    try:
        return msgdefs.full_name(name)
    except msgdefs.DefinitionError:
        raise BagError(f"{where} must be a message type pkg/msg/Type (got {name!r:.40})") from None


def _relative_file(value: Any, where: str) -> str:
    name = text(nonempty=True)(value, where)
    path = Path(name)
    if (
        not name.isprintable()
        or path.is_absolute()
        or ".." in path.parts
        or path.suffix != ".mcap"
    ):
        raise BagError(f"{where} must be an .mcap file inside the bag folder (got {shown(name)})")
    return name


TOPIC = mapping(
    {
        "topic_metadata": mapping(
            {
                "name": _topic_name,
                "type": _type_name,
                "serialization_format": text(["cdr"]),
                "offered_qos_profiles": lambda value, where: check_profiles(value, where),
                "type_description_hash": text(),
            },
            required=("name", "type", "serialization_format"),
        ),
        "message_count": COUNT,
    },
    required=("topic_metadata", "message_count"),
)
INFORMATION = mapping(
    {
        "version": integer(1, ROSBAG2_VERSION),
        "storage_identifier": text(["mcap"]),
        "relative_file_paths": listed(_relative_file, nonempty=True),
        "duration": NANOSECONDS,
        "starting_time": SINCE_EPOCH,
        "message_count": COUNT,
        "topics_with_message_count": listed(TOPIC),
        "compression_format": text(["", "zstd"]),
        "compression_mode": text(["", "file", "message", "FILE", "MESSAGE"]),
        "files": listed(
            mapping(
                {
                    "path": _relative_file,
                    "starting_time": SINCE_EPOCH,
                    "duration": NANOSECONDS,
                    "message_count": COUNT,
                },
                required=("path",),
            )
        ),
        "custom_data": optional(mapping({}, open_=True)),
        "ros_distro": text(),
    },
    required=(
        "version",
        "storage_identifier",
        "relative_file_paths",
        "duration",
        "starting_time",
        "message_count",
        "topics_with_message_count",
    ),
    open_=True,  # fields of rosbag2 versions to come
)
METADATA_FILE = mapping(
    {"rosbag2_bagfile_information": INFORMATION}, required=("rosbag2_bagfile_information",)
)


def load_metadata(file: Path) -> dict:
    """metadata.yaml's bag information, checked (BagError naming the first wrong value)."""
    data = read_yaml(file, "bag metadata", METADATA_MAX, BagError)  # strict, and not a FIFO
    info = METADATA_FILE(data, f"{file}:")["rosbag2_bagfile_information"]
    names = [t["topic_metadata"]["name"] for t in info["topics_with_message_count"]]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise BagError(f"{file} lists the topic {twice[0]} twice")
    if len(info["relative_file_paths"]) > 1:
        raise BagError(
            f"{file} names {len(info['relative_file_paths'])} files: camo reads bags of one file"
        )
    return info


# ---- levels 3 and 4: the MCAP file and its channels ------------------------------------


def check_magic(file: Path, tolerate: bool = False) -> str:
    """BagError unless `file` opens with MCAP's magic. One that ends with it (its closing
    magic) is an MCAP file whose first bytes are damaged: `tolerate` (bag repair) reads it by
    its records all the same, and says so (the returned note)."""
    try:
        with open(file, "rb") as stream:
            head = stream.read(len(MAGIC))
            size = stream.seek(0, 2)
            stream.seek(max(size - len(MAGIC), 0))
            tail = stream.read(len(MAGIC))
    except OSError as exc:
        raise BagError(f"cannot read {file}: {exc.strerror}") from None
    if head == MAGIC:
        return ""
    if tail == MAGIC and size > 2 * len(MAGIC):
        if tolerate:
            return "its opening magic is damaged: read by its records"
        raise BagError(
            f"{file}: its first bytes are damaged (it ends as an MCAP file does); "
            f"`./camo bag repair` writes a readable copy of what it holds"
        )
    raise BagError(f"{file} is not an MCAP file")


def _truncated(path: Path) -> BagError:
    return BagError(
        f"{path} is truncated or was not closed (no index); `./camo bag repair {path}` "
        f"writes a readable copy of its complete chunks"
    )


@cache
def schema_problem(encoding: str, name: str, definition: bytes) -> str:
    """Why a schema cannot be used here ("" when it can): not ros2msg, a type not installed,
    or text that does not parse."""
    if encoding != "ros2msg":
        return f"schema encoding {encoding!r:.20}, not ros2msg"
    try:
        msgdefs.message_class(name)
    except msgdefs.DefinitionError:
        return f"unknown type {name!r:.60}"
    from mcap_ros2._dynamic import generate_dynamic

    try:
        generate_dynamic(name, definition.decode())
    except Exception:  # noqa: BLE001 - the schema parser raises anything on a garbled text
        return f"a schema text of {name} that does not parse"
    return ""


@dataclass
class Bag:
    """A bag whose path, metadata, file structure and schemas were checked."""

    file: Path  # the .mcap file
    summary: BagSummary  # topics: the usable channels only
    metadata: dict | None = None  # metadata.yaml's bag information, checked; None: no file
    complete: bool = True  # False: a file without summary, read up to where it breaks
    ending: str = "complete"  # how reading the file ended
    left_out: dict[str, str] = field(default_factory=dict)  # topic -> why it was left out
    notes: list[str] = field(default_factory=list)  # what a partial read passed over
    rejected: dict[str, set[tuple[int, int, int]]] = field(default_factory=dict)  # undecodable
    _channels: dict[int, Channel] = field(default_factory=dict)  # usable, by id
    _schemas: dict[int, Schema] = field(default_factory=dict)
    _salvaged: list[Message] | None = None

    @property
    def path(self) -> Path:
        return self.file

    def messages(self, topics: list[str] | None = None) -> Iterator[BagMessage]:
        """Messages of the usable channels (of `topics`), in log-time order, as plain CDR: an
        encrypted run's opened with the run's key (--key-file, $CAMO_KEY_FILE); a damaged
        chunk, or an encrypted message without the key that sealed it, gives BagError."""
        opened = Unsealing(self.file)
        for message in self.raw_messages(topics):
            yield opened(message)

    def raw_messages(self, topics: list[str] | None = None) -> Iterator[BagMessage]:
        """`messages`, as recorded (an encrypted run's sealed)."""
        wanted = {c.topic for c in self._channels.values()}
        if topics is not None:
            wanted &= set(topics)
        if not wanted:
            return
        type_of = {c.id: self._schemas[c.schema_id].name for c in self._channels.values()}
        if self._salvaged is not None:
            for m in self._salvaged:
                channel = self._channels.get(m.channel_id)
                if channel is not None and channel.topic in wanted:
                    yield BagMessage(
                        channel.topic, type_of[m.channel_id], m.log_time, m.publish_time, m.data
                    )
            return
        try:
            with open(self.file, "rb") as stream:
                for _schema, channel, message in make_reader(
                    stream, validate_crcs=True
                ).iter_messages(topics=sorted(wanted), log_time_order=True):
                    if channel.id in type_of:
                        yield BagMessage(
                            channel.topic,
                            type_of[channel.id],
                            message.log_time,
                            message.publish_time,
                            message.data,
                        )
        except OSError as exc:
            raise BagError(f"cannot read {self.file}: {exc.strerror}") from None
        except DAMAGE as exc:
            raise damaged(self.file, exc) from None

    def reject(self, message: BagMessage) -> None:
        """A message whose bytes do not decode as its type: left out, and counted."""
        self.rejected.setdefault(message.topic, set()).add(
            (message.log_time, message.publish_time, hash(message.data))
        )

    @property
    def rejected_count(self) -> int:
        return sum(len(s) for s in self.rejected.values())

    def note(self) -> str:
        """One line on what was left out ("" when nothing was)."""
        parts = list(self.notes)
        if self.left_out:
            why = "; ".join(f"{t}: {w}" for t, w in sorted(self.left_out.items())[:3])
            more = ", ..." if len(self.left_out) > 3 else ""
            count = len(self.left_out)
            parts.append(f"{count} unusable topic{'s' * (count != 1)} ({why}{more})")
        if self.rejected:
            per = ", ".join(f"{t}: {len(s)}" for t, s in sorted(self.rejected.items())[:3])
            more = ", ..." if len(self.rejected) > 3 else ""
            count = self.rejected_count
            kind = "messages that do not decode" if count != 1 else "message that does not decode"
            parts.append(f"{count} {kind} ({per}{more})")
        return f"left out of {self.file}: " + "; ".join(parts) if parts else ""


def _read_summary(file: Path):
    try:
        with open(file, "rb") as stream:
            summary = make_reader(stream, validate_crcs=True).get_summary()
    except OSError as exc:
        if exc.errno == errno.EINVAL:  # a seek before the start: shorter than any footer
            return None
        raise BagError(f"cannot read {file}: {exc.strerror}") from None
    except DAMAGE:
        return None
    if summary is None or summary.statistics is None:
        return None
    return summary


def _salvage(file: Path) -> tuple[dict[int, Schema], dict[int, Channel], list[Message], str]:
    """Everything readable of a file: the chunks before and after damaged ones (salvage.py)."""
    try:
        found = salvage(file)
    except OSError as exc:
        raise BagError(f"cannot read {file}: {exc.strerror}") from None
    return found.schemas, found.channels, found.messages, found.ending


def _full(name: str) -> str:
    try:
        return msgdefs.full_name(name)
    except msgdefs.DefinitionError:
        return ""


def _bag_metadata(folder: Path) -> tuple[dict | None, Path | None]:
    """metadata.yaml's checked information and the file it names; (None, None) without one."""
    meta_file = folder / METADATA
    if not (meta_file.exists() or meta_file.is_symlink()):
        return None, None
    metadata = load_metadata(meta_file)
    file = folder / metadata["relative_file_paths"][0]
    if not file.is_file():
        raise BagError(
            f"{meta_file} names {metadata['relative_file_paths'][0]}, which is not in {folder}"
        )
    return metadata, file


def _bag_file(path: Path, partial: bool) -> tuple[dict | None, Path, list[str]]:
    """The bag's checked metadata (None without metadata.yaml), its .mcap file, and notes."""
    if not path.is_dir():
        return None, path, []
    metadata, file, notes = None, None, []
    try:
        metadata, file = _bag_metadata(path)
    except BagError as exc:
        if not partial:
            raise
        notes.append(f"{METADATA} passed over ({exc})")
    if file is None:
        files = sorted(path.glob("*.mcap"))
        if not files:
            raise BagError(f"{path} is not a bag: it holds no {METADATA} and no .mcap file")
        if len(files) > 1:
            raise BagError(
                f"{path} holds {len(files)} .mcap files and no {METADATA} to say which "
                f"is the bag's"
            )
        file = files[0]
    return metadata, file, notes


def _channels_into(bag: Bag, schemas: dict, channels: dict, counts: dict, partial: bool) -> None:
    """The usable channels into the bag's summary; the others into `left_out`."""
    for channel_id, channel in sorted(channels.items()):
        schema = schemas.get(channel.schema_id)
        if topic_problem(channel.topic):
            bag.left_out[shown(channel.topic)] = topic_problem(channel.topic)
            continue
        problem = "no schema" if schema is None else ""
        problem = problem or schema_problem(schema.encoding, schema.name, bytes(schema.data))
        if not problem and channel.message_encoding != "cdr":
            problem = f"message encoding {channel.message_encoding!r:.20}, not cdr"
        if problem:
            bag.left_out[channel.topic] = problem
            continue
        qos = channel.metadata.get("offered_qos_profiles", "")
        try:
            check_profiles(qos, f"{bag.file}: channel {channel.topic!r:.60} offered_qos_profiles")
        except BagError as exc:
            if not partial:
                raise
            bag.notes.append(f"QoS passed over ({exc})")
            qos = ""  # kept without: the messages matter more than the QoS they were sent with
        bag._channels[channel_id] = channel
        bag._schemas[channel.schema_id] = schema
        bag.summary.topics.append(
            TopicInfo(
                channel.topic,
                schema.name,
                qos,
                count=counts.get(channel_id, 0),
                definition=bytes(schema.data).decode(errors="replace"),
            )
        )


def _check_listed(
    folder: Path, bag: Bag, channels: dict, schemas: dict, counts: dict | None = None
) -> None:
    """metadata.yaml must list the topics the file holds, with their types, and (`counts`:
    the file's messages per channel, from its statistics) as many messages as it holds."""
    meta_file = folder / METADATA
    held = {}
    held_count: dict[str, int] = {}
    for channel_id, channel in channels.items():
        schema = schemas.get(channel.schema_id)
        held[channel.topic] = _full(schema.name) if schema is not None else ""
        held_count[channel.topic] = (counts or {}).get(channel_id, 0)
    if counts is not None:
        total = (bag.metadata or {}).get("message_count", sum(counts.values()))
        if total != sum(counts.values()):
            raise BagError(
                f"{meta_file} gives message_count {total}, {bag.file.name} holds "
                f"{sum(counts.values())} messages"
            )
        for listed in (bag.metadata or {}).get("topics_with_message_count", []):
            name, count = listed["topic_metadata"]["name"], listed["message_count"]
            if name in held and count != held_count[name]:
                raise BagError(
                    f"{meta_file} gives {name} {count} messages, {bag.file.name} holds "
                    f"{held_count[name]}"
                )
    listed_types = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["type"]
        for t in (bag.metadata or {}).get("topics_with_message_count", [])
    }
    for name, kind in sorted(listed_types.items()):
        if name not in held:
            raise BagError(f"{meta_file} lists {name}, which {bag.file.name} does not hold")
        if held[name] and held[name] != kind:
            raise BagError(
                f"{meta_file} gives {name} the type {kind}, {bag.file.name} {held[name]}"
            )
    unlisted = sorted(set(held) - set(listed_types))
    if unlisted:
        raise BagError(f"{meta_file} does not list {unlisted[0]}, which {bag.file.name} holds")


def open_bag(path: str | Path, partial: bool = False, stream: bool = False) -> Bag:
    """A bag, every level checked (BagError on the first that fails).

    `partial` (what `bag repair` and `render --partial` need) reads a file without summary
    up to where it breaks, passes over a metadata.yaml that is invalid, and keeps channels
    whose QoS is invalid without it, rather than refusing the bag; each is noted. `stream`
    (with `partial`) reads every file so, from its start, even one with a summary."""
    path = bag_path(path)
    metadata, file, notes = _bag_file(path, partial)
    damaged_head = check_magic(file, tolerate=partial and stream)
    notes = [*notes, damaged_head] if damaged_head else notes
    found = None if partial and stream else _read_summary(file)
    salvaged = None
    if found is not None:
        schemas, channels = found.schemas, found.channels
        counts = found.statistics.channel_message_counts
        start, end = found.statistics.message_start_time, found.statistics.message_end_time
        ending = "complete"
    elif partial:
        schemas, channels, salvaged, ending = _salvage(file)
        counts = {}
        for m in salvaged:
            counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
        start = min((m.log_time for m in salvaged), default=0)
        end = max((m.log_time for m in salvaged), default=0)
    else:
        raise _truncated(file)
    bag = Bag(file, BagSummary(file, start, end), metadata, found is not None, ending)
    bag._salvaged = salvaged
    bag.notes.extend(notes)
    if metadata is not None and bag.complete:
        try:
            _check_listed(path, bag, channels, schemas, counts)
        except BagError as exc:
            if not partial:
                raise
            bag.notes.append(f"{METADATA} passed over ({exc})")
    _channels_into(bag, schemas, channels, counts, partial)
    return bag


# ---- readers every command uses ------------------------------------------------------------


def read_summary(path: str | Path) -> BagSummary:
    return open_bag(path).summary


def read_messages(path: str | Path, topics: list[str] | None = None) -> Iterator[BagMessage]:
    """Messages of a closed bag in log-time order (BagError if it is truncated or corrupt)."""
    return open_bag(path).messages(topics)


def repair(src: str | Path, dst: str | Path) -> tuple[Bag, int]:
    """Write a complete, indexed bag of every message that can be read from `src`: the bag
    read, and how many messages were written."""
    bag = open_bag(src, partial=True, stream=True)
    writer = BagWriter(dst, library="camo bag repair")
    try:
        for topic in bag.summary.topics:
            writer.add_topic(topic, topic.definition)
        for message in bag.raw_messages():  # as recorded: an encrypted run's stays sealed
            writer.write(message.topic, message.data, message.log_time, message.publish_time)
    finally:
        writer.close()
    return bag, writer.message_count


class Unsealing:
    """A bag's messages made plain: a keyed run's trailer off (bags of older camo versions may
    hold it), an encrypted run's payload opened with the process's key."""

    def __init__(self, file: Path) -> None:
        self.file = file
        self.openers: dict[str, Opener] = {}
        self.key: RunKey | None = None
        self._looked = False

    def __call__(self, message: BagMessage) -> BagMessage:
        data = message.data
        if not sealed(data):
            plain = strip(data)
            return message if plain is data else replace(message, data=plain)
        if not self._looked:
            self.key, self._looked = process_key(), True
        if self.key is None:
            raise BagError(
                f"{self.file}: {message.topic} holds encrypted messages (a run with --encrypt): "
                "give its key file with --key-file"
            )
        run = run_of(message.topic)
        opener = self.openers.setdefault(run, Opener(self.key, run, replays=False))
        payload, why = opener.open(message.topic, data)
        if payload is None:
            raise BagError(f"{self.file}: {message.topic}: {why} (is it the run's key file?)")
        return replace(message, data=payload)
