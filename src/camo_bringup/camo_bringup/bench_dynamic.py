"""`./camo bench dynamic`: how fast a continuous swarm follows a changing scene, against the
launcher switching the same scenes (`--then`), measured in the same run; and how often a static
noisy scene starts a round it should not.

Following: the projector shows forest and desert in turn (`--images`, one frame per scene:
frame k is scene k), `--changes` times; each change is timed from the projection of its frame to
the moment its round's last robot was done (`rounds.csv`: done_at - changed_at). Every round
must be on a frame of its own, finished, and equal `./camo sim` on its frame with its seed: a
change missed or a round on another frame is said (and its change not timed), not taken for
another's. The baseline is a run whose launcher switches the same scenes with `--then` once each
round is done, timed the same way (`timing.json`: done_at - projected_at): the continuous
swarm's extra cost is noticing.

False rounds: a continuous run on a static scene streamed like a camera (frame noise, at 15
frames a second) with measurement noise on every reading, for `--static-s` seconds: rounds
beyond the first, per minute.

With `--scope local` the scenes are one scene whose right half changes (forest beside desert,
then beside leopard, in turn): each round must also keep what the left half showed. Said per
side: the most and the mean share of the robots two or more cells clear of the change whose
display changed with a round (at most 5% is the aim).
"""

from __future__ import annotations

import csv
import itertools
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.modes import modes_of
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import sense_colours, sense_image
from camo_core.algorithm.simulator import simulate
from camo_core.cli.commands import previous_round
from camo_core.cli.options import Parser
from camo_core.exceptions import EXIT_USAGE, CamoError
from camo_core.inputs.images import load_image
from camo_core.inputs.numeric import integer
from camo_core.results.summary import summary_bytes
from camo_nodes.topics.startup import bench_domain

SCENES = ("forest", "desert")
# --scope local: the left half stays, the right half changes.
LEFT, RIGHTS = "forest", ("desert", "leopard")


def half_scene(k: int) -> np.ndarray:
    """Frame k of a local run's scenes: forest on the left, desert or leopard on the right."""
    left = background(LEFT)
    right = background(RIGHTS[k % 2])
    return np.concatenate([left, right], axis=1)


def sides(text: str) -> list[int]:
    values = [integer(x) for x in text.split(",") if x]
    if not values or not all(4 <= v <= 128 for v in values):
        raise CamoError(f"sides must be integers in 4..128 (got {text!r})")
    return values


def said_last(ran: subprocess.CompletedProcess) -> str:
    """What a run said last (its stderr's last lines, in one): why it has nothing to show."""
    lines = ran.stderr.strip().splitlines()
    return " / ".join(lines[-3:]) if lines else "it said nothing"


def launch(argv: list[str], domain: int, timeout: float) -> subprocess.CompletedProcess:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    proc = subprocess.run(
        [sys.executable, "-m", "camo_bringup.launcher", *argv],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"camo run {' '.join(argv)} failed: {proc.stderr.strip()[-400:]}")
    return proc


def period_for(side: int) -> float:
    """Seconds each scene is shown: a round of that many robots and some."""
    return 2.5 + side * side / 1000.0


def like_sim(folder: Path, side: int, rho: float, scope: str = "global") -> bool:
    """Whether a continuous round (its folder) equals `./camo sim` on its frame with its seed
    (with --scope local after the round before: `--after`)."""
    live = json.loads((folder / "summary.json").read_text())
    params = CamoParams(rows=side, cols=side, rho_meas=rho, seed=live["seed"], scope=scope)
    image = load_image(str(folder / "background.png"))
    grid = sense_image(image, side, side, params.profile)
    before = folder.parent / f"round_{live['round'] - 1}"
    previous = None
    if scope == "local" and live["round"] > 0:
        previous = previous_round(str(before), params, modes_of(params))
    result = simulate(
        params, grid, raw_colours=sense_colours(image, side, side), previous=previous
    )
    sim = json.loads(summary_bytes(result.summary(arrays=True)))
    return all(live.get(key) == value for key, value in sim.items() if key != "elapsed_s")


