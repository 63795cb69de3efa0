"""Shared helpers. Tests run through `./camo test`, inside the project's venv and workspace."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run_camo(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the camo command line (already set up: we are inside ./camo test)."""
    return subprocess.run([sys.executable, "-m", "camo_core.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


@pytest.fixture
def domain_id(worker_id: str = "master") -> int:
    """A ROS domain id of this test process's own, so parallel runs do not hear each other."""
    return 100 + os.getpid() % 100
