"""Issue #15 item 2: the four dataset formats as importable files.

Microsoft/XYZ10 indoor-location traces, Brajdic & Harle traces (binary and
text), Oxford step-counter accelerometer files and TrundleWheel raw logs:
``core.importers`` recognises them by content and reads them in the
conventions of :mod:`core`, so ``pdr replay`` and the app open them.

* property tests: a valid file of each format (random streams, rates,
  values, layouts, gzip or not) round-trips -- every event comes back with
  its time and values, within the number formatting stated per format; a
  corrupted one gives a clean :class:`core.recording.RecordingError` or a
  well-formed recording (the harness of ``test_bad_input_fuzz.py``);
* detection refuses lookalikes (other CSVs of numbers, random bytes, the
  Oxford foot-switch file, a linear-acceleration file);
* each format's own rules (glued lines, cut records, GNSS rows, folders,
  the ground truth that is part of a file) and the extra streams surviving
  the project format;
* the real files of ``../shared/data`` (skipped when absent).
"""

from __future__ import annotations

import gzip
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.importers import (BRAJDIC, MSINDOOR, OXFORD, PHYPHOX, SENSORLOGGER, TRUNDLE, detect_format, load_recording,
                            read_brajdic, read_msindoor, read_oxford, read_trundle)
from core.importers.brajdic import RECORD
from core.recording import DamagedFileWarning, RecordingError, read_recording, write_recording
from test_bad_input_fuzz import FUZZ_EXAMPLES, _damage, _fresh, _gravity, _field, _read, _steps, _values

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
#: examples per property test: a tenth of PDR_FUZZ_EXAMPLES (20 in CI); seeded unless a long fuzz run
EXAMPLES = max(10, FUZZ_EXAMPLES // 10)
_SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=FUZZ_EXAMPLES <= 200,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("formats"))


def _write(root: str, name: str, data: bytes, gz: bool) -> str:
    path = os.path.join(root, name + (".gz" if gz else ""))
    with open(path, "wb") as f:
        f.write(gzip.compress(data, 6, mtime=0) if gz else data)
    return path


def _valid(workdir: str, name: str, fmt: str, data: bytes, gz: bool, expected: dict, atol: dict | float = 0.0,
           rtol: float = 0.0):
    """A valid file, written: recognised as ``fmt``, read with nothing repaired, every event as ``expected``."""
    path = _write(_fresh(workdir), name, data, gz)
    assert detect_format(path) == fmt
    rec = _read(load_recording, path)
    assert rec is not None and not rec.repairs, rec and rec.repairs
    assert rec.metadata["source_format"] == fmt and rec.metadata["time_base"]
    _check(rec, expected, atol, rtol)
    return rec


def _corrupted(workdir: str, name: str, data: bytes, gz: bool, reader, draw) -> None:
    """A damaged file, written and read (by the format's reader or through the detection)."""
    path = _write(_fresh(workdir), name, _damage(draw, data), gz)
    _read(draw(st.sampled_from([reader, load_recording])), path)


def _check(rec, expected: dict, atol: dict | float = 0.0, rtol: float = 0.0) -> None:
    assert set(rec.streams) == set(expected)
    for name, (t, v) in expected.items():
        s = rec.streams[name]
        np.testing.assert_array_equal(s.t_ns, t, err_msg=name)
        tol = atol.get(name, 0.0) if isinstance(atol, dict) else atol
        np.testing.assert_allclose(s.values, v, rtol=rtol, atol=tol, err_msg=name)


def _quaternion_xyz(draw, n: int) -> np.ndarray:
    """Rotation-vector parts (x, y, z) of unit quaternions with w >= 0.1."""
    q = draw(arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0, allow_nan=False)))
    q[:, 0] = np.abs(q[:, 0]) + 0.2
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q[:, 1:]


# ---------------------------------------------------------------------------
# Microsoft / XYZ10 traces: Unix ms, values written with repr (exact)

MS_RECORDS = [("TYPE_ACCELEROMETER", "acc", 3), ("TYPE_GYROSCOPE", "gyro", 3), ("TYPE_MAGNETIC_FIELD", "mag", 3),
              ("TYPE_ROTATION_VECTOR", "rotvec", 3), ("TYPE_GYROSCOPE_UNCALIBRATED", "gyro_uncal", 6),
              ("TYPE_MAGNETIC_FIELD_UNCALIBRATED", "mag_uncal", 6), ("TYPE_WAYPOINT", "waypoint", 2)]
