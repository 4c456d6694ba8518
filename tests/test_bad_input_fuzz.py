"""Issue #12: property tests and fuzzing of every importer (GetSensorData, Sensor Logger, phyphox).

Hypothesis strategies generate valid exports of each app -- random streams,
rates, values, column orders, dialects, pauses, containers (a file, a folder,
a zip, gzip members) -- and the tests check that

* a valid export round-trips: every event comes back with its time and its
  values, within the app's number formatting (stated per format below);
* a corrupted one (cut short, bytes flipped, lines deleted or repeated,
  numbers broken, fields missing or added, bytes that are not UTF-8, a
  damaged gzip member or zip archive) gives a clean
  :class:`core.recording.RecordingError` (one line naming the file) or a
  well-formed recording with only the readers' own warnings -- never another
  exception, never a hang (an alarm stops a read after 20 s).

The project format has the same tests in ``test_bad_input_readers.py``.
Examples per test: a quarter of ``PDR_FUZZ_EXAMPLES`` (200 in CI: 50 valid
and 50 corrupted exports per importer); the long fuzz run (README,
Development) sets it high.
"""

from __future__ import annotations

import gzip
import os
import shutil
import signal
import tempfile
import warnings
import zipfile
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from core.importers import load_recording, read_getsensordata, read_phyphox, read_sensorlogger
from core.recording import (DamagedFileWarning, RecordingError, SensorSubstitutedWarning,
                            TimestampRepairWarning)
from core.validation import StreamProblemWarning

