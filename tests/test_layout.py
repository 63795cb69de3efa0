"""The shape of the code: packages meet only where they should, the core needs no ROS, every
console script answers --help, modules stay small, and ruff is clean."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support import ROOT

SRC = ROOT / "src"
PACKAGES = (
    "camo_core",
    "camo_msgs",
    "camo_nodes",
    "camo_bag",
    "camo_droplet",
    "camo_projector",
    "camo_sweep",
)
# What each package may import of the others. Concerns meet through camo_core, camo_msgs and the
# topic module; a Droplet bridge is a robot node with the Droplet's sensor and LED, so it also
# composes camo_nodes.robot_node. Nothing imports a package that imports it back.
ALLOWED = {
    "camo_core": {"camo_core"},
    "camo_nodes": {"camo_core", "camo_msgs", "camo_nodes"},
    "camo_projector": {"camo_core", "camo_msgs", "camo_nodes.topics", "camo_projector"},
    # Sweeps run the simulator here and a swarm trial as a `./camo run` process: no ROS import.
    "camo_sweep": {"camo_core", "camo_sweep"},
    "camo_bag": {"camo_core", "camo_msgs", "camo_nodes.topics", "camo_bag"},
    "camo_droplet": {
        "camo_core",
        "camo_msgs",
        "camo_nodes.topics",
        "camo_nodes.robot_node",
        "camo_droplet",
    },
}

BLOCK_ROS = """
import importlib.abc, sys
ROS = ('rclpy', 'rosidl_runtime_py', 'camo_msgs', 'std_msgs', 'sensor_msgs', 'camo_nodes')
class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ROS:
            raise ImportError('ROS is blocked in this test: ' + name)
sys.meta_path.insert(0, NoRos())
import pkgutil, importlib, camo_core
names = [m.name for m in pkgutil.walk_packages(camo_core.__path__, 'camo_core.')]
for name in names:
    importlib.import_module(name)
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.simulator import simulate
from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.sensing import sense_image
result = simulate(CamoParams(), sense_image(background('forest'), 8, 8, 'paper'))
assert 'rclpy' not in sys.modules
print(len(names), result.majority_pattern)
"""


def modules(package: str) -> list[Path]:
    return sorted((SRC / package / package).glob("*.py"))


def first_party_imports(path: Path) -> set[str]:
    """Dotted names of the project's modules that a file imports (relative imports resolved)."""
    package = path.parent.name
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = f"{package}.{base}" if base else package
            found |= {base} | {f"{base}.{alias.name}" for alias in node.names}
    return {name for name in found if name.split(".")[0] in PACKAGES}


def allowed(name: str, rules: set[str]) -> bool:
    return any(name == rule or name.startswith(rule + ".") for rule in rules)


def test_camo_core_imports_and_runs_with_ros_blocked():
    out = subprocess.run(
        [sys.executable, "-c", BLOCK_ROS], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    count, pattern = out.stdout.split()
    assert int(count) >= 10 and pattern == "vertical"


def test_the_step_protocol_loads_no_rclpy():
    code = "import sys, camo_core.algorithm.protocol; print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False", out.stderr


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_packages_meet_only_through_core_messages_and_the_topic_module(package):
    wrong = {
        f"{path.name} imports {name}"
        for path in modules(package)
        for name in first_party_imports(path)
        if not allowed(name, ALLOWED[package])
        # `from camo_nodes.topics import X` also names camo_nodes.topics.X: the module is checked
        and not allowed(name.rsplit(".", 1)[0], ALLOWED[package])
    }
    assert not wrong, sorted(wrong)


def test_no_package_imports_one_that_imports_it_back():
    uses = {
        package: {
            name.split(".")[0] for path in modules(package) for name in first_party_imports(path)
        }
        - {package}
        for package in ALLOWED
    }
    cycles = [(a, b) for a in uses for b in uses[a] if a in uses.get(b, set())]
    assert not cycles


def test_no_module_is_over_400_lines():
    long = {
        str(path.relative_to(SRC)): n
        for path in SRC.rglob("*.py")
        if (n := len(path.read_text().splitlines())) > 400
    }
    assert not long


def console_scripts() -> list[tuple[str, str]]:
    """(package, script name) of every console script the packages declare."""
    scripts = []
    for setup in sorted(SRC.glob("*/setup.py")):
        for name, _target in re.findall(r'"(\w+) = ([\w.]+:\w+)"', setup.read_text()):
            scripts.append((setup.parent.name, name))
    return scripts


@pytest.mark.parametrize("package, script", console_scripts())
def test_every_console_script_answers_help(package, script):
    path = ROOT / "ros2_ws" / "install" / package / "lib" / package / script
    assert path.is_file(), f"{script} is not installed where ros2 run looks ({path})"
    out = subprocess.run([str(path), "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-1500:]
    assert "usage" in out.stdout.lower() and "Traceback" not in out.stderr


def test_ruff_lint_and_format_are_clean():
    ruff = [sys.executable, "-m", "ruff"]
    lint = subprocess.run(
        [*ruff, "check", "src", "tests"], capture_output=True, text=True, cwd=ROOT
    )
    assert lint.returncode == 0, lint.stdout[-3000:]
    form = subprocess.run(
        [*ruff, "format", "--check", "src", "tests"], capture_output=True, text=True, cwd=ROOT
    )
    assert form.returncode == 0, form.stdout[-3000:]


def test_no_text_cites_a_document_that_is_not_in_the_repository():
    """The algorithm is docs/algorithm.md; nothing refers to the spec it was written from."""
    tracked = subprocess.run(
        ["git", "ls-files"], capture_output=True, text=True, cwd=ROOT, check=True
    ).stdout.split()
    citing = [
        name
        for name in tracked
        if name.endswith((".py", ".md", ".txt", ".yaml", ".xml", ".toml"))
        and re.search(r"\bSPEC\b", (ROOT / name).read_text(errors="replace"))
    ]
    assert citing == []
    assert (ROOT / "docs" / "algorithm.md").exists()
