"""Keyed runs: every message a run's process writes carries a tag only holders of the run's key
can make, and readers believe only tagged messages they have not seen before.

A run's key is 256 random bits in a file of its own (0600). A writer appends a trailer to the
message it publishes (CDR bytes, as rclpy serializes them):

    payload | writer (8) | sequence (8) | tag (16) | "cmk1"

`writer` is random per publisher, `sequence` counts its messages from 1, and `tag` is
HMAC-SHA256 (truncated to 128 bits) over the run id, the topic, writer, sequence and payload:
a stranger can neither make one nor move one to another run, topic or writer, and a reader that
keeps each writer's last sequence refuses a message played again. DDS delivers one writer's
messages to a reader in order, so a sequence that does not grow is a replay. The trailer sits
after the CDR message, where deserializers stop reading: viewers without the key (Foxglove,
`ros2 topic echo`) still read a keyed run.

Sealed (encrypted) messages carry the payload as AES-GCM ciphertext instead, its 16-byte tag
inside it, and a random 96-bit nonce:

    ciphertext | writer (8) | sequence (8) | nonce (12) | "cme1"

with the run id, topic, writer and sequence as associated data. The tag is worked out once per
DDS message (an array of robot messages), not per robot.
"""

from __future__ import annotations

import hashlib
import hmac
import itertools
import os
import stat
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from camo_core.exceptions import UsageError

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM

KEY_BYTES = 32
TAGGED = b"cmk1"
SEALED = b"cme1"
WRITER_BYTES = 8
TAG_BYTES = 16
NONCE_BYTES = 12
_COUNTERS = struct.Struct("<8sQ")  # writer, sequence
TAGGED_TRAILER = _COUNTERS.size + TAG_BYTES + len(TAGGED)
SEALED_TRAILER = _COUNTERS.size + NONCE_BYTES + len(SEALED)
KEY_FILE_ENV = "CAMO_KEY_FILE"
ENCRYPT_ENV = "CAMO_ENCRYPT"  # "1": this process's robot messages and backgrounds are sealed

NO_TAG = "no valid key tag (a writer without the run's key)"
REPLAYED = "a keyed message played again (an old sequence number)"
UNSEALED = "an encrypted message that does not decrypt with the run's key"


def _derived(secret: bytes, purpose: bytes) -> bytes:
    """One key per use of the secret: tags and encryption never share one."""
    return hmac.digest(secret, b"camo run key: " + purpose, "sha256")


@dataclass(frozen=True)
class RunKey:
    """A run's secret, read from its key file."""

    secret: bytes = field(repr=False)
    path: Path | None = None

    def __post_init__(self) -> None:
        if len(self.secret) != KEY_BYTES:
            raise ValueError(f"a run key is {KEY_BYTES} bytes")

    @property
    def mac_key(self) -> bytes:
        return _derived(self.secret, b"tag")

    @property
    def aead_key(self) -> bytes:
        return _derived(self.secret, b"aead")


def new_key_file(path: str | Path) -> RunKey:
    """A fresh random key, written to `path` (created, owner read/write only)."""
    path = Path(path)
    secret = os.urandom(KEY_BYTES)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        there = "a key file or another file" if not path.is_dir() else "a folder"
        raise UsageError(
            f"{path}: {there} is there already (never replaced); give a new file name"
        ) from None
    except OSError as exc:
        raise UsageError(f"cannot write the run's key file {path}: {exc.strerror}") from None
    with os.fdopen(fd, "w") as out:
        out.write(secret.hex() + "\n")
    return RunKey(secret, path)