MS_HEADER = ("#\tstartTime:{t0}\n#\tSiteID:5dbc\tSiteName:Mall\tFloorId:5dbd\tFloorName:F3\n"
             "#\tBrand:OPPO\tModel:PBCM10\tAndroidName:8.1.0\tAPILevel:27\t\n"
             "#\ttype:1\tname:BMI160 Accelerometer\tvendor:BOSCH\n#\tVersionName:v2019\tVersionCode:403\t\n")


@st.composite
def ms_traces(draw):
    """(file bytes, gzip?, expected streams)."""
    t0 = draw(st.integers(1_500_000_000_000, 1_700_000_000_000))
    lines: list[tuple[int, str]] = []
    expected = {}
    for tag, name, k in MS_RECORDS:
        n = draw(st.integers(1 if name == "acc" else 0, 30))
        if not n:
            continue
        t = t0 + _steps(draw, n, 15, 25)
        if name == "acc":
            v = _gravity(draw, n)
        elif name in ("mag", "mag_uncal"):
            v = np.hstack([_field(draw, n), _values(draw, n, k - 3, 50.0)]) if k == 6 else _field(draw, n)
        elif name == "rotvec":
            v = _quaternion_xyz(draw, n)
        else:
            v = _values(draw, n, k, 200.0 if name == "waypoint" else 10.0)
        accuracy = name != "waypoint" and draw(st.booleans())
        for ti, row in zip(t.tolist(), v.tolist()):
            lines.append((ti, "\t".join([str(ti), tag] + [repr(x) for x in row] + (["3"] if accuracy else []))))
        if name == "rotvec":
            w = np.sqrt(np.maximum(0.0, 1.0 - np.sum(v * v, axis=1)))
            v = np.column_stack([w, v])
        expected[name] = (t * 1_000_000, v[:, :3] if k == 6 else v)
    for ti in draw(st.lists(st.integers(t0, t0 + 600), max_size=3)):  # records counted, not read
        lines.append((ti, f"{ti}\tTYPE_WIFI\tShop\t0e:74:9c:a7:b2:e4\t-64\t2462\t{ti}"))
    lines.sort(key=lambda x: x[0])
    text = MS_HEADER.format(t0=t0) + "".join(ln + "\n" for _, ln in lines) + f"#\tendTime:{t0 + 999}\n"
    return text.encode(), draw(st.booleans()), expected


@_SETTINGS
@given(trace=ms_traces())
def test_valid_msindoor_traces_round_trip(workdir, trace):
    rec = _valid(workdir, "trace.txt", MSINDOOR, *trace, {"rotvec": 1e-12})
    assert rec.device == {"platform": "android", "brand": "OPPO", "model": "PBCM10", "os_version": "8.1.0",
                          "android_api": 27}
    assert rec.metadata["unix_offset_ns"] == 0 and rec.metadata["site"]["floor_name"] == "F3"
    assert rec.metadata["sensors"][0]["name"] == "BMI160 Accelerometer"


@_SETTINGS
@given(trace=ms_traces(), data=st.data())
def test_corrupted_msindoor_traces_read_with_repairs_or_raise_a_recording_error(workdir, trace, data):
    raw, gz, _ = trace
    _corrupted(workdir, "trace.txt", raw, gz, read_msindoor, data.draw)


def _ms_lines(n: int = 200, t0: int = 1_574_142_012_000) -> list[str]:
    out = [MS_HEADER.format(t0=t0).rstrip("\n")]
    for i in range(n):
        t = t0 + 20 * i
        out += [f"{t}\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3", f"{t}\tTYPE_MAGNETIC_FIELD\t20.0\t0.0\t-40.0\t3"]
    out += [f"{t0 + 5}\tTYPE_WAYPOINT\t165.0\t100.5", f"{t0 + 3000}\tTYPE_WAYPOINT\t160.0\t97.5"]
    return out


