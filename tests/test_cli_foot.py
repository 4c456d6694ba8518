"""``pdr replay --mode {auto,handheld,foot}``: the foot-mounted INS from the command line (issue #11)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from core.recording import write_recording
from desktop.cli import main
from desktop.foot_simulator import footprints, simulate_foot
from tests._demo_helpers import demo_replay_json


@pytest.fixture(scope="module")
def foot_file(tmp_path_factory):
    """A simulated foot walk: 20 m East, a left turn, 10 m North, written in the project format."""
    prints = footprints([(20.0, 0.0), (10.0, math.pi / 2)])
    walk = simulate_foot(prints, rate_hz=100.0, acc_noise_m_s2=0.02, gyro_noise_rad_s=0.002, seed=3)
    path = tmp_path_factory.mktemp("foot") / "foot.csv"
    write_recording(str(path), walk.recording)
    return str(path), walk


def test_auto_mode_detects_the_foot_and_tracks_it(foot_file, capsys):
    path, walk = foot_file
    assert main(["replay", path, "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["mode"] == "foot" and "says the IMU is on the foot" in s["mode_reason"]  # the file declares it
    end = walk.footprints_n[-1]
    # the track starts heading the way the simulator's foot points only up to the unknown initial yaw:
    # compare what yaw cannot change -- the distance and the start-to-end distance
    path_len = float(np.sum(np.hypot(*np.diff(walk.footprints_n[:, :2], axis=0).T)))
    assert s["distance_m"] == pytest.approx(path_len, rel=0.03)
    assert s["start_to_end_m"] == pytest.approx(math.hypot(end[0], end[1]), rel=0.05)
    assert s["n_strides"] >= len(walk.footprints_n) - 2


def test_handheld_recordings_stay_handheld_and_the_mode_can_be_forced(foot_file, capsys, tmp_path):
    s = json.loads(demo_replay_json())  # pdr replay --json: the bundled hand-held demo
    assert s["mode"] == "handheld" and "detected" in s["mode_reason"]
    path, _ = foot_file
    csv = tmp_path / "foot.csv"
    assert main(["replay", path, "--mode", "foot", "--aid", "zupt", "--csv", str(csv)]) == 0
    out = capsys.readouterr().out
    assert "foot-mounted INS (chosen with --mode)" in out and csv.exists()
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("t_ns,") and len(rows) > 15


def test_foot_mode_refuses_gps_fusion_in_one_line(foot_file, capsys):
    path, _ = foot_file
    assert main(["replay", path, "--mode", "foot", "--gps", "chen"]) == 2
    err = capsys.readouterr().err
    assert "not built" in err and "Traceback" not in err


def test_device_streams_get_their_kinds_columns():
    from core.recording import make_stream

    s = make_stream("gyro@left_foot", [1, 2], [[0.0, 0.1, 0.2], [0.0, 0.1, 0.3]])
    assert s.columns == ("x", "y", "z") and s.unit == "rad/s"


def test_gyro_range_repairs_clipped_swings(tmp_path, capsys):
    """``--gyro-range``: the swings of a walk clipped at 80 % of the peak rate are repaired (and without it,
    none are)."""
    from tests.test_foot_saturation import _clipped_walk

    w, rec, level = _clipped_walk(1)
    path = str(tmp_path / "clipped.csv")
    write_recording(path, rec)
    out = {}
    for name, extra in (("off", []), ("on", ["--gyro-range", str(level / 0.995)])):
        assert main(["replay", path, "--json", "--no-smoother"] + extra) == 0
        out[name] = json.loads(capsys.readouterr().out)
    assert out["off"]["gyro_clipped_runs_repaired"] == 0 and out["on"]["gyro_clipped_runs_repaired"] >= 5


def test_replay_uses_the_gyro_range_the_recording_declares_and_the_flag_overrides_it(tmp_path, capsys):
    """A recording that declares its gyroscope's full scale (``device["sensors"]["gyro"]["max_range"]``, as
    the app writes Android's getMaximumRange) is repaired without ``--gyro-range``; the flag wins over it."""
    from dataclasses import replace

    from tests.test_foot_saturation import _clipped_walk

    w, rec, level = _clipped_walk(1)
    path = str(tmp_path / "declared.csv")
    write_recording(path, replace(rec, device={**rec.device, "sensors": {"gyro": {"max_range": level / 0.995}}}))
    out = {}
    for name, extra in (("declared", []), ("flag", ["--gyro-range", str(level / 0.995)]),
                        ("override", ["--gyro-range", "100"])):
        assert main(["replay", path, "--json", "--no-smoother"] + extra) == 0
        out[name] = json.loads(capsys.readouterr().out)
    assert out["declared"]["gyro_clipped_runs_repaired"] >= 5
    assert out["declared"]["final_east_m"] == out["flag"]["final_east_m"]
    assert out["declared"]["gyro_range_rad_s"] == pytest.approx(level / 0.995, abs=1e-12)
    assert out["override"]["gyro_clipped_runs_repaired"] == 0 and out["override"]["gyro_range_rad_s"] == 100
    assert main(["replay", path, "--no-smoother"]) == 0
    assert "(the recording's gyroscope):" in capsys.readouterr().out