def read_key_file(path: str | Path) -> RunKey:
    """The key in `path`: 64 hex digits, in a file nobody but its owner may read."""
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise UsageError(f"key file {path}: not a regular file")
        if info.st_mode & 0o077:
            raise UsageError(
                f"key file {path}: others may read it (mode {info.st_mode & 0o777:o}); "
                f"chmod 600 {path}"
            )
        if info.st_size > 1024:
            raise UsageError(f"key file {path}: not a camo key (too long)")
        text = path.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        raise UsageError(f"key file {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"key file {path}: cannot read it ({exc})") from None
    try:
        secret = bytes.fromhex(text)
    except ValueError:
        secret = b""
    if len(secret) != KEY_BYTES:
        raise UsageError(f"key file {path}: not a camo key ({2 * KEY_BYTES} hex digits)")
    return RunKey(secret, path)


def _header(magic: bytes, run: str, topic: str, counters: bytes) -> bytes:
    return magic + run.encode() + b"\0" + topic.encode() + b"\0" + counters


class Sealer:
    """One publisher's side: a writer id of its own and its sequence numbers."""

    def __init__(self, key: RunKey, run: str, topic: str, encrypt: bool = False) -> None:
        self.writer = os.urandom(WRITER_BYTES)
        self.run, self.topic = run, topic
        self._count = itertools.count(1)  # next() is atomic: a heartbeat thread may publish too
        self._mac = key.mac_key
        self._aead = _aead(key) if encrypt else None

    def seal(self, payload: bytes) -> bytes:
        counters = _COUNTERS.pack(self.writer, next(self._count))
        if self._aead is None:
            header = _header(TAGGED, self.run, self.topic, counters)
            tag = hmac.digest(self._mac, header + payload, "sha256")[:TAG_BYTES]
            return b"".join((payload, counters, tag, TAGGED))
        nonce = os.urandom(NONCE_BYTES)
        header = _header(SEALED, self.run, self.topic, counters)
        return b"".join((self._aead.encrypt(nonce, payload, header), counters, nonce, SEALED))


class Opener:
    """A reader's side, for one run: the payload of a message its key tagged (or sealed), once.

    `open` returns (payload, None) or (None, why it was refused)."""

    def __init__(self, key: RunKey, run: str, replays: bool = True) -> None:
        """`replays`: refuse a writer's sequence number that does not grow (off for a bag, whose
        messages a reader may go through more than once)."""
        self.run = run
        self._mac = key.mac_key
        self._key = key
        self._aead: AESGCM | None = None
        self.replays = replays
        self._last: dict[tuple[str, bytes], int] = {}

    def open(self, topic: str, data: bytes) -> tuple[bytes | None, str | None]:
        data = unpadded(data)
        magic = data[-4:]
        if magic == TAGGED and len(data) >= TAGGED_TRAILER:
            end = len(data) - TAGGED_TRAILER
            counters = data[end : end + _COUNTERS.size]
            tag = data[end + _COUNTERS.size : -4]
            payload = data[:end]
            header = _header(TAGGED, self.run, topic, counters)
            expected = hmac.digest(self._mac, header + payload, "sha256")[:TAG_BYTES]
            if not hmac.compare_digest(tag, expected):
                return None, NO_TAG
        elif magic == SEALED and len(data) >= SEALED_TRAILER + TAG_BYTES:
            end = len(data) - SEALED_TRAILER
            counters = data[end : end + _COUNTERS.size]
            nonce = data[end + _COUNTERS.size : -4]
            aead = self._aead = self._aead or _aead(self._key)
            try:
                payload = aead.decrypt(
                    nonce, data[:end], _header(SEALED, self.run, topic, counters)
                )
            except Exception:  # noqa: BLE001 - cryptography's InvalidTag, or a malformed one
                return None, UNSEALED
        else:
            return None, NO_TAG
        if self.replays:
            writer, sequence = _COUNTERS.unpack(counters)
            last = self._last.get((topic, writer), 0)
            if sequence <= last:
                return None, REPLAYED
            self._last[(topic, writer)] = sequence
        return payload, None


def unpadded(data: bytes) -> bytes:
    """The message as its writer sealed it: DDS pads a serialized message to a multiple of four
    bytes with zeros, after the trailer (whose magic ends in a digit, never a zero)."""
    if data[-4:] in (TAGGED, SEALED):
        return data
    end = len(data)
    while end > len(data) - 3 and end > 0 and data[end - 1] == 0:
        end -= 1
    return data[:end] if data[end - 4 : end] in (TAGGED, SEALED) else data


def strip(data: bytes) -> bytes:
    """A tagged message's payload without checking its tag (a bag read without the key: a keyed
    run's messages stay readable; sealed ones are not)."""
    data = unpadded(data)
    if data[-4:] == TAGGED and len(data) >= TAGGED_TRAILER:
        return data[: len(data) - TAGGED_TRAILER]
    return data


def sealed(data: bytes) -> bool:
    """Whether a message's payload is encrypted (a reader needs the run's key)."""
    return unpadded(data)[-4:] == SEALED


GOAL_NONCE_BYTES = 16


def goal_tag(key: RunKey, run: str, goal: bytes) -> bytes:
    """An action goal's key tag: a random nonce, and an HMAC over it, the run id and the goal
    (CDR bytes, its tag field empty). A server takes each nonce once."""
    nonce = os.urandom(GOAL_NONCE_BYTES)
    return nonce + _goal_mac(key, run, nonce, goal)


def goal_tag_nonce(key: RunKey, run: str, goal: bytes, tag: bytes) -> bytes | None:
    """The nonce of a valid goal tag (None: not a tag of this key, run and goal)."""
    nonce, mac = tag[:GOAL_NONCE_BYTES], tag[GOAL_NONCE_BYTES:]
    if len(nonce) != GOAL_NONCE_BYTES or not hmac.compare_digest(
        mac, _goal_mac(key, run, nonce, goal)
    ):
        return None
    return nonce


def _goal_mac(key: RunKey, run: str, nonce: bytes, goal: bytes) -> bytes:
    header = b"camo goal\0" + run.encode() + b"\0" + nonce
    return hmac.digest(key.mac_key, header + goal, "sha256")[:TAG_BYTES]


def _aead(key: RunKey) -> AESGCM:
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM  # only where one encrypts

    return AESGCM(key.aead_key)


def fingerprint(key: RunKey) -> str:
    """A short name of a key that gives nothing of it away: which key a run used, in its logs."""
    return hashlib.sha256(b"camo key fingerprint" + key.secret).hexdigest()[:12]
