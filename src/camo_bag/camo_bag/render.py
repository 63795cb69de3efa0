"""`./camo render BAG --out DIR`: a run's summary.json, figure.png and timeline.png from its bag
alone.

Nothing runs: the robots' statuses, the background and the run's parameters
are read from the bag, decoded with rclpy's serialization and assembled by the
monitor's own RoundRecord, so the summary equals the live run's (elapsed_s
aside). A robot that never reported done is dead, as the live monitor decides
at the end of a run.

A bag that lacks part of its run (`completeness.py`: robots the run's result
says finished whose messages or reports are missing, a round without its
background, no result at all) is refused, in one line that says what it
lacks; `--partial` renders what it holds, with the gaps named in summary.json
(`incomplete`) and unknown values written as null.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Image

from camo_bag.completeness import examine, run_topics_of, setup_in, status_decoder
from camo_bag.container import DAMAGE, BagError, BagMessage
from camo_bag.ledger import gaps_of_round
from camo_bag.loader import Bag, open_bag
from camo_core.algorithm.params import CamoParams
from camo_core.cli.options import Parser, add_out_options, out_dir
from camo_core.exceptions import CamoError
from camo_core.results import figures
from camo_core.results.animation import join_animations, write_animation
from camo_core.results.output import run_title, write_round
from camo_core.results.record import Backgrounds, Rounds, round_fields
from camo_core.results.snapshots import Snapshots
from camo_core.swarm.keys import KEY_FILE_ENV, read_key_file
from camo_core.swarm.status_rows import rows_of_message
from camo_msgs.msg import Notices
from camo_nodes.topics.images import frame_number, image_from_msg, pixels_sha256
from camo_nodes.topics.keyed import process_key


@dataclass
class RecordedRun:
    """What a bag tells of a run: enough to write its summaries and figures."""

    params: CamoParams
    labels: list[str]  # the backgrounds, in round order
    rounds: Rounds
    images: Backgrounds  # round r camouflaged images[r] (frame r)
    elapsed_s: dict[int, float]  # span of each round's statuses in the bag
    bridged: frozenset[int] = frozenset()  # robots that were real Droplets
    # A continuous run's notices: round -> (robot, changed_at, noticed_at) of its first.
    notices: dict[int, tuple[int, float, float]] = field(default_factory=dict)


def load_run(path: str | Path | Bag) -> RecordedRun:
    """The run's parameters, statuses and backgrounds, from a bag. A message that does not
    decode as its type is left out, and counted in the bag's `rejected`."""
    bag = path if isinstance(path, Bag) else open_bag(path)
    path = bag.path
    params_topic, status_topic, background_topic, _ = run_topics_of(bag.summary)
    notices_topic = background_topic.removesuffix("background") + "notices"
    decode_status = status_decoder(bag.summary, status_topic)
    setup = None
    notices: dict[int, tuple[int, float, float]] = {}
    pending: list[tuple[object, BagMessage]] = []
    for message in bag.messages([params_topic, status_topic, notices_topic]):
        try:
            if message.topic == params_topic and setup is None:
                setup = setup_in(message.data) or False
            elif message.topic == notices_topic:
                first_notices(deserialize_message(message.data, Notices), notices)
            elif message.topic == status_topic:
                pending.append((decode_status(message.data), message))
        except CamoError:
            raise
        except Exception:  # noqa: BLE001 - bytes that do not decode as their recorded type
            bag.reject(message)
    if setup is None:
        raise BagError(f"{path} has no message on {params_topic}")
    if not setup:
        raise BagError(f"{path}: {params_topic} does not hold a run's parameters")
    params = setup.params
    rounds = Rounds(params)
    times: dict[int, list[int]] = {}
    for status, message in pending:
        try:
            rows = rows_of_message(status)
        except DAMAGE:  # decoded with a damaged schema of the bag's own
            bag.reject(message)
            continue
        rows = rows.select(rows.sender_id < params.count)
        header = getattr(status, "header", None)  # when its process sent it, as live
        stamp = header.stamp.sec + header.stamp.nanosec * 1e-9 if header is not None else None
        for index in np.unique(rows.round).tolist():
            rounds[index].add_rows(rows.select(rows.round == index), stamp)
            times.setdefault(index, []).append(message.log_time)
    if not rounds:
        raise BagError(f"{path} holds no robot status: nothing to render")
    images = frames_of(bag, background_topic, set(rounds), setup.protocol.continuous)
    elapsed = {index: (max(t) - min(t)) / 1e9 for index, t in times.items()}
    bridged = frozenset(setup.bridged)
    return RecordedRun(params, list(setup.backgrounds), rounds, images, elapsed, bridged, notices)


def frames_of(bag: Bag, topic: str, rounds: set[int], continuous: bool) -> Backgrounds:
    """The frames of the rounds (a second pass over the bag: a continuous run's holds many more
    frames than rounds, and only those are decoded). A continuous run's frames are named by
    their numbers; the others' k-th background is round k's."""
    images = Backgrounds(keep=0 if continuous else len(rounds) + 1)
    for number in rounds:
        images.pin(number)
    for message in bag.messages([topic]):
        try:
            msg = deserialize_message(message.data, Image)
            number = frame_number(msg.header.frame_id) if continuous else None
            if continuous and number not in rounds:
                continue
            stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
            images.add(stamp, lambda msg=msg: image_from_msg(msg), number, pixels_sha256(msg))
        except CamoError:
            raise
        except Exception:  # noqa: BLE001 - bytes that do not decode as their recorded type
            bag.reject(message)
    return images


