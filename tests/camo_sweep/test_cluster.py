"""A sweep on a cluster of `./camo dask` processes: a worker SIGKILLed mid-sweep costs only its
tasks, and the table is the one a single process writes; swarm trials take a worker resource."""

import os
import signal
import socket
import subprocess
import sys
import time
from unittest import mock

import pytest
from support import CLUSTER, ROOT, SWARM, finished, sweep
from support import sweep_table as table

from camo_sweep.table import parts


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(*args: str) -> subprocess.Popen:
    """A `./camo dask ...` process in a session of its own (SIGKILL takes all of it)."""
    return subprocess.Popen(
        [str(ROOT / "camo"), "dask", *args],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def stop(proc: subprocess.Popen) -> None:
    """SIGTERM, as a cluster is stopped (Dask closes its workers and lets go of their
    semaphores in /dev/shm); SIGKILL only for one that does not end in 15 s."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


def wait_for_workers(address: str, count: int) -> None:
    from distributed import Client

    with Client(address, timeout=60) as client:
        client.wait_for_workers(count, timeout=120)


@pytest.fixture
def cluster():
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = start("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")
    workers = [
        start("worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard")
        for _ in range(2)
    ]
    try:
        wait_for_workers(address, 2)
        yield address, workers
    finally:
        for proc in (*workers, scheduler):
            stop(proc)


@pytest.mark.slow(SWARM)
def test_a_worker_killed_mid_sweep_costs_only_its_tasks(cluster, tmp_path):
    address, workers = cluster
    args = ["--axis", "rho_comm=0:0.5:0.05", "--set", "pattern=forest", "--trials", "200"]
    args += ["--batch-s", "0.02", "--quiet"]
    one = sweep(*args, "--workers", "1", "--out", str(tmp_path / "one"))
    assert one.returncode == 0, one.stderr
    out = tmp_path / "cluster"
    proc = subprocess.Popen(
        [sys.executable, "-m", "camo_sweep.cli", *args, "--scheduler", address, "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while len(parts(out)) < 3 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    os.killpg(workers[0].pid, signal.SIGKILL)  # the worker, its nanny and all
    stdout, stderr = finished(proc, 300)
    assert proc.returncode == 0, stderr
    assert "the Dask scheduler at tcp://127.0.0.1" in stdout
    assert len(parts(out)) > 3  # it went on after the kill
    assert table(out) == table(tmp_path / "one")


@pytest.mark.slow(CLUSTER)
def test_workers_elsewhere_never_open_the_sweeps_images(cluster, tmp_path):
    # The workers run in the repository's folder; the sweep, and its relative image, here.
    import cv2

    from camo_core.algorithm.backgrounds import background

    address, _ = cluster
    cv2.imwrite(str(tmp_path / "a.png"), background("desert"))
    args = ["--axis", "image=a.png", "--axis", "rho_comm=0,0.3", "--trials", "3", "--quiet"]
    runs = {}
    for name, engine in (("one", ["--workers", "1"]), ("far", ["--scheduler", address])):
        done = subprocess.run(
            [sys.executable, "-m", "camo_sweep.cli", *args, *engine, "--out", name],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=tmp_path,
        )
        assert done.returncode == 0, done.stderr
        runs[name] = table(tmp_path / name)
    assert all(r["status"] == "ok" for r in runs["far"]) and runs["far"] == runs["one"]


@pytest.mark.slow(CLUSTER)
def test_swarm_trials_need_a_worker_with_the_ros_resource(cluster, tmp_path):
    address, _ = cluster
    done = sweep(
        "--axis",
        "rho_comm=0.1",
        "--driver",
        "ros",
        "--scheduler",
        address,
        "--out",
        str(tmp_path / "s"),
    )
    assert done.returncode == 2 and "offers the 'ros' resource" in done.stderr
    assert not (tmp_path / "s").exists()


def _square(x: int) -> int:
    return x * x


@pytest.mark.slow(CLUSTER)
def test_a_local_cluster_listens_on_loopback_and_keeps_few_tasks_in_flight():
    from camo_sweep.engines import local_engine

    with mock.patch.dict(os.environ):  # one thread a worker: its processes', not ours
        engine = local_engine(1)
    try:
        assert engine.client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert engine.cluster.dashboard_link.startswith("http://127.0.0.1:")
        futures, most = [], [0]
        submit = engine._submit

        def counting(task, resources):
            running = sum(not f.done() for f in futures)  # handed out, not finished
            most[0] = max(most[0], running + 1)
            futures.append(submit(task, resources))
            return futures[-1]

        engine._submit = counting
        results = list(engine.run(((_square, (k,)) for k in range(200)), in_flight=5))
        assert sorted(results) == [k * k for k in range(200)]
        assert most[0] <= 5
    finally:
        engine.close()
