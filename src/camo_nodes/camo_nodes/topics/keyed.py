"""A keyed run's topics in rclpy: publishers whose messages carry the run's tag, readers that
believe only tagged messages (camo_core.swarm.keys says how).

A process learns its run's key once, from its --key-file or $CAMO_KEY_FILE (`process_key`);
without one it writes and reads plain messages, as before keys. Every writer of a run's own
topics is made by `publisher`, every reader unseals with an `Opener` of its own (a reader keeps
each writer's last sequence number; two readers in one process each see every message).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable

from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message, serialize_message

from camo_core.swarm.keys import (
    ENCRYPT_ENV,
    KEY_FILE_ENV,
    NO_TAG,
    Opener,
    RunKey,
    Sealer,
    goal_tag,
    goal_tag_nonce,
    read_key_file,
    sealed,
    strip,
)

Refuse = Callable[[str, bytes], None]  # (reason, publisher GID or b"")


@functools.cache
def process_key() -> RunKey | None:
    """This process's run key ($CAMO_KEY_FILE, which --key-file sets), read once."""
    path = os.environ.get(KEY_FILE_ENV)
    return read_key_file(path) if path else None


class KeyedPublisher:
    """A publisher whose every message carries the run's tag (or is sealed)."""

    def __init__(self, publisher, sealer: Sealer) -> None:
        self.publisher = publisher
        self.sealer = sealer

    def publish(self, msg) -> None:
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        self.publisher.publish(self.sealer.seal(data))

    def __getattr__(self, name: str):  # topic_name, wait_for_all_acked, handle ...
        return getattr(self.publisher, name)


def publisher(node: Node, msg_type, topic: str, qos, run: str, sealable: bool = False):
    """`node.create_publisher`, keyed with the process's key where it has one. `sealable`: a
    topic whose payloads an --encrypt run encrypts (robot messages and backgrounds)."""
    key = process_key()
    made = node.create_publisher(msg_type, topic, qos)
    if key is None:
        return made
    encrypt = sealable and os.environ.get(ENCRYPT_ENV) == "1"
    return KeyedPublisher(made, Sealer(key, run, made.topic_name, encrypt))


def opener(run: str) -> Opener | None:
    """A reader's opener of `run`'s messages, or None where the process has no key."""
    key = process_key()
    return None if key is None else Opener(key, run)


def unsealing(
    handle: Callable[[bytes, bytes], None], topic: str, opened: Opener | None, refuse: Refuse
) -> Callable[[bytes, bytes], None]:
    """`handle(CDR bytes, GID)` given only messages `opened` believes (all, without a key);
    the others go to `refuse(reason, GID)`."""
    if opened is None:
        return handle

    def handle_keyed(data: bytes, gid: bytes) -> None:
        payload, why = opened.open(topic, data)
        if why is not None:
            refuse(why, gid)
            return
        handle(payload, gid)

    return handle_keyed


def subscription(
    node: Node, msg_type, topic: str, callback, qos: QoSProfile | int, run: str, refuse: Refuse
):
    """`node.create_subscription` of a run's topic: `callback(msg)` for the messages the run's
    key tagged (every message, without a key); `refuse(reason, b"")` for the others."""
    opened = opener(run)
    if opened is None:
        return node.create_subscription(msg_type, topic, callback, qos)

    def on_raw(data: bytes) -> None:
        payload, why = opened.open(topic_name, data)
        if why is not None:
            refuse(why, b"")
            return
        try:
            msg = deserialize_message(payload, msg_type)
        except Exception:  # noqa: BLE001 - tagged by a key holder, yet not this type
            refuse(f"a keyed message that is no {msg_type.__name__}", b"")
            return
        callback(msg)

    made = node.create_subscription(msg_type, topic, on_raw, qos, raw=True)
    topic_name = made.topic_name
    return made


def _untagged(goal) -> bytes:
    """A Camouflage goal's content, byte for byte: its image's fields and pixels (its CDR
    bytes will not do: rclpy leaves alignment padding unset, so they differ from one
    serialization to the next)."""
    image = goal.image
    fields = (image.header.stamp.sec, image.header.stamp.nanosec, image.header.frame_id)
    fields += (image.height, image.width, image.encoding, image.is_bigendian, image.step)
    return repr(fields).encode() + b"\0" + bytes(image.data)


def tag_goal(goal, run: str):
    """A Camouflage goal with the process key's tag for `run` (unchanged without a key); the
    goal."""
    key = process_key()
    if key is not None:
        goal.key_tag = list(goal_tag(key, run, _untagged(goal)))
    return goal


class GoalCheck:
    """A server's check of its goals' key tags: each valid nonce once."""

    def __init__(self, run: str) -> None:
        self.run = run
        self.key = process_key()
        self.seen: set[bytes] = set()

    def problem(self, goal) -> str | None:
        """Why a goal is refused (None: taken, or no key)."""
        if self.key is None:
            return None
        nonce = goal_tag_nonce(self.key, self.run, _untagged(goal), bytes(goal.key_tag))
        if nonce is None:
            return NO_TAG
        if nonce in self.seen:
            return "a goal sent again (its key tag was taken once)"
        self.seen.add(nonce)
        return None


def run_of(topic: str) -> str:
    """The run a topic belongs to: /<run>/..."""
    return topic.split("/")[1] if topic.count("/") >= 2 else ""


class Reader:
    """What a reader of whole runs (a recorder, a viewer) makes of a message on `topic`. With
    the process's key: the payload of a message the key tagged or sealed, else (None, why).
    Without one: a tagged message's payload, unchecked, and nothing of a sealed one."""

    SEALED = "an encrypted message, and no key to read it (--key-file)"

    def __init__(self) -> None:
        self.key = process_key()
        self._openers: dict[str, Opener] = {}

    def payload(self, topic: str, data: bytes) -> tuple[bytes | None, str | None]:
        if self.key is None:
            return (None, self.SEALED) if sealed(data) else (strip(data), None)
        run = run_of(topic)
        opened = self._openers.get(run)
        if opened is None:
            opened = self._openers[run] = Opener(self.key, run)
        return opened.open(topic, data)