def following(
    side: int, changes: int, domain: int, out: Path, rho: float, scope: str = "global"
) -> tuple[list[float], dict]:
    """Seconds from each change's frame to its round's last robot done (continuous), and what
    the rounds were: their frames, the changes without a round of their own, the rounds on no
    change's frame or unfinished, how many equal the simulator; with --scope local how much of
    what the unchanged half showed changed."""
    scenes = out / "scenes"
    scenes.mkdir(parents=True, exist_ok=True)
    for k in range(changes + 1):  # forest, desert, forest, ...: each image a frame of its own
        scene = half_scene(k) if scope == "local" else background(SCENES[k % 2])
        cv2.imwrite(str(scenes / f"{k:03d}.png"), scene)
    # The run shows one frame more than the changes: the last scene again, no change (the
    # images loop, and the first scene again would be a change no round is asked of).
    cv2.imwrite(str(scenes / f"{changes + 1:03d}.png"), scene)
    period = period_for(side)
    argv = [
        # Its length, not a number of rounds: a change missed (or a round too many) is seen.
        "--continuous", "--duration", f"{period * (changes + 2):g}",
        "--images", str(scenes / "*.png"), "--period", str(period),
        "--rows", str(side), "--cols", str(side), "--scope", scope,
        "--rho-meas", str(rho), "--out", str(out / "run"),
    ]  # fmt: skip
    ran = launch(argv, domain, timeout=120 + period * (changes + 4))
    if not (out / "run" / "rounds.csv").exists():
        raise RuntimeError(f"the continuous run wrote no round: {said_last(ran)}")
    with open(out / "run" / "rounds.csv") as file:
        rows = list(csv.DictReader(file))
    frames = [int(r["frame"]) for r in rows]
    checks = {
        "frames": frames,
        "missed": sorted(set(range(1, changes + 1)) - set(frames)),  # frame k: change k
        "other": [f for f in frames if not 0 <= f <= changes or frames.count(f) > 1],
        "incomplete": [int(r["frame"]) for r in rows if r["complete"] != "1"],
        "like_sim": sum(
            like_sim(out / "run" / f"round_{k}", side, rho, scope) for k in range(len(rows))
        ),
        "rounds": len(rows),
    }
    if scope == "local":
        checks["kept"] = kept_shares(out / "run", len(rows), side)
    done = {int(r["frame"]): float(r["done_s"]) for r in rows if r["complete"] == "1"}
    return [done[f] for f in range(1, changes + 1) if f in done], checks  # round 0: no change


