"""Issue #12, the readers: damaged files, wrong units, wrong time bases, Sensor Logger exports with parts missing.

Each test feeds one class of bad input to the project-format reader or an
importer and checks the outcome: a :class:`RecordingError` naming the file,
the line and the problem, or a partial read listed in ``Recording.repairs``.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import warnings
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from core.importers import load_recording
from core.importers.getsensordata import parse_getsensordata, read_getsensordata
from core.recording import (_METADATA_TYPES, DamagedFileWarning, Recording, RecordingError, make_stream,
                            parse_recording, read_recording, write_recording)

#: examples of the reader fuzz tests: 200 in CI; the long fuzz run (README, Development) sets PDR_FUZZ_EXAMPLES
FUZZ_EXAMPLES = int(os.environ.get("PDR_FUZZ_EXAMPLES", "200"))

G = 9.80665


def _walk(n=400, rate_hz=100.0, seed=0, t0_ns=10**12):
    """A plausible hand-held recording: acc near g with a step rhythm, small gyro, a field of 45 uT."""
    rng = np.random.default_rng(seed)
    t = t0_ns + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    ph = 2 * np.pi * 2.0 * np.arange(n) / rate_hz
    acc = np.column_stack([0.5 * np.sin(ph), 0.3 * np.cos(ph), G + 1.5 * np.sin(ph)]) + rng.normal(0, 0.05, (n, 3))
    gyro = np.column_stack([0.4 * np.sin(ph), 0.2 * np.cos(ph), 0.1 * np.sin(ph / 2)]) + rng.normal(0, 0.01, (n, 3))
    mag = np.tile([20.0, 5.0, -40.0], (n, 1)) + rng.normal(0, 0.3, (n, 3))
    return Recording({"acc": make_stream("acc", t, acc), "gyro": make_stream("gyro", t + 500, gyro),
                      "mag": make_stream("mag", t + 900, mag)}, device={"model": "test"})


def _text(rec: Recording) -> str:
    from core.recording import FORMAT_VERSION, MAGIC, format_row
    return (f"{MAGIC} {FORMAT_VERSION}\n# " + json.dumps(rec.header(), sort_keys=True) + "\n"
            + "".join(format_row(n, t, v) for n, t, v in rec.events()))


def _quiet(fn, *a, **k):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **k)


# ---------------------------------------------------------------------------
# class 4: damaged files


def test_truncated_gzip_keeps_what_came_before_the_damage(tmp_path):
    rec = _walk(3000)
    path = tmp_path / "walk.csv.gz"
    write_recording(str(path), rec)
    data = path.read_bytes()
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(DamagedFileWarning, match="truncated"):
        back = read_recording(str(cut))
    n = sum(len(s) for s in back.streams.values())
    assert 0.3 * 9000 < n < 9000  # a good part of the walk, not all of it
    assert any("gzip stream is truncated" in r for r in back.repairs)
    # what was kept is exactly what was written
    for name, s in back.streams.items():
        orig = rec.streams[name]
        np.testing.assert_array_equal(s.t_ns, orig.t_ns[: len(s)])
        np.testing.assert_array_equal(s.values, orig.values[: len(s)])
    # the same through load_recording
    assert sum(len(s) for s in _quiet(load_recording, str(cut)).streams.values()) == n


def test_truncated_gzip_getsensordata_keeps_the_start(tmp_path):
    lines = ["% GetSensorData test"] + [f"ACCE;{k * 0.01:.3f};{100 + k * 0.01:.4f};0.1;0.2;9.8;3"
                                         for k in range(3000)]
    data = gzip.compress(("\n".join(lines) + "\n").encode())
    p = tmp_path / "log.txt.gz"
    p.write_bytes(data[: len(data) // 2])
    with pytest.warns(DamagedFileWarning, match="truncated"):
        rec = read_getsensordata(str(p))
    assert 100 < len(rec.streams["acc"]) < 3000
    np.testing.assert_allclose(rec.streams["acc"].values[:, 2], 9.8)


def test_last_line_cut_inside_a_number_is_dropped_not_read_as_another_number():
    rec = _walk(200)
    text = _text(rec) + "acc,99999999999999,0.1,0.2,2.586e-0"  # a cut 2.586e-05: parses, but is wrong
    with pytest.warns(DamagedFileWarning, match="incomplete last line"):
        back = parse_recording(text, "walk.csv")
    assert len(back.streams["acc"]) == 200
    assert 2.586 not in back.streams["acc"].values
    gsd = "% GetSensorData\n" + "".join(f"ACCE;{k * 0.01:.2f};{k * 0.01:.2f};0.1;0.2;9.8;3\n" for k in range(50))
    g = _quiet(parse_getsensordata, gsd + "ACCE;0.50;0.50;0.1;0.2;2.586e-0", "log.txt")
    assert len(g.streams["acc"]) == 50 and not np.any(g.streams["acc"].values == 2.586)


def test_sensorlogger_last_line_cut_inside_a_number_is_dropped_phyphox_keeps_its_unterminated_last_line(tmp_path):
    # Sensor Logger ends every line with a newline: one without it was cut, maybe inside its last number
    def cut(lines):
        lines[-2] = lines[-2][:-6] + "2.586e-0"  # "...,-0.003" of the last row cut as if mid-write
        del lines[-1]  # no newline after it

    with pytest.warns(DamagedFileWarning, match=r"Gyroscope.csv: dropped an incomplete last line 301 \(no newline"):
        rec = load_recording(_export(tmp_path, "sensorlogger", "Gyroscope.csv", cut))
    assert len(rec.streams["gyro"]) == 299 and not np.any(rec.streams["gyro"].values == 2.586)
    # phyphox writes no newline after its last row (the real exports of ../shared/data): a whole row is kept
    rec = _quiet(load_recording, _export(tmp_path / "p", "phyphox", "Gyroscope.csv", lambda lines: lines.pop()))
    assert len(rec.streams["gyro"]) == 200 and not rec.repairs


@pytest.mark.parametrize("bad", ["acc,1000000500000,0.1,zz,9.8", "acc,1000000500000,0.1,9.8",
                                 "acc,10000x0500000,0.1,0.2,9.8", "acx,1000000500000,0.1,0.2,9.8",
                                 "acc,99999999999999999999999,0.1,0.2,9.8"])
def test_one_bad_line_in_the_middle_is_skipped_and_counted(bad):
    rec = _walk(300)
    lines = _text(rec).split("\n")
    lines.insert(200, bad)
    with pytest.warns(DamagedFileWarning, match="skipped 1 bad line"):
        back = parse_recording("\n".join(lines), "walk.csv")
    assert sum(len(s) for s in back.streams.values()) == 900
    assert any("skipped 1 bad line(s) of 901 (first: line 201" in r for r in back.repairs)


def test_many_bad_lines_reject_the_file_naming_the_first():
    rec = _walk(300)
    lines = _text(rec).split("\n")
    for k in range(10):  # 10 of 910 lines: over 1 %
        lines.insert(100 + 50 * k, "acc,1000,0.1,zz,9.8")
    with pytest.raises(RecordingError,
                       match=r"'zz' of column 'y' is not a number \(10 bad lines of 910: too many") as e:
        parse_recording("\n".join(lines), "walk.csv")
    assert e.value.line == 101


def test_getsensordata_one_bad_line_is_skipped_many_reject():
    rows = [f"ACCE;{k * 0.01:.2f};{k * 0.01:.2f};0.1;0.2;9.8;3" for k in range(300)]
    bad = list(rows)
    bad[150] = "ACCE;1.50;1.5#;0.1;0.2;9.8;3"
    rec = _quiet(parse_getsensordata, "% GetSensorData\n" + "\n".join(bad) + "\n", "log.txt")
    assert len(rec.streams["acc"]) == 299
    assert any("skipped 1 bad line(s) of 300 (first: line 152" in r for r in rec.repairs)
    for k in range(0, 300, 30):
        bad[k] = "ACCE;1.50;0.1"
    with pytest.raises(RecordingError, match="missing fields.*bad lines of 300") as e:
        parse_getsensordata("% GetSensorData\n" + "\n".join(bad) + "\n", "log.txt")
    assert e.value.line == 2


def _export(tmp_path, fmt: str, member: str, change) -> str:
    """A Sensor Logger folder or a phyphox zip (the synthetic exports of test_importers) with one CSV changed.

    The CSV's text is encoded as Latin-1 (``"\\xff"`` stays one byte that is not UTF-8).
    """
    from tests.test_importers import phyphox_files, sl_files
    files = sl_files("android", n=300) if fmt == "sensorlogger" else phyphox_files()
    lines = files[member].split("\n")
    change(lines)
    data = {k: v.encode() for k, v in files.items()}
    data[member] = "\n".join(lines).encode("latin-1")
    if fmt == "sensorlogger":
        root = tmp_path / "sl"
        root.mkdir(parents=True)
        for name, b in data.items():
            (root / name).write_bytes(b)
        return str(root)
    tmp_path.mkdir(parents=True, exist_ok=True)
    path = tmp_path / "phy.zip"
    with zipfile.ZipFile(path, "w") as z:
        for name, b in data.items():
            z.writestr(name, b)
    return str(path)


#: one bad line in the middle of an export's CSV: (format, member, line index, how it is damaged, message)
_CSV_DAMAGE = [
    ("sensorlogger", "Gyroscope.csv", 150, lambda ln: ln.replace("0.002", "0.0o2"),
     r"column 'y' is not a number: '0.0o2'"),
    ("sensorlogger", "Magnetometer.csv", 99, lambda ln: ",".join(ln.split(",")[:3]),
     r"missing fields: the header has 5 columns, this line 3"),
    ("sensorlogger", "TotalAcceleration.csv", 200, lambda ln: ln[:5] + "\xff" + ln[6:],
     r"column 'time' is not an integer: '17000\xff"),
    ("phyphox", "Gyroscope.csv", 100, lambda ln: ln.replace("E-3", "E-3x", 1),
     r"column 'Gyroscope x \(rad/s\)' is not"),
    ("phyphox", "Raw Data.csv", 250, lambda ln: ",".join(ln.split(",")[:2]),
     r"missing fields: no value for Acceleration y \(m/s\^2\), Acceleration z"),
]


@pytest.mark.parametrize("fmt,member,k,damage,message", _CSV_DAMAGE)
def test_one_bad_line_in_an_export_csv_is_skipped_and_counted(tmp_path, fmt, member, k, damage, message):
    def change(lines):
        lines[k] = damage(lines[k])

    path = _export(tmp_path, fmt, member, change)
    with pytest.warns(DamagedFileWarning, match=rf"{member}: skipped 1 bad line\(s\) of \d+ \(first: line {k + 1}: "
                                                rf"{message}"):
        rec = load_recording(path)
    name = {"Gyroscope.csv": "gyro", "Magnetometer.csv": "mag"}.get(member, "acc")
    clean = _quiet(load_recording, _export(tmp_path / "clean", fmt, member, lambda lines: None))
    assert len(rec.streams[name]) == len(clean.streams[name]) - 1  # that line, and only it, is missing
    for other in set(clean.streams) - {name}:
        assert len(rec.streams[other]) == len(clean.streams[other])
    assert any(f"skipped 1 bad line(s)" in r for r in rec.repairs)


@pytest.mark.parametrize("fmt,member", [("sensorlogger", "Gyroscope.csv"), ("phyphox", "Gyroscope.csv")])
def test_more_bad_export_lines_than_1_percent_reject_the_walk_naming_the_first(tmp_path, fmt, member):
    def change(lines):
        for k in range(20, 40, 5):  # 4 of 150-300 lines: over 1 %
            lines[k] = lines[k].replace(",", ";", 1) if fmt == "sensorlogger" else lines[k].replace("E", "Q", 1)

    with pytest.raises(RecordingError, match=r"bad lines of \d+: too many to skip; at most 100 and 1 %") as e:
        load_recording(_export(tmp_path, fmt, member, change))
    assert e.value.line == 21 and str(e.value).startswith(str(tmp_path)) and member in str(e.value)


def test_at_most_100_bad_export_lines_are_skipped_even_in_a_long_file(tmp_path):
    from tests.test_importers import sl_files, write_folder
    files = sl_files("android", n=12_000)  # 101 bad lines are under 1 % of these, but over 100
    lines = files["Gyroscope.csv"].split("\n")
    for k in range(100, 100 + 101 * 50, 50):
        lines[k] = lines[k].replace("0.002", "x")
    files["Gyroscope.csv"] = "\n".join(lines)
    with pytest.raises(RecordingError, match=r"Gyroscope.csv:101: column 'y' is not a number: 'x' \(over 100 bad "
                                             r"lines of \d+: too many to skip"):
        load_recording(str(write_folder(tmp_path / "sl", files)))


def test_non_utf8_bytes_get_a_line_number_and_a_comment_does_not_matter(tmp_path):
    rec = _walk(300)
    lines = _text(rec).encode().split(b"\n")
    lines.insert(5, b"# comment with a Latin-1 byte: \xb5T")
    p = tmp_path / "walk.csv"
    p.write_bytes(b"\n".join(lines))
    back = read_recording(str(p))
    assert sum(len(s) for s in back.streams.values()) == 900 and not back.repairs
    lines[100] = b"acc,1000000000000,0.1,\xff\xfe,9.8"
    p.write_bytes(b"\n".join(lines))
    with pytest.warns(DamagedFileWarning, match="line 101: bytes that are not UTF-8"):
        back = read_recording(str(p))
    assert sum(len(s) for s in back.streams.values()) == 899
    lines[1] = lines[1].replace(b'"model"', b'"mod\xffel"')
    p.write_bytes(b"\n".join(lines))
    with pytest.raises(RecordingError, match="walk.csv:2: header line holds bytes that are not UTF-8"):
        read_recording(str(p))


def _with_header(change):
    rec = _walk(50)
    h = rec.header()
    change(h)
    return "# pdr-recording 1\n# " + json.dumps(h) + "\n" + _text(rec).split("\n", 2)[2]


@pytest.mark.parametrize("change,match", [
    (lambda h: h.update(streams=[["acc"]]), "non-empty 'streams' object"),
    (lambda h: h["streams"].update(acc=["x", "y", "z"]), "stream 'acc' must be a JSON object"),
    (lambda h: h.update(device=["phone"]), "'device' must be a JSON object, found list"),
    (lambda h: h.update(metadata="walker"), "'metadata' must be a JSON object, found str"),
    (lambda h: h["streams"]["acc"].update(unit=9.81), "'unit' must be a string, found float"),
    (lambda h: h["streams"]["acc"].update(columns=["x", "y"]), "stream 'acc' declares 2 columns; a 'acc' stream has 3"),
    (lambda h: h["streams"]["acc"].update(columns=[1, 2, 3]), "needs a non-empty list of 'columns'"),
    (lambda h: h.update(format_version="1"), "'format_version' is '1', the magic line says 1"),
    (lambda h: h.update(format_version=2), "'format_version' is 2, the magic line says 1"),
    (lambda h: h.update(format="other-format"), "'format' is 'other-format'"),
    (lambda h: h.update(metadata={"unix_offset_ns": "1700000000000000000"}), "'unix_offset_ns' must be an integer"),
    (lambda h: h.update(metadata={"waypoints_en_m": [[0, 0], ["10", 5]]}), "'waypoints_en_m' must be a list of"),
    (lambda h: h.update(metadata={"devices": {"left_foot": "shoe"}}), "'devices' must be an object of objects"),
])
def test_header_fields_of_the_wrong_type_are_a_clear_error(change, match):
    with pytest.raises(RecordingError, match=match) as e:
        parse_recording(_with_header(change), "walk.csv")
    assert e.value.line == 2 and str(e.value).startswith("walk.csv:2:")


# ---------------------------------------------------------------------------
# property tests of the project-format reader

_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def _recordings(draw):
    streams = {}
    lo, hi = 0, 2**63 - 1  # t_ns counts from the boot: never negative (round 3: a negative one is a bad line)
    for name, k in (("acc", 3), ("gyro", 3), ("gps", 6), ("pressure", 1)):
        if name != "acc" and not draw(st.booleans()):
            continue
        ts = sorted(draw(st.lists(st.integers(lo, hi), min_size=1 if name == "acc" else 0, max_size=12,
                                  unique=True)))
        if name == "acc":  # the other streams on the same clock as the IMU (core.validation checks it)
            lo, hi = ts[0], ts[-1]
        vals = [[draw(_finite) for _ in range(k)] for _ in ts]
        if name == "gps":  # possible fixes (core.validation drops impossible ones, sets impossible speeds unknown)
            vals = [[draw(st.floats(-90, 90)), draw(st.floats(-180, 180)), v[2], abs(v[3]), draw(st.floats(0, 515)),
                     draw(st.floats(0, 360))] for v in vals]
        cols = [f"v{j}" for j in range(k)] if name == "pressure" else None
        streams[name] = make_stream(name, ts, np.array(vals, dtype=np.float64).reshape(len(ts), k), columns=cols,
                                    unit="hPa" if name == "pressure" else None)
    # free metadata: keys the format gives a type to ("truth", "devices", ...) are not free (found by the long
    # fuzz run: {"truth": 0} was written and, rightly, refused on reading)
    typed = {k for k, _, _ in _METADATA_TYPES}
    meta = draw(st.dictionaries(st.text(max_size=5).filter(lambda k: k not in typed),
                                st.one_of(st.integers(-10**6, 10**6), st.text(max_size=8)), max_size=3))
    return Recording(streams, device={"model": draw(st.text(max_size=10))}, metadata=meta)


@settings(max_examples=max(100, FUZZ_EXAMPLES // 2), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rec=_recordings())
def test_valid_recordings_round_trip_exactly(rec):
    back = parse_recording(_text(rec), "r.csv", warn=False)
    assert back.device == rec.device and back.metadata == rec.metadata and not back.repairs
    for name, s in rec.streams.items():
        b = back.streams[name]
        assert b.columns == s.columns and b.unit == s.unit
        np.testing.assert_array_equal(b.t_ns, s.t_ns)
        np.testing.assert_array_equal(b.values, s.values)


@st.composite
def _corrupted(draw):
    data = bytearray(_text(draw(_recordings())).encode())
    for _ in range(draw(st.integers(1, 4))):
        what = draw(st.sampled_from(["flip", "cut", "insert", "delete"]))
        if not data:
            break
        i = draw(st.integers(0, len(data) - 1))
        if what == "flip":
            data[i] = draw(st.integers(0, 255))
        elif what == "cut":
            del data[i:]
        elif what == "delete":
            del data[i:i + draw(st.integers(1, 20))]
        else:
            data[i:i] = draw(st.sampled_from([b"\n", b",", b"acc,1,2,3\n", b"gyro,5,x,1,2\n", b"# c\n", b"\xff",
                                              b"1e999", b"nan", b"-", b"\"", b"{", b"]"]))
    return bytes(data)


@settings(max_examples=FUZZ_EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=_corrupted(), gz=st.booleans())
def test_corrupted_recordings_read_with_repairs_or_raise_a_recording_error(tmp_path_factory, data, gz):
    p = tmp_path_factory.mktemp("c") / ("r.csv.gz" if gz else "r.csv")
    if gz:  # a corrupted text, compressed, then the compressed bytes cut short
        raw = gzip.compress(data)
        p.write_bytes(raw[: max(10, len(raw) * 3 // 4)])
    else:
        p.write_bytes(data)
    try:
        rec = read_recording(str(p), warn=False)
    except RecordingError as e:
        assert "\n" not in str(e) and str(p) in str(e)
        return
    assert sum(len(s) for s in rec.streams.values()) > 0


# ---------------------------------------------------------------------------
# class 2: units


def _with_units(rec: Recording, **units) -> str:
    for name, u in units.items():
        rec.streams[name].unit = u
    return _text(rec)


@pytest.mark.parametrize("name,unit,factor", [("acc", "g", G), ("gyro", "deg/s", math.pi / 180), ("mag", "mT", 1000.0),
                                              ("mag", "nT", 1e-3), ("mag", "G", 100.0), ("mag", "\u00b5T", 1.0)])
def test_known_units_are_converted_and_noted(name, unit, factor):
    rec = _walk(200)
    si = rec.streams[name].values.copy()
    rec.streams[name].values = si / factor
    back = parse_recording(_with_units(rec, **{name: unit}), "walk.csv")
    s = back.streams[name]
    np.testing.assert_allclose(s.values, si, rtol=1e-12)
    assert s.unit == {"acc": "m/s^2", "gyro": "rad/s", "mag": "uT"}[name]
    assert factor == 1.0 or any(f"'{name}' converted from {unit}" in r for r in back.repairs)


def test_unknown_unit_is_refused_naming_stream_unit_and_the_accepted_ones():
    with pytest.raises(RecordingError, match=r"walk.csv:2: stream 'acc' declares unit 'furlong/fortnight\^2'; "
                                             r"a 'acc' stream takes 'm/s\^2', 'm/s2', 'g'"):
        parse_recording(_with_units(_walk(60), acc="furlong/fortnight^2"), "walk.csv")
    with pytest.raises(RecordingError, match="stream 'gyro@left_foot' declares unit 'rpm'"):
        rec = _walk(60)
        rec.streams["gyro@left_foot"] = make_stream("gyro@left_foot", rec.streams["gyro"].t_ns,
                                                    rec.streams["gyro"].values, unit="rpm")
        parse_recording(_text(rec), "walk.csv")


@pytest.mark.parametrize("name,scale,match", [
    ("acc", 1 / G, "stream 'acc' is declared in m/s\\^2 but its magnitude while still-ish is 0.9[0-9]*, about 1: "
                   "it looks like g"),
    ("acc", 100.0, "looks like cm/s\\^2 or mg"),
    ("gyro", 180 / math.pi * 20, "stream 'gyro' is declared in rad/s.*it looks like deg/s"),
    ("mag", 1000.0, "stream 'mag' is declared in uT.*looks like nT"),
    ("mag", 0.01, "looks like gauss"),
    ("mag", 0.001, "looks like mT"),
])
def test_values_that_do_not_fit_their_declared_unit_are_refused(name, scale, match):
    rec = _walk(300)
    rec.streams[name].values = rec.streams[name].values * scale
    with pytest.raises(RecordingError, match=match):
        parse_recording(_text(rec), "walk.csv")
    back = parse_recording(_text(rec), "walk.csv", check_units=False)  # the check can be turned off
    assert len(back.streams[name]) == 300


def test_a_dead_sensor_and_a_short_file_are_not_unit_errors():
    rec = _walk(300)
    rec.streams["acc"].values[:] = 0.0
    rec.streams["mag"].values[:] = 0.0
    assert len(parse_recording(_text(rec), "walk.csv").streams["acc"]) == 300
    short = _walk(30)
    short.streams["acc"].values /= G
    assert len(parse_recording(_text(short), "walk.csv").streams["acc"]) == 30


# ---------------------------------------------------------------------------
# class 3: time bases


def _retime(rec: Recording, fn) -> Recording:
    for s in rec.streams.values():
        s.t_ns = fn(s.t_ns)
    return rec


@pytest.mark.parametrize("divisor,looks", [(10**6, "milliseconds"), (10**3, "microseconds")])
def test_timestamps_in_ms_or_us_are_refused_saying_which(divisor, looks):
    rec = _retime(_walk(300), lambda t: t // divisor)
    with pytest.raises(RecordingError, match=f"stream 'acc': the median interval is .* if they were nanoseconds.*"
                                             f"look like {looks}") as e:
        parse_recording(_text(rec), "walk.csv")
    assert "1-2000 Hz" in str(e.value)


def test_timestamps_in_whole_seconds_are_refused():
    rec = _retime(_walk(300), lambda t: t // 10**9)
    with pytest.raises(RecordingError, match="repeat the previous timestamp.*too coarse"):
        parse_recording(_text(rec), "walk.csv")


def test_timestamps_beyond_int64_are_a_clean_error():
    text = _text(_walk(30)).replace("acc,1000", "acc,99999999999999999999")
    with pytest.raises(RecordingError, match=r"walk.csv:3: timestamp 99999999999999999999\d+ does not fit a 64-bit"):
        parse_recording(text, "walk.csv")


def test_a_clock_that_jumps_back_a_minute_is_refused_naming_the_line():
    rec = _walk(600)
    for s in rec.streams.values():
        s.t_ns = np.where(np.arange(len(s)) >= 300, s.t_ns - 63 * 10**9, s.t_ns)  # back 63 s after 3 s
    text = "# pdr-recording 1\n# " + json.dumps(rec.header()) + "\n" + "".join(
        f"{n},{t},{','.join(map(repr, v.tolist()))}\n" for n in ("acc",) for t, v in zip(rec.streams[n].t_ns,
                                                                                        rec.streams[n].values))
    with pytest.raises(RecordingError, match=r"walk.csv:303: stream 'acc': the clock jumps back by 63.0 s.*\(line "
                                             r"302\).*interleave"):
        parse_recording(text, "walk.csv")
    # small backwards steps (real phones) are still repaired by sorting
    lines = text.split("\n")
    lines[10], lines[11] = lines[11], lines[10]
    back = _quiet(parse_recording, "\n".join(lines[:200]) + "\n", "walk.csv")
    assert any("went backwards" in r for r in back.repairs)


def test_a_rate_change_is_not_thousands_of_gaps():
    t1 = np.arange(3000) * 5_000_000  # 200 Hz for 15 s
    t2 = t1[-1] + 20_000_000 + np.arange(3000) * 20_000_000  # then 50 Hz
    t = np.concatenate([t1, t2, t2[-1] + 5 * 10**9 + np.arange(500) * 20_000_000])  # and one 5 s gap
    s = make_stream("acc", t, np.zeros((len(t), 3)))
    st_ = s.interval_stats_s()
    assert st_["gaps"] == 1
    assert st_["rate_changes"] == 1 and st_["rates_hz"] == pytest.approx([200.0, 50.0])
    steady = make_stream("acc", t1, np.zeros((len(t1), 3))).interval_stats_s()
    assert steady["gaps"] == 0 and steady["rate_changes"] == 0 and steady["median_s"] == pytest.approx(0.005)


def test_a_header_only_file_is_an_error_or_with_allow_empty_an_empty_recording(tmp_path):
    from core.recording import FORMAT_VERSION, MAGIC, RecordingWriter, header_line
    p = tmp_path / "live.csv"
    w = RecordingWriter(str(p), device={"model": "phone"})
    w.flush()  # round 3: the writer holds the header until its first events: killed now, no file is left
    assert not p.exists()
    w.close()
    assert not p.exists()
    empty = Recording({n: make_stream(n, [], np.zeros((0, 6 if n == "gps" else 3))) for n in ("acc", "gyro", "mag",
                                                                                             "gps")},
                      device={"model": "phone"})
    p.write_text(f"{MAGIC} {FORMAT_VERSION}\n" + header_line(empty, str(p)))  # another writer's header-only file
    with pytest.raises(RecordingError, match="header but no sensor events: an empty recording"):
        read_recording(str(p))
    rec = read_recording(str(p), allow_empty=True, warn=False)
    assert set(rec.streams) == {"acc", "gyro", "mag", "gps"} and not any(len(s) for s in rec.streams.values())
    assert rec.device == {"model": "phone"} and any("no sensor events" in r for r in rec.repairs)
