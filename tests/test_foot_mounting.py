"""Mode detection: a simulated foot is "foot", a simulated hand-held walk "handheld"; stream naming."""

import math

import numpy as np
import pytest

from core.foot.devices import device_stream, devices, split_name, stream_name
from core.foot.mounting import FOOT, HANDHELD, detect_mounting
from core.recording import Recording, parse_recording, write_recording
from desktop.foot_simulator import footprints, simulate_foot
from desktop.simulator import simulate_walk


def test_simulated_foot_is_foot():
    w = simulate_foot(footprints([(14.0, 0.0), (7.0, math.pi / 2)]), rate_hz=100.0, acc_noise_m_s2=0.05,
                      gyro_noise_rad_s=0.01, seed=3)
    m = detect_mounting(w.recording)
    assert m.mode == FOOT and m.confidence > 0.9, m


def test_simulated_handheld_walk_is_handheld():
    walk = simulate_walk([(0.0, 0.0), (30.0, 0.0), (30.0, 20.0)], seed=5)
    m = detect_mounting(walk.recording)
    assert m.mode == HANDHELD and m.confidence > 0.8, m


def test_still_recording_gives_no_evidence():
    t = np.arange(500) * 10_000_000
    from core.recording import make_stream

    rec = Recording({"acc": make_stream("acc", t, np.tile([0.0, 0.0, 9.81], (500, 1))),
                     "gyro": make_stream("gyro", t, np.zeros((500, 3)))})
    m = detect_mounting(rec)
    assert m.walking_s == 0.0 and m.confidence == pytest.approx(0.5)


def test_device_streams_round_trip_through_the_file_format(tmp_path):
    w = simulate_foot(footprints([(2.8, 0.0)]), rate_hz=50.0, waist=True, seed=1)
    rec = w.recording
    assert devices(rec) == ["", "waist"]
    assert stream_name("acc", "left_foot") == "acc@left_foot" and split_name("mag@waist") == ("mag", "waist")
    with pytest.raises(ValueError):
        stream_name("acc", "a,b")
    path = tmp_path / "two_devices.pdr"
    write_recording(str(path), rec)
    back = parse_recording(path.read_text())
    assert set(back.streams) == set(rec.streams)
    assert np.allclose(back.streams["mag@waist"].values, rec.streams["mag@waist"].values)
    assert back.streams["acc@waist"].unit == "m/s^2"
    assert isinstance(device_stream("gyro", "shoe", [1], [[0.0, 0.0, 0.0]]).columns, tuple)
