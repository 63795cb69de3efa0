"""What can be read of a damaged MCAP file: every record it can still frame and decode, the
chunks before a damaged one and after it, and a count of what was lost.

An MCAP file is a run of records, each an opcode, a length and a body; a recorder's messages
sit in chunks (compressed, with a CRC), each followed by its message indexes. A damaged chunk
(a bad CRC, garbage inside) is passed over by its length, and the message indexes after it say
how many messages it held. Where the file's summary can still be read, its chunk indexes say
where each chunk starts and how long it is: a chunk whose own opcode or length is damaged is
read all the same. Other damaged framing (a length that runs past the file, an opcode MCAP does
not have) is passed over to the next chunk (by the index, else to the next place a chunk
plausibly starts), and the messages of the indexed chunks passed over are counted as lost from
their message indexes. mcap's own readers decode every record; this only decides where records
are.
"""

from __future__ import annotations

import mmap
from dataclasses import dataclass, field
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, Footer, Message, MessageIndex, Schema
from mcap.stream_reader import breakup_chunk

MAGIC = b"\x89MCAP0\r\n"
KNOWN = {int(op) for op in Opcode}
HEADER = 9  # opcode (1 byte) and length (8 bytes, little-endian)
COMPRESSIONS = {b"", b"zstd", b"lz4"}
MAX_INFLATION = 1024  # zstd and lz4 never inflate a chunk more: a size beyond is damage


@dataclass
class Salvaged:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    damaged: int = 0  # chunks or stretches of records passed over
    lost: int = 0  # messages their message indexes say they held
    uncounted: int = 0  # stretches passed over that no index tells the contents of
    reframed: int = 0  # chunks whose own framing was damaged, read by the summary's index
    cut_short: str = ""  # why reading stopped before the file's end, if it did

    @property
    def ending(self) -> str:
        """How reading went, in words (what `bag repair` says)."""
        parts = []
        if self.reframed:
            parts.append(
                f"{self.reframed} chunk{'s' if self.reframed > 1 else ''} with damaged framing "
                "read by the summary's index"
            )
        if self.damaged:
            said = (
                f"{self.damaged} damaged stretch{'es' if self.damaged > 1 else ''} passed over, "
                f"{self.lost} messages lost by their indexes"
            )
            if self.uncounted:
                said += f" (what {self.uncounted} of them held is not known)"
            parts.append(said)
        if self.cut_short:
            parts.append(f"cut short ({self.cut_short})")
        return "; ".join(parts) or "complete"


def salvage(file: Path) -> Salvaged:
    """Every readable record of `file` (OSError if it cannot be read at all)."""
    found = Salvaged()
    with open(file, "rb") as stream:
        size = stream.seek(0, 2)
        if size <= len(MAGIC):
            found.cut_short = "no records"
            return found
        with mmap.mmap(stream.fileno(), 0, access=mmap.ACCESS_READ) as data:
            _walk(data, size, found)
    found.messages = [m for m in found.messages if m.channel_id in found.channels]
    found.messages.sort(key=lambda m: m.log_time)
    return found


def _walk(data, size: int, found: Salvaged) -> None:
    position, counting = len(MAGIC), False  # counting: the indexes of a damaged chunk follow
    chunks = chunk_indexes(data, size)
    while position + HEADER <= size:
        opcode = data[position]
        length = int.from_bytes(data[position + 1 : position + HEADER], "little")
        indexed = chunks.get(position)
        if indexed is not None and (opcode, length) != (
            Opcode.CHUNK,
            indexed.chunk_length - HEADER,
        ):
            opcode, length = Opcode.CHUNK, indexed.chunk_length - HEADER  # its framing damaged
            found.reframed += 1
        end = position + HEADER + length
        if opcode not in KNOWN or end > size:
            later = [start for start in chunks if start > position]
            resumed = min(later) if later else _next_chunk(data, size, position + 1)
            if resumed is None:  # nothing readable after it: the file ends in it
                found.cut_short = "a record cut off" if end > size else "unreadable to its end"
                return
            found.damaged += 1
            if chunks:
                found.lost += _indexed_messages(data, size, chunks, position, resumed)
            else:
                found.uncounted += 1
            position, counting = resumed, False
            continue
        if opcode in (Opcode.DATA_END, Opcode.FOOTER):
            return  # the summary repeats what the data section held
        body = ReadDataStream(_Bytes(data, position + HEADER, end))
        try:
            counting = _take(opcode, length, body, found, counting)
        except Exception:  # noqa: BLE001 - a damaged body makes mcap fail in many ways
            found.damaged += 1
            counting = opcode == Opcode.CHUNK
        position = end
    if position < size:
        found.cut_short = "a record cut off at the end"


