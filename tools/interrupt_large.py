"""Ctrl-C of a large swarm mid-consensus: how long the launcher takes to stop it all, whether
anything it started is left running, and what it wrote (docs/swarm.md, "Large swarms").

    ./camo python tools/interrupt_large.py [--side 256] [--runs 3] [--after 3] [--out DIR]

Each run: `./camo run --rows SIDE --cols SIDE --consensus-steps 3000` on the forest scaled to the
grid (or --image), SIGINT to the
launcher AFTER seconds after its progress line first shows every robot in consensus; then the
seconds from SIGINT to the launcher's exit, its exit code, the processes it started that still
run 10 s after SIGINT, and whether summary.json (partial) was written.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LIMIT = 10.0  # s: nothing left running after this


def descendants(pid: int) -> set[int]:
    """Every process whose ancestry leads to `pid` (from /proc), itself excluded."""
    parent: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            parent[int(entry)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, up in parent.items() if up in frontier} - found
        found |= frontier
    return found


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def one_run(side: int, after: float, out: Path, image: Path) -> dict:
    command = [sys.executable, "-m", "camo_bringup.launcher", "--rows", str(side), "--cols"]
    command += [str(side), "--consensus-steps", "3000", "--image", str(image), "--out", str(out)]
    started = time.monotonic()
    launcher = subprocess.Popen(command, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    in_consensus = threading.Event()
    lines: list[str] = []
    everyone = re.compile(rf"consensus {side * side} \(step")

    def read() -> None:
        assert launcher.stderr is not None
        for line in launcher.stderr:
            lines.append(f"{time.monotonic() - started:8.2f} {line}")
            if everyone.search(line):
                in_consensus.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    children: set[int] = set()
    while not in_consensus.is_set() and launcher.poll() is None:
        children |= descendants(launcher.pid)
        time.sleep(0.5)
    if launcher.poll() is not None:
        raise RuntimeError("the run ended before consensus: " + "".join(lines[-5:]))
    reached = time.monotonic() - started
    time.sleep(after)
    children |= descendants(launcher.pid)
    launcher.send_signal(signal.SIGINT)
    interrupted = time.monotonic()
    lines.append(f"{interrupted - started:8.2f} (SIGINT)\n")
    try:
        launcher.wait(LIMIT)
    except subprocess.TimeoutExpired:
        pass
    stopped = time.monotonic() - interrupted
    time.sleep(max(0.0, LIMIT - (time.monotonic() - interrupted)))
    left = sorted(pid for pid in children | descendants(launcher.pid) if alive(pid))
    if launcher.poll() is None:
        launcher.kill()
    reader.join(5)
    (out / "launcher.log").write_text("".join(lines))  # its stderr, each line timed
    summary = out / "summary.json"
    partial = json.loads(summary.read_text()).get("incomplete") if summary.exists() else None
    return {
        "consensus_reached_s": round(reached, 1),
        "interrupt_to_exit_s": round(stopped, 2),
        "exit_code": launcher.returncode,
        "processes_started": len(children),
        "left_running_after_10_s": left,
        "summary_written": summary.exists(),
        "incomplete": partial,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="interrupt_large", description=__doc__.split("\n")[0])
    parser.add_argument("--side", type=int, default=256)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--after", type=float, default=3.0)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--image", type=Path, default=None)
    args = parser.parse_args(argv)
    base = args.out or Path(tempfile.mkdtemp(prefix="camo-interrupt-"))
    base.mkdir(parents=True, exist_ok=True)
    image = args.image
    if image is None:  # the forest, scaled up to the grid by whole pixels
        import cv2

        from camo_core.algorithm.backgrounds import background

        image = base / "forest.png"
        size = max(128, args.side)
        forest = background("forest")
        cv2.imwrite(str(image), cv2.resize(forest, (size, size), interpolation=cv2.INTER_NEAREST))
    for k in range(args.runs):
        row = one_run(args.side, args.after, base / f"run_{k}", image)
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
