"""The Tyrex attitude benchmark's walk reader (core.importers.tyrex) on a tiny synthetic walk: a QTM MAT export
(QTM's own header text) and the phone's text files; its detection (``pdr replay`` given the walk's folder or one of
its files)."""

import io
import os

import numpy as np
import pytest
import scipy.io as scipy_io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.importers import TYREX, detect_format, load_recording
from core.importers import tyrex as _tyrex
from core.importers._common import POSI, TRUTH_BODY_ATTITUDE
from core.importers.tyrex import read_tyrex
from core.recording import RecordingError
from desktop.cli import collect_recordings
from test_bad_input_fuzz import FUZZ_EXAMPLES, _fresh

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
    with pytest.raises(RecordingError, match="no Qualisys truth for this Tyrex walk: .*qualisys.Anna_Nexus5_NoDist_"
                                             "Swinging.mat is missing"):
        read_tyrex(str(folder), warn=False)


# ---------------------------------------------------------------------------
# detection: what a user points ``pdr replay`` at

#: examples of the property test: a tenth of PDR_FUZZ_EXAMPLES (20 in CI), seeded unless a long fuzz run
EXAMPLES = max(10, FUZZ_EXAMPLES // 10)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("tyrex"))


@st.composite
def tyrex_walks(draw):
    """A walk's accelerometer and gyroscope rows (t s, x, y, z), its time offset, extra columns or not, and the
    path a user gives (the folder, or one of its files)."""
    n = draw(st.integers(3, 30))
    steps = draw(arrays(np.float64, n - 1, elements=st.floats(0.001, 0.05)))
    t = draw(st.floats(0.0, 100.0)) + np.concatenate([[0.0], np.cumsum(steps)])
    gravity = draw(st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda u: np.linalg.norm(u) > 0.1))
    g = 9.81 * np.asarray(gravity) / np.linalg.norm(gravity)
    acc = np.column_stack([t, g + draw(arrays(np.float64, (n, 3), elements=st.floats(-1.5, 1.5)))])
    gyro = np.column_stack([t, draw(arrays(np.float64, (n, 3), elements=st.floats(-10.0, 10.0)))])
    offset_s = -float(t[0] + draw(st.floats(-0.3, 0.3)))  # the truth's 0.5 s overlap the phone's (else it is dropped)
    extra = draw(st.booleans())
    given_as = draw(st.sampled_from(["folder", "folder/", *_tyrex.WALK_FILES]))
    return acc, gyro, offset_s, extra, given_as


def _write_walk(root: str, acc, gyro, offset_s: float, extra: bool, mag: bool = True) -> str:
    folder = os.path.join(root, "datasets", "android", "Bo_Nexus5_Dist_FrontPocket")
    os.makedirs(folder)
    os.makedirs(os.path.join(root, "datasets", "qualisys"))
    from pathlib import Path

    _qtm_mat(Path(root) / "datasets" / "qualisys" / "Bo_Nexus5_Dist_FrontPocket.mat", 30, 0.2, lost=3)

    def text(rows):
        return "".join(" ".join(repr(float(x)) for x in r) + (" 3" if extra else "") + "\n" for r in rows)

    with open(os.path.join(folder, "accelerometer.txt"), "w") as f:
        f.write(text(acc))
    with open(os.path.join(folder, "gyroscope-calibrated.txt"), "w") as f:
        f.write(text(gyro))
    if mag:
        with open(os.path.join(folder, "magnetometer-calibrated.txt"), "w") as f:
            f.write(text(np.column_stack([acc[:, 0], np.tile([20.0, 0.0, -40.0], (len(acc), 1))])))
    with open(os.path.join(folder, "timeAlignment.txt"), "w") as f:
        f.write(f"  {offset_s!r}\n")
    with open(os.path.join(folder, "record.properties"), "w") as f:
        f.write("[Device]\nModel = Nexus 5\n")
    return folder


