"""A keyed run's tags and seals, alone: what a reader believes, and what it refuses."""

import os

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camo_core.exceptions import UsageError
from camo_core.swarm import keys
from camo_core.swarm.keys import NO_TAG, REPLAYED, UNSEALED, Opener, RunKey, Sealer

KEY = RunKey(bytes(range(32)))
OTHER = RunKey(bytes(range(1, 33)))
TOPIC = "/lab/camo/tile_0_7/edge/vote"


@settings(max_examples=50, deadline=None)
@given(st.binary(max_size=300), st.booleans(), st.integers(0, 3))
def test_a_tagged_or_sealed_message_opens_once_with_its_payload_even_padded(payload, encrypt, pad):
    # DDS pads a serialized message with up to three zeros: the reader takes them off.
    sealer = Sealer(KEY, "lab", TOPIC, encrypt)
    data = sealer.seal(payload)
    reader = Opener(KEY, "lab")
    assert reader.open(TOPIC, data + bytes(pad)) == (payload, None)
    assert reader.open(TOPIC, data) == (None, REPLAYED)  # the same message again


@pytest.mark.parametrize("encrypt", [False, True])
def test_a_message_moved_to_another_topic_run_key_or_changed_is_refused(encrypt):
    refused = UNSEALED if encrypt else NO_TAG
    data = Sealer(KEY, "lab", TOPIC, encrypt).seal(b"\x00\x01\x00\x00votes")
    assert Opener(KEY, "lab").open(TOPIC + "x", data) == (None, refused)
    assert Opener(KEY, "other").open(TOPIC, data) == (None, refused)
    assert Opener(OTHER, "lab").open(TOPIC, data) == (None, refused)
    changed = bytearray(data)
    changed[5] ^= 1
    assert Opener(KEY, "lab").open(TOPIC, bytes(changed)) == (None, refused)
    # Another writer's id or sequence number, put in by hand: the tag covers both.
    at = len(data) - (keys.TAGGED_TRAILER if not encrypt else keys.SEALED_TRAILER)
    for offset in (0, keys.WRITER_BYTES):
        forged = bytearray(data)
        forged[at + offset] ^= 1
        assert Opener(KEY, "lab").open(TOPIC, bytes(forged)) == (None, refused)


def test_plain_and_truncated_messages_have_no_tag():
    reader = Opener(KEY, "lab")
    for data in (b"", b"cmk1", b"\x00\x01\x00\x00plain", b"x" * 35 + b"cmk1", b"cme1" * 5):
        payload, why = reader.open(TOPIC, data)
        assert payload is None and why in (NO_TAG, UNSEALED)


def test_each_writer_counts_alone_and_an_older_sequence_is_a_replay():
    first, second = Sealer(KEY, "lab", TOPIC), Sealer(KEY, "lab", TOPIC)
    old = first.seal(b"a")
    new = first.seal(b"b")
    reader = Opener(KEY, "lab")
    assert reader.open(TOPIC, new) == (b"b", None)
    assert reader.open(TOPIC, second.seal(b"c")) == (b"c", None)  # its own sequence from 1
    assert reader.open(TOPIC, old) == (None, REPLAYED)
    # A bag read again is not a replay.
    again = Opener(KEY, "lab", replays=False)
    assert again.open(TOPIC, new) == again.open(TOPIC, new) == (b"b", None)


def test_strip_gives_a_tagged_payload_without_the_key_and_leaves_others():
    data = Sealer(KEY, "lab", TOPIC).seal(b"\x00\x01\x00\x00payload")
    assert keys.strip(data + b"\x00\x00") == b"\x00\x01\x00\x00payload"
    assert keys.strip(b"\x00\x01\x00\x00plain") == b"\x00\x01\x00\x00plain"
    secret = b"the robots' votes, not to be read" * 4
    assert keys.sealed(Sealer(KEY, "lab", TOPIC, True).seal(secret) + b"\x00")
    assert secret[:16] not in Sealer(KEY, "lab", TOPIC, True).seal(secret)
    assert not keys.sealed(data)


def test_key_files_are_made_private_and_read_back(tmp_path):
    made = keys.new_key_file(tmp_path / "run.key")
    assert (tmp_path / "run.key").stat().st_mode & 0o777 == 0o600
    assert keys.read_key_file(tmp_path / "run.key").secret == made.secret
    assert len(made.secret) == 32 and made.secret != keys.new_key_file(tmp_path / "b").secret
    with pytest.raises(UsageError, match="there already"):
        keys.new_key_file(tmp_path / "run.key")
    assert keys.read_key_file(tmp_path / "run.key").secret == made.secret  # never replaced


@pytest.mark.parametrize(
    ("text", "mode", "said"),
    [
        ("ab" * 32, 0o644, "others may read it"),
        ("ab" * 31, 0o600, "not a camo key"),
        ("zz" * 32, 0o600, "not a camo key"),
        ("ab" * 2000, 0o600, "too long"),
    ],
)
def test_a_bad_key_file_is_one_line(tmp_path, text, mode, said):
    path = tmp_path / "k"
    path.write_text(text)
    os.chmod(path, mode)
    with pytest.raises(UsageError, match=said):
        keys.read_key_file(path)
    with pytest.raises(UsageError, match="no such file"):
        keys.read_key_file(tmp_path / "missing")
    with pytest.raises(UsageError, match="not a regular file"):
        keys.read_key_file(tmp_path)


def test_a_key_has_a_fingerprint_that_gives_nothing_of_it_away(tmp_path):
    made = keys.new_key_file(tmp_path / "run.key")
    assert keys.fingerprint(made) != keys.fingerprint(KEY) and made.secret.hex()[:12] not in (
        keys.fingerprint(made)
    )
