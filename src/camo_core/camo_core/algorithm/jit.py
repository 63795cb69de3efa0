"""numba, loaded as camo's kernels need it: without what it loads for what they never use.

As numba loads, it checks whether SciPy's BLAS is there, for compiled code that
calls np.dot, np.linalg and their kind, by importing scipy.linalg (numba's
np/arraymath.py, through np/linalg.py's ensure_blas). That import takes 0.09 s
of the 0.35 s a process spends loading camo's kernels, and every `camo sim` and
every process that simulates pays it before its first step. It also imports the
coverage tool, for hooks into a coverage run (0.03 s; colcon's pytest-cov put it
in the venv), and cffi, for compiled calls to C functions (0.01 s). camo's
kernels call no BLAS and no cffi function. While numba loads, an import finder
refuses these modules to the thread that loads it, and to no other: numba takes
them to be absent, another thread (cmd_sim's, reading the image; a Dask worker's
other task) imports them as usual, and so does this one afterwards
(scikit-image's colour difference imports SciPy). Where one is loaded already
(a run under coverage), numba finds it as usual.
"""

from __future__ import annotations

import sys
import threading
from importlib.abc import MetaPathFinder

_UNUSED = ("scipy.linalg", "coverage", "cffi")


class _NotForThisThread(MetaPathFinder):
    """Refuses some modules to the thread that made it, while it is on sys.meta_path."""

    def __init__(self, *names: str) -> None:
        self.names, self.thread = set(names), threading.get_ident()

    def find_spec(self, fullname, path=None, target=None):
        if fullname in self.names and threading.get_ident() == self.thread:
            raise ModuleNotFoundError(f"{fullname}: not while numba loads", name=fullname)
        return None  # for every other module and thread: the finders after this one


_refused = [name for name in _UNUSED if name not in sys.modules]
_refusal = _NotForThisThread(*_refused) if _refused else None
if _refusal is not None:
    sys.meta_path.insert(0, _refusal)
try:
    import numba
    import numba.core.typing.cffi_utils  # where cffi is looked for (else at a first call)
    import numba.np.arraymath  # where the BLAS probe runs, once per process
    from numba import njit, prange
finally:
    if _refusal is not None:
        sys.meta_path.remove(_refusal)

__all__ = ["njit", "numba", "prange"]
