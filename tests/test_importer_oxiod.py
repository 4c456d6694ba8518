"""OxIOD syn pairs (core.importers.oxiod): a synthetic pair written by the test, never a copy of the data."""

import numpy as np
import pytest

from core.conventions import STANDARD_GRAVITY_M_S2
from core.importers import OXIOD, detect_format, load_recording
from core.importers.oxiod import read_oxiod, vicon_path
from core.recording import RecordingError


def _write_pair(folder, n=300, k=3, seed=7):
    rng = np.random.default_rng(seed)
    att = rng.uniform(-1.5, 1.5, size=(n, 3))  # roll, pitch, yaw (rad): Core Motion's ranges
    rate = rng.normal(scale=0.5, size=(n, 3))
    grav = np.tile([0.1, -0.2, -0.97], (n, 1)) + rng.normal(scale=0.01, size=(n, 3))  # iOS sign: points down
    user = rng.normal(scale=0.2, size=(n, 3))
    mag = rng.normal(scale=20.0, size=(n, 3))
    imu = np.column_stack([np.full(n, 1.5e11), att, rate, grav, user, mag])
    pos = np.cumsum(rng.normal(scale=0.01, size=(n, 3)), axis=0) + [1.0, 2.0, 0.9]
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)  # the Vicon's unit quaternion
    vi = np.column_stack([np.full(n, 1.5e11), np.full(n, 2.1e5), pos, quat])
    fmt = lambda a: "".join(",".join(f"{x:.6g}" for x in row) + "\n" for row in a)  # noqa: E731
    (folder / f"imu{k}.csv").write_text(fmt(imu))
    (folder / f"vi{k}.csv").write_text(fmt(vi))
    return imu, vi


def test_oxiod_pair_round_trip(tmp_path):
    imu, vi = _write_pair(tmp_path)
    rec = read_oxiod(str(tmp_path / "imu3.csv"), warn=False)
    acc, gyro, mag, posi = (rec.streams[s] for s in ("acc", "gyro", "mag", "posi"))
    # the total acceleration is gravity + user acceleration (g, iOS sign), turned into the specific force in m/s^2
    assert np.allclose(acc.values, -STANDARD_GRAVITY_M_S2 * (imu[:, 7:10] + imu[:, 10:13]), rtol=1e-5, atol=1e-4)
    assert np.mean(acc.values[:, 2]) > 9.0  # screen up reads +g (the specific force)
    assert np.allclose(gyro.values, imu[:, 4:7], rtol=1e-5, atol=1e-6)
    assert np.allclose(mag.values, imu[:, 13:16], rtol=1e-5, atol=1e-4)
    assert np.allclose(posi.values, vi[:, 2:5], rtol=1e-5, atol=1e-5)
    # rows at 100 Hz: the syn files' Time column is not read
    assert np.all(np.diff(acc.t_ns) == 10_000_000) and acc.t_ns[0] == 0
    assert np.array_equal(posi.t_ns, acc.t_ns)


def test_oxiod_bad_line_keeps_rows_aligned_and_mismatch_refused(tmp_path):
    imu, vi = _write_pair(tmp_path, n=400)
    lines = (tmp_path / "imu3.csv").read_text().splitlines(True)
    lines[10] = "1.5e11,oops\n"
    (tmp_path / "imu3.csv").write_text("".join(lines))
    rec = read_oxiod(str(tmp_path / "imu3.csv"), warn=False)
    assert len(rec.streams["acc"].t_ns) == 399 and 100_000_000 not in set(rec.streams["acc"].t_ns.tolist())
    assert len(rec.streams["posi"].t_ns) == 400 and rec.repairs  # the truth keeps row 10; the gap is counted
    assert np.allclose(rec.streams["posi"].values[11], vi[11, 2:5], atol=1e-5)
    (tmp_path / "vi3.csv").write_text("".join((tmp_path / "vi3.csv").read_text().splitlines(True)[:-5]))
    with pytest.raises(RecordingError, match="Vicon rows"):
        read_oxiod(str(tmp_path / "imu3.csv"), warn=False)
    assert vicon_path("/a/b/imu12.csv").endswith("/a/b/vi12.csv")
    with pytest.raises(RecordingError):
        vicon_path("/a/b/data.csv")


