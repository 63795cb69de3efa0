"""`./camo discovery-server [--port P] [--address A]`: the Fast DDS discovery server of the wheels.

Where multicast does not cross the network (clouds, many university LANs), DDS
participants can find each other through a server instead: start it on one
machine, then give every `./camo run`, `worker`, `record` and robot
`--discovery-server HOST:PORT`. Runs are then isolated by server (and by run
id), not by domain id. The server binary ships in the ROS wheels but needs
their library folders on LD_LIBRARY_PATH; this command sets them and becomes
the server (Ctrl-C stops it).
"""

from __future__ import annotations

import ipaddress
import os
import signal
import sys
from pathlib import Path

import rclpy

from camo_core.cli.options import Parser
from camo_core.exceptions import CamoError, UsageError

SERVER = "fast-discovery-server"


def server_command(address: str, port: int, server_id: int) -> tuple[str, list[str], dict]:
    """The executable, its argv and its environment."""
    binary = Path(sys.executable).parent / SERVER
    if not binary.is_file():
        raise CamoError(f"{SERVER} is not installed next to {sys.executable}")
    lib = Path(rclpy.__file__).resolve().parents[3]  # <venv>/lib
    site = Path(rclpy.__file__).resolve().parents[1]  # the wheels' site-packages
    folders = [str(lib), *map(str, sorted(site.glob("ros_fastrtps*.libs")))]
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = ":".join([*folders, env.get("LD_LIBRARY_PATH", "")]).rstrip(":")
    argv = [SERVER, "-i", str(server_id), "-l", address, "-p", str(port)]
    return str(binary), argv, env


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="camo discovery-server", description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=11811, help="UDP port (default 11811)")
    parser.add_argument(
        "--address",
        default="0.0.0.0",
        help="address to listen on (default 0.0.0.0: every interface)",
    )
    parser.add_argument("--server-id", type=int, default=0, help="server id 0..255 (default 0)")
    try:
        args = parser.parse_args(argv)
        if not 0 < args.port < 65536 or not 0 <= args.server_id <= 255:
            raise UsageError("--port must be in 1..65535 and --server-id in 0..255")
        try:
            ipaddress.ip_address(args.address)
        except ValueError:
            raise UsageError(f"--address takes an IPv4 address (got {args.address!r})") from None
        binary, command, env = server_command(args.address, args.port, args.server_id)
    except CamoError as exc:
        print(f"camo discovery-server: error: {exc}", file=sys.stderr)
        return 2
    # Ctrl-C must stop the server even before it has its own handler (it execs below, and an
    # ignored SIGINT, inherited from a script that started us in the background, would stay
    # ignored across the exec: a Ctrl-C in that moment would be lost).
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    print(
        f"camo discovery-server: listening on {args.address}:{args.port}; give clients "
        f"--discovery-server HOST:{args.port} (Ctrl-C to stop)",
        file=sys.stderr,
        flush=True,
    )
    os.execve(binary, command, env)  # the server itself: signals reach it, nothing is left over
    return 0


if __name__ == "__main__":
    sys.exit(main())
