"""Where a sweep's tasks run: in this process (`--workers 1`), on a Dask LocalCluster of
single-threaded worker processes (the default, one per core), on an existing Dask cluster
(`--scheduler tcp://HOST:PORT`) or on SLURM jobs (`--slurm`, dask-jobqueue).

Every engine runs the same tasks (batches of trials) and yields their results as they finish,
with a bounded number of tasks in flight. A Dask worker that dies costs only its tasks, which
the scheduler runs again elsewhere.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from camo_core.exceptions import UsageError
from camo_core.shm import remove_stale

ROOT = Path(__file__).resolve().parents[3]
CONNECT_TIMEOUT_S = 10
SLURM_KEYS = ("queue", "account", "cores", "memory", "walltime", "max_jobs")
ROS = "ros"  # the Dask worker resource a swarm trial takes one of


def lost_cluster() -> tuple[type[BaseException], ...]:
    """What a Dask client raises when its scheduler or the connection to it goes away: nothing
    where Dask was never imported (no cluster to lose; a sweep refused for its input, or run
    in-process, does not import it: 0.25 s)."""
    if "distributed" not in sys.modules:
        return ()
    try:
        from distributed.client import FutureCancelledError
        from distributed.comm import CommClosedError
    except ImportError:  # an older distributed: the names moved
        from concurrent.futures import CancelledError

        return (CancelledError,)
    return (FutureCancelledError, CommClosedError)


class InProcess:
    """Tasks one after the other in this process: no Dask."""

    name = "in-process"
    workers = 1

    def run(self, tasks: Iterable[tuple[Callable, tuple]], **_) -> Iterator[Any]:
        for function, args in tasks:
            yield function(*args)

    def close(self) -> None:
        pass


class DaskEngine:
    """A Dask client, and the cluster it started (if it started one)."""

    def __init__(self, client, cluster=None, name: str = "dask") -> None:
        self.client, self.cluster, self.name = client, cluster, name

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info(n_workers=-1).get("workers", {})))

    def warm(self) -> None:
        """Compile the kernels once on every worker, before the first task."""
        from camo_sweep.trials import warm

        self.client.run(warm)

    def ros_slots(self) -> int:
        """How many swarm trials the workers take at once (their `ros` resources)."""
        workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
        return int(sum(w.get("resources", {}).get(ROS, 0) for w in workers.values()))

    def run(
        self,
        tasks: Iterable[tuple[Callable, tuple]],
        in_flight: int | None = None,
        resources: dict[str, float] | None = None,
    ) -> Iterator[Any]:
        """Submit tasks, at most `in_flight` at a time, and yield their results as they end."""
        from distributed import as_completed

        limit = in_flight or 2 * self.workers + 2
        pending = iter(tasks)
        futures = as_completed()
        for _ in range(limit):
            task = next(pending, None)
            if task is None:
                break
            futures.add(self._submit(task, resources))
        for future in futures:
            result = future.result()
            future.release()
            task = next(pending, None)
            if task is not None:
                futures.add(self._submit(task, resources))
            yield result

    def _submit(self, task, resources):
        function, args = task
        # pure=False: every task is run (and rerun if its worker dies), never taken from a cache
        return self.client.submit(function, *args, pure=False, resources=resources)

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()
                # The semaphores of workers killed on the way (multiprocessing's, in /dev/shm):
                # nothing unlinks them but this (camo_core.shm).
                remove_stale()


def worker_environment() -> None:
    """Worker processes inherit this: one thread each for BLAS, OpenMP and numba."""
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    os.environ["NUMBA_NUM_THREADS"] = "1"


PER_CORE = 8  # local worker processes a core at most: more only wait (and each takes ~200 MB)


def check_local_workers(workers: int) -> None:
    """--workers: 1..1024, and no more local processes than PER_CORE a core of this machine
    (a thousand on two cores started for minutes and then broke in multiprocessing)."""
    cores = os.cpu_count() or 1
    if not 1 <= workers <= min(1024, PER_CORE * cores):
        raise UsageError(
            f"--workers must be in 1..{min(1024, PER_CORE * cores)} on this machine "
            f"({cores} cores, {PER_CORE} a core at most; got {workers}): more go to a "
            "cluster, --scheduler or --slurm"
        )


def local_engine(workers: int, ros_per_worker: int = 1) -> DaskEngine:
    """A LocalCluster of `workers` single-threaded processes over TCP on 127.0.0.1, its
    dashboard on 127.0.0.1 only."""
    worker_environment()
    remove_stale()  # what killed camo processes left in /dev/shm
    from distributed import Client, LocalCluster

    # The workers start ignoring SIGINT (they keep the disposition they are born with): Ctrl-C
    # in a terminal reaches the whole process group, and the sweep stops them itself.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            protocol="tcp",
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            resources={ROS: ros_per_worker},
            silence_logs=40,  # errors only
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    return DaskEngine(Client(cluster), cluster, f"LocalCluster of {workers} workers")


def remote_engine(address: str) -> DaskEngine:
    """A client of a running Dask scheduler (./camo dask scheduler)."""
    if not address.startswith(("tcp://", "tls://", "ws://", "wss://", "inproc://")):
        raise UsageError(f"--scheduler takes an address like tcp://HOST:8786 (got {address!r})")
    from distributed import Client

    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:  # ValueError: tcp://host:notaport
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise UsageError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    return DaskEngine(client, None, f"the Dask scheduler at {address}")


def slurm_cluster(settings: dict[str, Any]):
    """A dask_jobqueue SLURMCluster whose jobs start Dask workers in this clone's environment;
    no job is submitted until it is scaled."""
    unknown = set(settings) - set(SLURM_KEYS)
    if unknown:
        raise UsageError(
            f"slurm: unknown setting {sorted(unknown)[0]!r} ({', '.join(SLURM_KEYS)})"
        )
    for key in ("cores", "max_jobs"):
        value = settings.get(key, 1)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise UsageError(f"slurm {key} must be a positive integer (got {value!r})")
    cores = settings.get("cores", 1)
    from dask.utils import parse_bytes

    try:
        parse_bytes(str(settings.get("memory", "4GB")))
    except ValueError:
        memory = settings.get("memory")
        raise UsageError(f"slurm memory must be a size like 8GB (got {memory!r})") from None
    worker_environment()
    from dask_jobqueue import SLURMCluster

    return SLURMCluster(
        queue=settings.get("queue"),
        account=settings.get("account"),
        cores=cores,
        processes=cores,  # one single-threaded worker process per core
        memory=str(settings.get("memory", "4GB")),
        walltime=str(settings.get("walltime", "01:00:00")),
        python=sys.executable,
        job_script_prologue=[
            f"cd {ROOT}",
            f"source {ROOT}/.venv/bin/activate",
            "set +u",
            f"source {ROOT}/ros2_ws/install/setup.bash",
            # what ./camo sets before every command
            f"export AMENT_PREFIX_PATH={ROOT}/.venv${{AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}}",
            "export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}",
            "export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1",
        ],
        worker_extra_args=["--resources", f"{ROS}=1"],
        scheduler_options={"dashboard_address": "127.0.0.1:0"},
    )


def slurm_engine(settings: dict[str, Any]) -> DaskEngine:
    from distributed import Client

    if shutil.which("sbatch") is None:
        raise UsageError("--slurm needs SLURM's sbatch on the PATH (run it on a login node)")
    cluster = slurm_cluster(settings)
    jobs = settings.get("max_jobs", 1)
    cluster.scale(jobs=jobs)
    return DaskEngine(Client(cluster), cluster, f"SLURM ({jobs} jobs)")
