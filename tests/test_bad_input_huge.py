"""Issue #12, class 5: huge and hostile files.

The readers stream: their peak memory (tracemalloc: Python's and numpy's
allocations, deterministic for a given file) stays within a fixed number of
bytes per event above the recording they return, instead of holding the
file's text and a Python object per row (about 490 bytes an event before).
Gzip streams and archive members larger than a limit (2 GiB by default,
:data:`core.recording.MAX_UNCOMPRESSED_BYTES`; a small one passed as a
parameter here) are refused in one line naming the file, the member, its
size and the limit -- while inflating, since a zip header can lie -- without
taking more than about the limit's worth of memory.
"""

from __future__ import annotations

import gzip
import struct
import tracemalloc
import warnings
import zipfile

import numpy as np
import pytest

import core.recording
from benchmarks.reader_memory import _signals, write_gsd, write_pdr, write_phyphox, write_sensorlogger
from core.importers import load_recording, read_getsensordata, read_phyphox, read_sensorlogger
from core.recording import MAX_UNCOMPRESSED_BYTES, RecordingError, read_recording

#: peak bytes per event above the result allowed (measured here: 56-74; 160-550 before streaming); the
#: margin covers the chunk buffers on a short file
MAX_BYTES_PER_EVENT = 120
MINUTES = 3.0  # 45 000 events at 250 a second


