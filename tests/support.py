"""Helpers the tests share (fixtures live in conftest.py). Tests run through `./camo test`,
inside the project's venv and workspace."""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import psutil
import warm_cli

from camo_core.algorithm.link import LinkBook
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.sensing import Reading
from camo_core.swarm.mailbox import Mailbox
from camo_core.swarm.protocol import StepProtocol
from camo_core.swarm.robot_io import Message

ROOT = Path(__file__).resolve().parents[1]

# Why a test is slow (`@pytest.mark.slow(WHY)`): `./camo test --fast` leaves these out.
SWARM = "starts ROS 2 processes: a swarm, a recorder or a node of its own"
PROCESS = "runs a camo command in a process of its own"
CLUSTER = "starts a Dask cluster"
COMPUTE = "computes for seconds: large grids, many trials, serial timeouts or a type check"
# Why a test runs alone in a parallel session (`@pytest.mark.alone(TIMED)`, tests/conftest.py).
TIMED = "times a swarm against the wall clock: another test's processes would slow it"
MACHINE = "counts what the whole machine holds (/dev/shm): another test's leftovers would count"
FOXGLOVE_CLIENT = ROOT / "tests" / "foxglove_client"  # Foxglove's libraries, pinned (npm ci)


def finished(proc: subprocess.Popen, timeout: float) -> tuple[str, str]:
    """The whole output (stdout, stderr) of a process the test started, once it has ended, also
    printed: pytest shows it when the test fails. A process that has not ended in `timeout` s
    first writes every thread's stack, and so do the processes it started (SIGUSR1, see
    camo_core.shutdown), then all are killed and the test fails with the lot."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        family = [proc.pid, *(child.pid for child in psutil.Process(proc.pid).children(True))]
        for how in (signal.SIGUSR1, signal.SIGKILL):
            for pid in family:
                try:
                    os.kill(pid, how)
                except ProcessLookupError:
                    pass
            time.sleep(1.0)  # the stacks are written
        out, err = proc.communicate()
        show(proc, out, err)
        raise AssertionError(
            f"{' '.join(map(str, proc.args))[:200]} did not end in {timeout:g} s: the stacks of "
            "its processes are in its output (captured stdout)"
        ) from None
    show(proc, out, err)
    return out, err


def show(proc: subprocess.Popen, out: str | None, err: str | None) -> None:
    """A process's whole output, into the test's captured stdout."""
    print(f"==== {' '.join(map(str, proc.args))} (exit code {proc.returncode})")
    text = [x.decode(errors="replace") if isinstance(x, bytes) else x or "" for x in (out, err)]
    print(f"---- stdout\n{text[0]}---- stderr\n{text[1]}", flush=True)


def run_whole(argv: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess:
    """subprocess.run(argv, capture_output=True, text=True), its output kept whole (`finished`)."""
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, **kwargs
    )
    out, err = finished(proc, timeout)
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


_subprocess_run = subprocess.run


def run_keeping_output(args, *, capture_output=False, timeout=None, check=False, **kwargs):
    """subprocess.run as the tests use it (conftest puts it in its place): a process whose
    output is captured, with a timeout, goes through `finished`, so that its whole output is
    shown if the test fails, and its stacks if it does not end in time."""
    if not capture_output or timeout is None or "input" in kwargs:
        return _subprocess_run(
            args, capture_output=capture_output, timeout=timeout, check=check, **kwargs
        )
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)
    out, err = finished(proc, timeout)
    done = subprocess.CompletedProcess(args, proc.returncode, out, err)
    if check:
        done.check_returncode()
    return done


def run_camo(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the camo command line (already set up: we are inside ./camo test), as `python -m
    camo_core.cli` in a child of a warm process (tests/warm_cli.py) where it can."""
    forked = warm_cli.run(list(args), ROOT)
    if forked is None:
        return run_whole([sys.executable, "-m", "camo_core.cli", *args], timeout)
    out, err = finished(forked, timeout)  # type: ignore[arg-type] - what it uses of a Popen
    return subprocess.CompletedProcess(forked.args, forked.returncode, out, err)


