"""A bag is judged against its run: a complete recording passes, and a bag that lost robots'
votes, done reports or the run's result is named incomplete (which robots, which kinds) by the
ledger, by `bag info` and by `render`, which refuses it unless --partial and then writes no NaN."""

import json
import math

import numpy as np
import pytest
from support import BAG_COLS, BAG_ROWS, BAG_RUN, SWARM, bag_tool

from camo_bag.completeness import examine, message_fields
from camo_bag.container import BagWriter, TopicInfo
from camo_bag.loader import read_messages, read_summary
from camo_core.swarm.robot_io import PHASE_OF


def copy_bag(source, target, drop=lambda topic, data: False, edit=None) -> None:
    """A copy of a bag without the messages `drop(topic, data)` picks; `edit(topic, data)`, if
    given, returns what a message becomes: a list of CDR bytes (none: dropped)."""
    summary = read_summary(source)
    writer = BagWriter(target, library="test")
    for topic in summary.topics:
        writer.add_topic(
            TopicInfo(topic.name, topic.type, topic.qos, topic.type_hash), topic.definition
        )
    for message in read_messages(source):
        if drop(message.topic, message.data):
            continue
        edited = [message.data] if edit is None else edit(message.topic, message.data)
        for data in edited:
            writer.write(message.topic, data, message.log_time, message.publish_time)
    writer.close()


def without_votes_of(robots: set[int]):
    """An `edit` for copy_bag: vote columns without those robots' votes."""
    from rclpy.serialization import deserialize_message, serialize_message

    from camo_msgs.msg import Votes
    from camo_nodes.topics.robot_messages import Columns, unpack

    def edit(topic, data):
        if not topic.endswith("/vote"):
            return [data]
        kept = Columns("vote")
        for message in unpack("vote", deserialize_message(data, Votes)):
            if message.sender not in robots:
                kept.add(message)
        return [serialize_message(kept.take())] if len(kept) else []

    return edit


def single(message):
    """One robot's message as older camo sent it (`camo_msgs/Vote`, ...)."""
    from camo_nodes.topics.robot_messages import MESSAGE_TYPES

    msg = MESSAGE_TYPES[message.kind](sender_id=message.sender, round=message.round)
    msg.step, msg.phase, value = message.step, PHASE_OF[message.kind], message.value
    if message.kind == "vote":
        msg.p, msg.histogram, msg.degree = value[0][:3], value[0][3:], value[1]
    elif message.kind == "hello":
        msg.row, msg.col = value
    elif message.kind == "color":
        msg.value = value
    else:
        msg.state = value
    return msg


def older_layout(source, target, arrays: bool) -> None:
    """The bag as older camo recorded it: its robot messages in arrays (`camo_msgs/VoteArray`
    of `camo_msgs/Vote`s, and so on) or, `arrays` false, one per bag message."""
    from rclpy.serialization import deserialize_message, serialize_message

    from camo_bag.ledger import COLUMN_KINDS
    from camo_bag.msgdefs import message_class, message_definition
    from camo_nodes.topics.robot_messages import ARRAY_TYPES, MESSAGE_TYPES, unpack

    summary = read_summary(source)
    writer = BagWriter(target, library="test")
    columns = {}
    for topic in summary.topics:
        type_name, definition = topic.type, topic.definition
        if type_name in COLUMN_KINDS:
            kind = COLUMN_KINDS[type_name]
            columns[topic.name] = (kind, message_class(type_name))
            cls = (ARRAY_TYPES if arrays else MESSAGE_TYPES)[kind]
            type_name = f"camo_msgs/msg/{cls.__name__}"
            definition = message_definition(type_name)
        writer.add_topic(TopicInfo(topic.name, type_name, topic.qos, ""), definition)
    for message in read_messages(source):
        if message.topic not in columns:
            written = [message.data]
        else:
            kind, cls = columns[message.topic]
            singles = [single(m) for m in unpack(kind, deserialize_message(message.data, cls))]
            if arrays:
                written = [serialize_message(ARRAY_TYPES[kind](messages=singles))]
            else:
                written = [serialize_message(m) for m in singles]
        for data in written:
            writer.write(message.topic, data, message.log_time, message.publish_time)
    writer.close()