def test_msindoor_glued_lines_are_dropped_and_counted_bad_lines_skipped_or_refused(tmp_path):
    lines = _ms_lines()
    lines[50] = lines[50] + lines[51]  # a missing newline: the competition README's known defect
    lines[51] = lines[51].replace("\t0.2\t", "\tx\t")  # a bad number
    p = tmp_path / "trace.txt"
    p.write_text("\n".join(lines) + "\n")
    with pytest.warns(DamagedFileWarning):
        rec = load_recording(str(p))
    # lost: the two records of the glued line and the bad line (a second copy of the glued acc record)
    assert len(rec.streams["acc"]) == 199 and len(rec.streams["mag"]) == 199
    assert any("skipped 1 bad line(s)" in r and "line 56: TYPE_ACCELEROMETER: y is not a number" in r
               for r in rec.repairs)
    assert any("malformed line" in r and "two records" in r for r in rec.repairs)
    np.testing.assert_allclose(rec.streams["waypoint"].values, [[165.0, 100.5], [160.0, 97.5]])
    for i in range(100, 110):  # 10 bad lines of 400: over 1 %
        lines[i] = lines[i].rsplit("\t", 2)[0]
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"trace\.txt:56: TYPE_ACCELEROMETER: y is not a number.*too many"):
        load_recording(str(p))


def test_msindoor_streams_filter_reads_the_waypoints_alone(tmp_path):
    p = tmp_path / "trace.txt"
    p.write_text("\n".join(_ms_lines()) + "\n")
    rec = read_msindoor(str(p), streams=("waypoint",))
    assert list(rec.streams) == ["waypoint"] and rec.metadata["line_counts"] == {"TYPE_WAYPOINT": 2}
    p.write_text("\n".join(_ms_lines()[:-2]) + "\n")
    assert read_msindoor(str(p), streams=("waypoint",)).streams == {}


# ---------------------------------------------------------------------------
# Brajdic & Harle: big-endian binary records (float32: exact) or their text (float32's shortest repr)

@st.composite
def brajdic_traces(draw):
    """(file bytes, gzip?, binary?, expected streams)."""
    n = draw(st.integers(3, 40))
    t = draw(st.integers(10**9, 10**13)) + _steps(draw, n, 5_000_000, 15_000_000)
    masks = draw(arrays(np.int64, n, elements=st.integers(1, 7)))  # which of the three sensors at each time
    rows = [(ti, k) for ti, m in zip(t.tolist(), masks.tolist()) for k in (1, 2, 3) if m >> (k - 1) & 1]
    v = np.empty((len(rows), 3), dtype=np.float32)
    typ = np.array([k for _, k in rows])
    v[typ == 1] = _gravity(draw, int(np.sum(typ == 1)))
    v[typ == 2] = _values(draw, int(np.sum(typ == 2)), 3, 10.0)
    v[typ == 3] = _field(draw, int(np.sum(typ == 3)))
    binary = draw(st.booleans())
    rec = np.zeros(len(rows), dtype=RECORD)
    rec["t"], rec["type"], rec["v"] = [r[0] for r in rows], typ, v
    if binary:
        data = rec.tobytes()
    else:
        data = "".join(f"{r['t']} {r['type']} {r['v'][0]} {r['v'][1]} {r['v'][2]} \n" for r in rec).encode()
    tt = np.array([r[0] for r in rows], dtype=np.int64)
    expected = {name: (tt[typ == k], v[typ == k].astype(np.float64))
                for k, name in ((1, "acc"), (2, "gyro"), (3, "mag")) if np.any(typ == k)}
    return data, draw(st.booleans()), binary, expected


@_SETTINGS
@given(trace=brajdic_traces())
def test_valid_brajdic_traces_round_trip(workdir, trace):
    data, gz, binary, expected = trace
    # text: float32's shortest repr read as float64 (tiny values: a few float32 denormals apart)
    rec = _valid(workdir, "p1.1_Female_20-29_170-179cm_Hand_held." + ("out" if binary else "dat"), BRAJDIC, data, gz,
                 expected, *((0.0, 0.0) if binary else (1e-40, 1e-6)))
    assert rec.metadata["encoding"].startswith("binary" if binary else "text")


@_SETTINGS
@given(trace=brajdic_traces(), data=st.data())
def test_corrupted_brajdic_traces_read_with_repairs_or_raise_a_recording_error(workdir, trace, data):
    raw, gz, binary, _ = trace
    _corrupted(workdir, "trace." + ("out" if binary else "dat"), raw, gz, read_brajdic, data.draw)