def sweep(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `./camo sweep` (as the camo script does, inside ./camo test)."""
    return run_whole([sys.executable, "-m", "camo_sweep.cli", *args], timeout)


def sweep_table(folder) -> list[dict]:
    """A sweep table's rows by trial id, without the run times (the one column that may
    differ between two runs of one sweep)."""
    from camo_sweep.table import read

    rows = read(folder).to_pylist()
    for row in rows:
        row.pop("run_s")
    return sorted(rows, key=lambda r: r["trial_id"])


_next_domain = [0]


def xdist_worker() -> tuple[int, int]:
    """(this test process's number, how many there are): pytest-xdist's worker gwN of M, or
    (0, 1) in a session without workers."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return (int(name[2:]) if name.startswith("gw") else 0), max(count, 1)


def domains() -> range:
    """This test process's share of the ROS domains 1..200: each pytest-xdist worker a slice of
    its own, so that two workers of a session never run in one domain."""
    worker, count = xdist_worker()
    size = max(200 // count, 1)
    first = 1 + (worker * size) % 200
    return range(first, min(first + size, 201))


def domain() -> int:
    """A ROS domain of its own for each run, so parallel test processes do not hear each other:
    the next of this process's share (`domains`), from a place its pid picks (other sessions
    running at the same time start elsewhere)."""
    _next_domain[0] += 1
    share = domains()
    return share[(os.getpid() * 7 + _next_domain[0]) % len(share)]


@contextmanager
def ros_context(domain_id: int | None = None):
    """An rclpy context of the caller's own (in a domain of its own unless given), shut down on
    leaving."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain() if domain_id is None else domain_id)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


def camo_run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """`./camo run` with a domain of its own."""
    argv = [sys.executable, "-m", "camo_bringup.launcher", *args, "--domain-id", str(domain())]
    return run_whole(argv, timeout)


def ros_node(module: str, *ros_args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """A node's console module (`camo_nodes.robot_node`, ...) run with these ROS arguments in a
    domain of its own, where no run is: what it says before it would wait for one."""
    return subprocess.run(
        [sys.executable, "-m", module, "--ros-args", *ros_args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "ROS_DOMAIN_ID": str(domain())},
    )


def start_run(*args: str, domain_id: int | str | None = None) -> subprocess.Popen:
    """`./camo run` in the background, in `domain_id` or a domain of its own; its stdout and
    stderr piped as text (`wait_for_line`, `finished`)."""
    domain_id = domain() if domain_id is None else domain_id
    return subprocess.Popen(
        [sys.executable, "-m", "camo_bringup.launcher", *args, "--domain-id", str(domain_id)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_for_line(proc: subprocess.Popen, text: str, timeout: float = 120.0) -> list[str]:
    """Read a process's stderr up to the first line holding `text`; the lines read so far."""
    seen: list[str] = []
    deadline = time.monotonic() + timeout
    for line in proc.stderr:
        seen.append(line)
        print(line, end="")  # the test's captured stdout, shown if it fails
        if text in line:
            return seen
        assert time.monotonic() < deadline, (
            f"no line with {text!r} in {timeout:g} s:\n{''.join(seen[-30:])}"
        )
    raise AssertionError(f"the process ended before a line with {text!r}:\n{''.join(seen[-30:])}")


SCALAR_FIELDS = (
    "sender_id", "phase", "step", "round", "sensed", "pattern", "state", "alive", "deadlines",
)  # fmt: skip


class StatusListener:
    """The robots' statuses (/swarm/status) heard in one ROS domain, in a context of the test's
    own."""

    def __init__(self, domain_id: int, run: str) -> None:
        self.domain_id = domain_id
        self.run = run
        self.got: list = []

    def __enter__(self) -> StatusListener:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from camo_msgs.msg import StatusArray
        from camo_nodes.topics.names import RunTopics
        from camo_nodes.topics.qos import LATCHED_READER

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.node = rclpy.create_node("status_listener", context=self.context)
        self.node.create_subscription(
            StatusArray, RunTopics(self.run).status, self._take, LATCHED_READER
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        return self

    def _take(self, msg) -> None:
        """Each row of a process's status array, as a report with RobotStatus's fields, and
        `said`: when its process published it (its header stamp, by the wall clock:
        time.time())."""
        from types import SimpleNamespace

        from camo_core.swarm.status_rows import StatusRows

        rows = StatusRows.from_message(msg)
        said = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for k in range(len(rows)):
            self.got.append(
                SimpleNamespace(
                    **{name: getattr(rows, name)[k].item() for name in SCALAR_FIELDS},
                    p=rows.p[k].tolist(),
                    said=said,
                )
            )

    def spin_until(self, done, timeout: float) -> None:
        """Take messages until done() holds or `timeout` seconds pass."""
        deadline = time.monotonic() + timeout
        while not done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.1)

    def final_states(self) -> dict[int, int]:
        """Robot id -> state, of the robots that reported done."""
        return {m.sender_id: m.state for m in self.got if m.phase == 4}

    def __exit__(self, *exc) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def bag_tool(module: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run a camo_bag command line (`cli`, `render`, `replay`, `recorder_node`)."""
    return run_whole([sys.executable, "-m", f"camo_bag.{module}", *args], timeout)


def unpacked(msg, kind: str) -> list[SimpleNamespace]:
    """The robot messages in a decoded columns message of `kind` (`camo_msgs/Votes`, ...; by
    rclpy, mcap_ros2 or rosbags), one per robot: sender_id, step, round, phase and the kind's
    value fields (a value spread over several entries, as a vote's p, as a list)."""
    from camo_nodes.topics.robot_messages import VALUE_COLUMNS

    n = len(msg.sender_id)
    rows = [
        SimpleNamespace(
            sender_id=int(msg.sender_id[k]),
            step=int(msg.step[k]),
            round=int(msg.round[k]),
            phase=msg.phase,
        )
        for k in range(n)
    ]
    for name, _ in VALUE_COLUMNS[kind]:
        column = list(getattr(msg, name))
        width = len(column) // n if n else 0
        for k, row in enumerate(rows):
            setattr(row, name, column[k] if width == 1 else column[k * width : (k + 1) * width])
    return rows


def robot_messages_in(bag, suffix: str) -> list[SimpleNamespace]:
    """Every robot message a bag holds on the topics ending in `suffix` ("/vote"), unpacked from
    their columns."""
    from rclpy.serialization import deserialize_message

    from camo_bag.loader import read_messages, read_summary
    from camo_bag.msgdefs import message_class

    types = {t.name: message_class(t.type) for t in read_summary(bag).topics}
    topics = [name for name in types if name.endswith(suffix)]
    return [
        row
        for m in read_messages(bag, topics)
        for row in unpacked(deserialize_message(m.data, types[m.topic]), m.topic.rsplit("/")[-1])
    ]


def tile_range(topic: str) -> range:
    """The robots of a tile topic /<run>/camo/tile_FIRST_LAST/<part>/<kind>."""
    first, last = re.search(r"/tile_(\d+)_(\d+)/", topic).groups()
    return range(int(first), int(last) + 1)


# One recorded run that several bag tests read (the `recorded` fixture, made once a session and
# read by every pytest-xdist worker: its run id is the session's, not the process's).
BAG_RUN = f"bags_{os.environ.get('PYTEST_XDIST_TESTRUNUID', str(os.getpid()))[:12].lower()}"
BAG_ROWS, BAG_COLS = 5, 6
BAG_STEPS = 10  # droplet consensus steps
BAG_FORMATION = 20  # droplet formation steps
BAG_OPTIONS = [
    "--pattern", "forest", "--profile", "droplet", "--rows", str(BAG_ROWS), "--cols",
    str(BAG_COLS), "--rho-comm", "0.2", "--rho-meas", "0.1", "--seed", "4", "--procs", "2",
    "--run-id", BAG_RUN,
]  # fmt: skip


# ---- the step protocol without ROS ------------------------------------------------------------


class FixedSensor:
    def __init__(self, value: float, rgb: tuple[float, float, float] | None = None) -> None:
        self.value, self.rgb = value, rgb

    def read(self) -> Reading:
        return Reading(self.value, rgb=self.rgb)

    def next_round(self, frame: int) -> None:
        pass

    def ok(self) -> bool:
        return True


class Bus:
    """An in-memory transport that delivers every message in a random order, and keeps every
    report its robots make (`reports`, in the order made)."""

    def __init__(
        self,
        params: CamoParams,
        image_grid: np.ndarray,
        seed: int,
        colour_grid: np.ndarray | None = None,
        shared_link: bool = False,
    ) -> None:
        """`colour_grid`: the robots' colours (rows x cols x 3), besides their greys;
        `shared_link`: the link's draws made for all robots at once, as a process makes them
        for its robots (each robot draws its own otherwise)."""
        self.random = random.Random(seed)
        self.robots = {}
        book = LinkBook(list(range(params.count))) if shared_link else None
        for i in range(params.rows):
            for j in range(params.cols):
                rgb = None if colour_grid is None else tuple(colour_grid[i, j].tolist())
                sensor = FixedSensor(float(image_grid[i, j]), rgb)
                p = StepProtocol(params, i, j, sensor, mailbox=Mailbox(link=book))
                self.robots[p.id] = p
        self.listeners: dict[tuple[int, str], list[StepProtocol]] = {}
        for p in self.robots.values():
            for key in p.listens_to():
                self.listeners.setdefault(key, []).append(p)
        self.pending: list[tuple[StepProtocol, Message]] = []
        self.reports: list = []

    def post(self, out) -> None:
        self.reports.extend(out.reports)
        for message in out.send:
            for p in self.listeners.get((message.sender, message.kind), ()):
                self.pending.append((p, message))

    def run(self) -> None:
        order = list(self.robots.values())
        self.random.shuffle(order)
        for p in order:
            self.post(p.background(0.0))
            self.post(p.start(0.0))
        self.deliver()

    def show(self, image_grid: np.ndarray, frame: int) -> None:
        """Project frame `frame` (its robots' greys): the robots camouflage it, a round more."""
        order = list(self.robots.values())
        self.random.shuffle(order)
        for p in order:
            p.sensor.value = float(image_grid[divmod(p.id, image_grid.shape[1])])
            self.post(p.background(float(frame), frame))
        self.deliver()

    def deliver(self) -> None:
        while self.pending:
            k = self.random.randrange(len(self.pending))
            self.pending[k], self.pending[-1] = self.pending[-1], self.pending[k]
            p, message = self.pending.pop()
            self.post(p.deliver(message, 0.0))


def assert_like_sim(run: Path, sim: Path, attacked: bool = False) -> dict:
    """A run's summary.json says what the simulator's does (but for the time it took), and
    nothing was refused unless the run was `attacked`; the run's summary."""
    ran = json.loads((run / "summary.json").read_text())
    expected = json.loads((sim / "summary.json").read_text())
    for key in expected:
        if key != "elapsed_s":
            assert ran[key] == expected[key], key
    if not attacked:
        assert ran["rejected_messages"] == {"total": 0, "by_reason": {}}
    return ran


def brick_courses(
    height: int = 256, width: int = 256, course: int = 13, seed: int = 1
) -> np.ndarray:
    """Brick courses: dark bricks of random shades between light mortar rows, and noise: a
    texture whose block means differ by a few grey levels only."""
    generator = np.random.default_rng(seed)
    image = np.zeros((height, width))
    for top in range(0, height, course):
        offset = 14 * (top // course % 2)
        for left in range(-29 + offset, width, 29):
            image[top : top + course, max(0, left) : max(0, left + 29)] = generator.uniform(
                90, 140
            )
            image[top : top + course, max(0, left) : max(0, left + 3)] = 170
        image[top : top + 3, :] = 170
    image += generator.normal(0, 12, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


def drawn_direction(states: np.ndarray) -> float:
    """The direction of the stripes a grid of states draws (degrees in [0, 180), as
    --orientation any counts them): across the strongest wave of its 2-D Fourier transform."""
    spectrum = np.abs(np.fft.fft2(states - states.mean()))
    rows, cols = states.shape
    i, j = np.unravel_index(np.argmax(spectrum), spectrum.shape)
    ky, kx = (i if i <= rows // 2 else i - rows), (j if j <= cols // 2 else j - cols)
    return float(-(np.degrees(np.arctan2(ky, kx)) + 90) % 180)


def assert_drivers_agree(params: CamoParams, raw: np.ndarray, fields: tuple[str, ...], what=()):
    """The vectorised simulator and the per-robot driver give the same `fields`, bit for bit;
    the two results (`what` names the case in a failure)."""
    from camo_core.algorithm.perrobot import run_per_robot
    from camo_core.algorithm.simulator import simulate

    fast, slow = simulate(params, raw), run_per_robot(params, raw)
    for field in fields:
        assert np.array_equal(getattr(fast, field), getattr(slow, field)), (*what, field)
    return fast, slow


def png_bytes(
    width: int,
    height: int,
    *,
    depth: int = 8,
    colour: int = 0,
    pixels: tuple[int, int] | None = None,
    filter_byte: int = 0,
    extra: tuple[tuple[bytes, bytes], ...] = (),
) -> bytes:
    """A minimal PNG (signature, IHDR, one IDAT, IEND, every CRC right) whose header says
    `width` x `height`, `depth` bits and colour type `colour`, and whose data holds grey
    8-bit rows of `pixels` (width, height; default the header's), each behind `filter_byte`
    (0, none, is valid; 5 and up are not): a valid container whose fields may lie about what
    it holds. `extra`: (kind, data) chunks between IHDR and IDAT."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    w, h = pixels or (width, height)
    rows = b"".join(
        bytes([filter_byte]) + bytes((7 * (x + y)) % 256 for x in range(w)) for y in range(h)
    )
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + b"".join(chunk(kind, data) for kind, data in extra)
        + chunk(b"IDAT", zlib.compress(rows))
        + chunk(b"IEND", b"")
    )


# ---- every option of a command with bad values (issue 27) ------------------------------------

BAD_VALUES = ("", "1e300", str(10**30), "nan", "-1", "/tmp/" + "p" * 5000)


class Validated(Exception):
    """Raised in place of a command's work: its command line was parsed and checked."""


def validated(*args, **kwargs):
    raise Validated


def value_options(parser) -> list[str]:
    """The option strings of a parser's options that take a value (flags, --help and
    positionals left out), one per option: its long spelling."""
    options = []
    for action in parser._actions:
        if not action.option_strings or action.nargs == 0:
            continue
        options.append(max(action.option_strings, key=len))
    return options


# What a number option must refuse whatever its range: no option of camo takes these.
NOT_A_NUMBER = ("", "nan", "1e300", BAD_VALUES[-1])


def numeric(parser, option: str) -> bool:
    """Whether the parser's `option` takes a number (int, float, seconds, a declared one)."""
    action = parser._option_string_actions[option]
    kind = getattr(action.type, "kind", action.type)
    return kind in (int, float) or getattr(kind, "__name__", "") in ("int", "float", "seconds")


def bad_value_outcomes(main, argv, option: str, capsys, parser=None) -> list[str]:
    """For each BAD_VALUES value of `option`: what is wrong with how `main(argv + [option,
    value])` ended. Fine: exit 2 with one `... error: ...` line on stderr, or reaching its
    work (which the caller patched to raise Validated), except that an option of `parser` that
    takes a number must refuse NOT_A_NUMBER."""
    must_refuse = NOT_A_NUMBER if parser is not None and numeric(parser, option) else ()
    problems = []
    for value in BAD_VALUES:
        try:
            code = main([*argv, option, value])
        except Validated:
            capsys.readouterr()
            if value in must_refuse:
                problems.append(f"{option} {value[:20]!r}: taken as a number")
            continue
        except SystemExit as exc:  # argparse's own exits (a bug here: ours raise UsageError)
            code = exc.code
        except Exception as exc:  # noqa: BLE001 - what the test looks for
            problems.append(f"{option} {value[:20]!r}: {type(exc).__name__}: {exc}"[:300])
            continue
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        if code != 2 or len(lines) != 1 or "error:" not in lines[0] or "Traceback" in err:
            problems.append(f"{option} {value[:20]!r}: exit {code}, stderr {err[:200]!r}")
    return problems


def parser_of_main(main, argv, monkeypatch):
    """The parser a command's main() builds for itself (the last one it parses with: a
    subcommand's), found by running main(argv) up to its work (which the caller patched to
    raise Validated)."""
    from camo_core.cli.options import Parser

    parsers = []
    parse = Parser.parse_known_args

    def spy(self, args=None, namespace=None):
        parsers.append(self)
        return parse(self, args, namespace)

    monkeypatch.setattr(Parser, "parse_known_args", spy)
    try:
        main(argv)
    except Validated:
        pass
    monkeypatch.setattr(Parser, "parse_known_args", parse)
    return parsers[-1]


def bad_values_of_a_ros_tool(module, argv, monkeypatch, capsys) -> tuple[list[str], list[str]]:
    """(its options that take a value, what is wrong with how each BAD_VALUES value of each
    ended) for a ROS tool's main(argv + ...). Only the command line and the network it asks
    for are checked: starting ROS is replaced, and the environment it would set is the test's
    own copy. The caller chdirs to a folder of its own."""
    monkeypatch.setattr(os, "environ", dict(os.environ))
    monkeypatch.setattr(module, "start_ros", validated)
    parser = parser_of_main(module.main, argv, monkeypatch)
    options = value_options(parser)
    problems = [
        p for o in options for p in bad_value_outcomes(module.main, argv, o, capsys, parser)
    ]
    return options, problems


def path_without(tmp_path, *tools: str) -> str:
    """A PATH of every program of /usr/bin and /bin but `tools` (links in one folder)."""
    folder = tmp_path / "bin"
    folder.mkdir()
    for where in ("/usr/bin", "/bin"):
        for entry in os.scandir(where):
            if entry.name not in tools and not os.path.lexists(folder / entry.name):
                (folder / entry.name).symlink_to(entry.path)
    return str(folder)
