"""Offered QoS profiles read from a bag: every field checked before a publisher gets it."""

import pytest
from bag_files import one_line, qos_text
from hypothesis import given
from hypothesis import strategies as st

from camo_bag.container import BagError


def refused(text) -> str:
    from camo_bag.qos_yaml import load_first

    with pytest.raises(BagError) as caught:
        load_first(text, "topic /x offered_qos_profiles")
    return one_line(caught.value)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"depth": "abc"}, "[0].depth must be an integer in 0..2147483647 (got 'abc')"),
        ({"history": 99}, "[0].history must be one of system_default, keep_last, keep_all"),
        ({"depth": [1]}, "[0].depth must be an integer in 0..2147483647 (got a list)"),
    ],
)
def test_the_three_profiles_that_were_tracebacks_are_one_line(change, words):
    assert words in refused(qos_text(**change))


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"depth": -1}, "depth must be an integer in 0..2147483647"),
        ({"depth": 2**31}, "depth must be an integer"),
        ({"depth": True}, "depth must be an integer"),
        ({"reliability": "sometimes"}, "reliability must be one of system_default, reliable"),
        ({"durability": 7}, "durability must be one of"),
        ({"liveliness": 2}, "liveliness must be one of"),  # 2 is not a liveliness policy
        ({"deadline": {"sec": -1, "nsec": 0}}, "deadline.sec must be an integer in 0.."),
        ({"lifespan": {"sec": 1, "nsec": "5"}}, "lifespan.nsec must be an integer"),
        ({"lifespan": {"sec": 1}}, "lifespan lacks its field nsec"),
        ({"liveliness_lease_duration": 5}, "liveliness_lease_duration must be a mapping"),
        ({"avoid_ros_namespace_conventions": "no"}, "must be true or false"),
        ({"dept": 5}, "has an unknown field 'dept'"),
    ],
)
def test_each_field_is_checked_for_its_type_range_and_values(change, words):
    assert words in refused(qos_text(**change))


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[{depth: ", "is not YAML (line"),
        ("depth: 5", "must be a list"),
        ("- 5", "[0] must be a mapping"),
    ],
)
def test_text_that_is_not_a_list_of_profiles_is_refused(text, words):
    assert words in refused(text)


def test_a_valid_profile_gives_the_publisher_its_policies():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

    from camo_bag.qos_yaml import load_first

    qos = load_first(qos_text(reliability="best_effort", durability="transient_local"))
    assert (qos.history, qos.depth) == (HistoryPolicy.KEEP_LAST, 5)
    assert qos.reliability == ReliabilityPolicy.BEST_EFFORT
    assert qos.durability == DurabilityPolicy.TRANSIENT_LOCAL


def test_older_rosbag2_numbers_and_an_unknown_history_are_taken():
    """rosbag2 before metadata version 9 wrote policies as numbers, and an infinite duration
    as nsec 4294967295; graph discovery gives history unknown, depth 0 (keep all then)."""
    from rclpy.qos import HistoryPolicy, ReliabilityPolicy

    from camo_bag.qos_yaml import load_first

    infinite = {"sec": 2147483647, "nsec": 4294967295}
    qos = load_first(qos_text(history=3, depth=0, reliability=2, deadline=infinite))
    assert (
        qos.history == HistoryPolicy.KEEP_ALL and qos.reliability == ReliabilityPolicy.BEST_EFFORT
    )
    assert load_first("").depth == 10  # none recorded: the default


FIELDS = [
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
]
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**65), 2**65),
    st.floats(),
    st.text(max_size=6),
    st.sampled_from(["keep_last", "KEEP_ALL", "unknown", "best_available", "abc", "99"]),
    st.lists(st.integers(0, 3), max_size=2),
    st.fixed_dictionaries({"sec": st.integers(-2, 2**64), "nsec": st.integers(-2, 2**33)}),
)


@given(changes=st.dictionaries(st.sampled_from(FIELDS), VALUES, min_size=1, max_size=3))
def test_a_profile_with_wrong_values_anywhere_gives_a_publisher_qos_or_one_line(changes):
    from rclpy.qos import QoSProfile

    from camo_bag.qos_yaml import load_first

    text = qos_text(**changes)
    try:
        assert isinstance(load_first(text), QoSProfile)
    except BagError as exc:
        one_line(exc)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("- depth: 5\n  depth: 6\n", "(line 2): the key 'depth' is given twice"),
        ("- depth: 0x5\n", "'0x5' is a number in another base"),
        ("- depth: !!binary AAAA\n", "the tag !!binary is not read"),
        ("- depth: 5\n---\n- depth: 6\n", "more than one document"),
    ],
)
def test_a_qos_profile_string_is_read_strictly(text, said):
    assert said in refused(text)