def _brajdic_records(n: int = 300) -> np.ndarray:
    rec = np.zeros(3 * n, dtype=RECORD)
    rec["t"] = 5_000_000_000 + np.repeat(np.arange(n), 3) * 10_000_000
    rec["type"] = np.tile([1, 2, 3], n)
    rec["v"] = np.tile([[0.1, 0.2, 9.8], [0.01, 0.0, -0.02], [20.0, 0.0, -40.0]], (n, 1))
    return rec


def test_brajdic_binary_cut_record_and_bad_types(tmp_path):
    rec = _brajdic_records()
    rec["type"][40] = 7
    p = tmp_path / "trace.out"
    p.write_bytes(rec.tobytes() + rec[:1].tobytes()[:13])  # a record cut off mid-write
    with pytest.warns(DamagedFileWarning):
        r = load_recording(str(p))
    assert len(r.streams["gyro"]) == 299 and len(r.streams["acc"]) == 300
    assert any("record 41 (byte 840): sensor type 7" in x for x in r.repairs)
    assert any("incomplete last record (13 of 21 bytes" in x for x in r.repairs)
    rec["type"][100:120] = 0
    p.write_bytes(rec.tobytes())
    with pytest.raises(RecordingError, match=r"trace\.out:41: record 41 .*too many to skip"):
        read_brajdic(str(p))


def test_brajdic_is_recognised_by_content_whatever_the_name(tmp_path):
    p = tmp_path / "walk.csv"
    p.write_bytes(_brajdic_records().tobytes())
    assert detect_format(str(p)) == BRAJDIC


# ---------------------------------------------------------------------------
# Oxford step counter: integer ns, values written with repr (exact)

@st.composite
def oxford_files(draw):
    """(file bytes, gzip?, layout fields, expected streams)."""
    n = draw(st.integers(3, 60))
    t = draw(st.integers(10**8, 10**15)) + _steps(draw, n, 2_500_000, 10_000_000)
    acc = _gravity(draw, n)
    k = draw(st.sampled_from([5, 7]))
    if k == 5:
        flags = draw(arrays(np.int64, n, elements=st.integers(0, 3)))
        rows = [f"{ti},{f},{a!r},{b!r},{c!r}" for ti, f, (a, b, c) in zip(t.tolist(), flags.tolist(), acc.tolist())]
        expected = {"acc": (t, acc)}
    else:
        counts = np.cumsum(draw(arrays(np.int64, (n, 3), elements=st.integers(0, 1))), axis=0)
        rows = [f"{ti},{a!r},{b!r},{c!r},{x},{y},{z}"
                for ti, (a, b, c), (x, y, z) in zip(t.tolist(), acc.tolist(), counts.tolist())]
        expected = {"acc": (t, acc), "step_counts": (t, counts.astype(np.float64))}
    return ("\n".join(rows) + "\n").encode(), draw(st.booleans()), k, expected


@_SETTINGS
@given(f=oxford_files())
def test_valid_oxford_files_round_trip(workdir, f):
    data, gz, k, expected = f
    rec = _valid(workdir, "accelerometer.csv", OXFORD, data, gz, expected)
    assert rec.metadata["layout"] == ("optimisation" if k == 5 else "validation")
    if k == 7:
        assert list(rec.streams["step_counts"].columns) == ["app", "ground_truth", "android_hw"]


@_SETTINGS
@given(f=oxford_files(), data=st.data())
def test_corrupted_oxford_files_read_with_repairs_or_raise_a_recording_error(workdir, f, data):
    raw, gz, _, _ = f
    _corrupted(workdir, "accelerometer.csv", raw, gz, read_oxford, data.draw)


def test_oxford_folder_names_the_chip_and_bad_lines_are_skipped(tmp_path):
    d = tmp_path / "Nexus_Jamie_Hard_InHand_1"
    d.mkdir()
    rows = [f"{263239144953734 + 5_000_000 * i},3,0.1,0.2,9.8" for i in range(300)]
    rows[7] = "263239179953734,3,0.1,9.8"  # a field missing
    with gzip.open(d / "accelerometer.csv.gz", "wt") as f:
        f.write("\n".join(rows) + "\n")
    (d / "metadata.txt").write_text("accelerometer : MPU6515 Accelerometer\n")
    (d / "stepcounter.csv").write_text("263239180928096,1,1\n263239278194971,0,1\n263239375671377,1,1\n")
    assert detect_format(str(d)) == OXFORD
    with pytest.warns(DamagedFileWarning, match="line 8: missing fields"):
        rec = load_recording(str(d))
    assert rec.device == {"platform": "android", "accelerometer": "MPU6515 Accelerometer"}
    assert len(rec.streams["acc"]) == 299 and rec.metadata["accuracy_counts"] == {"3": 299}


