"""`./camo setup` on a machine that lacks what it needs: one line for each missing tool with the
Debian/Ubuntu package that provides it, before anything is made."""

import os
import shutil
import subprocess

import pytest
from support import ROOT, path_without

NEEDED = ("cmake", "make", "gcc", "g++")


def setup(tmp_path, path: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(ROOT / "camo"), "setup"],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PATH": path, **env},
    )


@pytest.mark.parametrize("lacking", [("make",), ("gcc", "g++"), NEEDED])
def test_a_missing_build_tool_is_named_with_its_package_before_anything_is_made(tmp_path, lacking):
    if not all(shutil.which(tool) for tool in NEEDED):
        pytest.fail(f"this machine lacks one of {NEEDED}: the README's apt-get line has them")
    stamps = [ROOT / ".venv" / ".camo-requirements", ROOT / "ros2_ws" / ".camo-build"]
    before = [p.stat().st_mtime_ns if p.exists() else None for p in stamps]
    done = setup(tmp_path, path_without(tmp_path, *lacking), CAMO_PYTHON=shutil.which("python3"))
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines[:-1] == [
        f"camo: error: the set-up needs {tool}: Debian/Ubuntu package {tool}" for tool in lacking
    ]
    assert lines[-1] == f"camo: install them with: sudo apt-get install {' '.join(lacking)}"
    assert [p.stat().st_mtime_ns if p.exists() else None for p in stamps] == before


def test_no_python_at_the_path_given_is_one_line_naming_the_package(tmp_path):
    done = setup(tmp_path, os.environ["PATH"], CAMO_PYTHON=str(tmp_path / "python3"))
    assert done.returncode == 1
    assert done.stderr.splitlines()[0] == (
        f"camo: error: the set-up needs a Python 3.11 at '{tmp_path / 'python3'}': "
        "Debian/Ubuntu package python3"
    )


def test_a_python_without_its_headers_or_venv_is_named_with_their_packages(tmp_path):
    # A Python as a bare system's: no ensurepip (Debian splits it into python3-venv) and no
    # include folder (python3-dev). This one's site is made to hide both.
    hide = tmp_path / "hide"
    hide.mkdir()
    (hide / "sitecustomize.py").write_text(
        "import importlib.util, sysconfig\n"
        "_find = importlib.util.find_spec\n"
        "importlib.util.find_spec = lambda n, *a: None if n == 'ensurepip' else _find(n, *a)\n"
        "_paths = sysconfig.get_paths\n"
        "sysconfig.get_paths = lambda *a, **k: {**_paths(*a, **k), 'include': '/nonexistent'}\n"
    )
    done = setup(
        tmp_path, os.environ["PATH"], CAMO_PYTHON=shutil.which("python3"), PYTHONPATH=str(hide)
    )
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "camo: error: the set-up needs Python's venv with ensurepip: Debian/Ubuntu package "
        "python3-venv",
        "camo: error: the set-up needs Python's C headers (Python.h): Debian/Ubuntu package "
        "python3-dev",
        "camo: install them with: sudo apt-get install python3-venv python3-dev",
    ]


def test_the_readmes_apt_get_line_holds_every_package_the_set_up_names():
    line = next(
        line for line in (ROOT / "README.md").read_text().splitlines() if "apt-get install" in line
    )
    packages = set(line.split())
    named = {"python3-venv", "python3-dev", *NEEDED}
    assert named <= packages, named - packages
    assert {"iproute2", "iptables", "nodejs", "npm", "podman", "debootstrap"} <= packages
    # docker/compose.yaml's services find one another by name: netavark's DNS
    assert {"netavark", "aardvark-dns"} <= packages


def test_the_suite_caches_what_python_compiles_where_the_machine_says_not_to(tmp_path):
    """`./camo test` under PYTHONDONTWRITEBYTECODE still caches compiled modules (camo's, and
    pytest's rewritten test modules): the suite starts hundreds of processes, and each compiled
    every module anew (the fast subset took 63 s instead of 51)."""
    cache = tmp_path / "pycache"  # a prefix of its own: what is written is this run's
    done = subprocess.run(
        [str(ROOT / "camo"), "test", "-n", "0", "--collect-only", "-q", "-p", "no:cacheprovider"]
        + ["tests/camo_core/test_rng.py"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
        env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": str(cache)},
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    written = {p.name.split(".")[0] for p in cache.rglob("*.pyc")}
    assert {"test_rng", "rng"} <= written, sorted(written)[:20]


@pytest.mark.parametrize("given", [None, "2"])
def test_camos_processes_load_blas_on_one_thread_unless_told_otherwise(given):
    """A process ./camo starts loads NumPy's and SciPy's OpenBLAS without its pool of threads
    (one per other core, each spinning a tenth of a CPU-second as it loads: every process paid
    it); a number the user gives is kept."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = "import os, numpy, scipy.linalg; print(len(os.listdir('/proc/self/task')))"
    done = subprocess.run(
        [str(ROOT / "camo"), "python", "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    # A pool of n threads is n - 1 besides the process's own, for each of the two libraries.
    cores = len(os.sched_getaffinity(0))  # what OpenBLAS counts
    wanted = 1 if given is None else 1 + 2 * (min(int(given), cores) - 1)
    assert int(done.stdout) == wanted
