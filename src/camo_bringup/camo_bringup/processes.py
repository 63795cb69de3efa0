"""The processes of one run: projector, Droplet bridges, workers and the recorder.

Each runs in a session of its own, so that the terminal's Ctrl-C reaches only
the launcher, which then stops them in order. Each is also told by the kernel
to stop (SIGTERM) when the launcher dies, however it dies.
"""

from __future__ import annotations

import ctypes
import os
import resource
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from camo_bringup.run_config import RunConfig, worker_groups
from camo_core.swarm.run_setup import contiguous
from camo_nodes.robot_node import RobotCell
from camo_nodes.topics.parameters import JoinParams, ros_arguments

PR_SET_PDEATHSIG = 1


def _dying_with(parent: int, how: int = signal.SIGKILL) -> Callable[[], None]:
    """In the child, before exec: signal `how` when the launcher exits, however it dies (SIGKILL,
    the OOM killer), so that no robot of a dead run lingers in the domain (Linux prctl). SIGKILL,
    not SIGTERM: a process whose writer is stuck on a dead peer's shared-memory port (Fast DDS)
    would never get to its shutdown. Only the recorder gets SIGTERM, to close its bag."""

    def die_with_parent() -> None:
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, how)
        except (OSError, AttributeError):
            return
        if os.getppid() != parent:  # it died between fork and prctl: nobody will signal
            os._exit(1)

    return die_with_parent


def layout_parameter(config: RunConfig) -> str:
    """A robot node's layout parameter: hex or jitter:A as given, a file layout as a CSV the
    run writes into its folder (the node reads it as --layout FILE would)."""
    params = config.params
    if params.layout != "file":
        return params.layout
    path = config.folder / "layout.csv"
    if not path.exists():
        path.write_text("".join(f"{x!r},{y!r}\n" for x, y in params.positions))
    return str(path.resolve())


def robot_parameters(config: RunConfig, robot: int) -> list[str]:
    """A standalone robot's (or bridge's) ROS parameters, as -p options: the run's, the
    protocol's, its cell and its run."""
    row, col = divmod(robot, config.params.cols)
    return [
        *ros_arguments(config.params, layout=layout_parameter(config)),
        *ros_arguments(config.protocol),
        *ros_arguments(RobotCell(row, col)),
        *ros_arguments(JoinParams(config.topics.run)),
    ]


def module_of(proc: subprocess.Popen) -> str:
    """The module a process of the group runs (ProcessGroup._start's command line)."""
    return proc.args[3]


