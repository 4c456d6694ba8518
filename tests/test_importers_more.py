"""Issue #15 "Done when": the foot-IMU dataset formats as importable files.

x-io NGIMU / x-IMU CSVs, XSens text exports (IPOL trials: lower back and
both feet in one recording), PyShoe's processed MAT-files (through the
numpy + zlib MAT v5 reader :mod:`core.importers.matv5`) and the
TrundleWheel authors' 1 Hz resampled files:

* property tests: a valid file of each format round-trips (values within
  the stated number formatting, units converted); the MAT reader agrees with
  scipy's writer on random variables (both byte orders, compressed or not,
  gzip or not); corrupted files give a clean RecordingError naming the file
  or a well-formed recording (the harness of ``test_bad_input_fuzz.py``);
* lookalikes are refused, the formats told apart (a phyphox CSV stays
  phyphox, a MAT-file without PyShoe's variables is not PyShoe);
* each format's own rules (units, the x-IMU rate, counter wraps, an IPOL
  trial's three files, the PyShoe truth in the recording, size limits);
* the real files of ``../shared/data`` (skipped when absent).
"""

from __future__ import annotations

import gzip
import io
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.importers import (PHYPHOX, PYSHOE, TRUNDLE, XIO, XSENS, detect_format, load_recording, read_pyshoe,
                            read_xio, read_xsens)
from core.importers import matv5
from core.importers.trundle import LowRateWarning
from core.metrics import truth_of
from core.recording import RecordingError, read_recording, write_recording
from test_bad_input_fuzz import FUZZ_EXAMPLES, _damage, _fresh, _gravity, _read, _steps, _values
from test_importers_formats import _first, _write, needs_data

scipy_io = pytest.importorskip("scipy.io")

G = 9.80665
#: examples per property test: a tenth of PDR_FUZZ_EXAMPLES (20 in CI); seeded unless a long fuzz run
EXAMPLES = max(10, FUZZ_EXAMPLES // 10)
_SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=FUZZ_EXAMPLES <= 200,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                            HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("more_formats"))


def _mat_bytes(variables: dict, compress: bool = False) -> bytes:
    buf = io.BytesIO()
    scipy_io.savemat(buf, variables, do_compression=compress)
    return buf.getvalue()


# ---------------------------------------------------------------------------
# the MAT v5 reader against scipy's writer

_DTYPES = [np.float64, np.float32, np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.uint64]


@st.composite
def mat_variables(draw):
    out = {}
    for k in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(["num", "num", "bool", "text"]))
        name = f"v{k}_" + draw(st.text("abcxyz_", max_size=6))
        if kind == "text":
            out[name] = draw(st.text("abc XYZ-_0123456789", min_size=1, max_size=20))
            continue
        shape = tuple(draw(st.lists(st.integers(1, 6), min_size=1, max_size=3)))
        if kind == "bool":
            out[name] = draw(arrays(np.bool_, shape))
            continue
        dt = np.dtype(draw(st.sampled_from(_DTYPES)))
        el = (st.floats(-1e6, 1e6, allow_nan=False, width=32 if dt == np.float32 else 64) if dt.kind == "f"
              else st.integers(int(np.iinfo(dt).min), int(np.iinfo(dt).max)))
        out[name] = draw(arrays(dt, shape, elements=el))
    return out


@_SETTINGS
@given(variables=mat_variables(), compress=st.booleans(), gz=st.booleans())
def test_the_mat_reader_reads_what_scipy_writes(workdir, variables, compress, gz):
    path = _write(_fresh(workdir), "v.mat", _mat_bytes(variables, compress), gz)
    with open(path, "rb") as f:
        mat = matv5.read_mat(f, path)
    back = scipy_io.loadmat(path if not gz else io.BytesIO(gzip.open(path).read()))
    assert mat.all_names == [n for n in back if not n.startswith("__")]
    for name, want in back.items():
        if name.startswith("__"):
            continue
        got = mat[name]
        if want.dtype.kind == "U":
            assert got == str(want.ravel()[0])
        elif isinstance(variables[name], np.ndarray) and variables[name].dtype == np.bool_:
            assert got.dtype == np.bool_ and got.shape == want.shape  # logical (scipy gives uint8)
            np.testing.assert_array_equal(got, want.astype(bool))
        else:
            assert got.dtype == want.dtype and got.shape == want.shape, name
            np.testing.assert_array_equal(got, want)