FUZZ_EXAMPLES = int(os.environ.get("PDR_FUZZ_EXAMPLES", "200"))
EXAMPLES = max(10, FUZZ_EXAMPLES // 4)
HANG_S = 20.0
G = 9.80665
_SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=FUZZ_EXAMPLES <= 200,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module")
def workdir():
    d = tempfile.mkdtemp(prefix="pdr_fuzz_")
    yield d
    shutil.rmtree(d, ignore_errors=True)


def _fresh(workdir: str) -> str:
    """An empty folder for one example (the same one every time: long runs leave nothing behind)."""
    d = os.path.join(workdir, "x")
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


@contextmanager
def _no_hang(seconds: float = HANG_S):
    def stop(*_):
        raise TimeoutError(f"a reader ran for over {seconds} s: a hang")

    old = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


#: the readers' own warnings: each says what was repaired or dropped (an impossible GPS fix, e.g. longitude 181,
#: is dropped with a StreamProblemWarning: a fuzzed GetSensorData log found that this tuple lacked it)
_OURS = (DamagedFileWarning, TimestampRepairWarning, SensorSubstitutedWarning, StreamProblemWarning)


def _read(reader, path: str):
    """The recording, or ``None`` after a clean RecordingError; anything else fails the test."""
    with warnings.catch_warnings(record=True) as caught, _no_hang():
        warnings.simplefilter("always")
        try:
            rec = reader(path)
        except RecordingError as e:
            msg = str(e)
            assert "\n" not in msg and msg.startswith(path), msg
            return None
    other = [f"{w.category.__name__}: {w.message}" for w in caught if not issubclass(w.category, _OURS)]
    assert not other, other
    assert rec.streams
    for s in rec.streams.values():
        assert s.t_ns.dtype == np.int64 and s.t_ns.ndim == 1 and s.values.dtype == np.float64
        assert s.values.shape == (len(s.t_ns), len(s.columns))
        assert np.all(s.t_ns[1:] > s.t_ns[:-1])  # sorted, repeats dropped
    return rec


def _write(root: str, files: dict[str, bytes], container: str) -> str:
    """``files`` as a folder, a zip, or (one file) the file itself; names ending in .gz are gzip members."""
    if container == "zip":
        path = os.path.join(root, "export.zip")
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in files.items():  # a fixed date: the same bytes every time (hypothesis replays)
                z.writestr(zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
        return path
    if container == "file":
        (name, data), = files.items()
        path = os.path.join(root, name)
        with open(path, "wb") as f:
            f.write(data)
        return path
    path = os.path.join(root, "export")
    for name, data in files.items():
        full = os.path.join(path, name)
        os.makedirs(os.path.dirname(full), exist_ok=True)
        with open(full, "wb") as f:
            f.write(data)
    return path


def _gz(files: dict[str, bytes], names) -> dict[str, bytes]:
    """``files`` with the members ``names`` gzip-compressed (``name.gz``; no time stamp: the same bytes every time)."""
    return {(n + ".gz" if n in names else n): (gzip.compress(d, 6, mtime=0) if n in names else d)
            for n, d in files.items()}


def _steps(draw, n: int, lo: int, hi: int) -> np.ndarray:
    """``n`` strictly increasing integers starting near 0 (steps of ``lo``..``hi``)."""
    return np.cumsum(np.array(draw(st.lists(st.integers(lo, hi), min_size=n, max_size=n)), dtype=np.int64))


def _gravity(draw, n: int) -> np.ndarray:
    """Accelerometer rows with gravity: |a| within 10 % of g, any direction."""
    d = draw(arrays(np.float64, (n, 3), elements=st.floats(-1.0, 1.0, allow_nan=False)))
    d[:, 2] += np.where(d[:, 2] >= 0, 1.0, -1.0)  # |d| >= 1: a direction
    scale = draw(arrays(np.float64, (n, 1), elements=st.floats(0.9 * G, 1.1 * G, allow_nan=False)))
    return d / np.linalg.norm(d, axis=1, keepdims=True) * scale


def _field(draw, n: int) -> np.ndarray:
    """Magnetometer rows (uT) with no all-zero row (that is 'no reading' for the importers)."""
    v = draw(arrays(np.float64, (n, 3), elements=st.floats(-80.0, 80.0, allow_nan=False)))
    v[:, 0] = np.where(np.abs(v[:, 0]) < 1.0, 20.0, v[:, 0])
    return v


def _values(draw, n: int, k: int, bound: float) -> np.ndarray:
    return draw(arrays(np.float64, (n, k), elements=st.floats(-bound, bound, allow_nan=False)))


# ---------------------------------------------------------------------------
# GetSensorData: times to 0.1 ms (4 decimals), sensor values to 5 decimals, quaternion parts to 8

TICK_NS = 100_000
#: round-trip tolerance per stream: half the last written decimal (the quaternion's w is restored from x, y, z;
#: gps: the altitude's 3 decimals)
GSD_TOL = {"acc": 5.1e-6, "gyro": 5.1e-6, "mag": 5.1e-6, "pressure": 5.1e-5, "rotvec": 1e-6, "gps": 5.1e-4}


@st.composite
def gsd_logs(draw):
    """(files, container, expected streams {name: (t_ns, values)})."""
    app0 = draw(st.integers(0, 10**6))  # ticks of 0.1 ms
    offset = draw(st.integers(0, 10**8))  # sensor clock - app clock
    lines: list[tuple[int, str]] = []
    expected = {}
    tags = ["ACCE"] + [t for t in ("GYRO", "MAGN", "PRES", "AHRS", "GNSS") if draw(st.booleans())]
    for tag in tags:
        n = draw(st.integers(1 if tag == "ACCE" else 0, 40))
        if not n:
            continue
        app = app0 + _steps(draw, n, 20, 500)
        sensor = app + offset
        if tag == "GNSS":
            fix = draw(st.integers(1_600_000_000, 1_700_000_000)) + np.arange(n)
            v = np.column_stack([_values(draw, n, 1, 80.0), _values(draw, n, 1, 179.0), _values(draw, n, 1, 900.0)])
            for a, f, (la, lo, al) in zip(app.tolist(), fix.tolist(), v.tolist()):
                for d in (0, 1):  # the app logs every fix twice
                    lines.append((a + d, f"GNSS;{(a + d) / 1e4:.4f};{f:.3f};{la:.7f};{lo:.7f};{al:.3f};45.000;5.0;"
                                         f"1.0;12;9"))
            expected["gps"] = ((app + offset) * TICK_NS, v)
            expected["gnss_status"] = ((app + offset) * TICK_NS, np.tile([9.0, np.nan, 12.0], (n, 1)))  # in use, view
            continue
        if tag == "AHRS":
            q = draw(arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0, allow_nan=False)))
            q[:, 0] = np.abs(q[:, 0]) + 0.2  # w >= 0.1 after normalising: the logged x, y, z fix it well
            q /= np.linalg.norm(q, axis=1, keepdims=True)
            for a, s, (w, x, y, z) in zip(app.tolist(), sensor.tolist(), q.tolist()):
                lines.append((a, f"AHRS;{a / 1e4:.4f};{s / 1e4:.4f};10.5;-3.25;120.75;{x:.8f};{y:.8f};{z:.8f};3"))
            expected["rotvec"] = (sensor * TICK_NS, q)
            continue
        k, bound, name = {"ACCE": (3, 100.0, "acc"), "GYRO": (3, 40.0, "gyro"), "MAGN": (3, 200.0, "mag"),
                          "PRES": (1, 1100.0, "pressure")}[tag]
        v = _values(draw, n, k, bound)
        for a, s, row in zip(app.tolist(), sensor.tolist(), v.tolist()):
            fields = ";".join(f"{x:.5f}" if k == 3 else f"{x:.4f}" for x in row)
            lines.append((a, f"{tag};{a / 1e4:.4f};{s / 1e4:.4f};{fields};3"))
        expected[name] = (sensor * TICK_NS, v)
    for a in draw(st.lists(st.integers(app0, app0 + 20_000), max_size=3)):  # records the reader counts, not reads
        lines.append((a, f"WIFI;{a / 1e4:.4f};{a / 1e4:.3f};eduroam;00:11:22:33:44:55;2437;-60"))
    lines.sort(key=lambda x: x[0])
    head = "% LogFile created by the 'GetSensorData' App for Android.\n% Version 2.21\n% Model: \tTEST\n"
    text = head + "".join(ln + "\n" for _, ln in lines)
    gz = draw(st.booleans())
    files = {"log.txt": text.encode()}
    return (_gz(files, ["log.txt"]) if gz else files), "file", expected


