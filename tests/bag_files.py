"""Tiny bags written in-process for the loader's tests (no ROS process started)."""

from __future__ import annotations

from pathlib import Path

import yaml

CHATTER = "/chatter"
STRING = "std_msgs/msg/String"


def write_bag(folder: Path, messages: int = 5, depth: int = 5) -> Path:
    """A closed bag of `messages` Strings on /chatter, offered keep-last `depth`."""
    from rclpy.qos import QoSProfile
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from camo_bag import qos_yaml
    from camo_bag.container import BagWriter, TopicInfo
    from camo_bag.msgdefs import message_definition

    writer = BagWriter(folder)
    writer.add_topic(
        TopicInfo(CHATTER, STRING, qos_yaml.dump([QoSProfile(depth=depth)])),
        message_definition(STRING),
    )
    for k in range(messages):
        writer.write(CHATTER, serialize_message(String(data=f"m{k}")), 10**9 + k, 10**9 + k)
    writer.close()
    return folder


def write_mcap(
    file: Path,
    channels: list[tuple[str, str, str, bytes, str, dict[str, str]]],
    messages: list[tuple[int, bytes]],
    chunked: bool = True,
) -> Path:
    """An MCAP file written with the `mcap` writer, uncompressed: channels as (topic, schema
    name, schema encoding, schema data, message encoding, metadata), messages as (channel
    index, data)."""
    from mcap.writer import CompressionType, Writer

    with open(file, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.NONE, use_chunking=chunked)
        writer.start(profile="ros2", library="test")
        ids = []
        for topic, name, encoding, data, message_encoding, metadata in channels:
            schema = writer.register_schema(name=name, encoding=encoding, data=data)
            ids.append(
                writer.register_channel(
                    topic=topic,
                    message_encoding=message_encoding,
                    schema_id=schema,
                    metadata=metadata,
                )
            )
        for k, (index, data) in enumerate(messages):
            writer.add_message(
                channel_id=ids[index], log_time=10**9 + k, data=data, publish_time=10**9 + k
            )
        writer.finish()
    return file


def metadata_of(bag: Path) -> dict:
    return yaml.safe_load((bag / "metadata.yaml").read_text())


def write_metadata(bag: Path, data) -> None:
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    (bag / "metadata.yaml").write_text(yaml.dump(data, Dumper=dumper, sort_keys=False))


def qos_text(**changes) -> str:
    """A valid offered profile as rosbag2 writes it, with `changes`."""
    profile = {
        "history": "keep_last",
        "depth": 5,
        "reliability": "reliable",
        "durability": "volatile",
        "deadline": {"sec": 9223372036, "nsec": 854775807},
        "lifespan": {"sec": 9223372036, "nsec": 854775807},
        "liveliness": "automatic",
        "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
        "avoid_ros_namespace_conventions": False,
    }
    profile.update(changes)
    return yaml.safe_dump([profile], sort_keys=False)


def one_line(exc: BaseException) -> str:
    """The error's text, checked to be camo's own and one line."""
    from camo_bag.container import BagError

    assert isinstance(exc, BagError), repr(exc)
    text = str(exc)
    assert text.strip() and "\n" not in text and "Traceback" not in text, text
    return text