# ---------------------------------------------------------------------------
# TrundleWheel raw logs: ms with binary fractions (exact), acceleration to 0.1 m/s^2, rates in deg/s (repr)

TW_COLUMNS = ["time", "o_alpha", "o_beta", "o_gamma", "m_acc_x", "m_acc_y", "m_acc_z", "m_accG_x", "m_accG_y",
              "m_accG_z", "m_rotTate_alpha", "m_rotTate_beta", "m_rotTate_gamma", "p_lat", "p_long", "p_alt", "p_acc",
              "p_head", "p_speed", "steps", "distance", "duration", "date", "total_distance", "total_steps",
              "device_os", "device_model"]


@st.composite
def trundle_logs(draw):
    """(file bytes, gzip?, expected streams)."""
    cols = draw(st.permutations(TW_COLUMNS))
    n = draw(st.integers(1, 80))
    t_ms = (draw(st.integers(0, 1000)) * 8 + _steps(draw, n, 40, 200)) / 8.0  # 5-25 ms apart, exact in binary
    kinds = draw(st.lists(st.sampled_from(["acc", "acc", "acc", "rot", "rot", "steps", "distance", "gnss"]),
                          min_size=n, max_size=n))
    kinds[0] = "acc"
    acc = np.round(_gravity(draw, n), 1)
    rot = _values(draw, n, 3, 500.0)
    lines = [";".join(cols)]
    got: dict[str, list] = {"acc": [], "gyro": [], "wheel": [], "step_counts": []}
    for i, (t, kind) in enumerate(zip(t_ms.tolist(), kinds)):
        f = dict.fromkeys(cols, "")
        f["time"] = repr(t)
        if i == 0:
            f.update(duration="297", date="2023-08-10", total_distance="394", total_steps="488",
                     device_os="Android 10", device_model="Redmi Note 9 Pro")
        if kind == "acc":
            f.update(m_accG_x=f"{acc[i, 0]:.1f}", m_accG_y=f"{acc[i, 1]:.1f}", m_accG_z=f"{acc[i, 2]:.1f}",
                     m_acc_x="0.1", m_acc_y="-0.2", m_acc_z="0.3")
            got["acc"].append((t, acc[i]))
        elif kind == "rot":
            f.update(m_rotTate_alpha=repr(float(rot[i, 0])), m_rotTate_beta=repr(float(rot[i, 1])),
                     m_rotTate_gamma=repr(float(rot[i, 2])))
            got["gyro"].append((t, np.radians([rot[i, 1], rot[i, 2], rot[i, 0]])))
        elif kind in ("steps", "distance"):
            f[kind] = str(i)
            got["wheel" if kind == "distance" else "step_counts"].append((t, [float(i)]))
        else:  # a GNSS row: Unix-epoch time, not read
            f.update(time=str(1691650000000 + i), p_lat="55.61", p_long="13.0", p_acc="5")
        lines.append(";".join(f[c] for c in cols))
    expected = {k: (np.array([round(t * 1e6) for t, _ in v], dtype=np.int64), np.array([x for _, x in v]))
                for k, v in got.items() if v}
    return ("\n".join(lines) + "\n").encode(), draw(st.booleans()), expected


@_SETTINGS
@given(log=trundle_logs())
def test_valid_trundle_logs_round_trip(workdir, log):
    rec = _valid(workdir, "normal_speed_valid.csv", TRUNDLE, *log, {"gyro": 1e-12})
    assert rec.device["model"] == "Redmi Note 9 Pro" and rec.device["platform"] == "android"
    assert rec.metadata["date"] == "2023-08-10"


@_SETTINGS
@given(log=trundle_logs(), data=st.data())
def test_corrupted_trundle_logs_read_with_repairs_or_raise_a_recording_error(workdir, log, data):
    raw, gz, _ = log
    _corrupted(workdir, "log.csv", raw, gz, read_trundle, data.draw)


