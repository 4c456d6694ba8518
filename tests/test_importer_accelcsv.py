"""The accelerometer CSV ``Timestamp,Milliseconds,X,Y,Z`` (issue #25: counted 20-step clips of that layout).

Synthetic files only (the real clips stay outside the repository): a file written from known values reads back
to them (times from the millisecond column, m/s^2 kept, g converted), a repeated millisecond is repaired, a bad
line is skipped and counted, linear acceleration without gravity and a missing column are refused with one line
naming the file, and the other CSV formats are not taken for it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.conventions import STANDARD_GRAVITY_M_S2
from core.importers import ACCEL_CSV, PHYSICS_TOOLBOX, detect_format, load_recording, read_accelcsv
from core.recording import RecordingError
from tests._csv_helpers import write_lines


def _walk(n: int = 500, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Milliseconds since the start (about 100 Hz) and an accelerometer in m/s^2: gravity tilted 25 deg, a 2 Hz bounce."""
    rng = np.random.default_rng(seed)
    ms = 1 + np.cumsum(rng.choice([9, 10, 11], size=n)).astype(np.int64)
    t = ms / 1e3
    g = STANDARD_GRAVITY_M_S2
    acc = np.zeros((n, 3))
    acc[:, 0] = 0.3 * np.cos(2 * np.pi * 1.0 * t)
    acc[:, 1] = g * np.sin(np.radians(25)) + 0.5 * np.sin(2 * np.pi * 2.0 * t)
    acc[:, 2] = g * np.cos(np.radians(25)) + 1.5 * np.sin(2 * np.pi * 2.0 * t + 0.3)
    return ms, acc


def _write(path, ms, acc, header="Timestamp,Milliseconds,X,Y,Z", gz: bool = False):
    lines = [header] + [f"2022-05-19 23:33:{19 + m // 1000:02d},{m},{a[0]:.7f},{a[1]:.7f},{a[2]:.7f}"
                        for m, a in zip(ms, acc)]
    return write_lines(path, lines, gz)


def _read(p):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(p)


def test_round_trip_times_from_the_milliseconds_and_m_s2_kept(tmp_path):
    ms, acc = _walk()
    for gz in (False, True):
        p = _write(tmp_path / ("clip.csv.gz" if gz else "clip.csv"), ms, acc, gz=gz)
        assert detect_format(p) == ACCEL_CSV
        rec = _read(p)
        a = rec.streams["acc"]
        assert np.array_equal(a.t_ns, ms * 1_000_000)
        np.testing.assert_allclose(a.values, np.round(acc, 7), atol=1e-9)
        assert rec.metadata["source_format"] == ACCEL_CSV and rec.repairs == []


def test_values_in_g_are_converted_and_a_repeated_millisecond_is_repaired(tmp_path):
    ms, acc = _walk(300)
    ms[100] = ms[99]  # a repeat, as in one real clip
    rec = _read(_write(tmp_path / "g.csv", ms, acc / STANDARD_GRAVITY_M_S2))
    a = rec.streams["acc"]
    assert len(a) == len(ms) - 1
    np.testing.assert_allclose(np.median(np.linalg.norm(a.values, axis=1)),
                               np.median(np.linalg.norm(np.delete(acc, 100, axis=0), axis=1)), rtol=1e-6)
    assert any("in g, converted" in r for r in rec.repairs) and any("repeated" in r for r in rec.repairs)


def test_a_bad_line_is_skipped_and_counted(tmp_path):
    ms, acc = _walk(400)
    p = _write(tmp_path / "clip.csv", ms, acc)
    lines = p.read_text().split("\n")
    lines[10] = "2022-05-19 23:33:19,105,abc,4.0,9.0"
    p.write_text("\n".join(lines))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_accelcsv(str(p))
    assert len(rec.streams["acc"]) == len(ms) - 1
    assert any("1 bad line" in r or "skipped 1" in r for r in rec.repairs), rec.repairs


def test_linear_acceleration_and_a_missing_column_are_refused_with_the_file_named(tmp_path):
    ms, acc = _walk(300)
    lin = 3.0 * (acc - acc.mean(axis=0))  # gravity removed (median |a| about 3.4 m/s^2, as on a real walk)
    p = _write(tmp_path / "linear.csv", ms, lin)
    with pytest.raises(RecordingError, match="linear acceleration without gravity") as e:
        read_accelcsv(str(p))
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)
    q = tmp_path / "noz.csv"
    q.write_text("Timestamp,Milliseconds,X,Y,Z\n")
    with pytest.raises(RecordingError, match="no accelerometer lines|no sensor events"):
        read_accelcsv(str(q))


def test_other_csv_layouts_are_not_taken_for_it(tmp_path):
    p = tmp_path / "ptb.csv"
    p.write_text("time,gFx,gFy,gFz,TgF\n" + "".join(f"{i * 0.01:.3f},0.0,-1.0,0.05,1.0\n" for i in range(50)))
    assert detect_format(p) == PHYSICS_TOOLBOX
    q = tmp_path / "other.csv"
    q.write_text("Timestamp,Milliseconds,X,Y\n2022-05-19 23:33:19,1,0.1,9.8\n")
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(q)


def test_a_folder_with_one_such_csv_is_read_through_it(tmp_path):
    ms, acc = _walk(300)
    folder = tmp_path / "20steps_01"
    folder.mkdir()
    _write(folder / "Accelerometer1.csv", ms, acc)
    assert detect_format(folder) == ACCEL_CSV
    assert len(_read(folder).streams["acc"]) == len(ms)
    _write(folder / "Accelerometer2.csv", ms, acc)
    with pytest.raises(RecordingError, match="2 accelerometer CSV"):
        read_accelcsv(str(folder))
