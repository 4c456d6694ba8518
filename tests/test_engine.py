"""The engine choice (issue #13): ``pdr replay --engine`` and the benchmark's, through ``desktop.engine``.

The fast path's agreement with the reference is ``tests/test_fast_path.py``'s
subject; here the question is whether the command line really runs the
engine asked for, with the same results, and says so (GPS fusion included)
-- and whether a pipeline the fast path does not implement (an attitude
filter without a kernel) is refused clearly (``--engine fast``) or falls
back to the reference with the reason (``auto``).
In CI numba is absent: the fast path's kernels run as plain Python (so the
walks here are short) and ``auto`` is the reference unless told otherwise.
"""

import json
import math

import pytest

import desktop.fast
from core.pdr.pipeline import Pipeline
from core.recording import write_recording
from desktop.cli import main
from desktop.engine import run_pipeline
from desktop.simulator import outdoor_walk

TOL = 1e-9  # m


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))


@pytest.fixture(scope="module")
def line_walk(tmp_path_factory):
    p = tmp_path_factory.mktemp("engine") / "line.csv"
    assert main(["simulate", str(p), "--shape", "line", "--rate", "50", "--seed", "3"]) == 0
    return p


def _replay_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main(["replay", *map(str, args), "--json", "--no-progress"]) == 0
    return json.loads(capsys.readouterr().out)


def test_replay_runs_the_engine_asked_for_with_the_same_track(line_walk, capsys):
    ref = _replay_json(capsys, line_walk, "--engine", "reference")
    fast = _replay_json(capsys, line_walk, "--engine", "fast")
    assert ref["engine"] == "reference" and fast["engine"] == "fast"
    assert ref["n_steps"] == fast["n_steps"] > 20
    for key in ("distance_m", "final_east_m", "final_north_m", "start_to_end_m"):
        assert fast[key] == pytest.approx(ref[key], abs=TOL), key
    assert fast["carry"]["time_s"] == ref["carry"]["time_s"] and fast["labels"] == ref["labels"]


def test_auto_is_the_reference_without_numba(line_walk, capsys, monkeypatch):
    monkeypatch.setattr(desktop.fast, "HAVE_NUMBA", False)
    assert _replay_json(capsys, line_walk)["engine"] == "reference"


@pytest.fixture(scope="module")
def gps_walk(tmp_path_factory):
    p = tmp_path_factory.mktemp("engine_gps") / "outdoor.csv"
    write_recording(str(p), outdoor_walk(2, minutes=0.5).recording)
    return p


def _close(a, b, where=""):
    """JSON values equal, numbers within TOL (nan equal to nan)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), where
        for k in a:
            _close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= TOL, (where, a, b)
    else:
        assert a == b, (where, a, b)


def test_gps_fusion_runs_on_the_fast_path_under_auto(gps_walk, capsys, monkeypatch):
    monkeypatch.setattr(desktop.fast, "HAVE_NUMBA", True)  # auto takes the fast path where it can
    ref = _replay_json(capsys, gps_walk, "--engine", "reference")
    auto = _replay_json(capsys, gps_walk)
    assert ref["engine"] == "reference" and auto["engine"] == "fast"
    assert auto["gps_fusion"] == ref["gps_fusion"] and auto["gps"]["fixes_accepted"] > 10
    _close({k: v for k, v in ref.items() if k != "engine"}, {k: v for k, v in auto.items() if k != "engine"})


def test_what_the_fast_path_does_not_implement_falls_back_under_auto_and_is_refused_under_fast(gps_walk,
                                                                                             monkeypatch):
    from core.pdr.attitude_qekf import QuaternionEKF
    from core.recording import read_recording

    monkeypatch.setattr(desktop.fast, "HAVE_NUMBA", True)
    rec = read_recording(str(gps_walk))
    res, ran = run_pipeline(Pipeline(attitude=QuaternionEKF(), carry=False), rec)
    assert ran.startswith("reference (") and "AttitudeEKF" in ran and len(res.steps) > 10
    with pytest.raises(ValueError, match="fast path cannot run this pipeline"):
        run_pipeline(Pipeline(attitude=QuaternionEKF()), rec, "fast")


def test_run_pipeline_refuses_an_unknown_engine():
    with pytest.raises(ValueError, match="auto, fast, reference"):
        run_pipeline(Pipeline(), None, "turbo")


def test_the_fast_path_reports_progress_after_its_stages(line_walk):
    # a long file on the fast path is minutes without an event loop: progress comes after each stage instead
    from core.recording import read_recording

    seen = []
    _, ran = run_pipeline(Pipeline(), read_recording(str(line_walk)), "fast", progress=seen.append)
    assert ran == "fast" and len(seen) >= 5
    assert all(b > a for a, b in zip(seen, seen[1:])) and 0.0 < seen[0] and seen[-1] == pytest.approx(1.0, abs=1e-12)
