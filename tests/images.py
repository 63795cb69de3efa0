"""camo's images for the container tests (tests/test_containers.py), built once a session.

Building takes minutes when podman's store lacks a layer (a change to src/): the session's
controller starts it in a thread of its own as the session starts (tests/conftest.py), while
the workers run other tests, and the container tests wait for it. A session that did not start
it (a -k selection, say) builds when a container test first needs the images."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASE = "localhost/camo-debian:bookworm"  # debootstrap's minbase, imported: nothing else
IMAGE = "localhost/camo:test"
BUILD = "localhost/camo-build:test"  # the image's build stage: the README's set-up, done
CONF = ROOT / "tests" / "containers.conf"
# The README's packages that only the tests which build images use: not in the images.
CONTAINER_TOOLS = ("podman", "runc", "netavark", "aardvark-dns", "debootstrap", "podman-compose")
NETAVARK = "/usr/lib/podman/netavark"  # the network backend CONF names (Debian's path)
# The build runs at the lowest priority: it takes the CPU the tests leave (their swarms wait on
# the wall clock, and a test marked alone leaves a core idle), not CPU a timed test needs.
NICE = ["nice", "-n", "19"]
MARKER_ENV = "CAMO_IMAGES_MARKER"  # where the controller's build says how it went


def readme_packages() -> list[str]:
    """The README's apt-get line's packages, but CONTAINER_TOOLS."""
    line = next(x for x in (ROOT / "README.md").read_text().splitlines() if "apt-get install" in x)
    words = line.split()[line.split().index("install") + 1 :]
    return [word for word in words if word[0] != "-" and word not in CONTAINER_TOOLS]


def build() -> str:
    """The base (debootstrap's, once a machine), then camo's image and its build stage, built
    with the README's apt-get line as PACKAGES by `./camo image`: "" once built, else why not."""
    if not shutil.which("podman") or not Path(NETAVARK).exists():
        tools = " ".join(CONTAINER_TOOLS)
        return f"the container tests need podman and its tools: apt-get install {tools}"
    env = {**os.environ, "CONTAINERS_CONF": str(CONF)}
    exists = subprocess.run(["podman", "image", "exists", BASE], env=env, capture_output=True)
    if exists.returncode != 0:
        with tempfile.TemporaryDirectory(prefix="camo-debian-", dir="/var/tmp") as root:
            made = subprocess.run(
                [*NICE, "debootstrap", "--variant=minbase", "bookworm", root],
                capture_output=True,
                text=True,
                timeout=900,
            )
            if made.returncode != 0:
                return "debootstrap failed: " + (made.stdout + made.stderr)[-2000:]
            tar = subprocess.Popen([*NICE, "tar", "-C", root, "-c", "."], stdout=subprocess.PIPE)
            imported = subprocess.run(
                [*NICE, "podman", "import", "-", BASE],
                stdin=tar.stdout,
                capture_output=True,
                env=env,
            )
            if tar.wait() != 0 or imported.returncode != 0:
                return "podman import failed: " + imported.stderr.decode()[-2000:]
    packages = f"PACKAGES={' '.join(readme_packages())}"
    for target, tag in (("build", BUILD), (None, IMAGE)):
        argv = [*NICE, str(ROOT / "camo"), "image", "--build-arg", f"BASE={BASE}"]
        argv += ["--build-arg", packages, "-t", tag, *(["--target", target] if target else [])]
        built = subprocess.run(
            argv,
            capture_output=True,
            text=True,
            timeout=1800,
            env={**env, "CAMO_ENGINE": "podman"},
        )
        if built.returncode != 0:
            return f"./camo image --target {target}: " + (built.stdout + built.stderr)[-3000:]
    return ""


def start_in_background(folder: Path) -> None:
    """Build in a thread of this process (the session's controller); the marker file, named
    in the environment the workers inherit, says how it went once it is done."""
    marker = folder / f"camo-images-{os.getpid()}"
    marker.unlink(missing_ok=True)
    os.environ[MARKER_ENV] = str(marker)

    def run() -> None:
        try:
            said = build()
        except Exception as exc:  # noqa: BLE001 - whatever failed, the tests say it
            said = f"{type(exc).__name__}: {exc}"
        done = marker.with_suffix(".tmp")
        done.write_text(said or "built")
        done.rename(marker)

    threading.Thread(target=run, name="camo-images", daemon=True).start()


def wait_for_images(timeout: float = 2400.0) -> str:
    """ "" once the images are built (by the controller's thread, or here), else why not."""
    marker = os.environ.get(MARKER_ENV)
    if not marker:
        return build()
    deadline = time.monotonic() + timeout
    while not Path(marker).exists():
        if time.monotonic() > deadline:
            return f"the images were not built within {timeout:g} s"
        time.sleep(1.0)
    said = Path(marker).read_text()
    return "" if said == "built" else said