def test_trundle_partial_rows_are_bad_lines_and_the_required_columns_are_named(tmp_path):
    head = "time;m_accG_x;m_accG_y;m_accG_z;distance"
    rows = [f"{10 * i};0.1;0.2;9.8;" for i in range(200)] + ["2001;;;;1"]
    rows[9] = "90;0.1;;9.8;"
    p = tmp_path / "log.csv"
    p.write_text("\n".join([head] + rows) + "\n")
    with pytest.warns(DamagedFileWarning, match="line 11: missing fields: acc needs 3 values"):
        rec = load_recording(str(p))
    assert len(rec.streams["acc"]) == 199 and "gyro" not in rec.streams
    assert rec.streams["wheel"].t_ns.tolist() == [2_001_000_000]
    p.write_text("time;m_accG_x;m_accG_y;m_accG_z\n" + "\n".join(r[:-1] for r in rows[:5]) + "\n")
    assert detect_format(str(p)) == TRUNDLE
    p.write_text("time;m_acc_x;m_acc_y;m_acc_z\n" + "\n".join(r[:-1] for r in rows[:5]) + "\n")  # no gravity
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(str(p))


# ---------------------------------------------------------------------------
# detection: lookalikes are refused, the formats are told apart


@pytest.mark.parametrize("name, content", [
    ("numbers.csv", "".join(f"{i * 0.01:.2f},{i},0.1,0.2,9.8\n" for i in range(30))),  # time not an integer
    ("stepcounter.csv", "".join(f"{263239180928096 + i * 90_000_000},{i % 2},1\n" for i in range(30))),
    ("linear.csv", "".join(f"{10**12 + i * 5_000_000},3,0.1,0.2,0.05\n" for i in range(30))),  # no gravity
    ("backwards.csv", "".join(f"{10**12 - i * 5_000_000},3,0.1,0.2,9.8\n" for i in range(30))),
    ("types.dat", "".join(f"{10**12 + i} {4 + i % 2} 0.1 0.2 9.8\n" for i in range(30))),
    ("tabs.txt", "".join(f"{10**12 + i}\tACCELEROMETER\t0.1\t0.2\t9.8\n" for i in range(30))),
    ("semicolons.csv", "t;ax;ay;az\n" + "".join(f"{i};0.1;0.2;9.8\n" for i in range(30))),
])
def test_lookalike_texts_are_not_taken_for_a_format(tmp_path, name, content):
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(str(p))


def test_random_bytes_and_records_of_another_layout_are_not_brajdic(tmp_path):
    rng = np.random.default_rng(15)
    for k in range(20):
        p = tmp_path / f"r{k}.out"
        p.write_bytes(rng.integers(0, 256, 21 * 64, dtype=np.uint8).tobytes())
        with pytest.raises(RecordingError, match="unrecognised recording format"):
            detect_format(str(p))
    little = _brajdic_records().astype([("t", "<i8"), ("type", "i1"), ("v", "<f4", 3)])  # the wrong byte order
    p = tmp_path / "little.out"
    p.write_bytes(little.tobytes())
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(str(p))


def test_every_format_is_named_in_the_unrecognised_message(tmp_path):
    p = tmp_path / "x.txt"
    p.write_text("hello\n")
    with pytest.raises(RecordingError) as e:
        detect_format(str(p))
    for name in (MSINDOOR, BRAJDIC, OXFORD, TRUNDLE):
        assert name in str(e.value)


# ---------------------------------------------------------------------------
# the extra streams survive the project format; size limits


def test_ground_truth_streams_survive_the_project_format(tmp_path):
    p = tmp_path / "trace.txt"
    p.write_text("\n".join(_ms_lines()) + "\n")
    rec = load_recording(str(p))
    out = tmp_path / "trace.pdr.gz"
    write_recording(str(out), rec)
    back = read_recording(str(out))
    for name in ("acc", "mag", "waypoint"):
        np.testing.assert_array_equal(back.streams[name].t_ns, rec.streams[name].t_ns)
        np.testing.assert_allclose(back.streams[name].values, rec.streams[name].values, rtol=0, atol=0)
    assert list(back.streams["waypoint"].columns) == ["east_m", "north_m"]
    assert back.metadata["unix_offset_ns"] == 0


