"""MATLAB Mobile sensor logs saved as MAT-files: timetable objects (MCOS) in the subsystem data (issue #25).

Synthetic files only, written here in the layout the module doc describes (the real logs stay outside the
repository): the sensors read back to the values written (times from the datetimes, sub-millisecond digits
of a complex datetime included, GPS columns mapped), the format is recognised from the file and from a folder
holding it, and damaged object metadata or a missing column is one line naming the file.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from core.importers import MATLAB_MOBILE, PYSHOE, detect_format, load_recording
from core.importers import matv5
from core.recording import RecordingError

T0_MS = 1_678_801_040_000.0  # 2023-03-14, as in the real logs


def _el(typ: int, data: bytes) -> bytes:
    return struct.pack("<II", typ, len(data)) + data + b"\0" * ((-len(data)) % 8)


def _matrix(cls: int, dims, name: str, *subs: bytes, complex_: bool = False) -> bytes:
    flags = struct.pack("<II", cls | (0x800 if complex_ else 0), 0)
    return _el(14, _el(6, flags) + _el(5, struct.pack(f"<{len(dims)}i", *dims)) + _el(1, name.encode()) + b"".join(subs))


def _double(a, name: str = "") -> bytes:
    a = np.asarray(a)
    if np.iscomplexobj(a):
        return _matrix(6, (len(a), 1), name, _el(9, a.real.astype("<f8").tobytes()),
                       _el(9, a.imag.astype("<f8").tobytes()), complex_=True)
    return _matrix(6, (len(a), 1), name, _el(9, np.asarray(a, "<f8").tobytes()))


def _u32(a, name: str = "") -> bytes:
    return _matrix(13, (len(a), 1), name, _el(6, np.asarray(a, "<u4").tobytes()))


def _u8(b: bytes, name: str = "") -> bytes:
    return _matrix(9, (1, len(b)), name, _el(2, b))


def _char(s: str) -> bytes:
    return _matrix(4, (1, len(s)), "", _el(4, s.encode("utf-16-le")))


def _cell(items: list[bytes], dims=None) -> bytes:
    return _matrix(1, dims or (1, len(items)), "", *items)


def _struct(fields: dict, name: str = "") -> bytes:
    width = 32
    names = b"".join(k.encode().ljust(width, b"\0") for k in fields)
    return _matrix(2, (1, 1), name, _el(5, struct.pack("<i", width)), _el(1, names), *fields.values())


def _opaque(name: str, type_name: str, class_name: str, data: bytes) -> bytes:
    body = _el(6, struct.pack("<II", 17, 0)) + _el(1, name.encode()) + _el(1, type_name.encode())
    return _el(14, body + _el(1, class_name.encode()) + data)


def _ref(obj_id: int, class_id: int) -> list[int]:
    return [0xDD000000, 2, 1, 1, obj_id, class_id]


def _metadata(n_sensors: int, names: list[str]) -> bytes:
    """Names, classes (1 datetime, 2 timetable), objects (timetable 2k-1, its datetime 2k), property lists."""
    text = b"".join(n.encode() + b"\0" for n in names)
    text += b"\0" * ((-len(text)) % 8)
    seg1 = [0, 0, 0, 0, 0, 4, 0, 0, 0, 6, 0, 0]
    seg2, seg3, seg4 = [0, 0], [0] * 6, [0, 0]
    for k in range(n_sensors):
        seg2 += [1, 1, 1, 3 * k + 2]  # timetable: 'any' -> cell 3k + 4
        seg4 += [2, 2, 1, 3 * k, 3, 1, 3 * k + 1, 0]  # datetime: 'data' -> cell 3k + 2, 'fmt' -> 3k + 3
        seg3 += [2, 0, 0, k + 1, 0, 2 * k + 2] + [1, 0, 0, 0, k + 1, 2 * k + 1]
    segs = [seg1, seg2, seg3, seg4, []]
    offsets, pos = [], 40 + len(text)
    for sg in segs:
        offsets.append(pos)
        pos += 4 * len(sg)
    offsets = offsets[1:] + [pos]
    head = struct.pack("<II", 4, len(names)) + struct.pack("<8I", offsets[0] - 0 if False else 40 + len(text),
                                                            *offsets[:5], 0, 0)
    return head + text + b"".join(struct.pack(f"<{len(sg)}I", *sg) for sg in segs)


def _log(path, sensors: dict, *, break_metadata: bool = False):
    """Write a MATLAB Mobile-like MAT-file: ``sensors`` maps a variable to (unix ms times, {column: values})."""
    names = ["any", "data", "fmt", "datetime", "tz", "timetable"]
    cells = [None, None]
    top = b""
    for k, (var, (ms, cols)) in enumerate(sensors.items()):
        cells += [_double(ms), _char("dd-MMM-uuuu HH:mm:ss.SSS"),
                  _struct({"data": _cell([_double(v) for v in cols.values()]),
                           "varNames": _cell([_char(c) for c in cols]),
                           "rowTimes": _u32(_ref(2 * k + 2, 1)), "numRows": _double([float(len(ms))])})]
        top += _opaque(var, "MCOS", "timetable", _u32(_ref(2 * k + 1, 2)))
    meta = _metadata(len(sensors), names)
    if break_metadata:
        meta = meta[:36]
    cells[0] = _u8(meta)
    cells[1] = _matrix(6, (0, 0), "", _el(9, b""))
    store = _struct({"MCOS": _opaque("", "MCOS", "FileWrapper__", _cell(cells, (len(cells), 1)))})
    subsystem = b"\x00\x01IM\x00\x00\x00\x00" + store
    header = b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: test".ljust(116, b" ") + b"\0" * 8 + b"\x00\x01IM"
    path.write_bytes(header + top + _u8(subsystem))
    return path


def _walk(n: int = 400, rate_hz: float = 100.0, seed: int = 1):
    rng = np.random.default_rng(seed)
    ms = T0_MS + np.arange(n) * 1000.0 / rate_hz
    acc = {"X": 0.3 * rng.standard_normal(n), "Y": -9.6 + rng.standard_normal(n), "Z": 0.5 * rng.standard_normal(n)}
    gyro = {"X": rng.standard_normal(n), "Y": rng.standard_normal(n), "Z": rng.standard_normal(n)}
    mag = {"X": 20 + rng.standard_normal(n), "Y": -5 + rng.standard_normal(n), "Z": -40 + rng.standard_normal(n)}
    gps_ms = T0_MS + np.array([1500.0, 2500.0, 3500.0])
    gps = {"latitude": [52.45, 52.4501, 52.4502], "longitude": [-1.936, -1.936, -1.9359], "altitude": [197.6] * 3,
           "speed": [1.2, 1.3, 1.4], "course": [10.0, 12.0, 11.0], "hacc": [13.5, 13.9, 9.0]}
    return {"Acceleration": (ms, acc), "AngularVelocity": (ms + 2.0, gyro), "MagneticField": (ms + 5.0, mag),
            "Position": (gps_ms, gps)}


def test_the_timetables_read_back_to_the_values_written(tmp_path):
    sensors = _walk()
    p = _log(tmp_path / "log.mat", sensors)
    assert detect_format(p) == MATLAB_MOBILE
    rec = load_recording(p)
    assert rec.metadata["source_format"] == MATLAB_MOBILE and rec.metadata["unix_offset_ns"] == int(T0_MS * 1e6)
    for var, stream in (("Acceleration", "acc"), ("AngularVelocity", "gyro"), ("MagneticField", "mag")):
        ms, cols = sensors[var]
        s = rec.streams[stream]
        assert np.array_equal(s.t_ns, np.round((ms - T0_MS) * 1e6).astype(np.int64))
        np.testing.assert_array_equal(s.values, np.column_stack(list(cols.values())))
    g = rec.streams["gps"]
    gps = sensors["Position"][1]
    np.testing.assert_allclose(g.values[:, 0], gps["latitude"])
    np.testing.assert_allclose(g.values[:, 3], gps["hacc"])  # lat, lon, alt, hacc, speed, course
    np.testing.assert_allclose(g.values[:, 4], gps["speed"])
    np.testing.assert_allclose(g.values[:, 5], gps["course"])


def test_a_complex_datetime_adds_its_sub_millisecond_part_and_a_folder_is_read_through_its_mat_file(tmp_path):
    sensors = _walk(200)
    ms, cols = sensors["Acceleration"]
    sensors["Acceleration"] = (ms + 0.25j, cols)  # MATLAB keeps the low digits in the imaginary part
    folder = tmp_path / "RightPocket50steps"
    folder.mkdir()
    _log(folder / "RightPocket50steps.mat", {"Acceleration": sensors["Acceleration"],
                                             "AngularVelocity": sensors["AngularVelocity"]})
    assert detect_format(folder) == MATLAB_MOBILE
    a = load_recording(folder).streams["acc"]
    assert np.array_equal(np.diff(a.t_ns), np.full(199, 10_000_000)) and a.t_ns[0] == 250_000  # 0.25 ms in


def test_damaged_metadata_and_a_missing_column_are_one_line_naming_the_file(tmp_path):
    p = _log(tmp_path / "bad.mat", _walk(50), break_metadata=True)
    with pytest.raises(RecordingError, match="not a MATLAB Mobile log") as e:
        load_recording(p)
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)
    sensors = _walk(50)
    ms, cols = sensors["Acceleration"]
    sensors["Acceleration"] = (ms, {"X": cols["X"], "Y": cols["Y"]})
    q = _log(tmp_path / "noz.mat", sensors)
    with pytest.raises(RecordingError, match="lacks column"):
        load_recording(q)


def test_value_of_reads_nested_cells_structures_and_complex_numbers():
    body = _struct({"a": _cell([_double([1.0, 2.0]), _char("xy")]), "b": _double(np.array([1 + 2j]))})[8:]
    v = matv5.value_of(body, "<", "test")
    assert list(v) == ["a", "b"] and v["a"][1] == "xy"
    np.testing.assert_array_equal(v["a"][0].ravel(), [1.0, 2.0])
    assert v["b"].ravel()[0] == 1 + 2j


def test_a_pyshoe_mat_file_is_still_pyshoe(tmp_path):
    header = b"MATLAB 5.0 MAT-file, test".ljust(116, b" ") + b"\0" * 8 + b"\x00\x01IM"
    p = tmp_path / "trial.mat"
    p.write_bytes(header + _double(np.zeros(6), "imu") + _double(np.arange(6.0), "ts"))
    assert detect_format(p) == PYSHOE


def test_an_accelerometer_only_log_is_read_and_a_plain_acceleration_matrix_is_not_a_log(tmp_path):
    # MATLAB Mobile with only the accelerometer on saves one timetable (GitHub Tclack88/MatlabSucks,
    # NIghtwing1914/Assignment2-Ubicomp): recognised and read back; a bare 'Acceleration' double is not a log
    ms, cols = _walk(300, rate_hz=53.0)["Acceleration"]
    p = _log(tmp_path / "120_pocket_sensorlog.mat", {"Acceleration": (ms, cols)})
    assert detect_format(p) == MATLAB_MOBILE
    rec = load_recording(p)
    assert set(rec.streams) == {"acc"}
    np.testing.assert_array_equal(rec.streams["acc"].values, np.column_stack(list(cols.values())))
    assert np.array_equal(rec.streams["acc"].t_ns, np.round((ms - T0_MS) * 1e6).astype(np.int64))
    header = b"MATLAB 5.0 MAT-file, test".ljust(116, b" ") + b"\0" * 8 + b"\x00\x01IM"
    q = tmp_path / "plain.mat"
    q.write_bytes(header + _double(np.zeros(9), "Acceleration"))
    with pytest.raises(RecordingError, match="MAT-file without"):
        detect_format(q)


def test_the_csv_matlab_writes_from_an_accelerometer_log_reads_back_and_skips_a_bad_line(tmp_path):
    # writetable(splitvars(struct2table(load(log)))) of an accelerometer-only log (GitHub Tclack88/MatlabSucks)
    from core.importers import MATLAB_MOBILE_CSV
    rng = np.random.default_rng(3)
    n = 400
    ms = np.round(np.cumsum(np.full(n, 19.0) + rng.integers(-1, 2, n)))  # about 53 Hz, whole ms as written
    acc = np.column_stack([0.3 * rng.standard_normal(n), -9.6 + rng.standard_normal(n), rng.standard_normal(n)])
    t0 = np.datetime64("2023-03-16T23:59:59.500")  # the day changes inside the file
    lines = ["Acceleration_Timestamp,X,Y,Z"]
    for m, (x, y, z) in zip(ms, acc):
        t = (t0 + np.timedelta64(int(m), "ms")).astype(object)
        lines.append(f"{t:%d-%b-%Y %H:%M:%S}.{t.microsecond // 1000:03d},{float(x)!r},{float(y)!r},{float(z)!r}")
    lines.insert(200, "16-Mar-2023 25:99,1,2,3")  # a damaged line
    p = tmp_path / "80_pocket.csv"
    p.write_text("\n".join(lines) + "\n")
    assert detect_format(p) == MATLAB_MOBILE_CSV
    with pytest.warns(Warning, match="skipped 1 bad line"):
        rec = load_recording(p)
    a = rec.streams["acc"]
    np.testing.assert_array_equal(a.values, acc)
    assert np.array_equal(a.t_ns, ((ms - ms[0]) * 1_000_000).astype(np.int64))
    folder = tmp_path / "walk"
    folder.mkdir()
    (folder / "80_pocket.csv").write_text(p.read_text())
    assert detect_format(folder) == MATLAB_MOBILE_CSV
