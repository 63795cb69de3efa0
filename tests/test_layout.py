"""The shape of the code: packages meet only where they should, the core needs no ROS and is
layered by job, each parameter is declared once, every console script answers --help, and ruff
(with its complexity rules) and mypy are clean."""

import ast
import re
import shutil
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
    "camo_bringup",
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
    # The bring-up composes the swarm with the recorder, the projector and the bridges.
    "camo_bringup": {
        "camo_core",
        "camo_msgs",
        "camo_nodes",
        "camo_bag",
        "camo_projector",
        "camo_droplet",
        "camo_bringup",
    },
}
# camo_core's jobs, each using only those below it: the command-line layer, results (summary
# files, figures, animation), the swarm runtime (the step protocol and what it exchanges), the
# algorithm (the rules, their modes and the two simulator drivers), outside input's loaders.
CORE_LAYERS = (
    "camo_core.cli",
    "camo_core.results",
    "camo_core.swarm",
    "camo_core.algorithm",
    "camo_core.inputs",
)

BLOCK_ROS = """
import importlib.abc, sys
ROS = ('rclpy', 'rosidl_runtime_py', 'camo_msgs', 'std_msgs', 'sensor_msgs', 'camo_nodes')
class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ROS:
            raise ImportError('ROS is blocked in this test: ' + name)
sys.meta_path.insert(0, NoRos())
import pkgutil, importlib, camo_core
names = [m.name for m in pkgutil.walk_packages(camo_core.__path__, 'camo_core.')
         if not m.name.endswith('__main__')]
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
    return sorted((SRC / package / package).rglob("*.py"))


def first_party_imports(path: Path) -> set[str]:
    """Dotted names of the project's modules that a file imports (relative imports resolved)."""
    package = ".".join(path.relative_to(SRC).parts[1:-1])
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
    code = "import sys, camo_core.swarm.protocol; print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False", out.stderr


def test_the_sweep_and_sim_command_lines_load_neither_numba_nor_dask_before_they_need_them():
    """numba's start (0.5 s of CPU) is paid where a grid is simulated: not by a sweep's own
    process (its workers simulate), nor by a command refused for its input; Dask's import
    (0.25 s) where a Dask cluster is used."""
    code = "import sys, camo_sweep.cli, camo_core.cli.commands\n"
    code += "print([m for m in ('numba', 'dask', 'distributed') if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stderr


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


def test_no_module_imports_one_that_imports_it_back_deferred_imports_included():
    """No circle of modules, even through an import inside a function (which works, but ties
    the two modules into one: neither reads, tests or changes alone)."""
    paths = {}
    for package in ALLOWED:
        for path in modules(package):
            parts = path.relative_to(SRC / package).with_suffix("").parts
            paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    imports = {
        module: {name for name in first_party_imports(path) if name in paths} - {module}
        for module, path in paths.items()
    }
    circles = []
    for start in imports:  # from each module, what its imports lead to: itself is a circle
        seen, todo = set(), list(imports[start])
        while todo:
            module = todo.pop()
            if module == start:
                circles.append(start)
                break
            if module not in seen:
                seen.add(module)
                todo.extend(imports[module])
    assert not circles, sorted(circles)


def test_camo_core_is_layered_by_job():
    wrong = set()
    for path in modules("camo_core"):
        module = ".".join(path.relative_to(SRC / "camo_core").with_suffix("").parts)
        layer = next((k for k, name in enumerate(CORE_LAYERS) if module.startswith(name)), None)
        if layer is None:
            continue  # exceptions, shutdown, schema: shared by every layer
        above = CORE_LAYERS[:layer]
        wrong |= {f"{module} imports {n}" for n in first_party_imports(path) if allowed(n, above)}
    assert not wrong, sorted(wrong)


def code_strings(path: Path) -> list[str]:
    """The string constants of a module's code, its docstrings and `__slots__` (attribute
    names) left out."""
    tree = ast.parse(path.read_text())
    docs = {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
    }
    docs |= {
        id(constant)
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "__slots__" for t in node.targets)
        for constant in ast.walk(node.value)
    }
    return [
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
    ]


def test_no_argparse_or_ros_environment_in_camo_core_outside_its_command_line_layer():
    cli = SRC / "camo_core" / "camo_core" / "cli"
    wrong = set()
    for path in modules("camo_core"):
        if cli in path.parents:
            continue
        if "argparse" in {n.split(".")[0] for n in imported_names(path)}:
            wrong.add(f"{path.name} imports argparse")
        ros = [s for s in code_strings(path) if re.match(r"(ROS|RMW|FASTRTPS|FASTDDS)_", s)]
        wrong |= {f"{path.name} names {s}" for s in ros}
        if "os.environ" in path.read_text():
            wrong.add(f"{path.name} reads the environment")
    assert not wrong, sorted(wrong)