def first_notices(msg: Notices, notices: dict[int, tuple[int, float, float]]) -> None:
    """A Notices message into round -> the first notice of it (what the monitor keeps)."""
    for robot, round_, changed, noticed in zip(
        msg.robot, msg.round, msg.changed_at, msg.noticed_at, strict=False
    ):
        first = notices.get(int(round_))
        if first is None or noticed < first[2]:
            notices[int(round_)] = (int(robot), float(changed), float(noticed))


class IncompleteBag(CamoError):
    """The bag lacks part of its run."""


def render(path: str | Path | Bag, out: Path, partial: bool = False) -> list[dict]:
    """Each round's summary, written with its figures to `out`. Without `partial`, a bag that
    lacks part of its run, or holds messages that do not decode, is refused."""
    bag = path if isinstance(path, Bag) else open_bag(path, partial)
    path = bag.path
    held = examine(bag)
    if bag.rejected and not partial:
        raise BagError(f"{bag.note()} (--partial renders the rest)")
    gaps = held.gaps()
    if gaps and not partial:
        raise IncompleteBag(
            f"{path} is incomplete: {'; '.join(gaps)} (--partial renders what it holds)"
        )
    run = load_run(bag)
    params, summaries = run.params, []
    results = (held.result or {}).get("rounds", [])
    # A continuous run's result names the rounds it wrote (by frame): those, as round_<k>/.
    named = [int(r["round"]) for r in results if isinstance(r.get("round"), int)]
    order = [r for r in named if r in run.rounds] if named else sorted(run.rounds)
    for k, index in enumerate(order):
        record = run.rounds[index]
        many = len(order) > 1 or bool(named)
        folder = out / f"round_{k if named else index}" if many else out
        folder.mkdir(parents=True, exist_ok=True)
        result = record.result(dead=~record.finished)
        result.elapsed_s = run.elapsed_s[index]
        label = run.labels[index] if index < len(run.labels) and not named else f"round {index}"
        if named:
            label = f"{run.labels[0] if run.labels else 'background'}, frame {index}"
        image = run.images.get(index)
        title = run_title(f"{label} (from {Path(path).name})", record.params, "robot nodes")
        extra = {}
        at = k if named else index
        if at < len(results) and "rejected_messages" in results[at]:
            extra["rejected_messages"] = results[at]["rejected_messages"]
        if named:
            extra.update(round_fields(k, index, run.images, run.notices, record))
            if image is not None:  # the frame, as the live run keeps it
                cv2.imwrite(str(folder / "background.png"), image)
        lacks = "; ".join(gaps_of_round(gaps, index))
        marks = record.marks(~record.finished, run.bridged)
        summaries.append(write_round(result, image, folder, title, lacks or None, extra, marks))
        snapshots = Snapshots.of_record(record)
        write_animation(
            snapshots, record.sensed_shown, ~record.finished, folder / "run.gif", title, marks
        )
        figures.timeline_figure(
            record.timeline(),
            folder / "timeline.png",
            title=f"{label}: {params.rows}x{params.cols} robots; consensus steps c0.., "
            f"formation steps f0..",
        )
    if named and summaries:  # a continuous run's GIF: its rounds one after another
        join_animations([out / f"round_{k}" for k in range(len(summaries))], out / "run.gif")
    return summaries


def main(argv: list[str] | None = None) -> int:
    parser = Parser(
        prog="camo render", description="rebuild a run's figures and summary from its bag"
    )
    parser.add_argument(
        "bag", help="bag folder (or its .mcap file) recorded by ./camo run --record"
    )
    add_out_options(parser)
    parser.add_argument(
        "--partial",
        action="store_true",
        help="render an incomplete bag: what it holds, its gaps named in summary.json",
    )
    parser.add_argument(
        "--key-file",
        metavar="FILE",
        default=None,
        help="the run's key file, to read a bag of a run with --encrypt (default: "
        "$CAMO_KEY_FILE, if set)",
    )
    bag = None
    try:
        args = parser.parse_args(argv)
        if args.key_file:
            read_key_file(args.key_file)  # missing, malformed or readable by others: one line
            os.environ[KEY_FILE_ENV] = str(Path(args.key_file).resolve())
            process_key.cache_clear()
        out = out_dir(args)
        bag = open_bag(args.bag, args.partial)
        summaries = render(bag, out, args.partial)
    except CamoError as exc:
        note = bag.note() if bag is not None else ""
        more = f" ({note})" if note and note not in str(exc) else ""
        print(f"camo render: error: {exc}{more}", file=sys.stderr)
        return 1 if isinstance(exc, IncompleteBag) else 2
    if bag.note():
        print(f"camo render: warning: {bag.note()}", file=sys.stderr)
    for k, summary in enumerate(summaries):
        print(
            f"round {k}: pattern {summary['pattern']} "
            f"({', '.join(f'{n} {c}' for n, c in summary['votes'].items())})"
        )
    print(f"wrote summary.json, figure.png and timeline.png to {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