@pytest.mark.parametrize("fmt", [MSINDOOR, BRAJDIC, OXFORD, TRUNDLE])
def test_a_gzip_stream_over_the_size_limit_is_refused(tmp_path, fmt):
    if fmt == MSINDOOR:
        data = ("\n".join(_ms_lines()) + "\n").encode()
    elif fmt == BRAJDIC:
        data = _brajdic_records().tobytes()
    elif fmt == OXFORD:
        data = "".join(f"{10**12 + i * 5_000_000},3,0.1,0.2,9.8\n" for i in range(2000)).encode()
    else:
        data = ("time;m_accG_x;m_accG_y;m_accG_z\n" + "".join(f"{10 * i};0.1;0.2;9.8\n" for i in range(2000))).encode()
    p = _write(str(tmp_path), "f", data, gz=True)
    assert detect_format(p) == fmt
    with pytest.raises(RecordingError, match="limit"):
        load_recording(p, max_uncompressed_bytes=len(data) // 2)


# ---------------------------------------------------------------------------
# the real files (skipped when ../shared/data is absent)

needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data not present")


def _first(pattern: str) -> Path | None:
    found = sorted(DATA.glob(pattern))
    return found[0] if found else None


@needs_data
def test_real_files_of_every_format_are_recognised_and_read():
    seen = 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the real files need no repair
        ms = _first("ms_indoor_location_2020/site*/*/path_data_files/*.txt*")
        if ms is not None:
            rec = load_recording(str(ms))
            assert rec.metadata["source_format"] == MSINDOOR and rec.device["platform"] == "android"
            for s in ("acc", "gyro", "mag", "rotvec"):
                assert 45 < rec.streams[s].rate_hz < 55, s
            np.testing.assert_allclose(np.linalg.norm(rec.streams["rotvec"].values, axis=1), 1.0, atol=1e-6)
            wp = rec.streams["waypoint"]
            assert len(wp) >= 2 and np.all((wp.values >= 0) & (wp.values < 250))  # the 236.7 x 219.7 m map
            assert 1.5e18 < rec.t0_ns < 1.6e18  # Unix time (Nov 2019)
            seen += 1
        for pattern, n in (("brajdic_harle_handheld/p1.1_*.out", 19281), ("brajdic_harle_handheld/p27.1_*.dat*",
                                                                           3 * 12083)):
            bh = _first(pattern)
            if bh is not None:
                rec = load_recording(str(bh))
                assert rec.metadata["source_format"] == BRAJDIC and rec.metadata["records"] == n
                assert 9.0 < np.mean(np.linalg.norm(rec.streams["acc"].values, axis=1)) < 10.0
                seen += 1
        ox = DATA / "oxford_step_counter" / "optimisation" / "data" / "Nexus_Jamie_Hard_InHand_1"
        if ox.is_dir():
            rec = load_recording(str(ox))
            # the foot-switch truth beside it (stepcounter.csv) comes along as a step_counts stream (issue #29)
            assert rec.metadata["source_format"] == OXFORD and list(rec.streams) == ["acc", "step_counts"]
            assert rec.streams["step_counts"].columns == ("ground_truth",)
            assert 190 < rec.streams["acc"].rate_hz < 210 and rec.device["accelerometer"] == "MPU6515 Accelerometer"
            seen += 1
        tw = _first("trundlewheel_distance/raw/*.csv*")  # absent from some copies
        if tw is not None:
            rec = load_recording(str(tw))
            assert rec.metadata["source_format"] == TRUNDLE and 50 < rec.streams["acc"].rate_hz < 70
            assert 390 < rec.streams["wheel"].values[-1, 0] < 410  # the README: 394 and 401 m
            seen += 1
    if not seen:
        pytest.skip("none of the four datasets is in ../shared/data")


@needs_data
def test_real_phone_walks_are_recognised():
    walks = DATA / "gps_walks_phone"
    if not walks.is_dir():
        pytest.skip("../shared/data/gps_walks_phone not present")
    formats = {p.name: detect_format(str(p)) for p in sorted(walks.iterdir()) if p.is_dir()}
    assert formats == {"babur_walking": PHYPHOX, "bahramib_walk_beni1": PHYPHOX, "bahramib_walk_stan1": PHYPHOX,
                       "liatoutou_walk2": PHYPHOX, "siberiawolfp_walking2": SENSORLOGGER}