def _element(order: str, typ: int, data: bytes) -> bytes:
    if len(data) <= 4:  # small data element
        return struct.pack(order + "HH", typ, len(data)) if order == "<" else struct.pack(order + "HH", len(data),
                                                                                           typ)
    return struct.pack(order + "II", typ, len(data)) + data + b"\0" * ((-len(data)) % 8)


def _small(order: str, typ: int, data: bytes) -> bytes:
    a = (len(data) << 16) | typ
    return struct.pack(order + "I", a) + data + b"\0" * (4 - len(data))


def _matrix(order: str, name: str, cls: int, dims, data_type: int, data: bytes) -> bytes:
    flags = struct.pack(order + "II", cls, 0)
    body = (_element(order, matv5.MI_UINT32, flags) + _element(order, matv5.MI_INT32,
                                                                struct.pack(order + f"{len(dims)}i", *dims))
            + (_small(order, matv5.MI_INT8, name.encode()) if len(name) <= 4
               else _element(order, matv5.MI_INT8, name.encode()))
            + (_small(order, data_type, data) if len(data) <= 4 else _element(order, data_type, data)))
    return struct.pack(order + "II", matv5.MI_MATRIX, len(body)) + body


def _header(order: str) -> bytes:
    text = b"MATLAB 5.0 MAT-file, written by a test".ljust(116, b" ")
    return text + b"\0" * 8 + struct.pack(order + "H", 0x0100) + (b"IM" if order == "<" else b"MI")


@pytest.mark.parametrize("order", ["<", ">"])
def test_the_mat_reader_reads_both_byte_orders_small_elements_and_compressed_ones(tmp_path, order):
    a = np.arange(6, dtype=float).reshape(2, 3)
    data = _header(order)
    data += _matrix(order, "a", 6, (2, 3), matv5.MI_DOUBLE, a.astype(order + "f8").tobytes(order="F"))
    data += _matrix(order, "k", 12, (1, 1), matv5.MI_INT16, struct.pack(order + "h", -7))  # int32 class, int16 data
    inner = _matrix(order, "name", 4, (1, 3), matv5.MI_UTF8, b"abc")
    data += struct.pack(order + "II", matv5.MI_COMPRESSED, len(zlib.compress(inner))) + zlib.compress(inner)
    p = tmp_path / "t.mat"
    p.write_bytes(data)
    with open(p, "rb") as f:
        mat = matv5.read_mat(f, str(p))
    np.testing.assert_array_equal(mat["a"], a)
    assert mat["k"].dtype == np.int32 and mat["k"].tolist() == [[-7]]
    assert mat["name"] == "abc" and mat.all_names == ["a", "k", "name"]


def test_the_mat_reader_skips_what_it_does_not_read_and_refuses_what_is_no_mat_v5(tmp_path):
    p = tmp_path / "c.mat"
    p.write_bytes(_mat_bytes({"cells": np.array([[1, "x"]], dtype=object), "s": {"a": 1}, "z": np.array([1 + 2j]),
                              "ok": np.ones(3)}))
    with open(p, "rb") as f:
        mat = matv5.read_mat(f, str(p))
    assert mat.names() == ["ok"] and mat.skipped == {"cells": "cell array", "s": "structure", "z": "complex array"}
    with pytest.raises(RecordingError, match="is a structure"):
        mat["s"]
    with pytest.raises(RecordingError, match="no variable 'imu'"):
        mat["imu"]
    p.write_bytes(b"MATLAB 7.3 MAT-file".ljust(512, b" ") + b"\x89HDF\r\n\x1a\n" + bytes(100))
    with open(p, "rb") as f, pytest.raises(RecordingError, match="7.3"):
        matv5.read_mat(f, str(p))
    big = _header("<") + struct.pack("<II", matv5.MI_MATRIX, 2_000_000_000)
    p.write_bytes(big)
    with open(p, "rb") as f, pytest.raises(RecordingError, match="limit"):
        matv5.read_mat(f, str(p), max_uncompressed_bytes=10_000_000)
    bomb = zlib.compress(_matrix("<", "z", 6, (1, 500_000), matv5.MI_DOUBLE, bytes(4_000_000)))
    p.write_bytes(_header("<") + struct.pack("<II", matv5.MI_COMPRESSED, len(bomb)) + bomb)
    with open(p, "rb") as f, pytest.raises(RecordingError, match="limit"):
        matv5.read_mat(f, str(p), max_uncompressed_bytes=1_000_000)
    with open(p, "rb") as f:
        assert matv5.read_mat(f, str(p))["z"].shape == (1, 500_000)


