"""Shared helpers. Tests run through `./camo test`, inside the project's venv and workspace."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_camo(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the camo command line (already set up: we are inside ./camo test)."""
    return subprocess.run([sys.executable, "-m", "camo_core.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


_next_domain = [0]


def domain() -> int:
    """A ROS domain of its own for each run, so parallel test processes do not hear each other."""
    _next_domain[0] += 1
    return 1 + (os.getpid() * 7 + _next_domain[0]) % 200


def camo_run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """`./camo run` with a domain of its own."""
    return subprocess.run([sys.executable, "-m", "camo_nodes.launcher", *args, "--domain-id", str(domain())],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)
