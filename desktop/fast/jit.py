"""The compiler switch of the fast path: numba's ``njit`` when it is installed, else plain Python.

numba is an optional desktop extra (``pip install -e ".[fast]"``), never
required: without it (or with ``PDR_FAST_NO_JIT=1`` in the environment) the
same kernel functions run as plain Python -- the same code path, only slow.
The kernels use only what both run alike: numpy arrays, scalars, ``math``.
A few small ones that only write out, for numba, what one numpy call does (a
small matrix product, a histogram's median, a block read into floats) are
declared with :func:`kernel_or`: without numba that numpy call runs in their
place, as element loops in plain Python cost tens of times more.

A kernel called from another is compiled once per set of argument types, and numba types a constant
argument (``True``, ``2``, a module constant) as a literal of its value: each call site with other
constants, and a variable first set to a constant (``c = 0`` then counted up), compile the callee (and
everything it calls) once more.  Pass typed values (``np.bool_(True)``, ``np.int64(2)``) instead.
"""

from __future__ import annotations

import os

try:  # pragma: no cover - depends on the installation
    if os.environ.get("PDR_FAST_NO_JIT"):
        raise ImportError("PDR_FAST_NO_JIT is set")
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None
    HAVE_NUMBA = False


def kernel(fn):
    """Compile ``fn`` with numba (no fast-math: the operations and their order stay IEEE's), or leave it."""
    if not HAVE_NUMBA:
        return fn
    return numba.njit(cache=True, fastmath=False)(fn)


def kernel_or(plain):
    """:func:`kernel`, or without numba ``plain`` in the kernel's place: for a kernel that only writes out, for
    numba, what numpy does in one call (a small matrix product), which as plain Python runs element by element
    about fifty times slower than the call.  ``plain`` must compute the same thing (up to rounding)."""

    def wrap(fn):
        return kernel(fn) if HAVE_NUMBA else plain

    return wrap