def imported_names(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level:
            found.add(node.module or "")
    return found


MODULE_BY_NAME = re.compile(r"^(camo_[a-z]+)\.[a-z_.]+$")


def modules_started_by_name(package: str) -> set[str]:
    """Other packages' modules a package names in its code (to start them, `python -m ...`)."""
    return {
        s
        for path in modules(package)
        for s in code_strings(path)
        if (m := MODULE_BY_NAME.match(s)) and m.group(1) in PACKAGES and m.group(1) != package
    }


def test_the_node_library_starts_no_other_packages_module_by_name():
    assert modules_started_by_name("camo_nodes") == set()


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_package_that_starts_another_packages_module_declares_it_in_package_xml(package):
    xml = (SRC / package / "package.xml").read_text()
    declared = set(re.findall(r"<exec_depend>(camo_\w+)</exec_depend>", xml))
    used = {name.split(".")[0] for name in modules_started_by_name(package)}
    imported = {
        name.split(".")[0] for path in modules(package) for name in first_party_imports(path)
    } - {package}
    assert used | imported <= declared, sorted((used | imported) - declared)


# Words that name something else as well: a sweep's root seed and the Droplet emulator's fault
# seed are seeds of their own.
# The bag ledger names the colour messages' topics "colours".
OTHER_MEANINGS = {"seed": {"camo_sweep", "camo_droplet"}, "colours": {"camo_bag"}}


def test_each_parameter_is_spelled_in_at_most_two_modules():
    """A run's parameter is declared once (camo_core.schema); what needs it by name derives it
    from the declaration. Spelled as a key (`"rho_comm"`), an option (`"--rho-comm"`) or a ROS
    argument (`"rho_comm:=..."`), a name may stand in its declaration and one more module."""
    from camo_core.algorithm.params import CamoParams
    from camo_core.schema import declared
    from camo_core.swarm.run_setup import ProtocolParams

    exempt = re.compile(r"(bench\w*|soak)\.py$|camo_sweep/errors\.py$")  # benches, presets
    names = [*declared(CamoParams), *declared(ProtocolParams)]
    spelled: dict[str, set[str]] = {name: set() for name in names}
    for path in sorted(SRC.rglob("*.py")):
        if exempt.search(str(path)):
            continue
        texts = code_strings(path)
        package = path.relative_to(SRC).parts[0]
        for name in names:
            if package in OTHER_MEANINGS.get(name, ()):
                continue
            forms = (name, "--" + name.replace("_", "-"))
            if any(s in forms or s.startswith(name + ":=") for s in texts):
                spelled[name].add(str(path.relative_to(SRC)))
    assert {n: m for n, m in spelled.items() if len(m) > 2} == {}


# The flags that choose a variation of the algorithm (camo_core.algorithm.modes.modes_of).
MODE_FLAGS = (
    "colours",
    "levels",
    "layout",
    "orientation",
    "orientation_any",
    "threshold_auto",
    "scope",
)
# Where a flag may be read freely: its declaration, the mode objects that it chooses, and the
# command line, which reads options as the user gave them.
MODE_HOMES = re.compile(r"camo_core/algorithm/(modes/|params\.py)|camo_core/cli/|run_config\.py")


def test_each_mode_flag_is_read_in_at_most_two_modules_besides_its_objects():
    """A variation of the algorithm is one object chosen once (modes.modes_of); the drivers,
    results, figures and nodes ask that object, not the flag that chose it."""
    readers: dict[str, set[str]] = {flag: set() for flag in MODE_FLAGS}
    for path in sorted(SRC.rglob("*.py")):
        where = str(path.relative_to(SRC))
        if MODE_HOMES.search(where):
            continue
        text = path.read_text()
        for flag in MODE_FLAGS:
            if re.search(rf"\bparams\.{flag}\b", text):
                readers[flag].add(where)
    assert {flag: found for flag, found in readers.items() if len(found) > 2} == {}


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


def test_mypy_finds_no_type_error_in_camo_core():
    """pyproject.toml's [tool.mypy] checks the algorithm, the results and the command line."""
    out = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", "/dev/null"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-1000:]


# What is not the repository's own in its folder: build outputs, caches, installed packages.
NOT_OURS = {".git", ".venv", "ros2_ws", "results", "node_modules", "__pycache__", ".hypothesis"}
NOT_OURS |= {".ruff_cache", ".mypy_cache", ".pytest_cache"}


def repository_files() -> list[str]:
    """The repository's files: git's list in a clone, else (a copy without .git, as the bare
    Debian suite runs on: tools/bare_debian_test.sh) every file outside NOT_OURS."""
    if (ROOT / ".git").exists() and shutil.which("git"):
        done = subprocess.run(["git", "ls-files"], capture_output=True, text=True, cwd=ROOT)
        return done.stdout.split()
    return [
        str(path.relative_to(ROOT))
        for path in ROOT.rglob("*")
        if path.is_file() and not NOT_OURS & set(path.relative_to(ROOT).parts)
    ]


def test_no_text_cites_a_document_that_is_not_in_the_repository():
    """The algorithm is docs/algorithm.md; nothing refers to the spec it was written from."""
    tracked = repository_files()
    citing = [
        name
        for name in tracked
        if name.endswith((".py", ".md", ".txt", ".yaml", ".xml", ".toml"))
        and re.search(r"\bSPEC\b", (ROOT / name).read_text(errors="replace"))
    ]
    assert citing == []
    assert (ROOT / "docs" / "algorithm.md").exists()


IMPORT_ALL = """
import importlib, pkgutil, sys
failed = []
for package in sys.argv[1:]:
    root = importlib.import_module(package)
    for info in pkgutil.walk_packages(root.__path__, package + '.'):
        if info.name.endswith('__main__'):
            continue
        try:
            importlib.import_module(info.name)
        except Exception as exc:
            failed.append(f'{info.name}: {type(exc).__name__}: {exc}')
print('\\n'.join(failed))
"""


def test_every_module_of_every_package_imports():
    packages = [p for p in PACKAGES if p != "camo_msgs"]
    out = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL, *packages], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0 and not out.stdout.strip(), out.stdout + out.stderr[-2000:]