def _peak(fn, *a, **k):
    """(result, peak traced bytes) of a call."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tracemalloc.start()
        try:
            out = fn(*a, **k)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    return out, peak


@pytest.fixture(scope="module")
def walk():
    return _signals(MINUTES, seed=3)


@pytest.mark.parametrize("name,writer,reader", [
    ("walk.csv", write_pdr, read_recording),
    ("log.txt", write_gsd, read_getsensordata),
    ("sl.zip", write_sensorlogger, read_sensorlogger),
    ("phy.zip", write_phyphox, read_phyphox),
])
def test_readers_stream_memory_does_not_grow_with_the_text(tmp_path, walk, name, writer, reader):
    path = str(tmp_path / name)
    writer(path, walk)
    rec, peak = _peak(reader, path)
    n = sum(len(s) for s in rec.streams.values())
    result = sum(s.t_ns.nbytes + s.values.nbytes for s in rec.streams.values())
    assert n >= 0.99 * MINUTES * 60 * 250
    per_event = (peak - result) / n
    assert per_event < MAX_BYTES_PER_EVENT, f"{per_event:.0f} bytes an event above the result"
    # and what was read is what was written (values within the writers' decimal formatting)
    t, v = walk["acc"]
    acc = rec.streams["acc"]
    assert len(acc) == len(t)
    np.testing.assert_allclose(acc.values, v, rtol=0, atol=1e-4)


# ---------------------------------------------------------------------------
# size limits

LIMIT = 1 << 20  # 1 MiB instead of 2 GiB: the same code path, a fast test


def _bomb_rows(n_bytes: int, row: str = "acc,{t},0.1,0.2,9.8\n") -> bytes:
    """Rows adding up to about ``n_bytes``: 10 s at 100 Hz again and again (they compress about 300 times)."""
    block = "".join(row.format(t=10**12 + 10_000_000 * k) for k in range(1000)).encode()
    return block * max(1, n_bytes // len(block))


def _pdr_bomb(n_bytes: int) -> bytes:
    head = ('# pdr-recording 1\n# {"streams": {"acc": {"columns": ["x", "y", "z"], "unit": "m/s^2"}}}\n').encode()
    return gzip.compress(head + _bomb_rows(n_bytes), 6)


def test_gzip_bomb_is_refused_while_inflating_naming_file_and_limit(tmp_path):
    p = tmp_path / "bomb.csv.gz"
    p.write_bytes(_pdr_bomb(2 * LIMIT))  # 2 MiB of text in about 35 KiB
    assert p.stat().st_size < LIMIT / 20
    with pytest.raises(RecordingError) as e:
        read_recording(str(p), max_uncompressed_bytes=LIMIT)
    msg = str(e.value)
    assert msg.startswith(f"{p}: the gzip stream inflates to more than the limit of 1.0 MiB (1048576 bytes)")
    assert "MAX_UNCOMPRESSED_BYTES" in msg and "\n" not in msg
    # the same file under a limit it fits reads (the limit is the only reason; its 10 s repeat themselves)
    rec = read_recording(str(p), max_uncompressed_bytes=4 * LIMIT, check_time=False, warn=False)
    assert len(rec.streams["acc"]) == 1000 and "repeated" in rec.repairs[-1]
    assert MAX_UNCOMPRESSED_BYTES == 2 * 1024 ** 3


def test_gzip_bomb_takes_about_the_limits_worth_of_memory(tmp_path):
    limit = 2 * LIMIT
    p = tmp_path / "bomb.csv.gz"
    p.write_bytes(_pdr_bomb(4 * limit))  # 8 MiB of text
    tracemalloc.start()
    try:
        with pytest.raises(RecordingError, match="inflates to more than"):
            read_recording(str(p), max_uncompressed_bytes=limit)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # the rows before the limit (arrays of 40 bytes a 31-byte row) and a few chunks, not the 8 MiB of text
    assert peak < 3 * limit, f"{peak / limit:.1f} times the limit"


def _zip(path, members: dict[str, bytes]):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def _sl_members(gyro_rows: int = 200) -> dict[str, bytes]:
    t0 = 1_700_000_000_000_000_000
    rows = "".join(f"{t0 + 10_000_000 * k},{k * 0.01},0.0,0.0,9.8\n" for k in range(gyro_rows))
    gyro = "".join(f"{t0 + 10_000_000 * k},{k * 0.01},0.001,0.002,0.003\n" for k in range(gyro_rows))
    return {"TotalAcceleration.csv": ("time,seconds_elapsed,z,y,x\n" + rows).encode(),
            "Gyroscope.csv": ("time,seconds_elapsed,z,y,x\n" + gyro).encode(),
            "Metadata.csv": b"version,device name,recording time,platform,appVersion\n3,P,2023,android,1.30\n"}


def test_zip_member_declared_too_large_is_refused_before_it_is_read(tmp_path):
    members = _sl_members()
    t0 = 1_700_000_000_000_000_000
    big = "time,seconds_elapsed,z,y,x\n" + "".join(f"{t0 + 10_000_000 * k},{k * 0.01},20.0,5.0,-40.0\n"
                                                 for k in range(60_000))
    members["Magnetometer.csv"] = big.encode()  # about 3 MiB
    z = _zip(tmp_path / "export.zip", members)
    size = zipfile.ZipFile(z).getinfo("Magnetometer.csv").file_size
    with pytest.raises(RecordingError) as e:
        read_sensorlogger(str(z), max_uncompressed_bytes=LIMIT)
    assert str(e.value) == (f"{z}: archive member 'Magnetometer.csv' is {size / 2**20:.1f} MiB ({size} bytes) "
                            "uncompressed, over the limit of 1.0 MiB (1048576 bytes) for what is read "
                            "(core.recording.MAX_UNCOMPRESSED_BYTES): refused as a decompression bomb (a real walk "
                            "that long must be split)")
    # load_recording passes the limit on; without it the export reads
    with pytest.raises(RecordingError, match="archive member 'Magnetometer.csv' is"):
        load_recording(str(z), max_uncompressed_bytes=LIMIT)
    assert len(load_recording(str(z)).streams["mag"]) == 60_000


def _lie_about_size(path, member: str, declared: int) -> None:
    """Rewrite a zip's local and central headers of ``member`` to declare ``declared`` bytes uncompressed."""
    data = bytearray(path.read_bytes())
    name = member.encode()
    for sig, off in ((b"PK\x01\x02", 24), (b"PK\x03\x04", 22)):  # central directory, local header
        i = data.find(sig)
        while i >= 0:
            name_at = i + (46 if sig == b"PK\x01\x02" else 30)
            if data[name_at:name_at + len(name)] == name:
                data[i + off:i + off + 4] = struct.pack("<I", declared)
            i = data.find(sig, i + 4)
    path.write_bytes(bytes(data))