# ---------------------------------------------------------------------------
# PyShoe trials


@st.composite
def pyshoe_trials(draw):
    n = draw(st.integers(2, 60))
    ts = (draw(st.integers(0, 1000)) + _steps(draw, n, 4, 6)) / 1024.0  # exact in binary
    imu = np.hstack([-_gravity(draw, n), _values(draw, n, 3, 20.0)])
    gt = _values(draw, n, 3, 5.0)
    v = {"imu": imu, "ts": ts[None, :]}
    if draw(st.booleans()):
        v.update(gt=gt, zv_shoe_opt=draw(arrays(np.int64, (1, n), elements=st.integers(0, 1))),
                 zv_vicon_opt=draw(arrays(np.int64, (1, n), elements=st.integers(0, 1))),
                 G_shoe_opt=np.array([[2.75e6]]), trial_error=np.array([[0.03, 0.04, 0.05, 0.06, 0.4]]),
                 best_detector="shoe", best_error=np.array([[0.03]]))
    return _mat_bytes(v, draw(st.booleans())), draw(st.booleans()), v


@_SETTINGS
@given(trial=pyshoe_trials())
def test_valid_pyshoe_trials_round_trip(workdir, trial):
    data, gz, v = trial
    path = _write(_fresh(workdir), "2017-11-22-11-22-03.mat", data, gz)
    assert detect_format(path) == PYSHOE
    rec = _read(load_recording, path)
    assert rec is not None and not rec.repairs
    t = np.round(v["ts"].ravel() * 1e9).astype(np.int64)
    for name, cols in (("acc", slice(0, 3)), ("gyro", slice(3, 6))):
        np.testing.assert_array_equal(rec.streams[name].t_ns, t)
        np.testing.assert_array_equal(rec.streams[name].values, v["imu"][:, cols])
    assert rec.device["placement"] == "foot" and rec.metadata["source_format"] == PYSHOE
    if "gt" in v:
        np.testing.assert_array_equal(rec.streams["posi"].values, v["gt"][:, [1, 0, 2]])
        assert rec.streams["zero_velocity"].columns == ("shoe", "vicon")
        np.testing.assert_array_equal(rec.streams["zero_velocity"].values[:, 1], v["zv_vicon_opt"].ravel())
        assert rec.metadata["pyshoe_best"] == ["shoe", 0.03] and rec.metadata["pyshoe_thresholds"] == {"shoe": 2.75e6}
        assert rec.metadata["pyshoe_errors_m"]["vicon"] == 0.4
    else:
        assert set(rec.streams) == {"acc", "gyro"}


@_SETTINGS
@given(trial=pyshoe_trials(), data=st.data())
def test_corrupted_pyshoe_trials_read_or_raise_a_recording_error(workdir, trial, data):
    raw, gz, _ = trial
    raw = _damage(data.draw, raw)
    path = _write(_fresh(workdir), "t.mat", raw, gz)
    _read(data.draw(st.sampled_from([read_pyshoe, load_recording])), path)


def test_pyshoe_shapes_that_do_not_fit_and_other_mat_files_are_refused(tmp_path):
    p = tmp_path / "t.mat"
    p.write_bytes(_mat_bytes({"imu": np.zeros((10, 6)), "ts": np.arange(9.0)[None, :]}))
    with pytest.raises(RecordingError, match=r"t\.mat: PyShoe 'ts' has 9 times for 10 'imu' rows"):
        load_recording(str(p))
    p.write_bytes(_mat_bytes({"imu": np.zeros((10, 5)), "ts": np.arange(10.0)[None, :]}))
    with pytest.raises(RecordingError, match="not N x 6"):
        load_recording(str(p))
    p.write_bytes(_mat_bytes({"imu": np.zeros((10, 6)), "ts": np.arange(10.0)[None, :], "gt": np.zeros((9, 3))}))
    with pytest.raises(RecordingError, match="not 10 x 3"):
        load_recording(str(p))
    p.write_bytes(_mat_bytes({"data": np.zeros((10, 6))}))
    with pytest.raises(RecordingError, match="unrecognised recording format.*MAT-file without PyShoe"):
        detect_format(str(p))


