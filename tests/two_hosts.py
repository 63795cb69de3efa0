"""Two "hosts" on this machine for tests of what crosses a network: two network namespaces joined
by a veth pair on a subnet of their own, with a multicast route, as root. Everything made here is
removed on leaving, processes inside the namespaces first (`ip netns del` only drops the name of
a namespace that still has processes)."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
import uuid


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check)


def netns_available() -> tuple[bool, str]:
    """(True, "") where namespaces and a veth can be made here, else (False, why in a line)."""
    if sys.platform != "linux" or shutil.which("ip") is None:
        return False, "needs Linux and iproute2's ip"
    if os.geteuid() != 0:
        return False, "ip netns needs root"
    tag = uuid.uuid4().hex[:8]
    ns = f"camo_chk_{tag}"
    try:
        made = ip("netns", "add", ns, check=False)
        if made.returncode:
            return False, "ip netns add is not permitted: " + made.stderr.strip()[-120:]
        veth = ip("link", "add", f"cck{tag}", "netns", ns, "type", "veth", "peer", "name",
                  f"ccp{tag}", "netns", ns, check=False)  # fmt: skip
        if veth.returncode:
            return False, "a veth pair is not permitted: " + veth.stderr.strip()[-120:]
        return True, ""
    finally:
        ip("netns", "del", ns, check=False)


def lossy_available() -> tuple[bool, str]:
    """(True, "") where packets can be dropped at random between the hosts, else why not."""
    ok, why = netns_available()
    if not ok:
        return ok, why
    if shutil.which("iptables") is None:
        return False, "needs iptables to drop packets (this kernel has no tc netem)"
    ns = f"camo_chk_{uuid.uuid4().hex[:8]}"
    try:
        ip("netns", "add", ns)
        rule = ["-A", "INPUT", "-m", "statistic", "--mode", "random", "--probability", "0.1"]
        tried = subprocess.run(
            ["ip", "netns", "exec", ns, "iptables", *rule, "-j", "DROP"],
            capture_output=True, text=True,
        )  # fmt: skip
        if tried.returncode:
            return False, "iptables cannot drop at random here: " + tried.stderr.strip()[-120:]
        return True, ""
    finally:
        ip("netns", "del", ns, check=False)


class TwoHosts:
    """Namespaces a and b; veth addresses <subnet>.1 (a) and <subnet>.2 (b)."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:8]  # interface names stay within 15 characters
        subnet = f"10.{random.randint(200, 250)}.{random.randint(1, 250)}"
        self.ns = {"a": f"camo_a_{tag}", "b": f"camo_b_{tag}"}
        self.dev = {"a": f"cva_{tag}", "b": f"cvb_{tag}"}
        self.addr = {"a": f"{subnet}.1", "b": f"{subnet}.2"}
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> TwoHosts:
        try:
            for host in "ab":
                ip("netns", "add", self.ns[host])
            ip("link", "add", self.dev["a"], "netns", self.ns["a"], "type", "veth",
               "peer", "name", self.dev["b"], "netns", self.ns["b"])  # fmt: skip
            for host in "ab":
                ns, dev = self.ns[host], self.dev[host]
                ip("-n", ns, "link", "set", "lo", "up")
                ip("-n", ns, "addr", "add", f"{self.addr[host]}/24", "dev", dev)
                ip("-n", ns, "link", "set", dev, "multicast", "on")
                ip("-n", ns, "link", "set", dev, "up")
                ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def popen(self, host: str, argv: list[str], env: dict[str, str]) -> subprocess.Popen:
        """A process in a host (`ip netns exec` execs it: its pid is the program's)."""
        proc = subprocess.Popen(
            ["ip", "netns", "exec", self.ns[host], *argv],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.procs.append(proc)
        return proc

    def cut(self) -> None:
        """Partition the hosts: the veth goes down (the kernel drops its routes)."""
        ip("-n", self.ns["a"], "link", "set", self.dev["a"], "down")

    def mend(self) -> None:
        """Join them again, with the multicast routes the cut took away."""
        ip("-n", self.ns["a"], "link", "set", self.dev["a"], "up")
        for host in "ab":
            ip("-n", self.ns[host], "route", "replace", "224.0.0.0/4", "dev", self.dev[host])

    def drop(self, host: str, probability: float) -> None:
        """Drop that share of the packets arriving at a host, at random (iptables' statistic
        match: this kernel has no netem; `lossy_available` says whether it works here)."""
        subprocess.run(
            ["ip", "netns", "exec", self.ns[host], "iptables", "-A", "INPUT", "-i",
             self.dev[host], "-m", "statistic", "--mode", "random", "--probability",
             str(probability), "-j", "DROP"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip

    def dropped(self, host: str) -> int:
        """Packets dropped at a host so far by `drop`."""
        out = subprocess.run(
            ["ip", "netns", "exec", self.ns[host], "iptables", "-L", "INPUT", "-v", "-n", "-x"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        rows = [line.split() for line in out.stdout.splitlines() if "DROP" in line]
        return sum(int(row[0]) for row in rows)

    def traffic(self, host: str = "a") -> int:
        """Bytes sent and received on a host's veth so far: proof that data crossed the net."""
        stats = f"/sys/class/net/{self.dev[host]}/statistics"
        out = subprocess.run(
            [
                "ip",
                "netns",
                "exec",
                self.ns[host],
                "cat",
                f"{stats}/tx_bytes",
                f"{stats}/rx_bytes",
            ],
            capture_output=True,
            text=True,
            check=True,
        )
        return sum(int(x) for x in out.stdout.split())

    def close(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 5
        for proc in self.procs:
            try:
                proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for host in "ab":
            for pid in ip("netns", "pids", self.ns[host], check=False).stdout.split():
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except (ProcessLookupError, ValueError):
                    pass
            ip("netns", "del", self.ns[host], check=False)  # the veth pair goes with it