def _read_valid(workdir: str, files: dict[str, bytes], container: str, reader):
    """A valid export, written and read: no error, nothing repaired."""
    rec = _read(reader, _write(_fresh(workdir), files, container))
    assert rec is not None and not rec.repairs
    return rec


def _check(rec, expected, tol: dict, rtol: float = 0.0):
    for name, (t, v) in expected.items():
        s = rec.streams[name]
        np.testing.assert_array_equal(s.t_ns, t, err_msg=name)
        k = v.shape[1]
        np.testing.assert_allclose(s.values[:, :k], v, rtol=rtol, atol=tol.get(name, 0.0), err_msg=name)


@_SETTINGS
@given(log=gsd_logs())
def test_valid_getsensordata_logs_round_trip(workdir, log):
    files, container, expected = log
    rec = _read_valid(workdir, files, container, read_getsensordata)
    _check(rec, expected, GSD_TOL)
    # every time maps onto the sensor clock: the app offset is recovered exactly
    assert set(rec.streams) == set(expected)


# ---------------------------------------------------------------------------
# Sensor Logger (Android): integer ns times, values written with repr -- exact

SL_T0 = 1_500_000_000_000_000_000


@st.composite
def sensorlogger_exports(draw):
    start = draw(st.integers(SL_T0, SL_T0 + 10**17))
    files = {}
    expected = {}
    for fname, name in (("TotalAcceleration.csv", "acc"), ("Gyroscope.csv", "gyro"), ("Magnetometer.csv", "mag"),
                        ("Barometer.csv", "pressure"), ("Location.csv", "gps")):
        if name != "acc" and not draw(st.booleans()):
            continue
        n = draw(st.integers(1, 40))
        t = start + draw(st.integers(0, 10**9)) + _steps(draw, n, 2_000_000, 50_000_000)
        el = (t - start) / 1e9
        if name == "gps":
            v = np.column_stack([_values(draw, n, 1, 80.0), _values(draw, n, 1, 179.0), _values(draw, n, 1, 900.0)])
            cols = ["latitude", "longitude", "altitude", "horizontalAccuracy", "speed", "bearing"]
            extra = [[5.0, 1.2, 45.0]] * n
        elif name == "pressure":
            v = _values(draw, n, 1, 1100.0)
            cols, extra = ["pressure", "relativeAltitude"], [[0.0]] * n
        else:
            v = {"acc": _gravity, "mag": _field}.get(name, lambda d, m: _values(d, m, 3, 30.0))(draw, n)
            cols, extra = ["x", "y", "z"], [[]] * n
        order = draw(st.permutations(list(range(len(cols)))))
        rows = [list(r) + e for r, e in zip(v.tolist(), extra)]
        head = "time,seconds_elapsed," + ",".join(cols[j] for j in order)
        body = "".join(f"{ti},{e!r}," + ",".join(repr(r[j]) for j in order) + "\n"
                       for ti, e, r in zip(t.tolist(), el.tolist(), rows))
        files[fname] = (head + "\n" + body).encode()
        expected[name] = (t - start, v)
    files["Metadata.csv"] = b"version,device name,recording time,platform,appVersion\n3,Fuzz,2024-01-01,android,1.30\n"
    container = draw(st.sampled_from(["zip", "folder"]))
    if container == "folder":
        files = _gz(files, draw(st.sets(st.sampled_from(sorted(files)))))
    return files, container, (start, expected)


