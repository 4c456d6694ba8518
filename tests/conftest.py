"""Test-wide settings: no test reads or writes the user's own app data (their stride profile)."""

import pytest


@pytest.fixture(autouse=True)
def _isolated_app_data(tmp_path_factory, monkeypatch):
    """``PDR_APP_DATA`` points at an empty folder, so ``pdr replay`` never finds a real ``profile.json``
    (subprocesses inherit it); tests that need one set their own."""
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path_factory.mktemp("app-data")))


#: test files that run numba's fast path (desktop.fast directly, or ``pdr replay`` in or out of process: engine auto).
#: In a clean checkout the first call of each kernel compiles it (about 30 s of one core; then cached in
#: desktop/fast/__pycache__).  Spread over both workers (--dist loadfile), each worker compiled every kernel; as one
#: work unit they run in one worker, which compiles them once (and, the unit having the most tests, first) while the
#: other runs the rest.  Module fixtures are still built once per file.  Measured on 2 quiet cores, full suite:
#: no numba cache 157-159 s -> 149-152 s; after the demo replay (CI's order) 142 -> 138 s.  A file missing here that
#: reaches the fast path (test_app_bad_input's ``pdr replay``, engine auto, was one) compiles the kernels a second time
#: in the other worker, at the same moment: about 30 s of CPU more on a cold cache.
NUMBA_TEST_FILES = frozenset(
    f"test_{name}.py" for name in (
        "acc_gap_bridge", "app_bad_input", "attitude_reset", "attitude_state", "bad_input_round3", "bad_numbers",
        "carry", "carry_outputs", "cli", "cli_batch", "cli_foot", "cli_map", "cli_truth", "engine", "fast_magcal",
        "fast_path", "fast_walkdir", "floors", "gnss", "kubrak", "truth_beside"))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (pyproject's default) with :data:`NUMBA_TEST_FILES` as one work unit."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class NumbaOnceScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "numba-kernels" if path.rsplit("/", 1)[-1] in NUMBA_TEST_FILES else path

    return NumbaOnceScheduling(config, log)