def test_pyshoe_truth_survives_the_project_format_and_is_the_replays_truth(tmp_path):
    n = 400
    ts = np.arange(n) / 200.0
    gt = np.column_stack([np.linspace(0, 4, n), np.zeros(n), np.zeros(n)])  # x of the file = north
    p = tmp_path / "t.mat"
    p.write_bytes(_mat_bytes({"imu": np.tile([0, 0, -G, 0, 0, 0], (n, 1)), "ts": ts[None, :], "gt": gt}))
    rec = load_recording(str(p))
    truth = truth_of(rec)
    assert truth.landmarks is not None and len(truth.landmarks.t_ns) == n
    np.testing.assert_allclose(truth.landmarks.north_m[-1] - truth.landmarks.north_m[0], 4.0)
    write_recording(str(tmp_path / "t.pdr.gz"), rec)
    back = read_recording(str(tmp_path / "t.pdr.gz"))
    assert back.streams["posi"].columns == ("east_m", "north_m", "up_m")
    np.testing.assert_allclose(back.streams["posi"].values, rec.streams["posi"].values, rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------
# x-io CSVs

NGIMU_HEAD = ("Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),"
              "Accelerometer Y (g),Accelerometer Z (g)")
XIMU_HEAD = ("Packet number,Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),"
             "Accelerometer Y (g),Accelerometer Z (g),Magnetometer X (G),Magnetometer Y (G),Magnetometer Z (G)")


@st.composite
def xio_files(draw):
    n = draw(st.integers(1, 80))
    ximu = draw(st.booleans())
    mag = ximu or draw(st.booleans())
    baro = not ximu and draw(st.booleans())
    gyro = _values(draw, n, 3, 2000.0)
    acc = _gravity(draw, n) / G
    magv = _values(draw, n, 3, 0.8 if ximu else 80.0)
    head = XIMU_HEAD if ximu else NGIMU_HEAD + (",Magnetometer X (uT),Magnetometer Y (uT),Magnetometer Z (uT)"
                                                if mag else "") + (",Barometer (hPa)" if baro else "")
    t = (draw(st.integers(0, 100)) + _steps(draw, n, 9, 11)) / 4096.0
    rows = []
    for i in range(n):
        f = [str(i * 3 + 3) if ximu else repr(float(t[i]))] + [repr(float(x)) for x in gyro[i]]
        f += [repr(float(x)) for x in acc[i]] + ([repr(float(x)) for x in magv[i]] if mag else [])
        rows.append(",".join(f + (["1013.25"] if baro else [])))
    t_ns = np.round(np.arange(n) * (1e9 / 256.0)).astype(np.int64) if ximu else np.round(t * 1e9).astype(np.int64)
    expected = {"gyro": (t_ns, np.radians(gyro)), "acc": (t_ns, acc * G)}
    if mag:
        expected["mag"] = (t_ns, magv * (100.0 if ximu else 1.0))
    if baro:
        expected["pressure"] = (t_ns, np.full((n, 1), 1013.25))
    return (head + "\n" + "\n".join(rows) + "\n").encode(), draw(st.booleans()), expected, ximu


@_SETTINGS
@given(f=xio_files())
def test_valid_xio_files_round_trip(workdir, f):
    data, gz, expected, ximu = f
    path = _write(_fresh(workdir), "walk.csv", data, gz)
    assert detect_format(path) == XIO
    rec = _read(load_recording, path)
    assert rec is not None and not rec.repairs and set(rec.streams) == set(expected)
    for name, (t, v) in expected.items():
        np.testing.assert_array_equal(rec.streams[name].t_ns, t)
        np.testing.assert_allclose(rec.streams[name].values, v, rtol=1e-15, atol=0)
    assert rec.device["model"] == ("x-io x-IMU" if ximu else "x-io NGIMU") and "placement" not in rec.device
    assert ("rate_hz_assumed" in rec.metadata) == ximu


@_SETTINGS
@given(f=xio_files(), data=st.data())
def test_corrupted_xio_files_read_or_raise_a_recording_error(workdir, f, data):
    raw, gz = f[0], f[1]
    path = _write(_fresh(workdir), "walk.csv", _damage(data.draw, raw), gz)
    _read(data.draw(st.sampled_from([read_xio, load_recording])), path)


def test_xio_session_folder_rate_units_and_lookalikes(tmp_path):
    rows = "".join(f"{i / 400:.6f},1,2,3,0,0,1\n" for i in range(50))
    session = tmp_path / "NGIMU - 0035EEA1"
    session.mkdir()
    (session / "sensors.csv").write_text(NGIMU_HEAD + "\n" + rows)
    (session / "quaternion.csv").write_text("Time (s),W,X,Y,Z\n0,1,0,0,0\n")
    assert detect_format(str(session)) == XIO
    rec = load_recording(str(session))
    assert len(rec.streams["acc"]) == 50 and rec.metadata["layout"] == "ngimu"
    ximu = tmp_path / "x.csv"
    ximu.write_text(XIMU_HEAD + "\n" + "".join(f"{i},1,2,3,0,0,1,0.1,0.2,0.3\n" for i in range(10)))
    assert read_xio(str(ximu), ximu_rate_hz=100.0).streams["acc"].t_ns[-1] == 90_000_000
    bad = tmp_path / "bad.csv"
    bad.write_text(NGIMU_HEAD.replace("(g)", "(furlongs)") + "\n" + rows)
    with pytest.raises(RecordingError, match=r"bad\.csv.*Accelerometer in 'furlongs'"):
        load_recording(str(bad))
    phy = tmp_path / "Accelerometer.csv"  # phyphox's "Time (s)" CSV is not x-io
    phy.write_text('"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"\n'
                   + "".join(f"{i / 100},0.1,0.2,9.8\n" for i in range(30)))
    assert detect_format(str(phy)) == PHYPHOX
    half = tmp_path / "half.csv"  # no accelerometer: not x-io
    half.write_text("Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s)\n" + "0,1,2,3\n" * 5)
    assert _detect_or_none(str(half)) != XIO
    loops = tmp_path / "loops"  # x-io CSVs side by side: a folder of recordings, not one export
    loops.mkdir()
    for k in range(2):
        (loops / f"walk{k}.csv").write_text(NGIMU_HEAD + "\n" + rows)
    assert _detect_or_none(str(loops)) is None and detect_format(str(loops / "walk0.csv")) == XIO


def _detect_or_none(path: str):
    try:
        return detect_format(path)
    except RecordingError:
        return None


# ---------------------------------------------------------------------------
# XSens text exports and IPOL trials

XS_HEAD = "PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z\tMag_X\tMag_Y\tMag_Z"


def _xsens_text(counter, acc, gyr, mag, rate: str = "100") -> str:
    rows = ["\t".join([f"{float(c):.1f}"] + [repr(float(x)) for x in (*a, *g, *m)])
            for c, a, g, m in zip(counter, acc, gyr, mag)]
    return f"Acquisition frequency: {rate} Hz\n{XS_HEAD}\n" + "\n".join(rows) + "\n"


@st.composite
def xsens_files(draw):
    n = draw(st.integers(1, 80))
    counter = draw(st.integers(0, 500)) + _steps(draw, n, 1, 4)  # dropped packets: gaps
    acc, gyr, mag = _gravity(draw, n), _values(draw, n, 3, 30.0), _values(draw, n, 3, 1.5)
    return _xsens_text(counter, acc, gyr, mag).encode(), draw(st.booleans()), (counter, acc, gyr, mag)


@_SETTINGS
@given(f=xsens_files())
def test_valid_xsens_files_round_trip(workdir, f):
    data, gz, (counter, acc, gyr, mag) = f
    path = _write(_fresh(workdir), "export.txt", data, gz)
    assert detect_format(path) == XSENS
    rec = _read(load_recording, path)
    assert rec is not None and not rec.repairs
    t = counter * 10_000_000
    for name, v in (("acc", acc), ("gyro", gyr), ("mag", mag * 47.0)):
        np.testing.assert_array_equal(rec.streams[name].t_ns, t)
        np.testing.assert_allclose(rec.streams[name].values, v, rtol=1e-15, atol=0)
    assert "placement" not in rec.device


@_SETTINGS
@given(f=xsens_files(), data=st.data())
def test_corrupted_xsens_files_read_or_raise_a_recording_error(workdir, f, data):
    path = _write(_fresh(workdir), "export.txt", _damage(data.draw, f[0]), f[1])
    _read(data.draw(st.sampled_from([read_xsens, load_recording])), path)


def _trial_files(folder: Path, n: int = 300, gz: bool = True) -> None:
    rng = np.random.default_rng(15)
    for part, offset in (("lb", 0), ("lf", 2), ("rf", 1)):
        counter = np.arange(offset, offset + n)
        text = _xsens_text(counter, rng.normal([0, 0, G], 0.1, (n, 3)), rng.normal(0, 1, (n, 3)),
                           rng.normal(0, 0.5, (n, 3)))
        _write(str(folder), f"3-2_{part}.txt", text.encode(), gz)


def test_an_ipol_trial_is_one_recording_with_the_feet_as_devices(tmp_path):
    _trial_files(tmp_path)
    lb, lf = tmp_path / "3-2_lb.txt.gz", tmp_path / "3-2_lf.txt.gz"
    rec = load_recording(str(lb))
    assert rec.device["placement"] == "waist" and rec.metadata["trial"] == "3-2"
    assert set(rec.streams) == {f"{k}{d}" for k in ("acc", "gyro", "mag") for d in ("", "@left_foot", "@right_foot")}
    assert rec.streams["acc@left_foot"].t_ns[0] == 20_000_000 and rec.streams["acc@right_foot"].t_ns[0] == 10_000_000
    assert rec.metadata["devices"]["left_foot"]["placement"] == "left foot"
    from core.foot.tracker import choose_mode
    assert choose_mode(rec)[0] == "handheld" and choose_mode(rec, foot_device="left_foot")[0] == "foot"
    with pytest.raises(RecordingError, match=r"3-2_lf\.txt\.gz: a foot sensor of the IPOL trial.*3-2_lb\.txt\.gz.*"
                                             r"--foot-device left_foot"):
        detect_format(str(lf))
    alone = read_xsens(str(lb), with_siblings=False)
    assert set(alone.streams) == {"acc", "gyro", "mag"}
    lb.unlink()  # without its lower-back file a foot file is a recording of its own
    rec = load_recording(str(lf))
    assert rec.device["placement"] == "left foot" and choose_mode(rec)[0] == "foot"


def test_xsens_counter_wraps_rates_and_headers(tmp_path):
    counter = np.r_[np.arange(65530, 65536), np.arange(0, 6)]
    z = np.zeros((12, 3))
    p = tmp_path / "w.txt"
    p.write_text(_xsens_text(counter, z + [0, 0, G], z, z, rate="60"))
    rec = load_recording(str(p))
    assert rec.metadata["counter_wraps"] == 1 and rec.metadata["rate_hz"] == 60.0
    unwrapped = np.r_[counter[:6], counter[6:] + 65536]
    np.testing.assert_array_equal(rec.streams["acc"].t_ns, np.round(unwrapped * (1e9 / 60)).astype(np.int64))
    p.write_text(XS_HEAD + "\n0\t0\t0\t9.8\t0\t0\t0\t0\t0\t0\n")
    with pytest.raises(RecordingError, match=r"w\.txt.*no 'Acquisition frequency"):
        load_recording(str(p))
    p.write_text("Acquisition frequency: 100 Hz\nCounter\tAcc_X\tAcc_Y\tAcc_Z\n0\t0\t0\t9.8\n")
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(str(p))


# ---------------------------------------------------------------------------
# the TrundleWheel authors' resampled files

TWC_HEAD = ("time;m_acc_x;m_acc_y;m_acc_z;m_accG_x;m_accG_y;m_accG_z;m_rotTate_alpha;m_rotTate_beta;"
            "m_rotTate_gamma;p_lat;p_long;p_alt;p_acc;p_head;p_speed;steps;distance")


def test_trundle_conditioned_files_carry_gps_wheel_and_steps_on_the_app_clock(tmp_path):
    rows = [f"{1000 * i + 2};0.1;0.2;0.3;0.5;2.8;9.3;10;20;30;{55.6 + i * 1e-5};13.0;20;5;{90 + i};1.2;{1.5 * i};"
            f"{0.8 * i}" for i in range(120)]
    p = tmp_path / "normal_speed_1_conditioned.csv"
    p.write_text(TWC_HEAD + "\n" + "\n".join(rows) + "\n")
    assert detect_format(str(p)) == TRUNDLE
    with pytest.warns(LowRateWarning, match="1.0 Hz.*too coarse for step detection"):
        rec = load_recording(str(p))
    assert rec.metadata["layout"] == "conditioned" and "rate_warning" in rec.metadata
    assert set(rec.streams) == {"acc", "gyro", "gps", "wheel", "step_counts"}
    assert rec.streams["gps"].t_ns[1] == 1_002_000_000 and rec.streams["gps"].values[1, 5] == 91.0
    np.testing.assert_allclose(rec.streams["gyro"].values[0], np.radians([20, 30, 10]))
    assert truth_of(rec).distance["m"] == pytest.approx(0.8 * 119)


# ---------------------------------------------------------------------------
# size limits


@pytest.mark.parametrize("fmt", [XIO, XSENS, PYSHOE])
def test_a_gzip_stream_over_the_size_limit_is_refused(tmp_path, fmt):
    n = 3000
    if fmt == XIO:
        data = (NGIMU_HEAD + "\n" + "".join(f"{i / 400},1,2,3,0,0,1\n" for i in range(n))).encode()
    elif fmt == XSENS:
        z = np.zeros((n, 3))
        data = _xsens_text(np.arange(n), z + [0, 0, G], z, z).encode()
    else:
        data = _mat_bytes({"imu": np.zeros((n, 6)), "ts": np.arange(n)[None, :] / 200.0})
    p = _write(str(tmp_path), "f", data, gz=True)
    assert detect_format(p) == fmt
    with pytest.raises(RecordingError, match="limit"):
        load_recording(p, max_uncompressed_bytes=len(data) // 2)


# ---------------------------------------------------------------------------
# the real files (skipped when absent)


@needs_data
def test_real_foot_imu_files_are_recognised_and_read():
    seen = 0
    ng = _first("xio_foot_imu/ngimu_loops/short_walk.csv*")
    if ng is not None:
        rec = load_recording(str(ng), warn=False)
        assert rec.metadata["source_format"] == XIO and 380 < rec.streams["acc"].rate_hz < 410
        assert len(rec.repairs) == 2  # the NGIMU's repeated rows, dropped
        seen += 1
    xi = _first("xio_foot_imu/ximu_2011/straightLine_*.csv*")
    if xi is not None:
        rec = load_recording(str(xi))
        assert rec.streams["mag"].rate_hz == pytest.approx(256.0) and rec.duration_s == pytest.approx(38.9, abs=0.1)
        seen += 1
    lb = _first("ipol_healthy_gait_xsens/GaitData/1-1_lb.txt*")
    if lb is not None:
        rec = load_recording(str(lb))
        assert rec.device["placement"] == "waist" and set(rec.metadata["devices"]) == {"left_foot", "right_foot"}
        assert 9.0 < np.median(np.linalg.norm(rec.streams["acc@left_foot"].values, axis=1)) < 10.5
        with pytest.raises(RecordingError, match="lower-back file 1-1_lb"):
            detect_format(str(lb).replace("_lb", "_lf"))
        seen += 1
    ps = _first("pyshoe_vicon/processed/*.mat*")
    if ps is not None:
        rec = load_recording(str(ps))
        assert rec.device["placement"] == "foot" and 199 < rec.streams["acc"].rate_hz < 201
        d = scipy_io.loadmat(io.BytesIO(gzip.open(ps).read()) if str(ps).endswith(".gz") else str(ps))
        np.testing.assert_array_equal(rec.streams["posi"].values, d["gt"][:, [1, 0, 2]])
        np.testing.assert_array_equal(rec.streams["gyro"].values, d["imu"][:, 3:6])
        assert rec.metadata["pyshoe_best"][0] == str(d["best_detector"].ravel()[0]).strip()
        seen += 1
    tw = _first("trundlewheel_distance/conditioned_by_authors/*.csv*")
    if tw is not None:
        rec = load_recording(str(tw), warn=False)
        assert rec.metadata["layout"] == "conditioned" and 0.9 < rec.streams["gps"].rate_hz < 1.1
        assert rec.streams["wheel"].values[-1, 0] > 300
        seen += 1
    if not seen:
        pytest.skip("none of the foot-IMU datasets is in ../shared/data")
