"""`camo render`: a run's summary and figures rebuilt from its bag alone."""

import json

import pytest
from support import COMPUTE, ROOT, SWARM, Bus, bag_tool, camo_run, robot_messages_in


@pytest.mark.slow(SWARM)
def test_render_reads_a_bag_into_one_record_per_round(recorded, count_round_records):
    from camo_bag.render import load_run

    made = count_round_records
    run = load_run(recorded[0])
    assert list(run.rounds) == [0] and len(made) == 1
    assert run.rounds[0].finished.all()


@pytest.mark.slow(SWARM)
def test_render_rebuilds_the_live_summary_from_the_bag_alone(recorded, tmp_path):
    bag, live = recorded
    out = bag_tool("render", str(bag), "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    rendered = json.loads((tmp_path / "summary.json").read_text())
    assert {k: v for k, v in rendered.items() if k != "elapsed_s"} == {
        k: v for k, v in live.items() if k != "elapsed_s"
    }
    assert (tmp_path / "figure.png").stat().st_size > 10_000
    assert (tmp_path / "timeline.png").stat().st_size > 10_000
    from PIL import Image

    with Image.open(tmp_path / "run.gif") as gif:  # the run's animation, from the bag alone
        assert gif.n_frames >= 10


@pytest.mark.slow(SWARM)
def test_render_of_a_run_with_three_backgrounds_writes_each_round_from_a_complete_bag(tmp_path):
    # A small swarm finishes a round in a fraction of a second, before the recorder may have
    # discovered its topics; each round must still be in the bag whole.
    out = camo_run(
        "--rows",
        "4",
        "--cols",
        "5",
        "--pattern",
        "forest",
        "--then",
        "desert",
        "--then",
        "forest",
        "--procs",
        "1",
        "--out",
        str(tmp_path / "live"),
        "--record",
        str(tmp_path / "bag"),
    )
    assert out.returncode == 0 and "lacks" not in out.stderr, out.stderr[-2000:]
    rendered = bag_tool("render", str(tmp_path / "bag"), "--out", str(tmp_path / "rendered"))
    assert rendered.returncode == 0, rendered.stderr
    for k in (0, 1, 2):
        live = json.loads((tmp_path / "live" / f"round_{k}" / "summary.json").read_text())
        again = json.loads((tmp_path / "rendered" / f"round_{k}" / "summary.json").read_text())
        assert {x: v for x, v in again.items() if x != "elapsed_s"} == {
            x: v for x, v in live.items() if x != "elapsed_s"
        }
        assert (tmp_path / "rendered" / f"round_{k}" / "timeline.png").exists()
    assert "round 2: pattern" in rendered.stdout
    info = bag_tool("cli", "info", str(tmp_path / "bag"))
    assert info.returncode == 0, info.stderr
    consensus_steps = len(live["consensus_trace"]) - 1
    votes = {(v.round, v.sender_id, v.step) for v in robot_messages_in(tmp_path / "bag", "/vote")}
    assert len(votes) == 3 * 4 * 5 * consensus_steps


@pytest.mark.slow(COMPUTE)
def test_render_refuses_a_bag_whose_messages_do_not_decode(tmp_path):
    from camo_bag.container import BagWriter, TopicInfo
    from camo_bag.msgdefs import message_definition

    writer = BagWriter(tmp_path / "odd")
    for topic, kind in (
        ("/swarm/params", "std_msgs/msg/String"),
        ("/swarm/status", "camo_msgs/msg/RobotStatus"),
    ):
        writer.add_topic(TopicInfo(topic, kind), message_definition(kind))
        writer.write(topic, b"\x00\x01\x00\x00\xff\xff", 10**9, 10**9)
    writer.close()
    out = bag_tool("render", str(tmp_path / "odd"), "--out", str(tmp_path / "r"))
    assert out.returncode == 2 and "do not decode" in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


@pytest.mark.slow(SWARM)
def test_render_reads_a_bag_of_the_older_layout_with_its_older_status_type(tmp_path):
    """A bag recorded before runs had ids: /swarm/params and /swarm/status at the root, one
    status a step, of a RobotStatus without the newer fields. Render still rebuilds the run."""
    import json as json_module

    import numpy as np
    from mcap_ros2._dynamic import serialize_dynamic
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from camo_bag.container import BagWriter, TopicInfo
    from camo_bag.msgdefs import SEPARATOR, message_definition
    from camo_core.algorithm.params import CamoParams
    from camo_core.algorithm.simulator import simulate

    params = CamoParams(rows=2, cols=3, consensus_steps=6, formation_steps=4, seed=3)
    grid = np.random.default_rng(2).uniform(0, 255, (params.rows, params.cols))
    bus = Bus(params, grid, seed=2)  # every robot reports every step, as camo did then
    bus.run()
    reports = bus.reports
    header = message_definition("std_msgs/msg/Header").split(SEPARATOR)[0].rstrip()
    old = (ROOT / "tests" / "data" / "RobotStatus_before_run_ids.msg").read_text().rstrip()
    schema = (
        f"{old}\n{SEPARATOR}\nMSG: std_msgs/Header\n{header}\n"
        f"{SEPARATOR}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    )
    encode = serialize_dynamic("camo_msgs/msg/RobotStatus", schema)["camo_msgs/msg/RobotStatus"]
    writer = BagWriter(tmp_path / "old")
    writer.add_topic(TopicInfo("/swarm/params", "std_msgs/msg/String"), message_definition(
        "std_msgs/msg/String"))  # fmt: skip
    writer.add_topic(TopicInfo("/swarm/status", "camo_msgs/msg/RobotStatus"), schema)
    setup = {"params": params.as_dict(), "backgrounds": ["an old run"]}
    writer.write("/swarm/params", serialize_message(String(data=json_module.dumps(setup))), 1, 1)
    for k, r in enumerate(reports):
        status = {
            "header": {"stamp": {"sec": 1, "nanosec": k}, "frame_id": "camo"},
            "sender_id": r.sender_id, "row": r.row, "col": r.col, "phase": r.phase,
            "step": r.step, "round": r.round, "sensed": r.sensed, "p": list(r.p),
            "pattern": r.pattern, "state": r.state, "alive": r.alive,
            "known_slots": r.known_slots, "deadlines": r.deadlines,
        }  # fmt: skip
        writer.write("/swarm/status", encode(status), 10 + k, 10 + k)
    writer.close()
    # Only statuses: no robot message and no background, so the bag is incomplete (named so),
    # and rendered only when asked to be.
    out = bag_tool("render", str(tmp_path / "old"), "--out", str(tmp_path / "r"))
    assert out.returncode == 1 and "6 robots lack hellos" in out.stderr, out.stderr
    out = bag_tool("render", str(tmp_path / "old"), "--out", str(tmp_path / "r"), "--partial")
    assert out.returncode == 0, out.stderr
    rendered = json_module.loads((tmp_path / "r" / "summary.json").read_text())
    assert "its background is not in the bag" in rendered["incomplete"]
    expected = simulate(params, grid).summary()
    for key in ("final", "initial", "sensed", "votes", "mean_p", "consensus_trace", "pattern"):
        assert rendered[key] == expected[key], key


@pytest.mark.slow(SWARM)
def test_render_partial_reads_a_truncated_bag_up_to_where_it_breaks(recorded, tmp_path):
    """A file cut short (a recorder killed) is refused in one line; with --partial its
    messages before the cut are rendered, the gaps named."""
    from mcap.reader import make_reader

    bag, _ = recorded
    with open(bag / "bag_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
        chunks = summary.chunk_indexes
        last = max(chunks, key=lambda c: c.chunk_start_offset)
        # The run's parameters and some statuses must be before the cut (the recorder writes
        # the parameters out at once; statuses can all come in the last chunk of a short run).
        for needed in ("/swarm/params", "/swarm/status"):
            ids = {c for c, ch in summary.channels.items() if ch.topic.endswith(needed)}
            held = [c.chunk_start_offset for c in chunks if ids & set(c.message_index_offsets)]
            if min(held) >= last.chunk_start_offset:
                pytest.skip(f"this recording holds {needed} in its last chunk only")
        f.seek(0)
        data = f.read(last.chunk_start_offset + last.chunk_length // 2)  # its last chunk torn
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "cut_0.mcap").write_bytes(data)
    out = bag_tool("render", str(cut), "--out", str(tmp_path / "r"))
    assert out.returncode == 2 and "truncated" in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    out = bag_tool("render", str(cut), "--out", str(tmp_path / "r"), "--partial")
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["incomplete"] and "pattern" in summary
