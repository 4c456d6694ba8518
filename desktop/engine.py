"""Which engine runs a hand-held pipeline over a recording: the phone's code or the fast desktop path.

One choice for the command line (``pdr replay --engine``) and the benchmark
(``python -m benchmarks --engine``), made here once:

``reference``
    ``pipeline.run(recording)``: :class:`core.pdr.pipeline.Pipeline`'s
    streaming kernel, one event at a time -- the code the phone runs.
``fast``
    :func:`desktop.fast.run_fast` over whole arrays, the same result within
    1e-9 (``tests/test_fast_path.py``), GPS fusion included (the fusion is
    core's own, fed the fixes and steps in the reference's order; the site the
    first fix gives the attitude filter between the same two events).  Without
    numba its kernels run as plain Python, much slower than the reference; a
    pipeline it does not implement (an attitude filter without a kernel) is
    refused with the reason.
``auto`` (the default)
    The fast path when numba is installed (the ``fast`` extra) and it
    implements the pipeline, else the reference.  The first use compiles the
    kernels (about a minute of CPU), which numba keeps in its cache for the
    next runs.
"""

from __future__ import annotations

ENGINES = ("auto", "fast", "reference")


def run_pipeline(pipeline, recording, engine: str = "auto", progress=None) -> tuple:
    """Run ``pipeline`` over ``recording`` on ``engine`` (one of :data:`ENGINES`); returns ``(result, ran)``.

    ``ran`` is ``"fast"``, ``"reference"``, or ``"reference (why the fast path could not)"`` for ``auto``.
    ``progress`` (the fraction done, 0..1) is called every few thousand events by the reference, after each
    stage by the fast path.  ``engine="fast"`` on a pipeline the fast path does not implement raises
    :class:`ValueError` with the reason.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine {engine!r}: one of {', '.join(ENGINES)}")
    if engine == "reference":
        return pipeline.run(recording, progress=progress), "reference"
    from desktop.fast import HAVE_NUMBA, run_fast

    if engine == "auto" and not HAVE_NUMBA:
        return pipeline.run(recording, progress=progress), "reference"
    try:
        result = run_fast(recording, pipeline=pipeline, progress=progress)
    except NotImplementedError as e:  # refused before any work: Pipeline.run starts afresh
        if engine == "fast":
            raise ValueError(f"the fast path cannot run this pipeline: {e}") from None
        return pipeline.run(recording, progress=progress), f"reference ({e})"
    return result, "fast"