class ProcessGroup:
    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.procs: list[subprocess.Popen] = []
        self.cells: dict[int, list[int]] = {}  # pid -> robot ids
        self.recorder: subprocess.Popen | None = None
        self.server: subprocess.Popen | None = None  # the run's own discovery server
        self.workers: list[subprocess.Popen] = []
        self.peak_kib: dict[int, int] = {}  # pid -> its largest resident set so far
        self._interrupted: list[subprocess.Popen] = []
        self.killed: list[str] = []  # modules that did not stop in time (their shm is left)

    def _start(
        self, module: str, *args: str, on_orphan: int = signal.SIGKILL, quiet: bool = False
    ) -> subprocess.Popen:
        """`quiet`: its standard output to /dev/null (a tool's banner)."""
        # Through camo_core.shutdown: a process interrupted while it still imports ends quietly.
        command = [sys.executable, "-m", "camo_core.shutdown", module, *args]
        proc = subprocess.Popen(
            command,
            env=self.env,
            stdout=subprocess.DEVNULL if quiet else None,
            start_new_session=True,
            preexec_fn=_dying_with(os.getpid(), on_orphan),
        )
        self.procs.append(proc)
        return proc

    def start_recorder(self, bag: str, run: str) -> subprocess.Popen:
        self.recorder = self._start(
            "camo_bag.recorder_node",
            *(bag, "--run-id", run, "--ros-args", "--log-level", "warn"),
            on_orphan=signal.SIGTERM,  # it closes its bag: nothing recorded is lost
        )
        return self.recorder

    def start_view(self, run: str, port: int) -> subprocess.Popen:
        return self._start(
            "camo_bag.view_node",
            "--run-id",
            run,
            "--exit-with-run",
            "--port",
            str(port),
            "--ros-args",
            "--log-level",
            "warn",
        )

    def start_discovery_server(self, address: str) -> subprocess.Popen:
        host, _, port = address.rpartition(":")
        server = ("camo_nodes.discovery_server", "--address", host, "--port", port)
        self.server = self._start(*server, quiet=True)
        return self.server

    def start_swarm(self, config: RunConfig, ready: Path | None = None) -> None:
        """Projector, bridges and workers; with `ready`, each worker touches a file in that
        folder once its robot nodes exist."""
        quiet = ("--ros-args", "--log-level", "warn")
        run = ("-p", f"run_id:={config.topics.run}")
        if config.projector is not None:
            goals = (
                "-p",
                f"goals:={config.folder / 'goals'}",
            )  # the Camouflage goals' (last: wins)
            self._start("camo_projector.projector_node", *quiet, *run, *config.projector, *goals)
        for robot, port in config.bridges.items():
            extra = ["-p", f"calibration:={config.calibration}"] if config.calibration else []
            bridge = self._start(
                "camo_droplet.bridge_node",
                *quiet,
                *robot_parameters(config, robot),
                "-p",
                f"port:={port}",
                *extra,
            )
            self.cells[bridge.pid] = [robot]
        for cells in worker_groups(config):
            ranges = [f"--cells={a}-{b}" for a, b in contiguous(cells)]
            worker = self._start(
                "camo_bringup.worker",
                "--setup",
                config.setup().to_json(),
                "--run-id",
                config.topics.run,
                *ranges,
                *([f"--ready={ready / str(len(self.workers))}"] if ready else []),
                *quiet,
            )
            self.cells[worker.pid] = cells
            self.workers.append(worker)

    def sample_memory(self) -> None:
        """Each running process's largest resident set so far (the kernel's VmHWM)."""
        for proc in self.procs:
            try:
                status = Path(f"/proc/{proc.pid}/status").read_text()
            except OSError:
                continue  # gone: its last sample stands
            for line in status.splitlines():
                if line.startswith("VmHWM:"):
                    kib = int(line.split()[1])
                    self.peak_kib[proc.pid] = max(kib, self.peak_kib.get(proc.pid, 0))

    def peak_mib(self) -> dict:
        """The largest resident sets (MiB): of a worker, of this process, and all together, and
        per process (`processes`: the launcher, then each process it started, by its module,
        workers numbered in the order started)."""
        mine = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
        workers = [self.peak_kib.get(p.pid, 0) for p in self.workers]
        total = mine + sum(self.peak_kib.values())
        processes = {"launcher": round(mine / 1024, 1)}
        for proc in self.procs:
            name = module_of(proc).rsplit(".", 1)[-1]
            if proc in self.workers:
                name = f"worker {self.workers.index(proc) + 1}"
            processes[name] = round(self.peak_kib.get(proc.pid, 0) / 1024, 1)
        return {
            "worker_max": round(max(workers, default=0) / 1024, 1),
            "launcher": round(mine / 1024, 1),
            "all": round(total / 1024, 1),
            "processes": processes,
        }

    def failed(self) -> str | None:
        """A process exited with an error (a robot killed by a signal is a fault, not this; a
        recorder that could not write costs its bag, not the run: `recording_failed`)."""
        for proc in self.procs:
            if proc is self.recorder:
                continue
            if proc.poll() is not None and proc.returncode > 0:
                return f"a swarm process exited with code {proc.returncode}: {module_of(proc)}"
        return None

    def recording_failed(self) -> bool:
        """Our recorder exited before the run's end with an error (it said why)."""
        recorder = self.recorder
        return recorder is not None and recorder.poll() is not None and recorder.returncode != 0

    def recording(self) -> bool:
        """Our recorder runs."""
        return self.recorder is not None and self.recorder.poll() is None

    def lost_cells(self) -> list[int]:
        """Robots whose process has exited (killed, say): they cannot finish."""
        return [c for p in self.procs if p.poll() is not None for c in self.cells.get(p.pid, ())]

    def interrupt(self, keep: Callable[[subprocess.Popen], bool] = lambda p: False) -> None:
        """SIGINT to each running process (but those `keep` spares), once; no waiting."""
        for proc in self.procs:
            if proc.poll() is None and not keep(proc) and proc not in self._interrupted:
                proc.send_signal(signal.SIGINT)
                self._interrupted.append(proc)

    def stop(
        self,
        grace: float = 5.0,
        keep: Callable[[subprocess.Popen], bool] = lambda p: False,
        meanwhile: Callable[[], object] | None = None,
    ):
        """SIGINT to each (but those `keep` spares), SIGKILL to those still running after
        `grace` seconds. `meanwhile` is called while they stop (a bounded piece of work, such
        as a turn of the monitor): a stopping worker sends its robots' last reports and waits
        for them to be taken, which they are only if somebody takes them."""
        stopping = [p for p in self.procs if p.poll() is None and not keep(p)]
        self.interrupt(keep)
        deadline = time.monotonic() + grace
        while any(p.poll() is None for p in stopping) and time.monotonic() < deadline:
            if not (meanwhile and meanwhile()):
                time.sleep(0.02)
        for proc in stopping:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                self.killed.append(module_of(proc))