@settings(max_examples=EXAMPLES, deadline=None, derandomize=FUZZ_EXAMPLES <= 200,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(walk=tyrex_walks())
def test_a_walk_given_as_its_folder_or_one_of_its_files_is_detected_and_read_back(workdir, walk):
    acc, gyro, offset_s, extra, given_as = walk
    folder = _write_walk(_fresh(workdir), acc, gyro, offset_s, extra)
    path = folder + "/" if given_as == "folder/" else folder if given_as == "folder" else os.path.join(folder, given_as)
    assert detect_format(path) == TYREX
    rec = load_recording(path, warn=False)
    np.testing.assert_array_equal(rec.streams["acc"].t_ns, np.round(acc[:, 0] * 1e9).astype(np.int64))
    np.testing.assert_array_equal(rec.streams["acc"].values, acc[:, 1:])  # written with repr: exact
    np.testing.assert_array_equal(rec.streams["gyro"].values, gyro[:, 1:])
    k = np.array([i for i in range(30) if i != 3])  # the truth on the phone's clock: Qualisys time - offset
    np.testing.assert_array_equal(rec.streams[POSI].t_ns, np.round((k / RATE_HZ - offset_s) * 1e9).astype(np.int64))
    assert rec.metadata["source_format"] == TYREX and rec.metadata["walk"] == "Bo_Nexus5_Dist_FrontPocket"


def test_a_walk_without_its_truth_is_one_clear_line_and_its_truth_points_at_the_walk(tmp_path):
    t = np.arange(20) * 0.005
    acc = np.column_stack([t, np.tile([0.1, 0.2, 9.8], (20, 1))])
    folder = _write_walk(str(tmp_path), acc, acc, -1.5, False, mag=False)
    mat = tmp_path / "datasets" / "qualisys" / "Bo_Nexus5_Dist_FrontPocket.mat"
    with pytest.raises(RecordingError, match="the Qualisys truth of the Tyrex walk Bo_Nexus5_Dist_FrontPocket: "
                                             "replay its folder .*android.Bo_Nexus5_Dist_FrontPocket"):
        detect_format(str(mat))
    found, _ = collect_recordings([str(tmp_path)])  # the whole dataset: each walk once, not its truth too
    assert found == [folder]
    assert set(load_recording(os.path.join(folder, "gyroscope-calibrated.txt"), warn=False).streams) == {
        "acc", "gyro", POSI, TRUTH_BODY_ATTITUDE}  # no magnetometer file: no mag stream
    mat.unlink()
    assert detect_format(folder) == TYREX  # the folder is still a Tyrex walk; reading it says what is missing
    with pytest.raises(RecordingError, match="no Qualisys truth for this Tyrex walk: .*Bo_Nexus5_Dist_FrontPocket."
                                             "mat is missing .*two folders above"):
        load_recording(os.path.join(folder, "accelerometer.txt"), warn=False)
    os.remove(os.path.join(folder, "timeAlignment.txt"))  # a needed file gone: not a Tyrex walk any more
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(folder)


def test_a_walk_without_its_clock_offset_is_one_clear_line(tmp_path):
    """``read_tyrex`` on a walk folder whose timeAlignment.txt is gone (review, 2026-12-08: a bare FileNotFoundError)."""
    t = np.arange(20) * 0.005
    acc = np.column_stack([t, np.tile([0.1, 0.2, 9.8], (20, 1))])
    folder = _write_walk(str(tmp_path), acc, acc, -1.5, False, mag=False)
    os.remove(os.path.join(folder, "timeAlignment.txt"))
    with pytest.raises(RecordingError, match="no timeAlignment.txt in this Tyrex walk's folder"):
        read_tyrex(folder, warn=False)


def test_other_space_separated_numbers_are_not_a_tyrex_accelerometer():
    rows = "".join(f"{1_000_000_000_000 + i * 5_000_000} 1 0.1 0.2 9.8\n" for i in range(20))  # Brajdic & Harle
    assert not _tyrex.looks_like(rows)
    assert not _tyrex.looks_like("".join(f"{i * 0.005} 0.01 0.02 0.99\n" for i in range(20)))  # g, not m/s^2
    assert not _tyrex.looks_like("".join(f"{1.0 - i * 0.005} 0.1 0.2 9.8\n" for i in range(20)))  # time goes back
    assert not _tyrex.looks_like("".join(f"{i * 0.005},0.1,0.2,9.8\n" for i in range(20)))  # commas
    assert _tyrex.looks_like("".join(f"{i * 0.005} 0.1 0.2 9.8\n" for i in range(20)))


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
    # pdr replay detects it from its folder or any of its files; its truth points at it (the case differs)
    for given in (str(folder), str(folder / "accelerometer.txt"), str(folder / "gyroscope.txt"),
                  str(folder / "description.txt")):
        assert detect_format(given) == TYREX
    assert set(load_recording(str(folder / "gyroscope.txt"), warn=False).streams) == set(rec.streams)
    with pytest.raises(RecordingError, match="replay its folder .*ios.Anna_iPhone5_NoDist_Backpocket"):
        detect_format(str(tmp_path / "datasets" / "qualisys" / "Anna_iPhone5_NoDist_BackPocket.mat"))
    # in m/s^2 it is no iPhone walk (g is the iPhone layout's unit), and an Android walk stays one
    assert not _tyrex.looks_like("".join(f"{1000 + i * 0.01} 0.1 0.2 9.8\n" for i in range(20)), ios=True)
    assert _tyrex.looks_like("".join(f"{100000 + i * 0.01} 0.01 -0.02 -1.0\n" for i in range(20)), ios=True)
