"""Ground truth kept beside a recording (issue #29): ``pdr replay`` shows the error against the Oxford
``stepcounter.csv``, the Brajdic & Harle ``groundtruth_SC.txt`` count and IPOL's foot strikes, in their
datasets' layouts (built here from a simulated walk, so the true count is known)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from core.importers import load_recording
from core.importers.beside import foot_switch_steps, truth_beside
from core.metrics import truth_of
from desktop.cli import main
from desktop.simulator import simulate_walk


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))


@pytest.fixture(scope="module")
def walk():
    return simulate_walk([(0, 0), (25, 0)], rate_hz=100.0, seed=7)


def _oxford_folder(folder, walk, drop_first=0):
    """An Oxford optimisation folder: headerless ``accelerometer.csv`` and ``stepcounter.csv`` whose foot
    switches rise at the simulator's heel strikes (every ~90 ms a row, as the device logs)."""
    folder.mkdir()
    acc = walk.recording.streams["acc"]
    with open(folder / "accelerometer.csv", "w") as f:
        for t, (x, y, z) in zip(acc.t_ns, acc.values):
            f.write(f"{int(t)},3,{x:.5f},{y:.5f},{z:.5f}\n")
    strikes = walk.truth.step_t_ns[drop_first:]
    rows = np.arange(int(acc.t_ns[0]), int(acc.t_ns[-1]), 90_000_000)
    feet = np.zeros((len(rows), 2), int)
    for k, t in enumerate(strikes):  # foot k % 2 is down from its strike for 45 % of a stride
        i = np.searchsorted(rows, t)
        feet[i:i + 5, k % 2] = 1
    with open(folder / "stepcounter.csv", "w") as f:
        for t, (a, b) in zip(rows, feet):
            f.write(f"{t},{a},{b}\n")
    return len(strikes)


def test_oxford_foot_switches_are_the_truth_of_the_folder_and_of_its_accelerometer_file(walk, tmp_path, capsys):
    folder = tmp_path / "Pixel_Test_Hard_InHand_1"
    n = _oxford_folder(folder, walk, drop_first=3)  # the switches miss the first 3 steps: the truth is theirs
    assert len(foot_switch_steps(str(folder / "stepcounter.csv"))[0]) == n
    for target in (folder, folder / "accelerometer.csv"):
        assert main(["replay", str(target), "--json", "--no-progress", "--no-profile"]) == 0
        steps = json.loads(capsys.readouterr().out)["truth"]["steps"]
        assert steps["n_true"] == n and "stepcounter.csv" in steps["what"]
    assert main(["replay", str(folder), "--no-progress", "--no-profile"]) == 0
    assert f"truth         {n} steps (stepcounter.csv" in capsys.readouterr().out


def test_brajdic_count_over_the_walk_window(walk, tmp_path):
    acc = walk.recording.streams["acc"]
    path = tmp_path / "p4.1_Male_20-29_170-179cm_Hand_held.dat"
    with open(path, "w") as f:
        for name, code in (("acc", 1), ("gyro", 2), ("mag", 3)):
            s = walk.recording.streams[name]
            for t, (x, y, z) in zip(s.t_ns, s.values):
                f.write(f"{int(t)} {code} {x:.5f} {y:.5f} {z:.5f}\n")
    (tmp_path / "groundtruth_SC.txt").write_text("p3.1 10\n\np4.1 37 \n")
    (tmp_path / "groundtruth_WD.txt").write_text("#Trace id (start sample, end sample)\n---\n"
                                                 "p4.1Hand_held     (100 900)\n")
    rec = load_recording(str(path), warn=False)
    truth = truth_of(rec).steps
    assert truth["n"] == 37 and "groundtruth_SC.txt" in truth["what"]
    t = load_recording(str(path), warn=False, truth_beside=False).streams["acc"].t_ns
    assert (truth["t0_ns"], truth["t1_ns"]) == (int(t[100]), int(t[900]))
    (tmp_path / "groundtruth_SC.txt").write_text("p3.1 10\n")  # no count for this trace: no truth, no error
    assert truth_beside(str(path), load_recording(str(path), warn=False, truth_beside=False)) is None


def test_no_annotation_beside_no_truth_added(walk, tmp_path):
    """A recording without the dataset's layout around it gets nothing added."""
    folder = tmp_path / "x"
    _oxford_folder(folder, walk)
    (folder / "stepcounter.csv").rename(folder / "other.csv")
    assert "step_counts" not in load_recording(str(folder), warn=False).streams