@_SETTINGS
@given(export=sensorlogger_exports())
def test_valid_sensorlogger_exports_round_trip(workdir, export):
    files, container, (start, expected) = export
    rec = _read_valid(workdir, files, container, read_sensorlogger)
    offset = rec.metadata["unix_offset_ns"]  # the recording's start (time - seconds_elapsed), to a few ns
    assert abs(offset - start) <= 2
    _check(rec, {n: (t + start - offset, v) for n, (t, v) in expected.items()}, {})


# ---------------------------------------------------------------------------
# phyphox: times on a 1 ms grid, values written as phyphox does (%.9E: 10 significant digits)

PHY_RTOL = 1e-9
PHY_SYS0_MS = 1_700_000_000_000


def _phy_num(x: float, comma: bool) -> str:
    m, e = f"{x:.9E}".split("E")
    s = f"{m}E{int(e)}"
    return s.replace(".", ",") if comma else s


@st.composite
def phyphox_exports(draw):
    delim, comma = draw(st.sampled_from([(",", False), (";", True), ("\t", False), ("\t", True)]))
    heads = {"acc": ("Raw Data.csv", "Acceleration {} (m/s^2)", _gravity),
             "gyro": ("Gyroscope.csv", "Gyroscope {} (rad/s)", lambda d, n: _values(d, n, 3, 30.0)),
             "mag": ("Magnetometer.csv", "Magnetic field {} (µT)", _field)}
    pause = draw(st.one_of(st.none(), st.tuples(st.integers(1, 3000), st.integers(0, 100_000))))  # at, gap (ms)
    with_time = pause is not None or draw(st.booleans())
    files, expected = {}, {}
    for name, (fname, head, gen) in heads.items():
        if name != "acc" and not draw(st.booleans()):
            continue
        n = draw(st.integers(1, 40))
        k_ms = draw(st.integers(0, 500)) + _steps(draw, n, 2, 50)
        v = gen(draw, n)
        cols = ["Time (s)"] + [head.format(a) for a in "xyz"]
        text = delim.join(f'"{c}"' for c in cols) + "\n"
        text += "".join(delim.join(_phy_num(x, comma) for x in [k / 1000.0] + row) + "\n"
                        for k, row in zip(k_ms.tolist(), v.tolist()))
        if draw(st.booleans()):  # a value buffer shorter than the time buffer: empty fields, rows dropped
            text += delim.join([_phy_num((k_ms[-1] + 5) / 1000.0, comma), "", "", ""]) + "\n"
        files[fname] = text.encode()
        t_ns = k_ms * 1_000_000
        if pause is not None:
            at, gap = pause
            t_ns = np.where(k_ms >= at, (at + gap) * 1_000_000 + (k_ms - at) * 1_000_000, t_ns)
        expected[name] = (t_ns, v)
    if with_time:
        ev = [("START", 0, PHY_SYS0_MS)]
        if pause is not None:
            at, gap = pause
            ev += [("PAUSE", at, PHY_SYS0_MS + at), ("START", at, PHY_SYS0_MS + at + gap)]
        rows = [delim.join(['"event"', '"experiment time"', '"system time"', '"system time text"'])]
        rows += [delim.join([f'"{e}"', _phy_num(x / 1000.0, comma), f"{s / 1000:.3f}".replace(".", "," if comma
                                                                                              else "."), '"t"'])
                 for e, x, s in ev]
        files["meta/time.csv"] = ("\n".join(rows) + "\n").encode()
        files["meta/device.csv"] = delim.join(['"property"', '"value"']).encode() + b"\n" + delim.join(
            ['"version"', '"1.1.15"']).encode() + b"\n"
    container = draw(st.sampled_from(["zip", "folder"] + (["file"] if len(files) == 1 else [])))
    return files, container, expected


