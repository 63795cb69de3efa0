"""The bare exchange `camo bench ros` measures the swarm against: the same messages, nothing else.

The same processes, each hosting a contiguous block of robot ids; per block the
same tile topics (edge and core); each process subscribes to the edge topics of
the blocks that hold its robots' neighbours and hands the rest over in memory.
Each step every robot publishes a `camo_msgs/Vote` as a DDS message of its own
(the exchange the swarm's targets are set against), and a process moves on
once every remote vote of that step that its robots need has arrived. No robot
nodes, no protocol, no statuses, no monitor. The swarm packs its messages
(`transport.py`); so the long-run rate is also measured against a *packed*
bare exchange, whose processes publish each step one `camo_msgs/Votes` per
tile topic, packed as the swarm packs them, as the swarm's do at best.

    python -m camo_bringup.bare_exchange SIDE STEPS BLOCK PROCS PACKED BUDGET

is one of its processes (bare_exchange() starts them): it prints its timings as JSON.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from camo_bringup.run_config import split_cells
from camo_core.algorithm.grid import neighbor_ids
from camo_core.algorithm.params import CamoParams
from camo_core.swarm.robot_io import Message
from camo_msgs.msg import Vote, Votes
from camo_nodes.topics.names import RunTopics, tile_name
from camo_nodes.topics.qos import history_qos
from camo_nodes.topics.robot_messages import Columns
from camo_nodes.topics.startup import LEAN_NODE, start_ros
from camo_nodes.transport import edge_of, listener_qos

BARE_RUN = "bench_bare"
PACKED_RUN = "bench_packed"
# s a bare process waits for its peers, set-up to last step, before it gives up; its parent
# waits that and as long again for set-up and exit, then has its stacks written and kills it.
BARE_BUDGET = 300


def bare_worker(
    side: int, steps: int, block: int, procs: int, packed: int = 0, budget: int = BARE_BUDGET
) -> dict:
    """One process of the bare exchange (block `block` of `procs`; `packed`: one Votes per
    topic and step; `budget`: seconds it waits for its peers); its timings."""
    started = time.monotonic()
    params = CamoParams(rows=side, cols=side, consensus_steps=steps)
    blocks = split_cells(list(range(side * side)), procs)
    mine = blocks[block]
    hosted = set(mine)
    first, last = mine[0], mine[-1]
    edge = edge_of(params, hosted, mine)
    needed = {
        n
        for r in mine
        for n in neighbor_ids(*divmod(r, side), side, side)[:8]
        if n is not None and n not in hosted
    }
    topics = RunTopics(PACKED_RUN if packed else BARE_RUN)
    wire = Votes if packed else Vote
    start_ros("camo bench ros", [], signal_handler_options=SignalHandlerOptions.NO)  # same footing
    node = rclpy.create_node(f"bare_{block}", **LEAN_NODE)
    qos = history_qos(len(mine) * (steps + 4))
    name = tile_name(first, last)
    writers = {
        part: node.create_publisher(wire, topics.tile(name, part, "vote"), qos)
        for part in ("edge", "core")
    }
    got: dict[int, int] = {}  # step -> remote votes of it received

    def on_vote(msg: Vote) -> None:
        if msg.sender_id in needed:
            got[msg.step] = got.get(msg.step, 0) + 1

    def on_votes(msg: Votes) -> None:
        for sender, step in zip(msg.sender_id.tolist(), msg.step.tolist(), strict=True):
            if sender in needed:
                got[step] = got.get(step, 0) + 1

    peers = [b for b in blocks if b is not mine and any(n in b for n in needed)]
    for peer in peers:
        topic = topics.tile(tile_name(peer[0], peer[-1]), "edge", "vote")
        node.create_subscription(wire, topic, on_votes if packed else on_vote, listener_qos())
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + budget
    while time.monotonic() < deadline and (
        writers["edge"].get_subscription_count() < len(peers)
        or sum(s.get_publisher_count() for s in node.subscriptions) < len(peers)
    ):
        executor.spin_once(timeout_sec=0.05)
    matched = time.monotonic()
    vote = Vote(p=[0.2, 0.3, 0.5], degree=8)
    parts = {"edge": [r for r in mine if r in edge], "core": [r for r in mine if r not in edge]}
    columns = {part: Columns("vote") for part in parts}
    local = {}
    for step in range(steps):
        vote.step = step
        for part, robots in parts.items():
            for robot in robots:
                local[robot] = step  # the in-memory hand-over to this process's robots
                if packed:
                    columns[part].add(Message("vote", robot, 0, step, ((0.2, 0.3, 0.5), 8)))
                else:
                    vote.sender_id = robot
                    writers[part].publish(vote)
            if packed and robots:
                writers[part].publish(columns[part].take())
        while got.get(step, 0) < len(needed) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    done = time.monotonic()
    linger = time.monotonic() + 2  # serve our history to slower peers a little longer
    while time.monotonic() < linger:
        executor.spin_once(timeout_sec=0.05)
    # Executor first, then the node (as the swarm's hosts do): the EventsExecutor must let go
    # of the node's handles before they are destroyed.
    executor.shutdown()
    executor.remove_node(node)
    node.destroy_node()
    rclpy.shutdown()
    return {"started": started, "matched": matched, "done": done, "complete": done < deadline}


def worker_reports(workers: list[subprocess.Popen], what: str, limit: float) -> list[dict]:
    """The last line of each worker's output, as JSON, once all have ended. A worker that
    fails ends them all at once (its peers would wait for it for their whole budget); one that
    has not ended within `limit` s has its threads' stacks written to stderr (SIGUSR1,
    camo_core.shutdown) and is killed, with the others: either is one line, and no process is
    left behind. (Each says one short line: its pipe never fills while it is polled.)"""
    end = time.monotonic() + limit
    try:
        while None in [w.poll() for w in workers]:  # each polled: its returncode is set
            failed = [k for k, w in enumerate(workers) if w.returncode not in (None, 0)]
            if failed:
                code = workers[failed[0]].returncode
                raise RuntimeError(f"{what}: process {failed[0]} failed (exit code {code})")
            if time.monotonic() > end:
                hung = next(k for k, w in enumerate(workers) if w.returncode is None)
                raise RuntimeError(
                    f"{what}: process {hung} did not end in {limit:g} s (its threads' stacks "
                    "are on stderr)"
                )
            time.sleep(0.05)
        reports = []
        for k, worker in enumerate(workers):
            lines = (worker.communicate()[0] or "").strip().splitlines()
            if worker.returncode != 0 or not lines:
                raise RuntimeError(f"{what}: process {k} failed (exit code {worker.returncode})")
            reports.append(json.loads(lines[-1]))
    except RuntimeError:
        _end_all(workers)
        raise
    return reports


def _end_all(workers: list[subprocess.Popen]) -> None:
    alive = [w for w in workers if w.poll() is None]
    for how in (signal.SIGUSR1, signal.SIGKILL):
        for worker in alive:
            with contextlib.suppress(ProcessLookupError):
                worker.send_signal(how)
        if how == signal.SIGUSR1 and alive:
            time.sleep(1.0)  # the stacks are written
    for worker in workers:
        worker.communicate()


def bare_exchange(
    side: int, steps: int, procs: int, domain: int, packed: bool = False, budget: int = BARE_BUDGET
) -> dict:
    """The bare exchange in `procs` processes: set-up, steps per second, launch to exit
    (`budget`: the seconds each waits for its peers; twice that, and they are ended)."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    launched = time.monotonic()
    command = [sys.executable, "-m", "camo_bringup.bare_exchange", str(side), str(steps)]
    workers = [
        subprocess.Popen(
            [*command, str(k), str(procs), str(int(packed)), str(budget)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        for k in range(min(procs, side * side))
    ]
    what = f"the bare exchange at {side}x{side}"
    reports = worker_reports(workers, what, 2 * budget)
    exited = time.monotonic()
    if not all(r["complete"] for r in reports):
        raise RuntimeError(f"{what} did not finish")
    start = max(r["matched"] for r in reports)
    end = max(r["done"] for r in reports)
    return {
        "setup_s": start - launched,
        "steps_per_s": steps / max(end - start, 1e-9),
        "wall_s": exited - launched,
    }


def main(argv: list[str] | None = None) -> int:
    """One process of the bare exchange, as bare_exchange() starts it (six whole numbers)."""
    print(json.dumps(bare_worker(*map(int, sys.argv[1:] if argv is None else argv))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
