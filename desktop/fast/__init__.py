"""The fast desktop path (issue #13 item 3): the hand-held pipeline over whole arrays.

:func:`run_fast` gives what ``Pipeline(...).run(recording)`` gives -- the
same steps, positions and headings within 1e-9 -- with the per-event loop
taken apart into vectorised array code and compiled kernels (numba, the
optional ``fast`` extra; without it the very same kernel functions run as
plain Python, slowly, a few small ones as the numpy call they write out:
:func:`desktop.fast.jit.kernel_or`).  It is deliberately a second implementation of the
per-event kernels of ``core/`` (the phone's code stays the reference), and
``tests/test_fast_path.py`` holds the two to each other on real recordings,
which makes it also the test that batch equals streaming.

Desktop only: nothing in ``core/`` or ``app/`` imports it.
"""

from desktop.fast.jit import HAVE_NUMBA
from desktop.fast.pipeline import run_fast

__all__ = ["HAVE_NUMBA", "run_fast"]
