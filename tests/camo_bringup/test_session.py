"""The launcher's session: when a tile of the run's own processes counts as taken by another."""

import logging
import time
from types import SimpleNamespace

import pytest

from camo_bringup.failures import EXIT_CONFLICT, RunFailed
from camo_bringup.session import Session
from camo_msgs.msg import Host
from camo_nodes.host import host_node_name
from camo_nodes.trust import OWN_TILES_CLAIMED, Hosts, Rejections

OURS, STRANGER = bytes([1] * 12) + bytes(4), bytes([2] * 12) + bytes(4)


def session(hosts: Hosts, timeout: float = 0.3) -> SimpleNamespace:
    """What check_hosts uses of a Session: its monitor's hosts, graph, spin and setup."""
    fake = SimpleNamespace(
        monitor=SimpleNamespace(trusted=hosts),
        node=SimpleNamespace(count_publishers=lambda topic: len(hosts.names)),
        topics=SimpleNamespace(run="lab", hosts="/lab/camo/hosts"),
        setup=SimpleNamespace(tiles=((0, 3), (4, 8)), discovery_timeout=timeout),
        started=time.monotonic(),
        spin=lambda seconds: time.sleep(seconds),
    )
    fake._hear_claimant = lambda conflict: Session._hear_claimant(fake, conflict)
    return fake


def announce(hosts: Hosts, gid: bytes, name: str, tiles, refused: dict | None = None) -> None:
    msg = Host(name=name, first=[a for a, _ in tiles], last=[b for _, b in tiles])
    msg.rejected_reasons = list(refused or {})
    msg.rejected_counts = list((refused or {}).values())
    hosts.learn(msg, gid)


def test_a_run_process_saying_another_announced_its_tiles_ends_the_run_unheard_here():
    """The worker heard the stranger, the launcher not (yet): the run ends all the same, once
    the launcher has waited its discovery timeout to say who it was."""
    hosts = Hosts(9, Rejections(logging.getLogger("test")))
    worker = host_node_name(4242)
    announce(hosts, OURS, worker, [(0, 3), (4, 8)])
    Session.check_hosts(session(hosts), [4242], final=True)  # nothing said: the run goes on
    announce(hosts, OURS, worker, [(0, 3), (4, 8)], {OWN_TILES_CLAIMED: 1})
    with pytest.raises(RunFailed) as failed:
        Session.check_hosts(session(hosts), [4242])
    assert failed.value.code == EXIT_CONFLICT
    assert f"cells of {worker}" in str(failed.value) and "not here" in str(failed.value)


def test_the_claimant_heard_while_waiting_is_named():
    hosts = Hosts(9, Rejections(logging.getLogger("test")))
    worker = host_node_name(4242)
    announce(hosts, OURS, worker, [(0, 3), (4, 8)], {OWN_TILES_CLAIMED: 1})
    fake = session(hosts, timeout=30.0)
    fake.spin = lambda seconds: announce(hosts, STRANGER, "stranger", [(4, 8)])
    with pytest.raises(RunFailed, match=r"cells 4-8 were .*node stranger, GUID prefix 0202"):
        Session.check_hosts(fake, [4242])
