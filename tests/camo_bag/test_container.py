"""Bags as rosbag2 writes them with MCAP: read back by two independent readers; bad files
refused in one line; a cut file repaired."""

import pytest
from hypothesis import given
from hypothesis import strategies as st
from support import (
    BAG_COLS,
    BAG_FORMATION,
    BAG_ROWS,
    BAG_RUN,
    BAG_STEPS,
    SWARM,
    bag_tool,
    tile_range,
    unpacked,
)


def deserialize(data: bytes) -> str:
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    return deserialize_message(data, String).data


@pytest.mark.slow(SWARM)
def test_bag_is_a_rosbag2_folder_with_an_indexed_ros2_mcap(recorded):
    from mcap.reader import make_reader

    bag, _ = recorded
    assert sorted(p.name for p in bag.iterdir()) == ["bag_0.mcap", "metadata.yaml"]
    with open(bag / "bag_0.mcap", "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    votes = next(
        s for s in summary.schemas.values() if s.name == "camo_msgs/msg/Votes"
    ).data.decode()
    assert votes.startswith("# Phase 2 (consensus): the senders' pattern votes p")
    assert "\nfloat64[] p\n" in votes
    assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in votes
    assert "\nMSG: builtin_interfaces/Time\n" in votes
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        assert "reliability:" in channel.metadata["offered_qos_profiles"]
    background = next(
        c for c in summary.channels.values() if c.topic == f"/{BAG_RUN}/camo/background"
    )
    assert "durability: transient_local" in background.metadata["offered_qos_profiles"]


