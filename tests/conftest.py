"""Test-wide settings: no test reads or writes the user's own app data (their stride profile); the test files that
run numba's fast path are one xdist work unit, and a file outside that unit that runs a kernel is an error."""

import os
import sys
from pathlib import Path

import pytest

# Bytecode is written, whatever PYTHONDONTWRITEBYTECODE says (this sandbox and, it seems, CI set it): without it each
# xdist worker and each subprocess a test starts (``pdr replay``, the app off-screen, the kill -9 recorders)
# compiled core/, desktop/ and app/ from source again, and pytest rewrote the test modules' asserts again. The
# environment is changed here, in the controller, before xdist starts its workers, so they and their children
# inherit it. Measured from a clean tree on the six files that start subprocesses (test_app_ui, test_cli,
# test_no_walk_lost, test_app_bad_input, test_foot_app, test_app_files; one process, other work running, two runs
# each): 33.5 -> 31.5 s of CPU (-6 %). __pycache__/ is git-ignored.
if os.environ.pop("PYTHONDONTWRITEBYTECODE", None) is not None:
    sys.dont_write_bytecode = False


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
#: reaches the fast path (test_app_bad_input's ``pdr replay``, engine auto, was one) compiles the kernels in the other
#: worker too where both reach them before either has written numba's cache: 30 s of CPU more for test_engine +
#: test_app_bad_input on a cold cache; in the full suite's order it mostly compiled them first (5 s, one run each).
NUMBA_TEST_FILES = frozenset(
    f"test_{name}.py" for name in (
        "acc_gap_bridge", "app_bad_input", "attitude_reset", "attitude_state", "bad_input_round3", "bad_numbers",
        "carry", "carry_outputs", "cli", "cli_batch", "cli_foot", "cli_map", "cli_truth", "end_steps", "engine",
        "fast_magcal", "fast_path", "fast_walkdir", "floors", "gnss", "kubrak", "truth_beside", "walk_start_steps",
        "weak_steps"))


#: other files that share a worker (one xdist work unit each): their module-level caches compute once what they
#: share (tests/test_app_logic.py's gps_walk_run: the GPS walk's batch run and session replay, 2.3 s of one core)
SHARED_WORK_UNITS = {"app-gps-walk": frozenset({"test_app_logic.py", "test_app_ui.py"})}


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` (pyproject's default) with :data:`NUMBA_TEST_FILES` as one work unit (and each of
    :data:`SHARED_WORK_UNITS`).  Also without numba
    (the README's ``.[test]`` install, as CI runs it), where the kernels compile nothing: plain ``loadfile`` there was
    slower, 164 s against 156 s on 2 quiet cores (1223 tests, 2026-12-07), and the unit lets files share a worker's
    module-level caches (the simulated GPS walk of test_gnss and test_kubrak: ``tests._gnss_helpers``)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class NumbaOnceScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            name = path.rsplit("/", 1)[-1]
            if name in NUMBA_TEST_FILES:
                return "numba-kernels"
            return next((unit for unit, files in SHARED_WORK_UNITS.items() if name in files), path)

    return NumbaOnceScheduling(config, log)


#: the fast path's modules, whose numba dispatchers :func:`_kernel_versions` counts
_FAST_MODULES = tuple(f"desktop.fast.{p.stem}"
                      for p in (Path(__file__).resolve().parents[1] / "desktop" / "fast").glob("*.py"))
_KERNELS_BEFORE = pytest.StashKey[int]()


def _kernel_versions() -> int:
    """How many compiled versions (compiled here or loaded from numba's cache) the fast path's kernels hold in this
    process; 0 without numba (``PDR_FAST_NO_JIT``, or not installed: the kernels are plain functions)."""
    n = 0
    for name in _FAST_MODULES:
        mod = sys.modules.get(name)
        if mod is not None:
            n += sum(len(f.overloads) for f in vars(mod).values() if hasattr(f, "overloads") and hasattr(f, "py_func"))
    return n


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    item.stash[_KERNELS_BEFORE] = _kernel_versions()
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    """A test outside :data:`NUMBA_TEST_FILES` that ran a fast-path kernel in this process (its setup, call or
    teardown) errors: in a clean checkout it may compile the kernels in the other worker while the numba unit
    compiles them too (up to about 30 s of CPU).  ``pdr replay`` in a subprocess is not seen here: list such files
    too."""
    result = yield
    if item.path.name not in NUMBA_TEST_FILES and _kernel_versions() > item.stash.get(_KERNELS_BEFORE, 0):
        pytest.fail(f"{item.path.name} runs numba's fast path (engine auto?): add it to NUMBA_TEST_FILES in "
                    "tests/conftest.py", pytrace=False)
    return result
