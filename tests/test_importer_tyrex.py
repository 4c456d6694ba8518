"""The Tyrex attitude benchmark's walk reader (core.importers.tyrex) on a tiny synthetic walk: a QTM MAT export
(QTM's own header text) and the phone's text files."""

import io

import numpy as np
import pytest
import scipy.io as scipy_io

from core.importers._common import POSI, TRUTH_BODY_ATTITUDE
from core.importers.tyrex import read_tyrex
from core.recording import RecordingError

RATE_HZ = 60.0


def _qtm_mat(path, n: int, yaw_rad_s: float, lost: int) -> None:
    t = np.arange(n) / RATE_HZ
    pos = np.stack([1000.0 * t, 500.0 + 0 * t, 950.0 + 0 * t])  # mm: 1 m/s along x
    c, s = np.cos(yaw_rad_s * t), np.sin(yaw_rad_s * t)
    rot = np.stack([c, s, 0 * t, -s, c, 0 * t, 0 * t, 0 * t, 1 + 0 * t])  # Rz(yaw) column-major: column 0 first
    pos[:, lost], rot[:, lost] = np.nan, np.nan
    buf = io.BytesIO()
    scipy_io.savemat(buf, {"walk": {"Frames": float(n), "FrameRate": RATE_HZ, "StartFrame": 1.0,
                                    "RigidBodies": {"Name": np.array(["Nexus5-Handler"], dtype=object),
                                                    "Positions": pos[None], "Rotations": rot[None]}}})
    data = bytearray(buf.getvalue())
    data[:116] = b"QTM_ver 2.10 (build 2084), Level 5 MAT-file, Platform: Windows7".ljust(116, b" ")
    path.write_bytes(bytes(data))


def _walk(tmp_path, *, bad_line: str | None = None):
    folder = tmp_path / "datasets" / "android" / "Anna_Nexus5_NoDist_Swinging"
    folder.mkdir(parents=True)
    (tmp_path / "datasets" / "qualisys").mkdir()
    _qtm_mat(tmp_path / "datasets" / "qualisys" / "Anna_Nexus5_NoDist_Swinging.mat", 120, 0.5, lost=7)
    t = 0.5 + np.arange(400) / 200.0
    acc = "\n".join(f"{x:.6f} 0.1 0.2 9.81" for x in t) + "\n"
    if bad_line:
        acc = acc.replace("\n", "\n" + bad_line + "\n", 1)
    (folder / "accelerometer.txt").write_text(acc)
    (folder / "gyroscope-calibrated.txt").write_text("\n".join(f"{x:.6f} 0 0 0.5" for x in t) + "\n")
    (folder / "magnetometer-calibrated.txt").write_text("\n".join(f"{x:.6f} 20 0 -40 3" for x in t[::4]))
    (folder / "timeAlignment.txt").write_text("  -2.0000000e+00\n")
    return folder


def test_the_truth_is_put_on_the_phone_clock_in_metres_and_the_handler_rotation_is_kept(tmp_path):
    rec = read_tyrex(str(_walk(tmp_path)), warn=False)
    posi, att = rec.streams[POSI], rec.streams[TRUTH_BODY_ATTITUDE]
    assert len(posi.t_ns) == 119  # the lost frame 7 dropped
    k = np.array([i for i in range(120) if i != 7])
    np.testing.assert_array_equal(posi.t_ns, np.round((k / RATE_HZ + 2.0) * 1e9).astype(np.int64))  # phone = q - (-2)
    np.testing.assert_allclose(posi.values[:, 0], k / RATE_HZ, atol=1e-12)  # mm -> m
    np.testing.assert_allclose(posi.values[:, 1:], [[0.5, 0.95]] * 119, atol=1e-12)
    yaw = 0.5 * k / RATE_HZ  # body -> room is Rz(yaw): w = cos(yaw/2), z = sin(yaw/2)
    np.testing.assert_allclose(att.values, np.column_stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)]),
                               atol=1e-12)
    assert len(rec.streams["acc"].t_ns) == 400 and len(rec.streams["mag"].t_ns) == 100  # extra column ignored
    np.testing.assert_allclose(rec.streams["gyro"].values[0], [0, 0, 0.5])


def test_a_bad_line_is_skipped_and_counted_and_a_missing_truth_is_one_line(tmp_path):
    folder = _walk(tmp_path, bad_line="0.51 oops 1")
    rec = read_tyrex(str(folder), warn=False)
    assert len(rec.streams["acc"].t_ns) == 400 and any("skipped 1 bad line" in r for r in rec.repairs)
    (tmp_path / "datasets" / "qualisys" / "Anna_Nexus5_NoDist_Swinging.mat").unlink()
    with pytest.raises((RecordingError, OSError)):
        read_tyrex(str(folder), warn=False)


def test_an_iphone_walk_is_read_in_g_with_the_android_sign_on_the_boot_clock_and_its_mat_found_by_any_case(tmp_path):
    folder = tmp_path / "datasets" / "ios" / "Anna_iPhone5_NoDist_Backpocket"  # the repository's one odd spelling
    folder.mkdir(parents=True)
    (tmp_path / "datasets" / "qualisys").mkdir()
    _qtm_mat(tmp_path / "datasets" / "qualisys" / "Anna_iPhone5_NoDist_BackPocket.mat", 120, 0.5, lost=7)
    t = 1000.5 + np.arange(400) / 100.0
    (folder / "accelerometer.txt").write_text("\n".join(f"{x:.4f} 0.0100 -0.0200 -1.0000" for x in t) + "\n")
    (folder / "gyroscope.txt").write_text("\n".join(f"{x:.4f} 0.1 0 0.5" for x in t) + "\n")
    (folder / "magnetometer-calibrated.txt").write_text("\n".join(f"{x:.4f} -28.5 -21.7 14.8 2" for x in t[::4]))
    (folder / "timeAlignment.txt").write_text("  -2.0000000e+00\n")
    (folder / "description.txt").write_text("[Time]\nBootTime = 1000.0")
    rec = read_tyrex(str(folder), warn=False)
    acc = rec.streams["acc"]
    np.testing.assert_allclose(acc.values[0], [-0.0980665, 0.196133, 9.80665], atol=1e-12)  # g, negated
    np.testing.assert_array_equal(acc.t_ns[:2], [500_000_000, 510_000_000])  # minus BootTime
    np.testing.assert_allclose(rec.streams["gyro"].values[0], [0.1, 0, 0.5])
    assert len(rec.streams["mag"].t_ns) == 100 and rec.device["platform"] == "ios"
    k = np.array([i for i in range(120) if i != 7])
    np.testing.assert_array_equal(rec.streams[POSI].t_ns, np.round((k / RATE_HZ + 2.0) * 1e9).astype(np.int64))