@pytest.mark.slow(SWARM)
def test_mcap_ros2_decoder_reads_every_robot_message(recorded):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    bag, live = recorded
    votes, final, publish_before_log = {}, {}, True
    with open(bag / "bag_0.mcap", "rb") as stream:
        for _schema, channel, message, msg in make_reader(
            stream, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            if channel.topic.endswith("/vote"):
                for vote in unpacked(msg, "vote"):
                    assert vote.sender_id in tile_range(channel.topic)  # a tile's robots only
                    assert abs(sum(vote.p) - 1.0) < 1e-9 and vote.phase == 2  # as Vote.msg says
                    votes.setdefault(vote.sender_id, []).append(vote.step)
            elif channel.topic == f"/{BAG_RUN}/swarm/status":
                for robot, phase, state in zip(msg.sender_id, msg.phase, msg.state, strict=True):
                    if phase == 4:  # done: its final state
                        final[divmod(robot, BAG_COLS)] = state
            publish_before_log &= message.publish_time <= message.log_time
    # Loss is drawn where a message is received, so every robot publishes every step's vote.
    assert sorted(votes) == list(range(BAG_ROWS * BAG_COLS))
    assert all(sorted(steps) == list(range(BAG_STEPS)) for steps in votes.values())
    assert [[final[(i, j)] for j in range(BAG_COLS)] for i in range(BAG_ROWS)] == live["final"]
    assert publish_before_log


@pytest.mark.slow(SWARM)
def test_rosbags_anyreader_reads_the_bag_folder(recorded):
    from rosbags.highlevel import AnyReader

    bag, live = recorded
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types[f"/{BAG_RUN}/camo/background"] == "sensor_msgs/msg/Image"
        tiles = sorted(t for t in types if "/tile_" in t)
        # Two processes, two tiles of 15 robots: edge and core topics of four kinds each.
        assert {t.split("/")[3] for t in tiles} == {"tile_0_14", "tile_15_29"} and len(tiles) == 16
        names = {"hello": "Hellos", "color": "Colors", "vote": "Votes", "state": "States"}
        assert all(types[t] == f"camo_msgs/msg/{names[t.rsplit('/', 1)[1]]}" for t in tiles)
        sent: dict[tuple[int, str], int] = {}
        sensed = {}
        robots = [c for c in reader.connections if "/tile_" in c.topic]
        for connection, _, raw in reader.messages(connections=robots):
            kind = connection.topic.rsplit("/", 1)[1]
            for msg in unpacked(reader.deserialize(raw, connection.msgtype), kind):
                sent[(msg.sender_id, kind)] = sent.get((msg.sender_id, kind), 0) + 1
                if kind == "color":
                    sensed[msg.sender_id] = msg.value
    assert sent[(7, "state")] == BAG_FORMATION and sent[(7, "hello")] == 1
    assert [[sensed[i * BAG_COLS + j] for j in range(BAG_COLS)] for i in range(BAG_ROWS)] == live[
        "sensed"
    ]


@pytest.mark.slow(SWARM)
def test_truncated_and_foreign_files_get_one_line_errors(recorded, tmp_path):
    bag, _ = recorded
    data = (bag / "bag_0.mcap").read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(data[: len(data) * 2 // 3])
    foreign = tmp_path / "foreign.mcap"
    foreign.write_bytes(b"this is not a bag\n" * 50)
    for path, words in (
        (cut, "truncated"),
        (foreign, "not an MCAP file"),
        (tmp_path / "missing", "no such bag"),
    ):
        for command in (
            ["cli", "info", str(path)],
            ["render", str(path), "--out", str(tmp_path / "r")],
            ["replay", str(path)],
        ):
            out = bag_tool(*command)
            assert out.returncode == 2, (command, out.stderr)
            assert words in out.stderr and len(out.stderr.strip().splitlines()) == 1, (
                command,
                out.stderr,
            )
    out = bag_tool("cli", "repair", str(foreign))
    assert out.returncode == 2 and "not an MCAP file" in out.stderr


@pytest.mark.slow(SWARM)
def test_bag_info_of_a_bag_whose_messages_are_damaged_says_so_and_fails(recorded, tmp_path):
    from mcap.reader import make_reader

    bag, _ = recorded
    data = bytearray((bag / "bag_0.mcap").read_bytes())
    with open(bag / "bag_0.mcap", "rb") as f:
        largest = max(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_length)
    # Inside a chunk's records: the summary still reads, the messages not.
    data[largest.chunk_start_offset + largest.chunk_length // 2] ^= 0xFF
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "damaged_0.mcap").write_bytes(bytes(data))
    out = bag_tool("cli", "info", str(damaged))
    assert out.returncode == 2, out.stdout
    assert "Duration:" in out.stdout  # what the summary says is still shown
    assert len(out.stderr.strip().splitlines()) == 1 and "corrupt" in out.stderr, out.stderr


def test_repair_keeps_every_complete_chunk_of_a_cut_file(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from camo_bag.container import BagWriter, TopicInfo
    from camo_bag.loader import read_messages
    from camo_bag.msgdefs import message_definition

    writer = BagWriter(tmp_path / "whole")
    writer.add_topic(
        TopicInfo("/chatter", "std_msgs/msg/String"), message_definition("std_msgs/msg/String")
    )
    ends = []
    for chunk in range(6):
        for k in range(50):
            writer.write(
                "/chatter",
                serialize_message(String(data=f"{chunk}-{k}")),
                10**9 + chunk * 100 + k,
                0,
            )
        writer.flush()
        ends.append(writer.file.stat().st_size)
    writer.close()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(
        (tmp_path / "whole" / "whole_0.mcap").read_bytes()[: ends[2] + 10]
    )
    out = bag_tool("cli", "repair", str(cut), "--out", str(tmp_path / "fixed"))
    assert out.returncode == 0, out.stderr
    assert "cut short" in out.stdout and "wrote 150 messages" in out.stdout
    texts = [deserialize(m.data) for m in read_messages(tmp_path / "fixed")]
    assert texts == [f"{c}-{k}" for c in range(3) for k in range(50)]


# ---- fuzzed: bags damaged in any way -----------------------------------------------------


def mutations():
    """A bag's bytes cut short, with bytes flipped or overwritten, or with bytes inserted."""
    spot = st.floats(0, 1, exclude_max=True)  # where, as a fraction of the file
    return st.one_of(
        st.tuples(st.just("cut"), spot, st.just(b"")),
        st.tuples(st.just("flip"), spot, st.binary(min_size=1, max_size=8)),
        st.tuples(st.just("insert"), spot, st.binary(min_size=1, max_size=64)),
    )


def mutated(data: bytes, changes) -> bytes:
    for how, where, payload in changes:
        at = int(where * len(data))
        if how == "cut":
            data = data[:at]
        elif how == "flip":
            data = (
                data[:at]
                + bytes(a ^ b | 1 for a, b in zip(data[at:], payload, strict=False))
                + data[at + len(payload) :]
            )
        else:
            data = data[:at] + payload + data[at:]
    return data


@pytest.mark.slow(SWARM)
@given(changes=st.lists(mutations(), min_size=1, max_size=3))
def test_a_damaged_bag_gives_a_one_line_error_or_what_it_holds(
    recorded, tmp_path_factory, changes
):
    """Every reader of bags (info, the completeness check, render, repair) either works or
    raises the project's own error; never anything else."""
    from camo_bag.completeness import examine
    from camo_bag.loader import read_messages, read_summary, repair
    from camo_bag.render import load_run
    from camo_core.exceptions import CamoError

    bag, _ = recorded
    folder = tmp_path_factory.mktemp("damaged")
    (folder / "damaged_0.mcap").write_bytes(mutated((bag / "bag_0.mcap").read_bytes(), changes))
    readers = [
        read_summary,
        lambda path: list(read_messages(path)),
        examine,
        load_run,
        lambda path: repair(path, folder.parent / f"{folder.name}_repaired"),
    ]
    for read in readers:
        try:
            read(folder)
        except CamoError as exc:
            assert "\n" not in str(exc), exc
