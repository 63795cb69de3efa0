"""numba, loaded as camo's kernels need it: without its probe for SciPy's BLAS.

As numba loads, it checks whether SciPy's BLAS is there, for compiled code that
calls np.dot, np.linalg and their kind, by importing scipy.linalg (numba's
np/arraymath.py, through np/linalg.py's ensure_blas). That import takes 0.09 s
of the 0.35 s a process spends loading camo's kernels, and every `camo sim` and
every process that simulates pays it before its first step. camo's kernels call
no BLAS. While numba loads, an import finder refuses scipy.linalg to the thread
that loads it, and to no other: numba takes BLAS to be absent, another thread
(cmd_sim's, reading the image; a Dask worker's other task) imports SciPy as
usual, and so does this one afterwards (scikit-image's colour difference does).
Where scipy.linalg is loaded already, numba finds BLAS as usual.
"""

from __future__ import annotations

import sys
import threading
from importlib.abc import MetaPathFinder

_PROBED = "scipy.linalg"


class _NotForThisThread(MetaPathFinder):
    """Refuses one module to the thread that made it, while it is on sys.meta_path."""

    def __init__(self, name: str) -> None:
        self.name, self.thread = name, threading.get_ident()

    def find_spec(self, fullname, path=None, target=None):
        if fullname == self.name and threading.get_ident() == self.thread:
            raise ModuleNotFoundError(f"{fullname}: not while numba loads", name=fullname)
        return None  # for every other module and thread: the finders after this one


_refusal = None if _PROBED in sys.modules else _NotForThisThread(_PROBED)
if _refusal is not None:
    sys.meta_path.insert(0, _refusal)
try:
    import numba
    import numba.np.arraymath  # where the probe runs, once per process
    from numba import njit, prange
finally:
    if _refusal is not None:
        sys.meta_path.remove(_refusal)

__all__ = ["njit", "numba", "prange"]
