"""The bag loader checks every level (path, metadata.yaml, QoS profiles, MCAP structure,
schemas, messages) before use: bad input gives one line of BagError, never a traceback, and
a partial read keeps what the file holds up to where it breaks."""

import copy
import os

import pytest
from bag_files import (
    CHATTER,
    STRING,
    metadata_of,
    one_line,
    qos_text,
    write_bag,
    write_mcap,
    write_metadata,
)
from hypothesis import event, given, settings
from hypothesis import strategies as st

from camo_bag.container import BagError
from camo_bag.loader import open_bag


def refused(path, **options) -> str:
    with pytest.raises(BagError) as caught:
        open_bag(path, **options)
    return one_line(caught.value)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A closed bag of five Strings; tests copy it before changing it."""
    return write_bag(tmp_path_factory.mktemp("tiny") / "bag")


@pytest.fixture
def bag(tiny, tmp_path):
    copy = tmp_path / "bag"
    copy.mkdir()
    for file in tiny.iterdir():
        (copy / file.name).write_bytes(file.read_bytes())
    return copy


def string_definition() -> bytes:
    from camo_bag.msgdefs import message_definition

    return message_definition(STRING).encode()


def string_cdr(text: str) -> bytes:
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    return serialize_message(String(data=text))


# ---- level 1: the path -------------------------------------------------------------------


def test_a_closed_bag_loads_with_its_topics_metadata_and_messages(bag):
    loaded = open_bag(bag)
    assert [(t.name, t.type, t.count) for t in loaded.summary.topics] == [(CHATTER, STRING, 5)]
    assert loaded.metadata["message_count"] == 5 and loaded.complete and not loaded.note()
    assert [m.data for m in loaded.messages()] == [string_cdr(f"m{k}") for k in range(5)]


def test_an_empty_path_is_refused_in_one_line():
    assert "empty" in refused("")
    assert "empty" in refused("   ")


def test_a_path_too_long_is_refused_in_one_line(tmp_path):
    assert "too long" in refused(tmp_path / ("x" * 300))
    assert "too long" in refused("/".join(["abc"] * 1100))


def test_a_path_with_a_control_character_is_refused_in_one_line():
    assert "control character" in refused("bag\0name")
    assert "control character" in refused("bag\nname")


def test_a_missing_bag_is_refused_in_one_line(tmp_path):
    assert "no such bag" in refused(tmp_path / "missing")


def test_a_file_that_is_neither_folder_nor_mcap_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    assert "neither a bag folder nor an .mcap file" in refused(tmp_path / "notes.txt")


def test_an_mcap_file_that_is_not_mcap_is_refused(tmp_path):
    (tmp_path / "foreign.mcap").write_bytes(b"this is not a bag\n" * 50)
    assert "not an MCAP file" in refused(tmp_path / "foreign.mcap")


def test_a_lone_mcap_file_is_read_as_a_bag(bag):
    loaded = open_bag(bag / "bag_0.mcap")
    assert loaded.metadata is None and loaded.summary.message_count == 5


def test_a_folder_without_metadata_or_mcap_is_not_a_bag(tmp_path):
    assert "no metadata.yaml and no .mcap file" in refused(tmp_path)


def test_a_folder_of_several_mcap_files_without_metadata_is_refused(bag):
    (bag / "metadata.yaml").unlink()
    (bag / "other_0.mcap").write_bytes((bag / "bag_0.mcap").read_bytes())
    assert "2 .mcap files" in refused(bag)


def test_a_folder_without_metadata_is_read_from_its_mcap_file(bag):
    (bag / "metadata.yaml").unlink()
    assert open_bag(bag).summary.message_count == 5


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any folder")
def test_an_unreadable_folder_is_refused_in_one_line(bag):
    bag.chmod(0)
    try:
        assert "permission denied" in refused(bag)
    finally:
        bag.chmod(0o755)


# ---- level 2: metadata.yaml --------------------------------------------------------------


def test_metadata_that_is_not_yaml_is_refused_with_its_line(bag):
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: [9\n")
    assert "is not YAML (line" in refused(bag)


def test_metadata_with_a_key_given_twice_is_refused_naming_the_line(bag):
    text = (bag / "metadata.yaml").read_text()
    lines = text.splitlines()
    at = next(k for k, line in enumerate(lines) if line.strip().startswith("version:"))
    lines.insert(at + 1, lines[at].replace("9", "8"))  # a second version, after the first
    (bag / "metadata.yaml").write_text("\n".join(lines) + "\n")
    said = refused(bag)
    assert (
        f"(line {at + 2}): the key 'version' is given twice (lines {at + 1} and {at + 2})" in said
    )


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("version: 1:00\n", "'1:00' is a base-60 number"),
        ("version: " + "9" * 5000 + "\n", "an integer of 5000 digits"),
        ("version: 9\n---\nversion: 9\n", "more than one document"),
        ("version: !!binary AAAA\n", "the tag !!binary is not read"),
        ("version: 9\x00\n", "the character U+0000"),
    ],
)
def test_metadata_that_yaml_1_1_reads_otherwise_is_one_line_in_words(bag, text, said):
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  " + text)
    message = refused(bag)
    assert said in message and "Error" not in message


def test_metadata_that_is_not_utf8_is_refused(bag):
    (bag / "metadata.yaml").write_bytes(b"\xff\xfe\x00")
    assert "not UTF-8" in refused(bag)


def test_metadata_without_bag_information_is_refused(bag):
    write_metadata(bag, {"something": 1})
    assert "lacks its field rosbag2_bagfile_information" in refused(bag)


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("version", 10, "version must be an integer in 1..9"),
        ("version", "9", "version must be an integer"),
        ("storage_identifier", "sqlite3", "storage_identifier must be one of mcap"),
        ("message_count", -1, "message_count must be an integer in 0.."),
        ("message_count", True, "message_count must be an integer"),
        ("duration", {"nanoseconds": 1.5}, "duration.nanoseconds must be an integer"),
        ("starting_time", {}, "starting_time lacks its field nanoseconds_since_epoch"),
        ("relative_file_paths", [], "relative_file_paths must be a non-empty list"),
        ("relative_file_paths", ["../x.mcap"], "must be an .mcap file inside the bag folder"),
        ("relative_file_paths", ["gone_0.mcap"], "names gone_0.mcap, which is not in"),
        ("topics_with_message_count", {}, "topics_with_message_count must be a list"),
    ],
)
def test_metadata_fields_of_a_wrong_type_or_range_are_refused(bag, field, value, words):
    data = metadata_of(bag)
    data["rosbag2_bagfile_information"][field] = value
    write_metadata(bag, data)
    assert words in refused(bag)


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("name", "chatter", "must be a topic name starting with /"),
        ("type", "String", "must be a message type pkg/msg/Type"),
        ("serialization_format", "json", "serialization_format must be one of cdr"),
        ("offered_qos_profiles", "[{depth: ", "offered_qos_profiles is not YAML"),
    ],
)
def test_metadata_topic_fields_are_checked(bag, field, value, words):
    data = metadata_of(bag)
    data["rosbag2_bagfile_information"]["topics_with_message_count"][0]["topic_metadata"][
        field
    ] = value
    write_metadata(bag, data)
    assert words in refused(bag)


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("depth", "abc", "depth must be an integer in 0..2147483647 (got 'abc')"),
        ("history", 99, "history must be one of system_default, keep_last"),
        ("depth", [1], "depth must be an integer in 0..2147483647 (got a list)"),
    ],
)
def test_a_malformed_qos_profile_in_metadata_is_refused_in_one_line(bag, field, value, words):
    """The three profiles that made `./camo replay` fail with a traceback."""
    data = metadata_of(bag)
    topic = data["rosbag2_bagfile_information"]["topics_with_message_count"][0]
    topic["topic_metadata"]["offered_qos_profiles"][0][field] = value
    write_metadata(bag, data)
    text = refused(bag)
    assert words in text and "offered_qos_profiles[0]" in text, text


def test_qos_profiles_as_rosbag2_writes_them_a_yaml_string_are_checked_too(bag):
    data = metadata_of(bag)
    topic = data["rosbag2_bagfile_information"]["topics_with_message_count"][0]
    topic["topic_metadata"]["offered_qos_profiles"] = qos_text(depth=3)
    write_metadata(bag, data)
    assert open_bag(bag).summary.topics[0].name == CHATTER
    topic["topic_metadata"]["offered_qos_profiles"] = qos_text(depth="abc")
    write_metadata(bag, data)
    assert "depth must be an integer" in refused(bag)


@pytest.mark.parametrize(
    ("field", "value", "said"),
    [
        ("name", "/other", "lists /other, which bag_0.mcap does not hold"),
        ("type", "std_msgs/msg/Int32", "gives /chatter the type std_msgs/msg/Int32"),
    ],
)
def test_metadata_naming_a_topic_or_type_the_file_does_not_hold_is_refused(
    bag, field, value, said
):
    data = metadata_of(bag)
    topic = data["rosbag2_bagfile_information"]["topics_with_message_count"][0]
    topic["topic_metadata"][field] = value
    write_metadata(bag, data)
    assert said in refused(bag)


def test_metadata_counting_other_messages_than_the_file_holds_is_refused(bag):
    data = metadata_of(bag)
    info = data["rosbag2_bagfile_information"]
    held = info["message_count"]
    info["message_count"] = 1_000_000
    write_metadata(bag, data)
    assert f"gives message_count 1000000, bag_0.mcap holds {held} messages" in refused(bag)
    info["message_count"] = held
    info["topics_with_message_count"][0]["message_count"] += 1
    write_metadata(bag, data)
    assert "gives /chatter" in refused(bag) and "messages, bag_0.mcap holds" in refused(bag)


def test_metadata_listing_a_topic_twice_is_refused(bag):
    data = metadata_of(bag)
    info = data["rosbag2_bagfile_information"]
    info["topics_with_message_count"] *= 2
    write_metadata(bag, data)
    assert "lists the topic /chatter twice" in refused(bag)


def test_a_partial_read_passes_over_an_invalid_metadata_and_says_so(bag):
    (bag / "metadata.yaml").write_text("version: [")
    loaded = open_bag(bag, partial=True)
    assert loaded.summary.message_count == 5
    assert "metadata.yaml passed over" in loaded.note() and "\n" not in loaded.note()


# ---- level 3: the MCAP file ---------------------------------------------------------------


def four_chunks(tmp_path):
    """A bag of four chunks of 20 messages each; the file and where each chunk ends."""
    from camo_bag.container import BagWriter, TopicInfo
    from camo_bag.msgdefs import message_definition

    writer = BagWriter(tmp_path / "whole")
    writer.add_topic(TopicInfo(CHATTER, STRING), message_definition(STRING))
    ends = [writer.file.stat().st_size]
    for chunk in range(4):
        for k in range(20):
            writer.write(CHATTER, string_cdr(f"{chunk}-{k}"), 10**9 + chunk * 100 + k, 0)
        writer.flush()
        ends.append(writer.file.stat().st_size)
    writer.close()
    return writer.file, ends


@pytest.mark.parametrize(
    "where", ["inside", "length", "opcode", "length, no summary", "opcode, no summary"]
)
def test_a_damaged_chunk_costs_its_messages_only_and_repair_says_how_many(tmp_path, where):
    """Chunks before and after a damaged one are kept, whether its contents or its framing
    are broken. A chunk whose framing is broken is read by the summary's chunk index while
    the summary reads; without it, the chunk is passed over, and the repair says it cannot
    tell what it held (it used to say 0 messages lost)."""
    from camo_bag.loader import repair

    file, ends = four_chunks(tmp_path)
    data = bytearray(file.read_bytes())
    chunk = ends[1]  # the second chunk's record starts where the first one's indexes end
    assert data[chunk] == 0x06
    if where == "inside":
        data[chunk + 80 : chunk + 100] = bytes(20)  # its records: a CRC that does not match
    elif where.startswith("length"):
        data[chunk + 1 : chunk + 9] = (2**62).to_bytes(8, "little")  # a length past the end
    else:
        data[chunk] = 0x7F  # an opcode MCAP does not have
    if where.endswith("no summary"):
        data[-8:] = bytes(8)  # its closing magic: the footer and summary are not to be trusted
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "damaged_0.mcap").write_bytes(bytes(data))
    bag, count = repair(damaged, tmp_path / "fixed")
    kept = [m.data for m in open_bag(tmp_path / "fixed").messages()]
    if where in ("length", "opcode"):
        assert count == 80 and len(kept) == 80, bag.ending
        assert bag.ending.startswith("1 chunk with damaged framing read by the summary's index")
        return
    expected = [string_cdr(f"{c}-{k}") for c in (0, 2, 3) for k in range(20)]
    assert kept == expected and count == 60, (len(kept), bag.ending)
    assert "1 damaged stretch passed over" in bag.ending, bag.ending
    if where == "inside":  # its indexes follow it intact
        assert "20 messages lost" in bag.ending, bag.ending
    else:
        assert "(what 1 of them held is not known)" in bag.ending, bag.ending


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 10**6), st.binary(min_size=1, max_size=16)), max_size=4))
def test_damage_anywhere_keeps_only_whole_messages_or_one_line(tmp_path_factory, damage):
    """Bytes overwritten anywhere: what partial reading keeps are messages as written, never
    a broken one; or a BagError."""
    tmp_path = tmp_path_factory.mktemp("damage")
    file, _ = four_chunks(tmp_path)
    data = bytearray(file.read_bytes())
    for offset, garbage in damage:
        at = 8 + offset % (len(data) - 8)  # the magic stays: another test breaks it
        data[at : at + len(garbage)] = garbage
    damaged = tmp_path / "d"
    damaged.mkdir()
    (damaged / "d_0.mcap").write_bytes(bytes(data)[: len(file.read_bytes())])
    written = {string_cdr(f"{c}-{k}") for c in range(4) for k in range(20)}
    try:
        bag = open_bag(damaged, partial=True, stream=True)
        kept = [m.data for m in bag.messages()]
    except BagError as exc:
        assert "\n" not in str(exc)
        return
    assert set(kept) <= written and len(kept) == len(set(kept))


def test_a_truncated_bag_is_refused_but_read_up_to_the_cut_when_partial(tmp_path):
    file, ends = four_chunks(tmp_path)
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(file.read_bytes()[: ends[2] + 10])  # two chunks whole
    assert "is truncated or was not closed" in refused(cut)
    loaded = open_bag(cut, partial=True)
    assert not loaded.complete and loaded.ending.startswith("cut short")
    assert [m.data for m in loaded.messages()] == [
        string_cdr(f"{c}-{k}") for c in range(2) for k in range(20)
    ]


def test_a_chunk_whose_crc_is_wrong_is_refused_in_one_line(tmp_path):
    file = write_mcap(
        tmp_path / "crc.mcap",
        [(CHATTER, STRING, "ros2msg", string_definition(), "cdr", {})],
        [(0, string_cdr("PAYLOAD-PAYLOAD"))],
    )
    data = bytearray(file.read_bytes())
    at = data.index(b"PAYLOAD-PAYLOAD")
    data[at] ^= 0xFF  # inside the (uncompressed) chunk: only its CRC can tell
    file.write_bytes(bytes(data))
    with pytest.raises(BagError) as caught:
        list(open_bag(file).messages())
    assert "CRC" in one_line(caught.value) or "corrupt" in str(caught.value)


def test_garbage_after_the_magic_is_refused_in_one_line(tmp_path):
    from camo_bag.container import MAGIC

    (tmp_path / "junk.mcap").write_bytes(MAGIC + b"\x01" * 300)
    assert "truncated" in refused(tmp_path / "junk.mcap")
    loaded = open_bag(tmp_path / "junk.mcap", partial=True)
    assert loaded.summary.topics == [] and loaded.ending.startswith("cut short")


def test_a_channel_with_a_malformed_qos_is_refused_but_kept_without_it_when_partial(tmp_path):
    file = write_mcap(
        tmp_path / "qos.mcap",
        [
            (
                CHATTER,
                STRING,
                "ros2msg",
                string_definition(),
                "cdr",
                {"offered_qos_profiles": qos_text(history=99)},
            )
        ],
        [(0, string_cdr("a"))],
    )
    assert "history must be one of" in refused(file)
    loaded = open_bag(file, partial=True)
    assert loaded.summary.topics[0].qos == "" and "QoS passed over" in loaded.note()


# ---- level 4: schemas ---------------------------------------------------------------------


def test_channels_whose_schema_is_unusable_are_left_out_and_noted(tmp_path):
    file = write_mcap(
        tmp_path / "schemas.mcap",
        [
            (CHATTER, STRING, "ros2msg", string_definition(), "cdr", {}),
            ("/alien", "alien_msgs/msg/Thing", "ros2msg", b"int32 x\n", "cdr", {}),
            ("/garbled", "std_msgs/msg/Int32", "ros2msg", b"int32[ data x y\n", "cdr", {}),
            ("/json", "std_msgs/msg/String", "jsonschema", b"{}", "json", {}),
            ("/odd", "not a type", "ros2msg", b"", "cdr", {}),
            ("/two\nlines", STRING, "ros2msg", string_definition(), "cdr", {}),
        ],
        [(k, b"\x00\x01\x00\x00") for k in range(6)] + [(0, string_cdr("kept"))],
    )
    loaded = open_bag(file)
    assert [t.name for t in loaded.summary.topics] == [CHATTER]
    assert sorted(loaded.left_out) == ["'/two\\nlines'", "/alien", "/garbled", "/json", "/odd"]
    assert "unknown type 'alien_msgs/msg/Thing'" in loaded.left_out["/alien"]
    assert "does not parse" in loaded.left_out["/garbled"]
    assert [m.topic for m in loaded.messages()] == [CHATTER, CHATTER]
    note = loaded.note()
    assert note.startswith("left out of") and "5 unusable topics" in note and "\n" not in note


# ---- level 5: messages --------------------------------------------------------------------


def test_messages_that_do_not_decode_are_rejected_and_counted(tmp_path):
    """The completeness check decodes every message of the run; one that does not decode is
    left out and counted once, however many readers meet it."""
    from camo_bag.completeness import examine

    file = write_mcap(
        tmp_path / "run.mcap",
        [("/swarm/params", STRING, "ros2msg", string_definition(), "cdr", {})],
        [(0, b"\x00\x01\x00\x00\xff\xff"), (0, b"\x00"), (0, string_cdr("{}"))],
    )
    loaded = open_bag(file)
    examine(loaded)
    examine(loaded)
    assert loaded.rejected_count == 2
    assert "2 messages that do not decode (/swarm/params: 2)" in loaded.note()


def test_replay_refuses_a_channel_qos_that_is_malformed_in_one_line(tmp_path, capsys):
    """`./camo replay` checked nothing of the QoS it gave its publishers: depth abc, history
    99 and depth [1] were three tracebacks. Now one line each, before ROS starts."""
    from camo_bag.replay import main

    for k, change in enumerate(({"depth": "abc"}, {"history": 99}, {"depth": [1]})):
        file = write_mcap(
            tmp_path / f"q{k}.mcap",
            [
                (
                    CHATTER,
                    STRING,
                    "ros2msg",
                    string_definition(),
                    "cdr",
                    {"offered_qos_profiles": qos_text(**change)},
                )
            ],
            [(0, string_cdr("a"))],
        )
        assert main([str(file)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("camo replay: error: ") and err.count("\n") == 1, err
        assert f"offered_qos_profiles[0].{next(iter(change))} must be" in err


def test_replay_refuses_a_topic_it_cannot_replay_before_ros_starts(tmp_path, capsys):
    from camo_bag.replay import main

    file = write_mcap(
        tmp_path / "t.mcap",
        [
            (CHATTER, STRING, "ros2msg", string_definition(), "cdr", {}),
            ("/alien", "alien_msgs/msg/Thing", "ros2msg", b"int32 x\n", "cdr", {}),
        ],
        [(0, string_cdr("a"))],
    )
    assert main([str(file), "--topics", "/alien"]) == 2
    err = capsys.readouterr().err
    assert "topic /alien cannot be replayed: unknown type" in err and err.count("\n") == 1
    assert main([str(file), "--topics", "/nothing"]) == 2
    assert "the bag has no topic /nothing" in capsys.readouterr().err


def test_bag_info_warns_in_one_line_of_what_it_left_out(tmp_path, capsys):
    from camo_bag.cli import main

    file = write_mcap(
        tmp_path / "info.mcap",
        [
            (CHATTER, STRING, "ros2msg", string_definition(), "cdr", {}),
            ("/alien", "alien_msgs/msg/Thing", "ros2msg", b"int32 x\n", "cdr", {}),
        ],
        [(0, string_cdr("a")), (1, b"\x00\x01\x00\x00\x01\x00\x00\x00")],
    )
    assert main(["info", str(file)]) == 0
    captured = capsys.readouterr()
    assert f"Topic: {CHATTER}" in captured.out and "/alien" not in captured.out
    assert captured.err.count("\n") == 1 and "unknown type" in captured.err


def test_repair_keeps_every_usable_topic_and_writes_a_valid_bag(tmp_path):
    from camo_bag.loader import repair

    file = write_mcap(
        tmp_path / "r.mcap",
        [
            (
                CHATTER,
                STRING,
                "ros2msg",
                string_definition(),
                "cdr",
                {"offered_qos_profiles": qos_text(depth="abc")},
            ),
            ("/alien", "alien_msgs/msg/Thing", "ros2msg", b"int32 x\n", "cdr", {}),
        ],
        [(0, string_cdr("a")), (1, b"\x00"), (0, string_cdr("b"))],
    )
    read, count = repair(file, tmp_path / "fixed")
    assert count == 2 and "QoS passed over" in read.note()
    fixed = open_bag(tmp_path / "fixed")
    assert [m.data for m in fixed.messages()] == [string_cdr("a"), string_cdr("b")]


# ---- fuzzed: structured bad input at every level -----------------------------------------

BAD_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True),
    st.text(max_size=8),
    st.sampled_from(["abc", "99", "keep_last", "unknown", "-1", "", "/", "mcap", "cdr"]),
    st.lists(st.integers(-3, 3), max_size=2),
    st.dictionaries(st.sampled_from(["sec", "nsec", "x"]), st.integers(-2, 2), max_size=2),
)


def places(value, at=()):
    """Every place in a nested structure of dicts and lists, as key paths."""
    yield at
    if isinstance(value, dict):
        for key, item in value.items():
            yield from places(item, (*at, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from places(item, (*at, index))


def changed(data, at, how, value):
    """A copy of `data` with the value at `at` replaced, removed, or given an extra key."""
    data = copy.deepcopy(data)
    if not at:
        return value
    parent = data
    for key in at[:-1]:
        parent = parent[key]
    if how == "replace":
        parent[at[-1]] = value
    elif how == "remove":
        del parent[at[-1]]
    elif isinstance(parent[at[-1]], dict):
        parent[at[-1]]["unexpected"] = value
    return data


def loads_or_one_line(path, **options):
    """Open the bag, read its messages and take its QoS as replay does: all of it works, or
    gives one line of BagError."""
    from camo_bag import qos_yaml

    try:
        loaded = open_bag(path, **options)
        for topic in loaded.summary.topics:
            qos_yaml.load_first(topic.qos)
        messages = [m.data for m in loaded.messages()]
    except BagError as exc:
        event(f"refused: {one_line(exc).split(' ', 1)[1][:30]}")
        return None, None
    event("loads")
    return loaded, messages


@given(data=st.data())
def test_metadata_with_a_wrong_value_anywhere_loads_or_gives_one_line(tiny, tmp_path, data):
    import shutil

    original = metadata_of(tiny)
    at = data.draw(st.sampled_from(list(places(original))), label="at")
    how = data.draw(st.sampled_from(["replace", "remove", "extra"]), label="how")
    value = data.draw(BAD_VALUES, label="value")
    bag = tmp_path / "bag"
    shutil.rmtree(bag, ignore_errors=True)
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes((tiny / "bag_0.mcap").read_bytes())
    write_metadata(bag, changed(original, at, how, value))
    loaded, messages = loads_or_one_line(bag)
    if loaded is not None:
        assert messages == [string_cdr(f"m{k}") for k in range(5)]
    partial, _ = loads_or_one_line(bag, partial=True)
    assert partial is not None  # a partial read passes over a wrong metadata.yaml


TYPES = [STRING, "std_msgs/msg/Int32", "sensor_msgs/msg/Image", "alien_msgs/msg/Thing", "x", ""]
QOS_FIELDS = ["history", "depth", "reliability", "durability", "deadline", "liveliness"]


@st.composite
def channels(draw):
    name = draw(st.sampled_from(TYPES))
    definition = draw(
        st.one_of(
            st.just(None),  # the installed definition of the type
            st.binary(max_size=20),
            st.sampled_from([b"int32 data\n", b"string data\n", b"int32[ x\n", b"Foo bar\n"]),
        )
    )
    if definition is None:
        from camo_bag.msgdefs import DefinitionError, message_definition

        try:
            definition = message_definition(name).encode()
        except DefinitionError:
            definition = b""
    qos = draw(
        st.one_of(
            st.just(qos_text()),
            st.builds(
                lambda field, value: qos_text(**{field: value}),
                st.sampled_from(QOS_FIELDS),
                BAD_VALUES,
            ),
            st.text(max_size=12),
        )
    )
    return (
        draw(st.sampled_from(["/a", "/b", "/c", "no_slash", "/new\nline"])),
        name,
        draw(st.sampled_from(["ros2msg", "ros2msg", "jsonschema", ""])),
        definition,
        draw(st.sampled_from(["cdr", "cdr", "json"])),
        {"offered_qos_profiles": qos},
    )


@given(
    chans=st.lists(channels(), min_size=1, max_size=3),
    payloads=st.lists(
        st.tuples(st.integers(0, 2), st.one_of(st.binary(max_size=16), st.just(b"GOOD"))),
        max_size=6,
    ),
)
def test_an_mcap_file_with_any_schema_and_qos_loads_or_gives_one_line(tmp_path, chans, payloads):
    """Written with the `mcap` writer: channels of known, unknown and garbled schemas, any QoS
    metadata, messages of any bytes. Loading, reading and decoding each as its type (a
    message that does not: rejected, counted) works or gives one line."""
    from rclpy.serialization import deserialize_message

    from camo_bag.msgdefs import message_class

    messages = [(i % len(chans), string_cdr("ok") if p == b"GOOD" else p) for i, p in payloads]
    file = write_mcap(tmp_path / "fuzz.mcap", chans, messages)
    loaded, _ = loads_or_one_line(file)
    if loaded is None:
        return
    types = {t.name: message_class(t.type) for t in loaded.summary.topics}
    for message in loaded.messages():
        try:
            deserialize_message(message.data, types[message.topic])
        except Exception:  # noqa: BLE001 - what the loader's readers do with such bytes
            loaded.reject(message)
    assert "\n" not in loaded.note()


@given(cut=st.floats(0, 1, exclude_max=True))
def test_a_bag_cut_anywhere_gives_one_line_or_what_it_holds_up_to_the_cut(tiny, tmp_path, cut):
    """Cut at any offset, a bag is refused in one line; read partially, it gives the messages
    before the cut, in order; repaired, a bag that loads."""
    import shutil

    from camo_bag.loader import repair

    whole = (tiny / "bag_0.mcap").read_bytes()
    bag = tmp_path / "bag"
    shutil.rmtree(bag, ignore_errors=True)
    shutil.rmtree(tmp_path / "fixed", ignore_errors=True)
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(whole[: int(cut * len(whole))])
    loaded, _ = loads_or_one_line(bag)
    assert loaded is None
    partial, messages = loads_or_one_line(bag, partial=True)
    if partial is None:  # the magic itself cut
        return
    expected = [string_cdr(f"m{k}") for k in range(5)]
    assert messages == expected[: len(messages)]
    _, count = repair(bag, tmp_path / "fixed")
    assert count == len(messages)
    assert [m.data for m in open_bag(tmp_path / "fixed").messages()] == messages


# ---- every option of the bag commands with bad values (issue 27) -----------------------------


@pytest.mark.parametrize(
    "module, argv, work",
    [
        ("camo_bag.render", ["BAG", "--out", "OUT"], "render"),
        ("camo_bag.replay", ["BAG"], "start_ros"),
        ("camo_bag.cli", ["repair", "BAG"], "repair"),
    ],
)
def test_every_option_of_render_replay_and_repair_with_a_bad_value_is_one_line(
    module, argv, work, tiny, tmp_path, monkeypatch, capsys
):
    # Only the command line and the bag are checked: the work itself is replaced.
    import importlib

    from support import bad_value_outcomes, parser_of_main, validated, value_options

    command = importlib.import_module(module)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(command, work, validated)
    argv = [str(tiny) if a == "BAG" else str(tmp_path / "out") if a == "OUT" else a for a in argv]
    parser = parser_of_main(command.main, argv, monkeypatch)
    options = value_options(parser)
    assert options, module
    problems = [
        p for o in options for p in bad_value_outcomes(command.main, argv, o, capsys, parser)
    ]
    assert problems == []


def test_every_option_of_the_discovery_server_with_a_bad_value_is_one_line(
    tmp_path, monkeypatch, capsys
):
    from support import bad_value_outcomes, validated

    from camo_nodes import discovery_server as command

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(command.os, "execve", validated)
    monkeypatch.setattr(command, "server_command", lambda *a: ("x", ["x"], {}))
    for option in ("--port", "--address", "--server-id"):
        assert bad_value_outcomes(command.main, [], option, capsys) == [], option


def test_a_bag_whose_opening_magic_is_damaged_is_repaired_whole(tmp_path):
    # Its first 8 bytes overwritten: every reader said "not an MCAP file", and its messages
    # were out of reach though every chunk was whole.
    from camo_bag.loader import repair

    file, _ = four_chunks(tmp_path)
    data = bytearray(file.read_bytes())
    data[:8] = b"garbage!"
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    (damaged / "damaged_0.mcap").write_bytes(bytes(data))
    said = refused(damaged)
    assert "its first bytes are damaged" in said and "bag repair" in said and "\n" not in said
    bag, count = repair(damaged, tmp_path / "fixed")
    assert count == 80 and "its opening magic is damaged" in bag.note()
    kept = [m.data for m in open_bag(tmp_path / "fixed").messages()]
    assert kept == [string_cdr(f"{c}-{k}") for c in range(4) for k in range(20)]


@pytest.mark.parametrize("size", [9, 30, 40])
def test_a_file_shorter_than_any_footer_is_truncated_not_an_os_error(tmp_path, size):
    # A 30-byte MCAP said "cannot read ...: Invalid argument" (a seek before its start).
    folder = tmp_path / "short"
    folder.mkdir()
    (folder / "short_0.mcap").write_bytes((b"\x89MCAP0\r\n" + bytes(64))[:size])
    assert "is truncated or was not closed" in refused(folder)
