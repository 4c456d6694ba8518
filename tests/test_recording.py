"""The pdr-recording format: exact round trips, clear errors, timestamp repair."""

import json
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from core.recording import (MissingSensorError, Recording, RecordingError, RecordingWriter, TimestampRepairWarning,
                            make_stream, parse_recording, read_recording, write_recording)

HEADER = ('# pdr-recording 1\n# {"format": "pdr-recording", "format_version": 1, "streams": '
          '{"acc": {"columns": ["x", "y", "z"], "unit": "m/s^2"}, "gyro": {"columns": ["x", "y", "z"], '
          '"unit": "rad/s"}}}\n')


def _small_recording(rng, n=50):
    t = 10**12 + np.cumsum(rng.integers(5_000_000, 15_000_000, n))
    return Recording({
        "acc": make_stream("acc", t, rng.normal(0, 5, (n, 3))),
        "gyro": make_stream("gyro", t + 1234, rng.normal(0, 1, (n, 3))),
        "gps": make_stream("gps", t[:3], [[47.1, 8.5, 400.0, 4.0], [47.2, 8.6, 401.0, math.nan], [47.3, 8.7, 402, 3]]),
    }, device={"model": "test"}, metadata={"walker": "x", "height_m": 1.8})


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz"])
def test_round_trip_is_exact(tmp_path, suffix):
    rec = _small_recording(np.random.default_rng(0))
    path = tmp_path / f"r{suffix}"
    write_recording(str(path), rec)
    back = read_recording(str(path))
    assert back.device == rec.device and back.metadata == rec.metadata
    for name, s in rec.streams.items():
        b = back.streams[name]
        assert b.columns == s.columns and b.unit == s.unit
        np.testing.assert_array_equal(b.t_ns, s.t_ns)
        np.testing.assert_array_equal(b.values, s.values)  # repr() floats read back bit for bit


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(rows=st.lists(st.tuples(st.integers(0, 2**62), finite, finite, finite), min_size=1, max_size=30, unique_by=lambda r: r[0]))
def test_round_trip_property(rows):
    rows = sorted(rows)
    rec = Recording({"acc": make_stream("acc", [r[0] for r in rows], [r[1:] for r in rows])})
    text = "# pdr-recording 1\n# " + __import__("json").dumps(rec.header()) + "\n" + "".join(
        f"acc,{t},{x!r},{y!r},{z!r}\n" for t, x, y, z in rows)
    back = parse_recording(text, check_time=False, check_units=False)  # the number format, not plausibility
    np.testing.assert_array_equal(back.streams["acc"].t_ns, [r[0] for r in rows])
    np.testing.assert_array_equal(back.streams["acc"].values, [r[1:] for r in rows])


@pytest.mark.parametrize("text,match,line", [
    ("", "empty file", 1),
    ("acc,1,2,3,4\n", "not a pdr-recording", 1),
    ("# pdr-recording 2\n# {}\n", "version 2 is not supported", 1),
    ("# pdr-recording 1\n# {not json\n", "not valid JSON", 2),
    ("# pdr-recording 1\n# {\"streams\": {}}\n", "non-empty 'streams'", 2),
    (HEADER + "acc,1000,1.0,2.0\nacc,2000,1,2,3\n", "missing columns.*found 2", 3),
    (HEADER + "acc,1000,1.0,2.0,3.0,4.0\nacc,2000,1,2,3\n", "extra columns", 3),
    (HEADER + "acc,1000,1.0,abc,3.0\nacc,2000,1,2,3\n", "'abc' of column 'y' is not a number", 3),
    (HEADER + "acc,1.5e3,1.0,2.0,3.0\nacc,2000,1,2,3\n", "not an integer nanosecond", 3),
    (HEADER + "mag,1000,1.0,2.0,3.0\nacc,2000,1,2,3\n", "stream 'mag' is not declared", 3),
    (HEADER, "no sensor events", None),
])
def test_bad_input_gives_one_clear_line(text, match, line):
    with pytest.raises(RecordingError, match=match) as e:
        parse_recording(text, "walk.csv")
    assert e.value.line == line
    assert str(e.value).startswith("walk.csv:")
    assert "\n" not in str(e.value)


def test_unreadable_file_names_it(tmp_path):
    with pytest.raises(RecordingError, match="cannot open"):
        read_recording(str(tmp_path / "missing.csv"))
    p = tmp_path / "bad.csv.gz"
    p.write_bytes(b"not gzip at all")
    with pytest.raises(RecordingError, match="bad.csv.gz"):
        read_recording(str(p))


def test_backwards_and_repeated_timestamps_are_repaired_with_a_count():
    text = HEADER + "".join(f"acc,{t},1,2,3\n" for t in [1000, 2000, 2000, 1500, 3000, 3000, 4000])
    with pytest.warns(TimestampRepairWarning, match="1 timestamp.*backwards and 2 repeated"):
        rec = parse_recording(text, "x.csv")
    np.testing.assert_array_equal(rec.streams["acc"].t_ns, [1000, 1500, 2000, 3000, 4000])
    assert len(rec.repairs) == 1 and "2 repeat(s) dropped" in rec.repairs[0]


