"""docs/img/continuous.gif: a 16x16 continuous run following a camera-like topic that switches
from forest to desert to leopard (docs/swarm.md), its run.gif copied into the docs.

    ./camo python tools/continuous_gif.py [--out docs/img/continuous.gif]

The camera (camo_bringup.scene_stream: 15 frames a second, pixel noise of sigma 6) holds the
forest until the run's first round is written, then switches every 6 s; the run (`./camo run
--continuous --rounds 3`, rho_meas 0.15, rho_comm 0.05, two processes) ends after its third
round. About half a minute; the run's folder is kept in a temporary folder it names.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "continuous.gif")
    parser.add_argument("--domain-id", type=int, default=77)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="camo-continuous-gif-"))
    run = work / "run"
    env = {**os.environ, "ROS_DOMAIN_ID": str(args.domain_id)}
    camera = subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.scene_stream", "/cam/image_raw",
         "--scenes", "forest,desert,leopard", "--switch", "6", "--fps", "15", "--noise", "6",
         "--seconds", "120", "--start-when", str(run / "round_0")],
        env=env, stderr=subprocess.DEVNULL,  # its words when stopped mid-frame
    )  # fmt: skip
    try:
        done = subprocess.run(
            [sys.executable, "-m", "camo_bringup.launcher", "--continuous", "--rounds", "3",
             "--background-topic", "/cam/image_raw", "--rows", "16", "--cols", "16",
             "--rho-meas", "0.15", "--rho-comm", "0.05", "--procs", "2", "--out", str(run),
             "--domain-id", str(args.domain_id)],
            timeout=180,
        )  # fmt: skip
    finally:
        camera.terminate()
        camera.wait(10)
    if done.returncode != 0:
        print(f"continuous_gif: the run failed (exit code {done.returncode}); see {run}/")
        return 1
    shutil.copyfile(run / "run.gif", args.out)
    print(f"continuous_gif: wrote {args.out} (the run: {run}/)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