def _take(opcode: int, length: int, body: ReadDataStream, found: Salvaged, counting: bool):
    """One record's contents into `found`; whether the message indexes that follow count
    the messages of a damaged chunk."""
    if opcode == Opcode.CHUNK:
        chunk = Chunk.read(body)
        if chunk.uncompressed_size > MAX_INFLATION * len(chunk.data) + (1 << 20):
            raise ValueError("a chunk's uncompressed size no compressor reaches")  # damaged
        for record in breakup_chunk(chunk, validate_crc=True):
            _keep(record, found)
        return False
    if opcode == Opcode.MESSAGE_INDEX:
        if counting:
            found.lost += len(MessageIndex.read(body).records)
        return counting
    if opcode == Opcode.SCHEMA:
        _keep(Schema.read(body), found)
    elif opcode == Opcode.CHANNEL:
        _keep(Channel.read(body), found)
    elif opcode == Opcode.MESSAGE:
        _keep(Message.read(body, length), found)
    return False


def chunk_indexes(data, size: int) -> dict[int, ChunkIndex]:
    """The summary's chunk indexes by where each chunk starts, if the file still ends in its
    footer and magic and its summary reads; else none."""
    footer_at = size - len(MAGIC) - HEADER - 20  # the footer's body: 8 + 8 + 4 bytes
    try:
        if footer_at <= len(MAGIC) or bytes(data[size - len(MAGIC) : size]) != MAGIC:
            return {}
        if data[footer_at] != Opcode.FOOTER:
            return {}
        footer = Footer.read(ReadDataStream(_Bytes(data, footer_at + HEADER, size)))
        position, found = footer.summary_start, {}
        while 0 < position and position + HEADER <= footer_at:
            length = int.from_bytes(data[position + 1 : position + HEADER], "little")
            end = position + HEADER + length
            if end > footer_at:
                break
            if data[position] == Opcode.CHUNK_INDEX:
                index = ChunkIndex.read(ReadDataStream(_Bytes(data, position + HEADER, end)))
                if len(MAGIC) <= index.chunk_start_offset < size and index.chunk_length > HEADER:
                    found[index.chunk_start_offset] = index
            position = end
        return found
    except Exception:  # noqa: BLE001 - a damaged summary: read without it
        return {}


def _indexed_messages(data, size: int, chunks: dict, start: int, stop: int) -> int:
    """Messages the message indexes of the indexed chunks in [start, stop) say they held."""
    count = 0
    for offset, index in chunks.items():
        if not start <= offset < stop:
            continue
        for at in index.message_index_offsets.values():
            try:
                length = int.from_bytes(data[at + 1 : at + HEADER], "little")
                if data[at] == Opcode.MESSAGE_INDEX and at + HEADER + length <= size:
                    body = ReadDataStream(_Bytes(data, at + HEADER, at + HEADER + length))
                    count += len(MessageIndex.read(body).records)
            except Exception:  # noqa: BLE001 - an index damaged too: not counted
                continue
    return count


def _keep(record, found: Salvaged) -> None:
    if isinstance(record, Schema):
        found.schemas[record.id] = record
    elif isinstance(record, Channel):
        found.channels[record.id] = record
    elif isinstance(record, Message):
        found.messages.append(record)


def _next_chunk(data, size: int, start: int) -> int | None:
    """Where a chunk plausibly starts after `start`: its opcode, a length inside the file and
    a header MCAP would write (a compression it knows)."""
    position = start
    while (position := data.find(bytes([Opcode.CHUNK]), position, size)) != -1:
        length = int.from_bytes(data[position + 1 : position + HEADER], "little")
        # start and end times, uncompressed size and CRC (8+8+8+4), then the compression
        name_at = position + HEADER + 28
        if position + HEADER + length <= size and name_at + 4 <= size:
            name_length = int.from_bytes(data[name_at : name_at + 4], "little")
            if bytes(data[name_at + 4 : name_at + 4 + name_length]) in COMPRESSIONS:
                return position
        position += 1
    return None


class _Bytes:
    """A file-like view of data[start:end] for mcap's ReadDataStream, without a copy of the
    whole file."""

    def __init__(self, data, start: int, end: int) -> None:
        self.data, self.position, self.end = data, start, end

    def read(self, count: int = -1) -> bytes:
        stop = self.end if count < 0 else min(self.end, self.position + count)
        out = bytes(self.data[self.position : stop])
        self.position = stop
        return out