def test_missing_sensor_names_it():
    rec = parse_recording(HEADER + "gyro,1000,1,2,3\n")
    with pytest.raises(MissingSensorError, match="no 'acc' stream.*step detection.*present: gyro"):
        rec.stream("acc", "step detection")


def test_writer_survives_an_abrupt_stop(tmp_path):
    path = tmp_path / "live.csv"
    w = RecordingWriter(str(path), device={"model": "phone"})
    for k in range(100):
        w.add("acc", 10**9 + k * 10_000_000, (0.1 * k, 9.8, 0.3))
    w.flush()
    w._f.write("acc,2000000000,1.0,9.")  # killed mid-line: no newline, no close
    w._f.flush()
    rec = read_recording(str(path))
    assert len(rec.streams["acc"]) == 100
    assert any("incomplete last line" in r for r in rec.repairs)
    with pytest.raises(RecordingError):
        read_recording(str(path), allow_truncated_tail=False)


def test_events_are_merged_in_time_order():
    rec = _small_recording(np.random.default_rng(1))
    ts = [t for _, t, _ in rec.events()]
    assert ts == sorted(ts)
    assert len(ts) == sum(len(s) for s in rec.streams.values())


# ---------------------------------------------------------------------------
# the writers refuse a header the reader would refuse (issue #12): one check, core.recording.check_header

@pytest.mark.parametrize("device,metadata,match", [
    ({}, {"truth": 0}, "header metadata 'truth' must be an object, found 0"),
    ({}, {"unix_offset_ns": "1700000000000000000"}, "'unix_offset_ns' must be an integer"),
    ({}, {"t0_unix_ns": 1.7e18}, "'t0_unix_ns' must be an integer"),
    ({}, {"waypoints_en_m": [[0, 0], [1, "2"]]}, "'waypoints_en_m' must be a list of"),
    ({}, {"devices": {"left_foot": "shoe"}}, "'devices' must be an object of objects"),
    (["phone"], {}, "'device' must be a JSON object, found list"),
    ({}, {"walker": {1, 2}}, r"the header is not JSON \(Object of type set"),
])
def test_writers_refuse_a_header_the_reader_refuses_and_write_nothing(tmp_path, device, metadata, match):
    rec = _small_recording(np.random.default_rng(2))
    rec.device, rec.metadata = device, metadata
    path = tmp_path / "walk.csv"
    with pytest.raises(RecordingError, match=f"^{path}: cannot write: .*{match}"):
        write_recording(str(path), rec)
    assert not path.exists()
    with pytest.raises(RecordingError, match=f"^{path}: cannot write: .*{match}"):
        RecordingWriter(str(path), device=device, metadata=metadata)
    assert not path.exists()


_json = st.recursive(st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats(allow_nan=False, width=64)
                     | st.text(max_size=4),
                     lambda inner: (st.lists(inner, max_size=3)
                                    | st.dictionaries(st.text(max_size=3), inner, max_size=3)),
                     max_leaves=8)


@settings(max_examples=150, deadline=None)
@given(meta=st.dictionaries(st.sampled_from(["truth", "devices", "unix_offset_ns", "t0_unix_ns", "waypoints_en_m",
                                             "walker"]), _json, max_size=4))
def test_what_the_writer_writes_reads_back_and_what_it_refuses_the_reader_refuses(tmp_path_factory, meta):
    rec = _small_recording(np.random.default_rng(3), n=30)
    rec.metadata = meta
    path = tmp_path_factory.mktemp("w") / "walk.csv"
    try:
        write_recording(str(path), rec)
    except RecordingError as e:
        assert not path.exists() and "cannot write: header metadata" in str(e)
        refused = str(e).split("cannot write: ", 1)[1]
        with pytest.raises(RecordingError, match=re.escape(refused)):
            parse_recording(_text_with_header(rec), "walk.csv", check_units=False)
        return
    back = read_recording(str(path), check_units=False)
    assert back.metadata == json.loads(json.dumps(meta))


def _text_with_header(rec) -> str:
    """The file the writer would write, without the writer's check (what the reader alone says of it)."""
    from core.recording import FORMAT_VERSION, MAGIC, format_row
    return (f"{MAGIC} {FORMAT_VERSION}\n# {json.dumps(rec.header(), sort_keys=True)}\n"
            + "".join(format_row(n, t, v) for n, t, v in rec.events()))


def test_jitter_leaves_gaps_out():
    import numpy as np

    from core.recording import jitter_s

    rng = np.random.default_rng(4)
    dt = 0.01 + rng.normal(0.0, 0.0005, 2000)
    with_gaps = dt.copy()
    with_gaps[::100] = 0.5  # 20 gaps of half a second: reported as gaps, not as jitter
    assert abs(jitter_s(dt) - 0.0005) < 0.00005
    assert abs(jitter_s(with_gaps) - jitter_s(dt[np.arange(len(dt)) % 100 != 0])) < 1e-12
    assert np.isnan(jitter_s([0.01]))
