"""`./camo bag info BAG` and `./camo bag repair BAG [--out NEW]`."""

from __future__ import annotations

import sys
from pathlib import Path

from camo_bag.completeness import examine
from camo_bag.container import BagDamaged, BagError, format_info
from camo_bag.loader import Bag, open_bag, repair
from camo_core.cli.options import Parser
from camo_core.exceptions import CamoError
from camo_core.shutdown import quiet_on_a_closed_pipe


def build_parser() -> Parser:
    parser = Parser(prog="camo bag", description="inspect and repair MCAP bags")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    info = sub.add_parser(
        "info", help="duration, topics, types and message counts (like ros2 bag info)"
    )
    info.add_argument("bag", help="bag folder or .mcap file")
    fix = sub.add_parser(
        "repair", help="write a complete, indexed copy of what a damaged bag still holds"
    )
    fix.add_argument("bag", help="bag folder or .mcap file, e.g. from a recorder that was killed")
    fix.add_argument(
        "--out", type=Path, default=None, help="new bag folder (default: BAG_repaired)"
    )
    return parser


def run_verdict(bag: Bag) -> str:
    """What `bag info` says of the run a bag holds: complete, or what it lacks (BagDamaged if
    its messages cannot be read)."""
    try:
        ledger = examine(bag)
    except BagDamaged:
        raise
    except BagError as exc:
        return f"Run:               none ({exc})"
    gaps = ledger.gaps()
    held = f"Robot messages:    {ledger.distinct} (each robot's step of a kind once)"
    if not gaps:
        whole = "complete (every robot's messages of every round it finished)"
        return f"{held}\nRun:               {whole}"
    lines = "\n".join(f"                   {g}" for g in gaps)
    return f"{held}\nRun:               INCOMPLETE\n{lines}"


def main(argv: list[str] | None = None) -> int:
    quiet_on_a_closed_pipe()  # `./camo bag info BAG | head`
    try:
        args = build_parser().parse_args(argv)
        if args.command == "info":
            bag = open_bag(args.bag)
            print(format_info(bag.summary))  # from the bag's summary: even of damaged messages
            print(run_verdict(bag))
            if bag.note():
                print(f"camo bag: warning: {bag.note()}", file=sys.stderr)
            return 0
        out = args.out or Path(str(Path(args.bag)).rstrip("/") + "_repaired")
        bag, count = repair(args.bag, out)
    except CamoError as exc:
        print(f"camo bag: error: {exc}", file=sys.stderr)
        return 2
    if bag.note():
        print(f"camo bag: warning: {bag.note()}", file=sys.stderr)
    print(f"camo bag: read {bag.file} ({bag.ending}); wrote {count} messages to {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