def kept_shares(run: Path, rounds: int, side: int) -> list[float]:
    """Per later round: the share of the robots two or more cells clear of the changed half
    whose display changed from the round before."""
    clear = np.zeros((side, side), bool)
    clear[:, : side // 2 - 2] = True
    shown = [
        np.array(json.loads((run / f"round_{k}" / "summary.json").read_text())["display"])
        for k in range(rounds)
    ]
    return [
        float(np.mean((b != a).reshape(side, side, -1).any(-1)[clear]))
        for a, b in itertools.pairwise(shown)
    ]


def switched(
    side: int, changes: int, domain: int, out: Path, rho: float, scope: str = "global"
) -> list[float]:
    """Seconds from each --then switch's frame to its round's last robot done (baseline): the
    same scenes (with --scope local its files, from the continuous run's folder)."""
    if scope == "local":
        scenes = sorted((out.parent / "continuous" / "scenes").glob("*.png"))[: changes + 1]
        first, later = ["--image", str(scenes[0])], [str(path) for path in scenes[1:]]
    else:
        first, later = ["--pattern", SCENES[0]], [SCENES[(k + 1) % 2] for k in range(changes)]
    then = [arg for name in later[:changes] for arg in ("--then", name)]
    argv = [
        *first, *then, "--rows", str(side), "--cols", str(side), "--scope", scope,
        "--rho-meas", str(rho), "--out", str(out / "run"),
    ]  # fmt: skip
    ran = launch(argv, domain, timeout=120 + 20 * changes)
    delays = []
    for k in range(1, changes + 1):
        path = out / "run" / f"round_{k}" / "timing.json"
        if not path.exists():
            raise RuntimeError(f"the --then run wrote no round {k}: {said_last(ran)}")
        timing = json.loads(path.read_text())
        delays.append(timing["done_at"] - timing["projected_at"])
    return delays


def false_rounds(side: int, seconds: float, domain: int, out: Path, rho: float) -> dict:
    """Rounds beyond the first a static, noisy camera-like scene starts in `seconds`."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    camera = subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.scene_stream", "/bench/camera", "--scenes",
         "leopard", "--fps", "15", "--noise", "8", "--seconds", str(seconds + 120)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        argv = [
            "--continuous", "--duration", str(seconds), "--background-topic", "/bench/camera",
            "--rows", str(side), "--cols", str(side), "--rho-meas", str(rho),
            "--out", str(out / "run"),
        ]  # fmt: skip
        launch(argv, domain, timeout=seconds + 180)
    finally:
        camera.terminate()
        camera.wait(10)
    path = out / "run" / "rounds.csv"
    rounds = len(list(csv.DictReader(open(path)))) if path.exists() else 0
    extra = max(0, rounds - 1)
    return {"seconds": seconds, "rounds": rounds, "per_minute": extra * 60.0 / seconds}


def quantiles(values: list[float]) -> dict:
    if not values:
        return {"median_s": None, "p90_s": None, "max_s": None, "changes": 0}
    return {
        "median_s": statistics.median(values),
        "p90_s": float(np.percentile(values, 90)),
        "max_s": max(values),
        "changes": len(values),
    }


def checks_said(checks: dict, changes: int) -> str:
    """What the continuous run's rounds were, in a line."""
    rounds, equal = checks["rounds"], checks["like_sim"]
    said = f"{rounds} rounds, {equal} equal to ./camo sim on their frames with their seeds"
    problems = []
    if checks["missed"]:
        problems.append(f"changes without a round of their own: frames {checks['missed']}")
    if checks["other"]:
        problems.append(f"rounds on no change's frame: {checks['other']}")
    if checks["incomplete"]:
        problems.append(f"unfinished: frames {checks['incomplete']}")
    if rounds == changes + 1 and not problems:
        return f"{said}; one round a change (frames 0-{changes})"
    return f"{said}; WARNING: {'; '.join(problems) or 'not one round a change'} (not timed)"


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo bench dynamic", description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--sides", type=sides, default="16,64", help="grid sides (default 16,64)")
    parser.add_argument("--changes", type=int, default=10, help="scene changes per side (10)")
    parser.add_argument(
        "--static-s",
        type=float,
        default=60.0,
        help="seconds of a static noisy scene (60; 0: none)",
    )
    parser.add_argument(
        "--rho-meas", type=float, default=0.15, help="measurement noise of every reading (0.15)"
    )
    parser.add_argument(
        "--scope",
        choices=("global", "local"),
        default="global",
        help="local: the scenes' right half changes, and how much of what the left half "
        "showed changed is said",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("results") / time.strftime("bench-dynamic-%Y%m%d-%H%M%S")
    )
    try:
        args = parser.parse_args(argv)
        if not (1 <= args.changes <= 100 and 0 <= args.static_s <= 86400):
            raise CamoError("--changes must be in 1..100 and --static-s in 0..86400")
        if not 0 <= args.rho_meas <= 1:
            raise CamoError(f"--rho-meas must be in [0, 1] (got {args.rho_meas})")
        domain = bench_domain(140, 40)
    except CamoError as exc:
        print(f"camo bench dynamic: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        rows, static = measure(args, domain)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        print(f"camo bench dynamic: error: {exc}", file=sys.stderr)
        return 1
    report(args, rows, static)
    return 0


def measure(args, domain: int) -> tuple[list[dict], dict | None]:
    rows = []
    for side in args.sides:
        out = args.out / f"{side}"
        print(f"camo bench dynamic: {side}x{side}, {args.changes} changes", file=sys.stderr)
        delays, checks = following(
            side, args.changes, domain, out / "continuous", args.rho_meas, args.scope
        )
        print(
            f"camo bench dynamic: {side}x{side}: {checks_said(checks, args.changes)}",
            file=sys.stderr,
        )
        noticed = quantiles(delays)
        then = quantiles(
            switched(side, args.changes, domain, out / "then", args.rho_meas, args.scope)
        )
        ratio = noticed["median_s"] / then["median_s"] if delays else None
        rows.append(
            {
                "robots": f"{side}x{side}",
                "continuous": noticed,
                "then": then,
                "ratio": ratio,
                "rounds": checks,
            }
        )
    static = None
    if args.static_s:
        side = args.sides[0]
        static = false_rounds(side, args.static_s, domain, args.out / "static", args.rho_meas)
        static["robots"] = f"{side}x{side}"
    return rows, static


def report(args, rows: list[dict], static: dict | None) -> None:
    if args.json:
        print(json.dumps({"following": rows, "static": static}))
        return
    print(f"scene change to every robot done (rho_meas {args.rho_meas}), seconds:")
    print("| robots | continuous median | p90 | max | --then median | p90 | max | ratio |")
    print("|---|---|---|---|---|---|---|---|")

    def figure(value) -> str:
        return "-" if value is None else f"{value:.2f}"

    for r in rows:
        c, t = r["continuous"], r["then"]
        cells = [c["median_s"], c["p90_s"], c["max_s"], t["median_s"], t["p90_s"], t["max_s"]]
        print(f"| {r['robots']} | {' | '.join(map(figure, cells))} | {figure(r['ratio'])} |")
    for r in rows:
        print(f"{r['robots']} continuous: {checks_said(r['rounds'], args.changes)}")
        kept = r["rounds"].get("kept")
        if kept:
            print(
                f"{r['robots']} --scope local: robots clear of the change whose display changed: "
                f"at most {100 * max(kept):.1f}%, mean {100 * statistics.mean(kept):.1f}% "
                f"({len(kept)} changes)"
            )
    if static:
        print(
            f"static noisy scene, {static['robots']}, {static['seconds']:g} s: {static['rounds']} "
            f"rounds, {static['per_minute']:.2f} false rounds a minute"
        )


if __name__ == "__main__":
    sys.exit(main())
