"""`python -m camo_nodes.worker --cells ...`: a process hosting many robots (started by the
launcher)."""

from __future__ import annotations

import argparse
import json
import sys

import rclpy
from rclpy.signals import SignalHandlerOptions

from camo_core.exceptions import CamoError
from camo_core.params import CamoParams
from camo_core.shutdown import StopFlag

from .robot_node import host_robots


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="swarm worker")
    parser.add_argument("--params", required=True, help="CamoParams as JSON")
    parser.add_argument("--cells", required=True, help="robot ids, comma-separated")
    parser.add_argument("--step-timeout", type=float, default=10.0)
    parser.add_argument("--discovery-timeout", type=float, default=300.0)
    args, ros_args = parser.parse_known_args(argv)
    stop = StopFlag()
    rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        params = CamoParams(**json.loads(args.params))
        cells = [int(c) for c in args.cells.split(",") if c]
        return host_robots(params, cells, args.step_timeout, args.discovery_timeout).run(stop)
    except CamoError as exc:
        print(f"swarm worker: error: {exc}", file=sys.stderr)
        return 2
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
