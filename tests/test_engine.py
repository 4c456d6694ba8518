"""The engine choice (issue #13): ``pdr replay --engine`` and the benchmark's, through ``desktop.engine``.

The fast path's agreement with the reference is ``tests/test_fast_path.py``'s
subject; here the question is whether the command line really runs the
engine asked for, with the same results, and says so -- and whether a
pipeline the fast path does not implement (GPS fusion) is refused clearly
(``--engine fast``) or falls back to the reference with the reason (``auto``).
In CI numba is absent: the fast path's kernels run as plain Python (so the
walks here are short) and ``auto`` is the reference unless told otherwise.
"""

import json

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
    p = tmp_path_factory.mktemp("engine") / "line.csv.gz"
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
    p = tmp_path_factory.mktemp("engine_gps") / "outdoor.csv.gz"
    write_recording(str(p), outdoor_walk(2, minutes=0.5).recording)
    return p


def test_gps_fusion_falls_back_under_auto_and_is_refused_under_fast(gps_walk, capsys, monkeypatch):
    monkeypatch.setattr(desktop.fast, "HAVE_NUMBA", True)  # auto would take the fast path if it could
    s = _replay_json(capsys, gps_walk)
    assert s["engine"].startswith("reference (") and "GPS" in s["engine"]
    assert s.get("gps_fusion")  # the fallback ran the whole pipeline, the fusion included
    capsys.readouterr()
    assert main(["replay", str(gps_walk), "--engine", "fast", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fast path" in err[0] and "GPS" in err[0]
    # without the fusion the same recording runs on the fast path
    assert _replay_json(capsys, gps_walk, "--engine", "fast", "--gps", "off")["engine"] == "fast"


def test_run_pipeline_refuses_an_unknown_engine():
    with pytest.raises(ValueError, match="auto, fast, reference"):
        run_pipeline(Pipeline(), None, "turbo")
