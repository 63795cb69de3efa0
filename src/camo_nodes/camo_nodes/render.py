"""`./camo render BAG --out DIR`: a run's summary.json, figure.png and timeline.png from its bag alone.

Nothing runs: the robots' statuses, the background and the run's parameters
are read from the bag, decoded with rclpy's serialization and assembled by the
monitor's own RoundRecord, so the summary equals the live run's (elapsed_s
aside). A robot that never reported done is dead, as the live monitor decides
at the end of a run.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from rclpy.serialization import deserialize_message

from camo_core import cli, figures
from camo_core.params import CamoParams, ParameterError
from camo_msgs.msg import RobotStatus
from camo_projector.image_msg import from_msg
from camo_projector.qos import BACKGROUND_TOPIC
from sensor_msgs.msg import Image
from std_msgs.msg import String

from .bag import BagError, read_messages
from .monitor_node import RoundRecord, write_round
from .topics import PARAMS_TOPIC, STATUS_TOPIC


def load_run(path: str | Path) -> tuple[CamoParams, list[str], dict[int, RoundRecord], list[np.ndarray]]:
    """Parameters, background labels, one RoundRecord per round and the backgrounds, from a bag."""
    setup = None
    rounds: dict[int, RoundRecord] = {}
    images: list[np.ndarray] = []
    stamps: list[tuple[int, int]] = []
    times: dict[int, list[int]] = {}
    pending: list[tuple[RobotStatus, int]] = []
    try:
        for message in read_messages(path, [PARAMS_TOPIC, STATUS_TOPIC, BACKGROUND_TOPIC]):
            if message.topic == PARAMS_TOPIC and setup is None:
                setup = json.loads(deserialize_message(message.data, String).data)
            elif message.topic == BACKGROUND_TOPIC:
                image = deserialize_message(message.data, Image)
                stamp = (image.header.stamp.sec, image.header.stamp.nanosec)
                if stamp not in stamps:
                    stamps.append(stamp)
                    images.append(from_msg(image))
            elif message.topic == STATUS_TOPIC:
                pending.append((deserialize_message(message.data, RobotStatus), message.log_time))
    except BagError:
        raise
    except Exception as exc:  # noqa: BLE001 - bytes that do not decode as their recorded type
        raise BagError(f"{path}: a message does not decode as its recorded type ({exc})") from None
    if setup is None:
        raise BagError(f"{path} has no {PARAMS_TOPIC} message: it was not recorded from `./camo run`")
    params = CamoParams(**setup["params"])
    for status, log_time in pending:
        if status.sender_id < params.count:
            rounds.setdefault(status.round, RoundRecord(params)).add(status)
            times.setdefault(status.round, []).append(log_time)
    if not rounds:
        raise BagError(f"{path} holds no robot status: nothing to render")
    for index, record in rounds.items():
        record.elapsed_ns = max(times[index]) - min(times[index])
    return params, setup.get("backgrounds", []), rounds, images


def render(path: str | Path, out: Path) -> list[dict]:
    params, labels, rounds, images = load_run(path)
    summaries = []
    for index in sorted(rounds):
        record = rounds[index]
        folder = out if len(rounds) == 1 else out / f"round_{index}"
        folder.mkdir(parents=True, exist_ok=True)
        result = record.result(dead=~record.finished)
        result.elapsed_s = record.elapsed_ns / 1e9
        label = labels[index] if index < len(labels) else f"round {index}"
        image = images[index] if index < len(images) else None
        summaries.append(write_round(result, image, folder, f"{label} (from {Path(path).name})"))
        figures.timeline_figure(record.timeline(), folder / "timeline.png",
                                title=f"{label}: {params.rows}x{params.cols} robots; consensus steps c0.., "
                                      f"formation steps f0..")
    return summaries


def main(argv: list[str] | None = None) -> int:
    parser = cli.Parser(prog="camo render", description="rebuild a run's figures and summary from its bag")
    parser.add_argument("bag", help="bag folder (or its .mcap file) recorded by ./camo run --record")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default results/<timestamp>/)")
    try:
        args = parser.parse_args(argv)
        out = cli.out_dir(argparse.Namespace(out=args.out))
        summaries = render(args.bag, out)
    except (cli.UsageError, BagError, ParameterError, ValueError, KeyError) as exc:
        print(f"camo render: error: {exc}", file=sys.stderr)
        return 2
    for k, summary in enumerate(summaries):
        print(f"round {k}: pattern {summary['pattern']} ({', '.join(f'{n} {c}' for n, c in summary['votes'].items())})")
    print(f"wrote summary.json, figure.png and timeline.png to {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