def strict_json(path) -> dict:
    """summary.json, refusing NaN and Infinity."""

    def refuse(constant):
        raise AssertionError(f"{path} holds {constant}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_robot_message_fields_are_read_from_cdr_as_rclpy_would_decode_them():
    from rclpy.serialization import serialize_message

    from camo_msgs.msg import Color, Hello, State, Vote

    messages = {
        "hello": Hello(sender_id=70000, row=3, col=9, phase=0, step=0, round=2),
        "color": Color(sender_id=5, phase=1, step=0, round=1, value=12.5),
        "vote": Vote(sender_id=7, phase=2, step=1234, round=3, p=[0.2, 0.3, 0.5], degree=4),
        "state": State(sender_id=8, phase=3, step=9, round=0, state=1),
    }
    for frame in ("", "camo", "a longer frame"):
        for kind, msg in messages.items():
            msg.header.frame_id = frame
            expected = (msg.sender_id, msg.round, msg.step)
            assert message_fields(kind, serialize_message(msg)) == expected, (kind, frame)


@pytest.mark.slow(SWARM)
def test_a_whole_recording_is_complete(recorded):
    bag, _ = recorded
    ledger = examine(bag)
    assert ledger.gaps() == [] and ledger.result["ended"] == "finished"
    info = bag_tool("cli", "info", str(bag))
    assert info.returncode == 0 and "Run:               complete" in info.stdout


@pytest.mark.slow(SWARM)
def test_a_bag_that_lost_robots_votes_is_incomplete_and_render_refuses_it(recorded, tmp_path):
    bag, live = recorded
    lost = {3, 4, 5, 11}
    copy_bag(bag, tmp_path / "cut", edit=without_votes_of(lost))
    gaps = examine(tmp_path / "cut").gaps()
    assert gaps == ["round 0: 4 robots lack votes: 3-5, 11"]
    # Bags of older camo: arrays of robot messages, and one robot message a bag message (whose
    # fields are read from the CDR bytes).
    for name, arrays in (("arrays", True), ("older", False)):
        older_layout(bag, tmp_path / name, arrays)
        assert examine(tmp_path / name).gaps() == []
        again = bag_tool("render", str(tmp_path / name), "--out", str(tmp_path / f"{name}_r"))
        assert again.returncode == 0, again.stderr
        assert strict_json(tmp_path / f"{name}_r" / "summary.json")["final"] == live["final"]
    copy_bag(
        tmp_path / "older",
        tmp_path / "older_cut",
        lambda topic, data: topic.endswith("/vote") and message_fields("vote", data)[0] in lost,
    )
    assert examine(tmp_path / "older_cut").gaps() == gaps
    info = bag_tool("cli", "info", str(tmp_path / "cut"))
    assert "INCOMPLETE" in info.stdout and "3-5, 11" in info.stdout
    refused = bag_tool("render", str(tmp_path / "cut"), "--out", str(tmp_path / "r"))
    assert refused.returncode == 1 and "Traceback" not in refused.stderr
    assert refused.stderr.count("\n") == 1 and "is incomplete" in refused.stderr
    partial = bag_tool("render", str(tmp_path / "cut"), "--out", str(tmp_path / "p"), "--partial")
    assert partial.returncode == 0, partial.stderr
    summary = strict_json(tmp_path / "p" / "summary.json")
    assert summary["incomplete"] == gaps[0]
    assert summary["final"] == live["final"]  # the statuses are all there


@pytest.mark.slow(SWARM)
def test_a_bag_without_statuses_or_result_names_every_robot_and_writes_null_not_nan(
    recorded, tmp_path
):
    bag, _ = recorded
    done_of = set(range(0, BAG_ROWS * BAG_COLS, 2))  # half the robots' statuses are gone

    def drop(topic, data):
        return topic.endswith("/swarm/result")

    def edit(topic, data):
        """Status arrays without those robots' rows."""
        if not topic.endswith("/swarm/status"):
            return [data]
        from rclpy.serialization import deserialize_message, serialize_message

        from camo_core.swarm.status_rows import StatusRows
        from camo_msgs.msg import StatusArray

        msg = deserialize_message(data, StatusArray)
        rows = StatusRows.from_message(msg)
        kept = rows.select(~np.isin(rows.sender_id, list(done_of)))
        cut = StatusArray(header=msg.header, name=msg.name, **kept.message_fields())
        return [serialize_message(cut)] if len(kept) else []

    copy_bag(bag, tmp_path / "cut", drop, edit)
    gaps = examine(tmp_path / "cut").gaps()
    assert gaps[0].startswith("the run's result is not in the bag")
    count = BAG_ROWS * BAG_COLS
    assert gaps[1].startswith(f"round 0: {count // 2} robots lack done reports: 0, 2, 4")
    partial = bag_tool("render", str(tmp_path / "cut"), "--out", str(tmp_path / "p"), "--partial")
    assert partial.returncode == 0, partial.stderr
    summary = strict_json(tmp_path / "p" / "summary.json")
    assert summary["final"][0][0] is None and summary["final"][0][1] is not None
    assert all(v is None or math.isfinite(v) for row in summary["sensed"] for v in row)


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("ended", ["interrupted", "failed"])
def test_a_run_that_ended_early_makes_an_incomplete_bag(recorded, tmp_path, ended):
    from camo_bag.ledger import Ledger

    ledger = Ledger()
    ledger.set_run(examine(recorded[0]).params, 1)
    ledger.set_result({"run": BAG_RUN, "ended": ended, "rounds": []})
    assert ledger.gaps() == [f"the run ended early ({ended}): not every round ran"]


def test_the_ledger_counts_each_step_once_and_ignores_steps_no_robot_sends():
    from camo_bag.ledger import Ledger
    from camo_core.algorithm.params import CamoParams

    ledger = Ledger()
    ledger.set_run(CamoParams(rows=1, cols=2, consensus_steps=3, formation_steps=2), 1)
    ledger.background()  # frame 0
    for robot in (0, 1):
        ledger.message("hello", robot, 0)
        ledger.message("color", robot, 0)
        ledger.reported_done(robot, 0)
        for step in (0, 1, 1, 1, 7, 10**9, -1):  # the same step thrice, steps out of range
            ledger.message("vote", robot, 0, step)
        ledger.message("state", robot, 0, 0)
        ledger.message("state", robot, 0, 1)
    ledger.message("vote", 1, 0, 2)
    ledger.set_result({"run": "r", "ended": "finished", "rounds": [{"finished": [[0, 1]]}]})
    assert ledger.complete(0) == {1}
    assert ledger.gaps() == ["round 0: 1 robot lacks votes: 0"]
    assert ledger.lacking(0) == {"vote": 1}


def test_a_continuous_runs_rounds_are_its_frames_and_its_result_names_them():
    from camo_bag.ledger import Ledger
    from camo_core.algorithm.params import CamoParams

    ledger = Ledger()
    ledger.set_run(CamoParams(rows=1, cols=1, consensus_steps=1, formation_steps=1), 1, True)
    for frame in (0, 1, 7, 40):
        ledger.background(frame)
    for round_ in (7, 40):
        for kind in ("hello", "color", "vote", "state"):
            ledger.message(kind, 0, round_)
        ledger.reported_done(0, round_)
    result = [{"round": 7, "finished": [[0, 0]]}, {"round": 40, "finished": [[0, 0]]}]
    ledger.set_result({"run": "r", "ended": "finished", "rounds": result})
    assert ledger.complete(7) == ledger.complete(40) == {0} and not ledger.gaps()
    ledger.set_result(
        {"run": "r", "ended": "finished", "rounds": [{"round": 41, "finished": [[0, 0]]}]}
    )
    assert ledger.gaps() == [
        "round 41: its background is not in the bag",
        "round 41: 1 robot lacks hellos, colours, votes, states, done reports: 0",
    ]


def test_a_long_continuous_runs_ledger_holds_a_few_numbers_a_round():
    # Every round's every robot's flags of every step were kept for as long as the run went, and
    # the rounds a recorder reported grew with them, rebuilt four times a second.
    import tracemalloc

    from camo_bag.ledger import ACTIVE_ROUNDS, Ledger
    from camo_core.algorithm.params import CamoParams
    from camo_core.swarm.robot_io import messages_per_round

    params = CamoParams(rows=4, cols=4, consensus_steps=12, formation_steps=4)
    ledger = Ledger()
    ledger.set_run(params, 1, continuous=True)
    wanted = messages_per_round(params)
    finished = []

    def rounds(first: int, last: int) -> None:
        for round_ in range(first, last):
            for frame in range(10 * round_, 10 * round_ + 10):  # a camera's frames
                ledger.background(frame)
            superseded = round_ % 3 == 2  # its robots left it half way for the next
            for robot in range(params.count):
                for kind, n in wanted.items():
                    for step in range(n // 2 if superseded else n):
                        ledger.message(kind, robot, 10 * round_, step)
                if not superseded:
                    ledger.reported_done(robot, 10 * round_)
            if not superseded:
                finished.append(10 * round_)

    rounds(0, 100)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    rounds(100, 400)
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert grown < 300 * 400  # bytes a round: its number, where its whole robots are shared
    assert len(ledger.steps) + len(ledger.counts) + len(ledger.done) <= 3 * ACTIVE_ROUNDS
    assert ledger.latest_rounds() == finished[-ACTIVE_ROUNDS:]
    assert ledger.complete_count(finished[-1]) == ledger.complete_count(finished[0]) == 16
    result = [{"round": r, "finished": [[0, 15]]} for r in finished]
    ledger.set_result({"run": "r", "ended": "finished", "rounds": result})
    assert not ledger.gaps()
    assert ledger.backgrounds == 4000 and 3990 in ledger.frames and 4000 not in ledger.frames
    # A round the bag holds half of (superseded: not in a real result) says so, however old.
    ledger.set_result(
        {"run": "r", "ended": "finished", "rounds": [{"round": 20, "finished": [[0, 15]]}]}
    )
    assert ledger.gaps() == [
        "round 20: 16 robots lack hellos, colours, votes, states, done reports: 0-15"
    ]


# What camo_msgs/StatusArray held before the swarm reported colours (--colours).
COLOUR_FIELDS = ("sensed_rgb_count", "sensed_rgb", "palette_rgb_count", "palette_rgb")
COLOUR_FIELDS += ("shades_count", "shades")


def before_colours(source, target) -> None:
    """The bag as camo recorded it before StatusArray had its colour columns: the status topic
    with that older definition, its arrays written without those fields."""
    from mcap_ros2._dynamic import serialize_dynamic
    from rclpy.serialization import deserialize_message

    from camo_bag.msgdefs import SEPARATOR
    from camo_msgs.msg import StatusArray

    summary = read_summary(source)
    status = next(t for t in summary.topics if t.type.endswith("StatusArray"))
    main, _, rest = status.definition.partition(SEPARATOR)
    kept = [
        line
        for line in main.splitlines()
        if not (line.split()[1:2] and line.split()[1] in COLOUR_FIELDS)
    ]
    definition = "\n".join(kept) + "\n" + SEPARATOR + rest
    encode = serialize_dynamic("camo_msgs/msg/StatusArray", definition)[
        "camo_msgs/msg/StatusArray"
    ]

    def older(topic, data):
        if topic != status.name:
            return [data]
        msg = deserialize_message(data, StatusArray)
        fields = {
            name: getattr(msg, name)
            for name in StatusArray.get_fields_and_field_types()
            if name not in COLOUR_FIELDS
        }
        return [encode(fields)]

    writer = BagWriter(target, library="test")
    for topic in summary.topics:
        text = definition if topic.name == status.name else topic.definition
        writer.add_topic(TopicInfo(topic.name, topic.type, topic.qos, ""), text)
    for message in read_messages(source):
        for data in older(message.topic, message.data):
            writer.write(message.topic, data, message.log_time, message.publish_time)
    writer.close()


@pytest.mark.slow(SWARM)
def test_a_bag_of_statuses_without_colour_columns_renders_and_replays_as_the_installed_type(
    recorded, tmp_path
):
    from support import domain

    bag, live = recorded
    before_colours(bag, tmp_path / "older")
    status = next(t for t in read_summary(tmp_path / "older").topics if t.name.endswith("/status"))
    assert "float64[] sensed_rgb" not in status.definition
    rendered = bag_tool("render", str(tmp_path / "older"), "--out", str(tmp_path / "r"))
    assert rendered.returncode == 0, rendered.stderr
    summary = strict_json(tmp_path / "r" / "summary.json")
    assert summary["final"] == live["final"] and summary["display"] == live["display"]
    assert summary["colour_distance"] is None  # the older statuses never said what they sensed
    replay = bag_tool("replay", str(tmp_path / "older"), "--rate", "50",
                      "--topics", status.name, "--domain-id", str(domain()))  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    assert f"published {status.count} messages on 1 topics" in replay.stderr