@_SETTINGS
@given(export=phyphox_exports())
def test_valid_phyphox_exports_round_trip(workdir, export):
    files, container, expected = export
    _check(_read_valid(workdir, files, container, read_phyphox), expected, {}, rtol=PHY_RTOL)


# ---------------------------------------------------------------------------
# corrupted exports: only a RecordingError or a well-formed recording

_BAD_TOKENS = [b"x", b"", b"1e999", b"nan", b"-", b"1_0", b"0x10", "\u0661".encode(), b"inf", b"--1", b"1.2.3", b'"',
               b"99999999999999999999999"]
_INSERTS = [b"\xff", b"\xc3", b"\x00", b"\xef\xbb\xbf", b"\r", b"\n", b";", b",", b"\t", b'"', b"%", b"#"]


def _damage(draw, data: bytes) -> bytes:
    lines = data.split(b"\n")
    op = draw(st.sampled_from(["cut", "flip", "insert", "delete_line", "repeat_line", "swap_lines", "bad_number",
                               "drop_field", "add_field"]))
    if not data:
        return draw(st.sampled_from([b"", b"\n", b"\xff\xfe"]))
    i = draw(st.integers(0, len(data) - 1))
    j = draw(st.integers(0, len(lines) - 1))
    if op == "cut":
        return data[:i]
    if op == "flip":
        return data[:i] + bytes([draw(st.integers(0, 255))]) + data[i + 1:]
    if op == "insert":
        return data[:i] + draw(st.sampled_from(_INSERTS)) + data[i:]
    if op == "delete_line":
        del lines[j]
    elif op == "repeat_line":
        lines.insert(j, lines[j])
    elif op == "swap_lines":
        k = draw(st.integers(0, len(lines) - 1))
        lines[j], lines[k] = lines[k], lines[j]
    else:
        sep = b";" if lines[j].count(b";") > lines[j].count(b",") else (b"\t" if b"\t" in lines[j] else b",")
        fields = lines[j].split(sep)
        f = draw(st.integers(0, len(fields) - 1))
        if op == "bad_number":
            fields[f] = draw(st.sampled_from(_BAD_TOKENS))
        elif op == "drop_field":
            del fields[f]
        else:
            fields.insert(f, draw(st.sampled_from([b"1.5", b"", b"x"])))
        lines[j] = sep.join(fields)
    return b"\n".join(lines)