def test_a_zip_header_that_lies_about_the_size_cannot_inflate_past_the_limit(tmp_path):
    members = _sl_members()
    members["Gyroscope.csv"] += _bomb_rows(16 * LIMIT, "{t},0.0,0.001,0.002,0.003\n")  # 16 MiB inflated
    z = tmp_path / "liar.zip"
    _zip(z, members)
    _lie_about_size(z, "Gyroscope.csv", 4096)  # "4 KiB"
    tracemalloc.start()
    try:
        with pytest.raises(RecordingError) as e:
            read_sensorlogger(str(z), max_uncompressed_bytes=LIMIT)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert str(e.value).startswith(f"{z}/Gyroscope.csv: cannot read: Bad CRC-32") and "\n" not in str(e.value)
    assert peak < 4 * LIMIT


def test_gzip_member_of_an_export_and_a_gzip_logfile_are_limited_too(tmp_path):
    members = _sl_members()
    inner = gzip.compress(members.pop("Gyroscope.csv") + _bomb_rows(8 * LIMIT, "{t},0.0,0.001,0.002,0.003\n"), 9)
    members["Gyroscope.csv.gz"] = inner
    z = _zip(tmp_path / "gz_member.zip", members)
    with pytest.raises(RecordingError, match=rf"^{z}/Gyroscope.csv.gz: the gzip stream inflates to more than the "
                                             r"limit of 1.0 MiB"):
        read_sensorlogger(str(z), max_uncompressed_bytes=LIMIT)
    log = tmp_path / "log.txt.gz"
    log.write_bytes(gzip.compress(b"% GetSensorData\n" + _bomb_rows(4 * LIMIT, "ACCE;{t};1.0;0.1;0.2;9.8;3\n"), 9))
    with pytest.raises(RecordingError, match=rf"^{log}: the gzip stream inflates to more than the limit"):
        read_getsensordata(str(log), max_uncompressed_bytes=LIMIT)
    head = b'"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"\n'
    phy = _zip(tmp_path / "phy.zip", {"Raw Data.csv": head + _bomb_rows(2 * LIMIT, "{t},1,2,9\n")})
    with pytest.raises(RecordingError, match=rf"^{phy}: archive member 'Raw Data.csv' is .* over the limit"):
        read_phyphox(str(phy), max_uncompressed_bytes=LIMIT)


def test_a_line_longer_than_any_recording_line_is_refused_without_holding_it(tmp_path, monkeypatch):
    monkeypatch.setattr(core.recording, "MAX_LINE_BYTES", 4096)
    p = tmp_path / "walk.csv"
    p.write_bytes(b"# pdr-recording 1\n# {\"streams\": {\"acc\": {\"columns\": [\"x\", \"y\", \"z\"]}}}\n"
                  + b"acc,1000," + b"7" * (1 << 20))
    with pytest.raises(RecordingError, match=r"walk.csv:3: a line longer than 4.0 KiB: not a line of a recording"):
        read_recording(str(p))


def test_side_files_are_read_whole_only_when_small(tmp_path):
    members = _sl_members()
    members["Metadata.csv"] += b"x" * (2 << 20)
    with pytest.raises(RecordingError, match=r"Metadata.csv: over 1.0 MiB of text: not the small metadata file"):
        read_sensorlogger(str(_zip(tmp_path / "meta.zip", members)))


def test_archive_damage_is_a_recording_error_not_a_traceback(tmp_path):
    members = _sl_members()
    z = _zip(tmp_path / "export.zip", members)
    data = bytearray(z.read_bytes())
    i = data.find(b"PK\x03\x04", data.find(b"Gyroscope.csv") - 40)
    assert i >= 0
    for k in range(i + 60, i + 120):  # inside the deflate data of Gyroscope.csv
        data[k] ^= 0x5A
    z.write_bytes(bytes(data))
    with pytest.raises(RecordingError) as e:
        read_sensorlogger(str(z))
    assert str(e.value).startswith(f"{z}/Gyroscope.csv: cannot read: ") and "\n" not in str(e.value)
