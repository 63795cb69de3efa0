"""The two drivers (per-robot step functions, whole-grid simulator) agree bit for bit."""

import os
import subprocess
import sys

import numpy as np
import pytest
from support import PROCESS, assert_drivers_agree

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.simulator import simulate

FIELDS = ("sensed", "votes", "p", "selected", "initial", "final", "consensus_trace")
SHAPES = [(1, 1), (1, 7), (6, 1), (2, 2), (3, 5), (8, 8), (9, 4)]


@pytest.mark.parametrize("profile", ["paper", "droplet"])
@pytest.mark.parametrize("rho", [0.0, 0.2, 0.5])
@pytest.mark.parametrize("seed", [0, 17, 2**64 - 2])
def test_drivers_agree_on_random_grids(profile, rho, seed):
    generator = np.random.default_rng(seed % 1000 + int(rho * 10))
    for rows, cols in SHAPES:
        params = CamoParams(
            profile=profile, rows=rows, cols=cols, seed=seed, rho_meas=rho, rho_comm=rho
        )
        raw = generator.uniform(0, 255, (rows, cols))
        assert_drivers_agree(params, raw, FIELDS, (rows, cols))


def test_drivers_agree_with_measurement_only_and_communication_only():
    raw = np.random.default_rng(3).uniform(0, 255, (7, 6))
    for rho_meas, rho_comm in [(0.3, 0.0), (0.0, 0.3)]:
        params = CamoParams(rows=7, cols=6, seed=5, rho_meas=rho_meas, rho_comm=rho_comm)
        assert_drivers_agree(params, raw, FIELDS)


def test_errors_change_the_outcome_and_seeds_matter():
    raw = np.random.default_rng(4).uniform(0, 255, (8, 8))
    clean = simulate(CamoParams(), raw)
    noisy_a = simulate(CamoParams(seed=1, rho_meas=0.5, rho_comm=0.5), raw)
    noisy_b = simulate(CamoParams(seed=2, rho_meas=0.5, rho_comm=0.5), raw)
    assert not np.array_equal(clean.sensed, noisy_a.sensed)
    assert not np.array_equal(noisy_a.p, noisy_b.p)
    # Without errors the seed changes nothing.
    assert np.array_equal(clean.final, simulate(CamoParams(seed=99), raw).final)


def test_consensus_keeps_p_a_probability_vector_under_loss():
    raw = np.random.default_rng(5).uniform(0, 255, (10, 10))
    result = simulate(CamoParams(rows=10, cols=10, seed=3, rho_comm=0.5), raw)
    assert np.allclose(result.p.sum(axis=2), 1.0)
    assert (result.p >= 0).all()
    assert result.consensus_trace.shape == (36, 3)


def test_exempt_robots_are_never_replaced_by_noise():
    raw = np.full((4, 4), 100.0)
    exempt = np.zeros((4, 4), bool)
    exempt[1, 2] = True
    params = CamoParams(rows=4, cols=4, rho_meas=1.0)
    result = simulate(params, raw, exempt=exempt)
    assert result.sensed[1, 2] == 100.0
    assert np.array_equal(result.sensed, run_per_robot(params, raw, exempt=exempt).sensed)
    assert (result.sensed[~exempt] != 100.0).sum() >= 12


STALE_CACHE_RUN = """
import sys
import numpy as np
from camo_core.algorithm import rules
if sys.argv[1] == "changed":  # a rules.py of another version: fewer mottled inhibitors
    rules.INHIBITORS[rules.MOTTLED] = (4, 5, 6, 7)
from camo_core.algorithm import kernels
from camo_core.algorithm.backgrounds import background
from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.perrobot import run_per_robot
from camo_core.algorithm.sensing import sense_image
from camo_core.algorithm.simulator import simulate
params = CamoParams(rows=8, cols=8)
raw = sense_image(background("leopard"), 8, 8, "paper")
grid, robots = simulate(params, raw), run_per_robot(params, raw)
print(kernels.frozen_tables() == kernels.TABLES, np.array_equal(grid.final, robots.final))
"""


@pytest.mark.slow(PROCESS)
def test_cached_kernels_of_other_tables_are_built_again(tmp_path):
    # numba keys its cache on kernels.py alone; the tables it freezes come from rules.py.
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    outs = [
        subprocess.run(
            [sys.executable, "-c", STALE_CACHE_RUN, version],
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        for version in ("as is", "changed")
    ]
    for out in outs:
        assert out.returncode == 0, out.stderr[-2000:]
        assert out.stdout.split() == ["True", "True"], out.stdout


def test_a_small_grid_simulates_on_one_numba_thread_and_a_large_one_on_all():
    import numba

    from camo_core.algorithm.simulator import ONE_THREAD_ROBOTS

    threads: dict[int, set[int]] = {}
    for rows, cols in ((8, 8), (128, 128), (129, 128)):
        seen = threads.setdefault(rows * cols, set())
        result = simulate(
            CamoParams(rows=rows, cols=cols, consensus_steps=2, formation_steps=1),
            np.full((rows, cols), 100.0),
            observe=lambda *_, seen=seen: seen.add(numba.get_num_threads()),
        )
        assert result.final.shape == (rows, cols)
        assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS  # as it was after it
    assert 128 * 128 == ONE_THREAD_ROBOTS
    assert threads == {64: {1}, 128 * 128: {1}, 129 * 128: {numba.config.NUMBA_NUM_THREADS}}


@pytest.mark.slow(PROCESS)
def test_loading_the_kernels_leaves_scipy_coverage_and_cffi_unloaded_and_whole():
    # numba's probe for SciPy's BLAS (an import of scipy.linalg) is skipped, as are its hooks
    # for coverage and cffi: the kernels use none. Each imports whole afterwards, and a
    # simulation runs.
    code = (
        "import sys\n"
        "from camo_core.algorithm.simulator import simulate\n"
        "from camo_core.algorithm.params import CamoParams\n"
        "import numpy as np\n"
        "for name in ('scipy.linalg', 'coverage', 'cffi'):\n"
        "    assert name not in sys.modules, name + ' was imported'\n"
        "simulate(CamoParams(rows=4, cols=4), np.full((4, 4), 90.0))\n"
        "import scipy.linalg.cython_blas, scipy.linalg, coverage, cffi\n"
        "assert cffi.FFI() and coverage.Coverage\n"
        "print(scipy.linalg.det(np.eye(2)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "1.0"


def test_the_probes_module_is_refused_to_the_thread_loading_numba_only(tmp_path, monkeypatch):
    import importlib
    import threading

    from camo_core.algorithm.jit import _NotForThisThread

    (tmp_path / "camo_probe_stand_in.py").write_text("VALUE = 7\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    refusal = _NotForThisThread("camo_probe_stand_in")
    monkeypatch.setattr(sys, "meta_path", [refusal, *sys.meta_path])
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("camo_probe_stand_in")  # this thread: refused
    found = []
    other = threading.Thread(
        target=lambda: found.append(importlib.import_module("camo_probe_stand_in"))
    )
    other.start()
    other.join()
    assert [module.VALUE for module in found] == [7]  # another thread: imported as usual
    sys.modules.pop("camo_probe_stand_in", None)  # imported from a folder of this test only
