"""Bags as rosbag2 writes them with its MCAP storage: no ROS imports here.

A bag is a folder NAME/ holding NAME_0.mcap and metadata.yaml. The MCAP file
has the `ros2` profile, one `ros2msg` schema per type, `cdr` channels with
their `offered_qos_profiles` metadata, zstd chunks, message indexes and a
summary; the file's own `rosbag2` metadata record repeats metadata.yaml. The
container is the `mcap` library's; this module only decides what goes in. Every
reader opens bags through `loader.py`, which checks them first.
"""

from __future__ import annotations

import os
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path

import zstandard
from mcap.exceptions import McapError
from mcap.writer import CompressionType, Writer

from camo_core.exceptions import CamoError
from camo_core.inputs.strict_yaml import dump_yaml, parse_yaml
from camo_core.results.folders import new_folder_problem

MAGIC = b"\x89MCAP0\r\n"
ROSBAG2_VERSION = 9  # Jazzy's metadata version
CHUNK_SIZE = 256 * 1024  # small chunks: a killed recorder loses at most one


class BagError(CamoError):
    """A bag that cannot be used: missing, not MCAP, truncated, or unwritable. Always one line:
    line breaks that a path or a name from the bag brings are shown escaped."""

    def __init__(self, message: str) -> None:
        super().__init__(str(message).replace("\r", "\\r").replace("\n", "\\n"))


# What the mcap, zstd and ros2msg parsers raise on damaged bytes. They check little, so a
# corrupt length or id surfaces as any of these (found by tests/camo_bag fuzzing).
DAMAGE = (
    McapError,
    EOFError,
    ValueError,  # UnicodeDecodeError included
    TypeError,
    LookupError,  # KeyError, IndexError
    AttributeError,
    ArithmeticError,
    MemoryError,
    struct.error,
    zstandard.ZstdError,
)


class BagDamaged(BagError):
    """A bag whose bytes do not parse where they should (a wrong CRC, a corrupt record)."""


def damaged(path: str | Path, exc: BaseException, what: str = "is corrupt") -> BagError:
    """A one-line error for a bag whose bytes did not parse."""
    reason = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else ""
    return BagDamaged(f"{path} {what} ({type(exc).__name__}{': ' + reason if reason else ''})")


@dataclass
class TopicInfo:
    name: str
    type: str  # pkg/msg/Type
    qos: str = ""  # offered_qos_profiles, YAML text
    type_hash: str = ""
    count: int = 0
    definition: str = ""  # the ros2msg schema text the bag holds for its type


@dataclass
class BagSummary:
    path: Path  # the .mcap file
    start_ns: int
    end_ns: int
    topics: list[TopicInfo] = field(default_factory=list)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)


@dataclass
class BagMessage:
    topic: str
    type: str
    log_time: int  # ns since the epoch, when the recorder received it
    publish_time: int  # ns since the epoch, from the message's header stamp
    data: bytes  # CDR, exactly as published


# ---- writing ----------------------------------------------------------------------


