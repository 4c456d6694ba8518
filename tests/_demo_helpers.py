"""The bundled demo's ``pdr replay --json``, shared by test_cli.py and test_cli_foot.py (one xdist worker: both are
in tests/conftest.py's numba unit)."""

from __future__ import annotations

import contextlib
import functools
import io
import os


@functools.cache
def demo_replay_json() -> str:
    """What ``pdr replay --json`` (the bundled demo) prints, run once per process.  The caller's test has
    ``PDR_APP_DATA`` pointing at an empty folder (tests/conftest.py): no stored profile changes the output."""
    from desktop.cli import main

    assert not os.path.exists(os.path.join(os.environ["PDR_APP_DATA"], "profile.json"))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["replay", "--json"]) == 0
    return out.getvalue()