def test_oxiod_is_detected_by_content_as_a_file_or_its_folder_and_the_truth_comes_along(tmp_path):
    # fails before the wiring: detect_format refused the headerless file ("unrecognised recording format")
    imu, vi = _write_pair(tmp_path, n=200)
    assert detect_format(str(tmp_path / "imu3.csv")) == OXIOD
    assert detect_format(str(tmp_path)) == OXIOD  # a syn folder with one pair is read through its imu3.csv
    rec = load_recording(str(tmp_path), warn=False)
    assert rec.metadata["source_format"] == OXIOD and rec.metadata["truth_file"] == "vi3.csv"
    assert np.allclose(rec.streams["posi"].values, vi[:, 2:5], atol=1e-5)
    with pytest.raises(RecordingError, match="Vicon truth of the OxIOD sequence imu3.csv beside it"):
        detect_format(str(tmp_path / "vi3.csv"))
    other = tmp_path / "walk.csv"  # the content without the pair's name: its truth cannot be found
    other.write_bytes((tmp_path / "imu3.csv").read_bytes())
    with pytest.raises(RecordingError, match="not named imu<K>.csv"):
        detect_format(str(other))
    other.unlink()
    _write_pair(tmp_path, n=200, k=4)
    with pytest.raises(RecordingError, match=r"2 OxIOD/RIDI recordings in this folder \(imu3.csv, imu4.csv\)"):
        detect_format(str(tmp_path))


def _near_miss(imu: np.ndarray, what: str) -> str:
    v = imu.copy()
    if what == "gravity in m/s^2":
        v[:, 7:10] *= STANDARD_GRAVITY_M_S2
    elif what == "pitch past 90 deg":
        v[:, 2] = 2.0
    elif what == "a spinning gyroscope":
        v[:, 4] = 50.0
    elif what == "15 fields":
        v = v[:, :15]
    elif what == "17 fields":
        v = np.column_stack([v, v[:, :1]])
    text = "".join(",".join(f"{x:.6g}" for x in row) + "\n" for row in v)
    return "Time,roll,pitch,yaw,rx,ry,rz,gx,gy,gz,ux,uy,uz,mx,my,mz\n" + text if what == "a header line" else text


@pytest.mark.parametrize("what", ["gravity in m/s^2", "pitch past 90 deg", "a spinning gyroscope", "15 fields",
                                  "17 fields", "a header line"])
def test_oxiod_lookalikes_are_not_detected(tmp_path, what):
    imu, _ = _write_pair(tmp_path, n=30)
    (tmp_path / "imu3.csv").write_text(_near_miss(imu, what))
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(str(tmp_path / "imu3.csv"))


def test_oxiod_drops_repeated_magnetometer_rows_and_reads_or_gaps_the_last_line(tmp_path):
    # fails before the change: every row's field was a mag sample (Core Motion repeats it at about half the rows)
    imu, vi = _write_pair(tmp_path, n=200)
    imu[1::2, 13:16] = imu[0:-1:2, 13:16]  # each field on two rows ...
    imu[4:8, 13:16] = imu[4, 13:16]  # ... and one on four (rows 4-7)
    text = "".join(",".join(f"{x:.6g}" for x in row) + "\n" for row in imu)
    (tmp_path / "imu3.csv").write_text(text.rstrip("\n"))  # the last line without its newline: a row
    rec = read_oxiod(str(tmp_path / "imu3.csv"), warn=False)
    mag = rec.streams["mag"]
    kept = [i for i in range(200) if i % 2 == 0 and i != 6]  # the first row of each run
    assert np.array_equal(mag.t_ns, np.asarray(kept) * 10_000_000)
    assert np.allclose(mag.values, imu[kept, 13:16], rtol=1e-5, atol=1e-4)
    assert rec.metadata["mag_repeats_dropped"] == 200 - len(kept) and not rec.repairs
    assert len(rec.streams["acc"].t_ns) == 200  # the other streams keep every row
    (tmp_path / "imu3.csv").write_text(text.rstrip("\n")[:-12])  # the last line cut inside its fields: a gap
    rec = read_oxiod(str(tmp_path / "imu3.csv"), warn=False)
    assert len(rec.streams["acc"].t_ns) == 199 and len(rec.streams["posi"].t_ns) == 200
    assert any("cut off" in r for r in rec.repairs)


def test_oxiod_gzip_pair_is_read_and_its_size_limit_holds(tmp_path):
    import gzip

    imu, vi = _write_pair(tmp_path, n=100)
    for name in ("imu3.csv", "vi3.csv"):
        (tmp_path / (name + ".gz")).write_bytes(gzip.compress((tmp_path / name).read_bytes()))
    rec = read_oxiod(str(tmp_path / "imu3.csv.gz"), warn=False)
    assert len(rec.streams["acc"].t_ns) == 100 and rec.metadata["truth_file"] == "vi3.csv.gz"
    with pytest.raises(RecordingError, match="1000"):
        read_oxiod(str(tmp_path / "imu3.csv.gz"), warn=False, max_uncompressed_bytes=1000)
