"""The SensorLog (iOS) CSV (issue #25: counted pocket walks of that layout).

Synthetic files only (the real walks stay outside the repository): a file written from known values, in iOS's g and
sign, with rows repeating the slower gyroscope's and magnetometer's last sample and unread columns around them, reads
back to them (acc in m/s^2 with Android's sign, repeats dropped and counted); the same with units in the column
names; linear acceleration, a missing accelerometer column and other layouts are refused or not taken for it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.conventions import STANDARD_GRAVITY_M_S2
from core.importers import SENSORLOG, detect_format, load_recording, read_sensorlog
from core.recording import RecordingError

G = STANDARD_GRAVITY_M_S2


def _walk(n: int = 400, seed: int = 2):
    """100 Hz accelerometer (g, iOS sign: flat screen up reads z = -1), a gyroscope and magnetometer at 50 Hz."""
    rng = np.random.default_rng(seed)
    t = 20029.7 + np.cumsum(rng.uniform(0.009, 0.011, size=n))
    a_ios = np.zeros((n, 3))
    a_ios[:, 1] = 0.9 + 0.2 * np.sin(2 * np.pi * 1.8 * t)  # upright, top down (Android y = -9.8 * 0.9)
    a_ios[:, 2] = -0.3 + 0.1 * np.cos(2 * np.pi * 1.8 * t)
    gyro = np.column_stack([np.sin(t), 0.5 * np.cos(t), 0.1 * np.ones(n)])
    mag = np.column_stack([20 + np.sin(t), -5 * np.ones(n), -40 + np.cos(t)])
    slow = np.arange(n) // 2 * 2  # the slower sensors: each sample on two rows
    return t, a_ios, t[slow], gyro[slow], mag[slow]


def _write(path, t, a, tg, g, m, units: bool = False):
    u = (lambda s, unit: f"{s}({unit})") if units else (lambda s, unit: s)
    head = ["time(ms)", "locationLatitude", u("accelerometerTimestamp_sinceReboot", "s")]
    head += [u(f"accelerometerAcceleration{c}", "G") for c in "XYZ"]
    head += [u("gyroTimestamp_sinceReboot", "s")] + [u(f"gyroRotation{c}", "rad/s") for c in "XYZ"]
    head += [u("motionTimestamp_sinceReboot", "s"), "motionYaw"] + [u(f"motionMagneticField{c}", "µT") for c in "XYZ"]
    lines = [",".join(head)]
    for i in range(len(t)):
        row = [f"{(t[i] - t[0]) * 1e3:.4f}", "37.35297047", f"{t[i]:.5f}", *(f"{x:.9f}" for x in a[i]),
               f"{tg[i]:.5f}", *(f"{x:.9f}" for x in g[i]), f"{tg[i]:.5f}", "1.55", *(f"{x:.6f}" for x in m[i])]
        lines.append(",".join(row))
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


def _read(p):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(p)


@pytest.mark.parametrize("units", [False, True])
def test_round_trip_g_and_ios_sign_converted_repeats_dropped(tmp_path, units):
    t, a, tg, g, m = _walk()
    p = _write(tmp_path / "walk.csv", t, a, tg, g, m, units=units)
    assert detect_format(p) == SENSORLOG
    rec = _read(p)
    acc, gyro, mag = rec.streams["acc"], rec.streams["gyro"], rec.streams["mag"]
    np.testing.assert_array_equal(acc.t_ns, np.round(np.round(t, 5) * 1e9).astype(np.int64))
    np.testing.assert_allclose(acc.values, -G * np.round(a, 9), atol=1e-7)
    assert len(gyro) == len(mag) == len(t) // 2 and rec.metadata["repeated_rows"] == {"acc": 0, "gyro": 200, "mag": 200}
    np.testing.assert_allclose(gyro.values, np.round(g[::2], 9), atol=1e-12)
    np.testing.assert_allclose(mag.values, np.round(m[::2], 6), atol=1e-9)
    assert rec.metadata["source_format"] == SENSORLOG and rec.repairs == []


def test_linear_acceleration_a_missing_column_and_other_layouts_are_refused(tmp_path):
    t, a, tg, g, m = _walk(300)
    lin = 0.3 * (a - a.mean(axis=0))  # user acceleration only (no gravity)
    with pytest.raises(RecordingError, match="linear acceleration without gravity") as e:
        read_sensorlog(str(_write(tmp_path / "linear.csv", t, lin, tg, g, m)))
    assert str(e.value).startswith(str(tmp_path / "linear.csv")) and "\n" not in str(e.value)
    p = _write(tmp_path / "noz.csv", t, a, tg, g, m)
    p.write_bytes(p.read_bytes().replace(b"accelerometerAccelerationZ", b"accelerometerAccelerationW", 1))
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(p)
    with pytest.raises(RecordingError, match="no SensorLog CSV|missing column"):
        read_sensorlog(str(p))
    q = tmp_path / "converted.csv"  # the class's other export: no SensorLog columns
    q.write_text("time(ms),time(ds),x_accel,y_accel,z_accel,g_measured,TimeInterval\n0,0,-0.13,-0.94,-0.17,0.97,3556.2\n")
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(q)
