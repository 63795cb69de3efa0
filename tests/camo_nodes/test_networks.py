"""One swarm across two "hosts" (network namespaces joined by a veth pair on their own subnet):
the launcher and half the robots on one, a worker with the other half on the other, found by
multicast or through a discovery server; the result equals the simulator."""

import json
import os
import sys
import time

import pytest
from support import PROCESS, SWARM, assert_like_sim, domain, finished, run_camo
from two_hosts import TwoHosts, lossy_available, netns_available

from camo_core.swarm.keys import new_key_file

OK, WHY = netns_available()
pytestmark = pytest.mark.skipif(not OK, reason=WHY)

ROWS = COLS = 32
OPTIONS = ["--pattern", "leopard", "--rows", str(ROWS), "--cols", str(COLS), "--seed", "6"]
OPTIONS += ["--rho-comm", "0.1", "--rho-meas", "0.05"]


def environment() -> dict[str, str]:
    """UDP only (no shared memory): every byte between the hosts crosses the veth."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTRTPS_"))}
    return {**env, "ROS_DOMAIN_ID": str(domain()), "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}


def discovery_server(net: TwoHosts, env: dict[str, str]) -> str:
    """`./camo discovery-server` on host a; its HOST:PORT once it runs."""
    port = 11811 + os.getpid() % 1000
    server = net.popen(
        "a",
        [sys.executable, "-m", "camo_nodes.discovery_server", "--address", net.addr["a"]]
        + ["--port", str(port)],
        env,
    )
    deadline = time.monotonic() + 30
    while "running" not in server.stdout.readline():
        assert server.poll() is None and time.monotonic() < deadline, server.stderr.read()
    return f"{net.addr['a']}:{port}"


@pytest.mark.slow(SWARM)
@pytest.mark.parametrize("mode", ["multicast", "discovery server"])
def test_a_swarm_split_across_two_hosts_equals_the_simulator(tmp_path, mode):
    half = ROWS * COLS // 2
    env = environment()
    with TwoHosts() as net:
        if mode == "multicast":
            network = ["--network", "subnet"]
        else:
            network = ["--discovery-server", discovery_server(net, env)]
        before = net.traffic("a")
        key = ["--key-file", str(new_key_file(tmp_path / "split.key").path)]  # on both hosts
        launcher = net.popen(
            "a",
            [sys.executable, "-m", "camo_bringup.launcher", *OPTIONS, "--procs", "1"]
            + ["--remote-cells", f"{half}-{ROWS * COLS - 1}", "--run-id", "split"]
            + ["--out", str(tmp_path / "run"), *network, *key],
            env,
        )
        worker = net.popen(
            "b",
            [sys.executable, "-m", "camo_bringup.worker", "--cells", f"{half}-{ROWS * COLS - 1}"]
            + ["--run-id", "split", *network, *key],
            env,
        )
        _, said = finished(launcher, 240)
        assert launcher.returncode == 0, said[-3000:]
        _, said_there = finished(worker, 60)  # it sees the launcher gone (its stacks if not)
        assert worker.returncode == 0, said_there[-2000:]
        crossed = net.traffic("a") - before
    assert crossed > 100_000, f"only {crossed} bytes crossed between the hosts"
    sim = run_camo("sim", *OPTIONS, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")


def test_the_discovery_server_stops_on_ctrl_c_even_with_sigint_ignored_by_its_starter():
    """A script's background job inherits SIGINT ignored, and an ignored signal stays ignored
    across the exec into the server binary: a Ctrl-C before the server has its own handler was
    lost, and the server ran on."""
    import signal
    import subprocess

    port = 12811 + os.getpid() % 1000
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "camo_nodes.discovery_server",
            "--address",
            "127.0.0.1",
            "--port",
            str(port),
        ],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    try:
        assert "listening on 127.0.0.1" in server.stderr.readline()
        server.send_signal(signal.SIGINT)  # at once: the server binary is still starting
        server.wait(timeout=20)
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()
            pytest.fail("the discovery server ran on after SIGINT")


def split_run(net: TwoHosts, tmp_path, env: dict[str, str], options=OPTIONS) -> tuple:
    """The launcher with half the robots on host a, a worker with the rest on host b."""
    half = ROWS * COLS // 2
    network = ["--network", "subnet"]
    network += ["--key-file", str(new_key_file(tmp_path / "faults.key").path)]  # both hosts
    launcher = net.popen(
        "a",
        [sys.executable, "-m", "camo_bringup.launcher", *options, "--procs", "1"]
        + ["--remote-cells", f"{half}-{ROWS * COLS - 1}", "--run-id", "faults"]
        + ["--out", str(tmp_path / "run"), *network],
        env,
    )
    worker = net.popen(
        "b",
        [sys.executable, "-m", "camo_bringup.worker", "--cells", f"{half}-{ROWS * COLS - 1}"]
        + ["--run-id", "faults", *network],
        env,
    )
    return launcher, worker


def equals_the_simulator(tmp_path, launcher, worker, options=OPTIONS) -> None:
    _, said = finished(launcher, 300)
    assert launcher.returncode == 0, said[-3000:]
    _, said_there = finished(worker, 60)  # it sees the launcher gone (its stacks if not)
    assert worker.returncode == 0, said_there[-2000:]
    assert "Traceback" not in said
    sim = run_camo("sim", *options, "--out", str(tmp_path / "sim"))
    assert sim.returncode == 0, sim.stderr
    assert_like_sim(tmp_path / "run", tmp_path / "sim")
    timing = json.loads((tmp_path / "run" / "timing.json").read_text())
    assert timing["deadlines"] == 0


@pytest.mark.slow(SWARM)
def test_a_partition_of_five_seconds_mid_consensus_leaves_the_result_equal_to_the_simulator(
    tmp_path,
):
    # Consensus long enough (400 steps, seconds) for a progress line, a second apart, to fall
    # in it: with the profile's 35 steps it lasted a third of a second, and the run could end
    # without a line saying consensus (it did, in CI).
    options = [*OPTIONS, "--consensus-steps", "400"]
    with TwoHosts() as net:
        launcher, worker = split_run(net, tmp_path, environment(), options)
        deadline = time.monotonic() + 180
        while "consensus" not in launcher.stderr.readline():  # its progress line
            assert launcher.poll() is None and time.monotonic() < deadline
        net.cut()
        time.sleep(0.5)
        before = net.traffic("a")
        time.sleep(4.5)
        assert net.traffic("a") == before  # nothing crossed
        net.mend()
        assert launcher.poll() is None  # the cut fell within the run
        equals_the_simulator(tmp_path, launcher, worker, options)


LOSSY, WHY_NOT = lossy_available()


@pytest.mark.slow(SWARM)
@pytest.mark.skipif(not LOSSY, reason=WHY_NOT)
def test_a_tenth_of_the_packets_lost_between_hosts_leaves_the_result_equal_to_the_simulator(
    tmp_path,
):
    with TwoHosts() as net:
        for host in "ab":
            net.drop(host, 0.1)
        launcher, worker = split_run(net, tmp_path, environment())
        equals_the_simulator(tmp_path, launcher, worker)
        assert net.dropped("a") + net.dropped("b") > 100


# ---- the environment a run inherits (issue 27) -----------------------------------------------


def _network_args(**given):
    import argparse

    return argparse.Namespace(
        **{"domain_id": None, "network": None, "discovery_server": None, **given}
    )


@pytest.mark.parametrize(
    "name, value, said",
    [
        ("ROS_DOMAIN_ID", "abc", "ROS_DOMAIN_ID must be an integer in 0..232 (got 'abc')"),
        ("ROS_DOMAIN_ID", "-1", "ROS_DOMAIN_ID must be"),
        ("ROS_DOMAIN_ID", "233", "ROS_DOMAIN_ID must be"),
        ("ROS_DOMAIN_ID", "1e300", "ROS_DOMAIN_ID must be"),
        ("ROS_DOMAIN_ID", "7" * 5000, "ROS_DOMAIN_ID must be"),
        ("ROS_DOMAIN_ID", "nan", "ROS_DOMAIN_ID must be"),
        ("ROS_DOMAIN_ID", "\u00b2", "ROS_DOMAIN_ID must be"),
        ("ROS_AUTOMATIC_DISCOVERY_RANGE", "everywhere", "must be one of LOCALHOST, SUBNET"),
        ("ROS_AUTOMATIC_DISCOVERY_RANGE", "\x00", "must be one of"),
        ("ROS_AUTOMATIC_DISCOVERY_RANGE", "off", "OFF: a run's processes could not find each"),
        ("ROS_STATIC_PEERS", ";;;:::garbage", "ROS_STATIC_PEERS: ':::garbage' is not a host"),
        ("ROS_STATIC_PEERS", "a b", "is not a host name or an IP address"),
        ("ROS_STATIC_PEERS", "-host", "is not a host name"),
        ("ROS_STATIC_PEERS", "x" * 300, "is not a host name"),
        ("RMW_IMPLEMENTATION", "rmw_bogus", "RMW_IMPLEMENTATION='rmw_bogus' is not installed"),
        ("RMW_IMPLEMENTATION", "rmw_dds_common", "is not installed"),  # a library, no RMW
        ("RMW_IMPLEMENTATION", " ", "is not installed"),  # rcl takes it for a name too
        ("ROS_DISCOVERY_SERVER", "garbage!!", "'garbage!!' is not HOST or HOST:PORT"),
        ("ROS_DISCOVERY_SERVER", "host:0", "is not HOST or HOST:PORT"),
        ("ROS_DISCOVERY_SERVER", "a:1:2", "is not HOST or HOST:PORT"),
        ("ROS_DISCOVERY_SERVER", "[::1]:99999", "is not HOST or HOST:PORT"),
        ("ROS_SUPER_CLIENT", "perhaps", "ROS_SUPER_CLIENT must be one of TRUE, FALSE"),
        ("ROS_LOCALHOST_ONLY", "2", "ROS_LOCALHOST_ONLY must be one of 0, 1"),
        ("CAMO_ENCRYPT", "yes", "CAMO_ENCRYPT must be one of 0, 1 (got 'yes')"),
        ("CAMO_KEY_FILE", "/nonexistent.key", "key file /nonexistent.key: no such file"),
        ("FASTRTPS_DEFAULT_PROFILES_FILE", "/nonexistent.xml", "is not a file"),
        ("FASTRTPS_DEFAULT_PROFILES_FILE", __file__, "is not XML"),
        ("FASTDDS_DEFAULT_PROFILES_FILE", "/nonexistent.xml", "FASTDDS_DEFAULT_PROFILES_FILE"),
        ("ROS_DISCOVERY_SERVER", ";;;;", "names no server"),
        ("ROS_LOG_DIR", "/dev/null", "ROS_LOG_DIR /dev/null is not a folder"),
        ("ROS_HOME", "/dev/null/x", "ROS_HOME /dev/null/x is not a folder (nor under one)"),
        ("ROS_LOG_DIR", "/proc/1/x", "may not be written"),
    ],
)
def test_a_bad_ros_variable_in_the_environment_is_one_line(name, value, said):
    from camo_core.exceptions import UsageError
    from camo_nodes.topics.startup import network_env

    with pytest.raises(UsageError) as caught:
        network_env(_network_args(), {name: value})
    assert said in str(caught.value) and "\n" not in str(caught.value)
    assert len(str(caught.value)) < 300


def test_good_or_empty_ros_variables_pass_and_options_override_bad_ones():
    from camo_nodes.topics.startup import network_env

    env = network_env(_network_args(), {"ROS_DOMAIN_ID": "", "ROS_AUTOMATIC_DISCOVERY_RANGE": ""})
    assert env["ROS_DOMAIN_ID"] == "" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    env = network_env(
        _network_args(), {"ROS_DOMAIN_ID": "232", "ROS_AUTOMATIC_DISCOVERY_RANGE": "subnet"}
    )
    assert env["ROS_DOMAIN_ID"] == "232" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    env = network_env(
        _network_args(domain_id=3, network="localhost"),
        {"ROS_DOMAIN_ID": "abc", "ROS_AUTOMATIC_DISCOVERY_RANGE": "everywhere"},
    )
    assert env["ROS_DOMAIN_ID"] == "3" and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


@pytest.mark.parametrize("server", ["host:\uff11\uff11", "host:1_1", "host:", "host:0"])
def test_a_discovery_server_port_is_ascii_digits_in_1_to_65535(server):
    from camo_core.exceptions import UsageError
    from camo_nodes.topics.startup import network_env

    with pytest.raises(UsageError, match="--discovery-server takes HOST:PORT"):
        network_env(_network_args(discovery_server=server), {})
    assert network_env(_network_args(discovery_server="localhost:11811"), {})["ROS_SUPER_CLIENT"]


def test_a_discovery_servers_name_is_given_to_fast_dds_as_its_address_once_it_resolves(
    monkeypatch,
):
    # Fast DDS looks a name up once, as a participant starts: in a compose network whose DNS
    # did not serve it yet, that process searched for no server, for good (docker/compose.yaml).
    import socket

    from camo_core.exceptions import UsageError
    from camo_nodes.topics import startup

    def env(server: str) -> str:
        return startup.network_env(_network_args(discovery_server=server), {})[
            "ROS_DISCOVERY_SERVER"
        ]

    assert env("localhost:11811") == "127.0.0.1:11811"
    assert env("10.0.0.5:11811") == "10.0.0.5:11811"
    real, tries = socket.getaddrinfo, []

    def late(host, *args):
        tries.append(host)
        if len(tries) < 3:
            raise socket.gaierror(socket.EAI_AGAIN, "Temporary failure in name resolution")
        return real("localhost", *args)

    monkeypatch.setattr(startup.socket, "getaddrinfo", late)
    monkeypatch.setattr(startup.time, "sleep", lambda s: None)
    assert env("discovery:11811") == "127.0.0.1:11811" and len(tries) == 3
    monkeypatch.setattr(startup.socket, "getaddrinfo", real)
    monkeypatch.setattr(startup, "RESOLVE_WAIT", 0.0)
    with pytest.raises(UsageError) as caught:
        env("no-such-host.invalid:11811")
    said = str(caught.value)
    assert said.startswith("--discovery-server no-such-host.invalid:11811: 'no-such-host.invalid'")
    assert "has no IPv4 address" in said and "\n" not in said


def test_static_peers_of_names_and_addresses_and_an_installed_rmw_pass():
    from camo_nodes.topics.startup import installed_rmws, network_env

    prefix = os.environ["AMENT_PREFIX_PATH"]
    assert "rmw_fastrtps_cpp" in installed_rmws(prefix)
    assert "rmw_implementation" not in installed_rmws(prefix)
    given = {
        "ROS_STATIC_PEERS": "robot-1.local;192.168.0.7;;fe80::1; ",  # empty entries ignored
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "AMENT_PREFIX_PATH": prefix,
    }
    assert network_env(_network_args(), given)["ROS_STATIC_PEERS"] == given["ROS_STATIC_PEERS"]
    network_env(_network_args(), {"RMW_IMPLEMENTATION": "", "ROS_STATIC_PEERS": ""})
    env = network_env(_network_args(network="subnet"), {"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"})
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"  # --network overrides OFF


def test_discovery_servers_switches_and_a_profiles_file_that_fast_dds_reads_pass(tmp_path):
    from camo_nodes.topics.startup import network_env

    profiles = tmp_path / "profiles.xml"
    profiles.write_text('<?xml version="1.0"?><dds><profiles/></dds>')
    given = {
        "ROS_DISCOVERY_SERVER": "127.0.0.1:11811;;server.lab;[fe80::1]:11812",
        "ROS_SUPER_CLIENT": "TRUE",
        "CAMO_ENCRYPT": "1",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(profiles),
    }
    assert (
        network_env(_network_args(), given)["ROS_DISCOVERY_SERVER"]
        == given["ROS_DISCOVERY_SERVER"]
    )
    bad = {"ROS_DISCOVERY_SERVER": "garbage!!"}  # --discovery-server overrides it
    assert network_env(_network_args(discovery_server="127.0.0.1:11811"), bad)[
        "ROS_DISCOVERY_SERVER"
    ]


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize("value", ["rmw_bogus", " ", "rmw_x\nTraceback"])
def test_the_camo_script_refuses_an_rmw_that_is_not_installed_before_rcl_exits_102(value):
    import subprocess
    from pathlib import Path

    script = Path(__file__).resolve().parents[2] / "camo"
    done = subprocess.run(
        [str(script), "worker", "--cells", "0-1", "--wait", "1"],
        capture_output=True,
        text=True,
        env={**os.environ, "RMW_IMPLEMENTATION": value},
        timeout=120,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("camo: error: RMW_IMPLEMENTATION=") and "not installed" in lines[0]


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize("value", ["/nonexistent", "x" * 5000])
def test_a_bad_camo_rcl_lib_is_one_line_and_exit_2(value):
    import subprocess

    env = {**os.environ, "CAMO_RCL_LIB": value}
    done = subprocess.run(
        [sys.executable, "-c", "import camo_nodes.rcl_take"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("camo: error: CAMO_RCL_LIB="), done.stderr
