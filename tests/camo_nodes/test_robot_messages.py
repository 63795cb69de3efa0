"""Robot messages as columns on the wire: every kind comes back as it was sent, Python numbers
and all; columns that do not line up are refused whole; bags of every layout read alike."""

import pytest
from hypothesis import given
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

from camo_core.swarm.robot_io import PHASE_OF, Message
from camo_nodes.topics.robot_messages import (
    ARRAY_TYPES,
    COLUMN_TYPES,
    MESSAGE_TYPES,
    VALUE_COLUMNS,
    Columns,
    RaggedColumns,
    senders_rounds_steps,
    unpack,
)

u32 = st.integers(0, 2**32 - 1)
unit = st.floats(0.0, 1.0)
grey = st.floats(0.0, 255.0)
state = st.integers(0, 7)
VALUES = {
    "hello": st.tuples(u32, u32),
    "color": grey,
    "energy": st.tuples(st.floats(0.0, 1e6), st.integers(0, 8)),
    "state": state,
    "relay": st.tuples(*[st.one_of(st.none(), state)] * 8),
}


def messages(kind: str, value, count: int):
    return st.lists(
        st.builds(Message, st.just(kind), u32, u32, u32, value), min_size=1, max_size=count
    )


def votes(width: int):
    return messages("vote", st.tuples(st.tuples(*[unit] * width), st.integers(0, 8)), 20)


def through_the_wire(kind: str, sent: list[Message]) -> list[Message]:
    columns = Columns(kind)
    for message in sent:
        columns.add(message)
    msg = columns.take()
    assert len(columns) == 0 and msg.phase == PHASE_OF[kind]  # empty again, for the next turn
    return unpack(kind, deserialize_message(serialize_message(msg), COLUMN_TYPES[kind]))


@pytest.mark.parametrize("kind", sorted(VALUES))
@given(data=st.data())
def test_every_kind_comes_back_from_its_columns_as_it_was_sent(kind, data):
    sent = data.draw(messages(kind, VALUES[kind], 20))
    assert through_the_wire(kind, sent) == sent


@given(sent=st.one_of(votes(3), votes(35)))  # the paper's p, and --levels' 3 + 32 values
def test_votes_come_back_with_python_floats_whatever_their_width(sent):
    back = through_the_wire("vote", sent)
    assert back == sent
    assert all(type(x) is float for m in back for x in m.value[0])  # not numpy scalars


def mixed_votes():
    """Votes of robots in different phases of a --scope local round: p, the classes' shares,
    p with its class (of --levels' width, say)."""
    value = st.one_of(*(st.tuples(st.tuples(*[unit] * w), st.integers(0, 8)) for w in (3, 13, 36)))
    return messages("vote", value, 20)


@given(sent=mixed_votes())
def test_votes_of_different_widths_in_one_message_come_back_as_sent(sent):
    assert through_the_wire("vote", sent) == sent


def test_votes_whose_widths_do_not_add_up_are_refused_whole():
    columns = Columns("vote")
    for k, width in enumerate((3, 4, 3)):
        columns.add(Message("vote", k, 0, k, ((0.25,) * width, 2)))
    msg = deserialize_message(serialize_message(columns.take()), COLUMN_TYPES["vote"])
    assert list(msg.width) == [3, 4, 3]
    msg.width = [3, 4, 4]
    with pytest.raises(RaggedColumns):
        unpack("vote", msg)
    msg.width = [3, 4]
    with pytest.raises(RaggedColumns):
        unpack("vote", msg)


def ragged_copies(kind: str):
    """Columns messages of three votes (or states, ...) with one column an entry short."""
    sent = [Message(kind, k, 0, k, EXAMPLES[kind]) for k in range(3)]
    columns = Columns(kind)
    for message in sent:
        columns.add(message)
    whole = columns.take()
    for name in ("sender_id", "step", "round", *(n for n, _ in VALUE_COLUMNS[kind])):
        msg = deserialize_message(serialize_message(whole), COLUMN_TYPES[kind])
        setattr(msg, name, getattr(msg, name)[:-1])
        yield name, msg


EXAMPLES = {
    "hello": (1, 2),
    "color": 12.5,
    "energy": (3.0, 4),
    "vote": ((0.2, 0.3, 0.5), 4),
    "state": 1,
    "relay": (1, None, 0, 1, 1, 0, None, 0),
}


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_columns_an_entry_short_are_refused_whole(kind):
    for name, msg in ragged_copies(kind):
        with pytest.raises(RaggedColumns):
            unpack(kind, msg)
        if name in ("sender_id", "step", "round"):
            with pytest.raises(RaggedColumns):
                senders_rounds_steps(msg)


def test_a_bag_message_of_any_layout_names_its_senders_rounds_and_steps():
    sent = [Message("state", 10 + k, 2, k, k % 2) for k in range(3)]
    columns = Columns("state")
    for message in sent:
        columns.add(message)
    singles = [
        MESSAGE_TYPES["state"](sender_id=m.sender, round=m.round, step=m.step, state=m.value)
        for m in sent
    ]
    expected = [(m.sender, m.round, m.step) for m in sent]
    assert senders_rounds_steps(columns.take()) == expected
    assert senders_rounds_steps(ARRAY_TYPES["state"](messages=singles)) == expected
    assert [senders_rounds_steps(s)[0] for s in singles] == expected
