"""numba, loaded as camo's kernels need it: without its probe for SciPy's BLAS.

As numba loads, it checks whether SciPy's BLAS is there, for compiled code that
calls np.dot, np.linalg and their kind, by importing scipy.linalg (numba's
np/arraymath.py, through np/linalg.py's ensure_blas). That import takes 0.09 s
of the 0.35 s a process spends loading camo's kernels, and every `camo sim` and
every process that simulates pays it before its first step. camo's kernels call
no BLAS. A None in sys.modules makes that one import fail at once, so numba
takes BLAS to be absent; the entry is taken out again as soon as numba has
loaded, so a later import of SciPy (scikit-image's colour difference makes one)
is whole. Where SciPy's BLAS is loaded already, numba finds it as usual.
"""

from __future__ import annotations

import sys

_PROBED = "scipy.linalg.cython_blas"
_blocked = _PROBED not in sys.modules
if _blocked:
    sys.modules[_PROBED] = None  # type: ignore[assignment]
try:
    import numba
    import numba.np.arraymath  # where the probe runs, once per process
    from numba import njit, prange
finally:
    if _blocked and sys.modules.get(_PROBED, False) is None:
        del sys.modules[_PROBED]

__all__ = ["njit", "numba", "prange"]