class BagWriter:
    """Writes one bag folder. Call close() (also on Ctrl-C) for an indexed file and
    metadata.yaml."""

    def __init__(self, folder: str | Path, library: str = "camo") -> None:
        self.folder = Path(folder)
        if self.folder.suffix == ".mcap":
            raise BagError(
                f"{folder}: give a bag folder name, not a .mcap file "
                "(rosbag2 writes NAME/NAME_0.mcap)"
            )
        problem = new_folder_problem(self.folder, "the bag")
        if problem:
            raise BagError(problem)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            self.file = self.folder / f"{self.folder.name}_0.mcap"
            self._stream = open(self.file, "wb")
        except OSError as exc:
            raise BagError(f"cannot write the bag {folder}: {exc.strerror}") from None
        self._writer = Writer(
            self._stream, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD
        )
        self._writer.start(profile="ros2", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.topics: dict[str, TopicInfo] = {}
        self._sequence: dict[str, int] = {}
        self.start_ns: int | None = None
        self.end_ns = 0
        self.closed = False
        # Why writing stopped (a full disk, a lost device): the bag ends there, the run goes on.
        self.failed: str | None = None
        self.saved = 0  # messages surely in the file: up to the last flush that succeeded
        self.saved_ns = 0  # the log time of the last of them

    def _stopped(self, exc: OSError) -> None:
        """A write failed: keep what the file holds and write nothing more (the file's index
        and metadata.yaml are left out; `bag repair` rebuilds them)."""
        self.failed = exc.strerror or str(exc)
        self.closed = True
        try:
            self._stream.close()
        except OSError:
            pass  # the unwritten rest of its buffer is what the failure cost

    def add_topic(self, topic: TopicInfo, definition: str) -> None:
        if topic.name in self._channels or self.closed:
            return
        try:
            self._register(topic, definition)
        except OSError as exc:
            self._stopped(exc)

    def _register(self, topic: TopicInfo, definition: str) -> None:
        if topic.type not in self._schemas:
            self._schemas[topic.type] = self._writer.register_schema(
                name=topic.type, encoding="ros2msg", data=definition.encode()
            )
        self._channels[topic.name] = self._writer.register_channel(
            topic=topic.name,
            message_encoding="cdr",
            schema_id=self._schemas[topic.type],
            metadata={"offered_qos_profiles": topic.qos},
        )
        self.topics[topic.name] = TopicInfo(topic.name, topic.type, topic.qos, topic.type_hash)
        self._sequence[topic.name] = 0

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int) -> None:
        """One message (nothing once the bag is closed or writing has failed)."""
        if self.closed:
            return
        self._sequence[topic] += 1
        try:
            self._writer.add_message(
                channel_id=self._channels[topic],
                log_time=log_time,
                data=data,
                publish_time=publish_time,
                sequence=self._sequence[topic],
            )
        except OSError as exc:  # a chunk was full and could not be written
            self._stopped(exc)
            return
        self.topics[topic].count += 1
        self.start_ns = log_time if self.start_ns is None else min(self.start_ns, log_time)
        self.end_ns = max(self.end_ns, log_time)

    def flush(self) -> None:
        """Write the chunk in progress, so that a killed process loses nothing written before."""
        if self.closed:
            return
        try:
            self._writer.flush()
            self._stream.flush()
        except OSError as exc:
            self._stopped(exc)
            return
        self.saved, self.saved_ns = self.message_count, self.end_ns

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    def close(self) -> None:
        if self.closed:
            return
        self.flush()  # what is written before the index, should the index not fit
        if self.closed:
            return
        self.closed = True
        metadata = metadata_yaml(
            self.file.name, list(self.topics.values()), self.start_ns or 0, self.end_ns
        )
        try:
            self._writer.add_metadata(
                "rosbag2", {"serialized_metadata": metadata, "ROS_DISTRO": "jazzy"}
            )
            self._writer.finish()
            self._stream.close()
        except OSError as exc:
            self._stopped(exc)
            return
        info = dump_yaml({"rosbag2_bagfile_information": parse_yaml(metadata, "metadata")})
        try:
            (self.folder / "metadata.yaml").write_text(info)
        except OSError as exc:
            (self.folder / "metadata.yaml").unlink(missing_ok=True)  # no half a description
            self.failed = exc.strerror or str(exc)


def metadata_yaml(file_name: str, topics: list[TopicInfo], start_ns: int, end_ns: int) -> str:
    """rosbag2's bag information (version 9), as YAML text."""
    duration = max(0, end_ns - start_ns)
    count = sum(t.count for t in topics)
    info = {
        "version": ROSBAG2_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start_ns},
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": parse_yaml(t.qos, f"{t.name} offered_qos_profiles")
                    or [],
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": start_ns},
                "duration": {"nanoseconds": duration},
                "message_count": count,
            }
        ],
        "custom_data": None,
        "ros_distro": "jazzy",
    }
    return dump_yaml(info)


# ---- reading: loader.py, which checks every level first ------------------------------


def format_info(summary: BagSummary) -> str:
    """What `ros2 bag info` prints."""

    def stamp(ns: int) -> str:
        return (
            time.strftime("%b %d %Y %H:%M:%S", time.localtime(ns / 1e9))
            + f".{ns % 10**9 // 10**6:03d} ({ns / 1e9:.9f})"
        )

    size = os.path.getsize(summary.path)
    lines = [
        f"Files:             {summary.path.name}",
        f"Bag size:          {size / 1024 / 1024:.1f} MiB"
        if size >= 1024 * 1024
        else f"Bag size:          {size / 1024:.1f} KiB",
        "Storage id:        mcap",
        f"Duration:          {(summary.end_ns - summary.start_ns) / 1e9:.9f}s",
        f"Start:             {stamp(summary.start_ns)}",
        f"End:               {stamp(summary.end_ns)}",
        f"Messages:          {summary.message_count}",
    ]
    width = max((len(t.name) for t in summary.topics), default=0)
    for k, topic in enumerate(sorted(summary.topics, key=lambda t: t.name)):
        head = "Topic information: " if k == 0 else " " * 19
        lines.append(
            f"{head}Topic: {topic.name:<{width}} | Type: {topic.type} | Count: {topic.count} | "
            f"Serialization Format: cdr"
        )
    return "\n".join(lines)