def _corrupt(draw, files: dict[str, bytes], container: str) -> tuple[dict[str, bytes], bool]:
    """Damage members of ``files``; returns them and whether to damage the zip archive itself too.

    A gzip member (or a member made one) may also be cut or flipped part-way after compression.
    """
    raw = {n[:-3] if n.endswith(".gz") else n: (gzip.decompress(d) if n.endswith(".gz") else d)
           for n, d in files.items()}
    gz = {n[:-3] for n in files if n.endswith(".gz")}
    for _ in range(draw(st.integers(1, 4))):
        name = draw(st.sampled_from(sorted(raw)))
        raw[name] = _damage(draw, raw[name])
        if container != "zip" and draw(st.integers(0, 5)) == 0:
            gz.add(name)
    out = {}
    for name, data in raw.items():
        if name in gz:
            comp = gzip.compress(data, 6, mtime=0)
            if draw(st.booleans()):
                comp = _damage(draw, comp)
            out[name + ".gz"] = comp
        else:
            out[name] = data
    return out, container == "zip" and draw(st.integers(0, 4)) == 0


def _read_damaged(workdir: str, export, draw, reader) -> None:
    """Damage a generated export (members, and now and then the zip archive itself) and read it."""
    files, container, _ = export
    files, archive = _corrupt(draw, files, container)
    path = _write(_fresh(workdir), files, container)
    if archive:
        with open(path, "rb") as f:
            data = f.read()
        with open(path, "wb") as f:
            f.write(_damage(draw, data))
    _read(draw(st.sampled_from([reader, load_recording])), path)


@_SETTINGS
@given(log=gsd_logs(), data=st.data())
def test_corrupted_getsensordata_logs_read_with_repairs_or_raise_a_recording_error(workdir, log, data):
    _read_damaged(workdir, log, data.draw, read_getsensordata)


@_SETTINGS
@given(export=sensorlogger_exports(), data=st.data())
def test_corrupted_sensorlogger_exports_read_with_repairs_or_raise_a_recording_error(workdir, export, data):
    _read_damaged(workdir, export, data.draw, read_sensorlogger)


@_SETTINGS
@given(export=phyphox_exports(), data=st.data())
def test_corrupted_phyphox_exports_read_with_repairs_or_raise_a_recording_error(workdir, export, data):
    _read_damaged(workdir, export, data.draw, read_phyphox)


# ---------------------------------------------------------------------------
# what the fuzzing found (each a traceback before)


def test_found_a_gzip_logfile_corrupt_from_its_start_is_a_recording_error(tmp_path):
    comp = bytearray(gzip.compress(b"% GetSensorData\n" + b"ACCE;0.0100;5.0100;0.1;0.2;9.8;3\n" * 50, 6))
    comp[12:16] = b"\xff\xff\xff\xff"  # the first deflate block: zlib.error while detecting the format
    p = tmp_path / "log.txt.gz"
    p.write_bytes(bytes(comp))
    for reader in (load_recording, read_getsensordata):
        with pytest.raises(RecordingError, match=f"^{p}: "):
            reader(str(p))


def test_found_a_sensorlogger_export_whose_sensor_files_are_all_empty_is_a_recording_error(tmp_path):
    files = {"TotalAcceleration.csv": b"", "Gyroscope.csv": b"  \n",
             "Metadata.csv": b"version,device name,recording time,platform,appVersion\n3,P,2024,android,1.30\n"}
    path = _write(str(tmp_path), files, "zip")
    with pytest.raises(RecordingError, match=r"no usable sensor data \(all Sensor Logger files empty\?\)"):
        read_sensorlogger(path)  # was: ValueError: min() arg is an empty sequence


def test_found_an_error_message_is_one_line_whatever_the_file_held(tmp_path):
    files = {"Raw Data.csv": b'"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"\n'
                             b"2.000000000E-3,0.000000000E0,0.000000000E0,9.000000000E0\n",
             "meta/time.csv": b'"\n"\n'}  # a quoted field holding a newline where the header belongs
    path = _write(str(tmp_path), files, "zip")
    with pytest.raises(RecordingError) as e:
        read_phyphox(path)
    assert str(e.value) == f"{path}/meta/time.csv:1: meta/time.csv: expected columns event, experiment time, " \
                           "system time; found \\n"
