"""The Sensibility Testbed accelerometer CSV ``Time, x, y, z`` (issue #25: counted clips of that layout).

Synthetic files only (the real clips stay outside the repository): a file written from known values, with lines
ended by ``\\r`` as in the source, ``None`` before the first sensor event and the experimenter's notes in further
columns, reads back to them (times in seconds, m/s^2 kept); a line with only some axes, linear acceleration
without gravity and a header of another layout are refused with one line naming the file.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.conventions import STANDARD_GRAVITY_M_S2
from core.importers import ACCEL_CSV, SENSIBILITY, detect_format, load_recording, read_sensibility
from core.recording import RecordingError


def _walk(n: int = 600, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Seconds since the script started (about 100 Hz, from 5 s) and an accelerometer in m/s^2 (a 1.8 Hz gait)."""
    rng = np.random.default_rng(seed)
    t = 5.0 + np.cumsum(rng.uniform(0.008, 0.012, size=n))
    g = STANDARD_GRAVITY_M_S2
    acc = np.zeros((n, 3))
    acc[:, 0] = 0.4 * np.sin(2 * np.pi * 0.9 * t)
    acc[:, 1] = -g + 2.0 * np.sin(2 * np.pi * 1.8 * t)  # upright, top down: a trouser pocket
    acc[:, 2] = -1.0 + 0.8 * np.cos(2 * np.pi * 1.8 * t)
    return t, acc


def _write(path, t, acc, n_none: int = 3, eol: str = "\r", header: str = "Time, x, y, z,,,,"):
    notes = ["Lap1,Lap2", "20.11,04:26.9", "wait,481", "Total,", "481,"]
    t_first = t[0] if len(t) else 5.0
    lines = [header] + [f"{t_first - 0.05 * (n_none - i):.9f},None,None,None,,{notes[i] if i < len(notes) else ''}"
                        for i in range(n_none)]
    lines += [f"{ti:.9f},{a[0]:.8f},{a[1]:.8f},{a[2]:.8f},,," for ti, a in zip(t, acc)]
    path.write_bytes((eol.join(lines) + eol).encode())
    return path


def _read(p):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(p)


def test_round_trip_cr_lines_none_rows_dropped_and_counted(tmp_path):
    t, acc = _walk()
    for eol in ("\r", "\n", "\r\n"):
        p = _write(tmp_path / f"clip{len(eol)}{eol == chr(10)}.csv", t, acc, eol=eol)
        assert detect_format(p) == SENSIBILITY
        rec = _read(p)
        a = rec.streams["acc"]
        np.testing.assert_array_equal(a.t_ns, np.round(np.round(t, 9) * 1e9).astype(np.int64))
        np.testing.assert_allclose(a.values, np.round(acc, 8), atol=1e-12)
        assert rec.metadata["source_format"] == SENSIBILITY and rec.metadata["lines_without_sample"] == 3
        assert rec.repairs == []


def test_a_folder_with_one_such_csv_is_read_through_it(tmp_path):
    t, acc = _walk(300)
    folder = tmp_path / "T_2_1_15_08"
    folder.mkdir()
    _write(folder / "T_2_1_15_08_result.csv", t, acc)
    assert detect_format(folder) == SENSIBILITY
    assert len(_read(folder).streams["acc"]) == len(t)


def test_partial_axes_linear_acceleration_and_other_headers_are_refused(tmp_path):
    t, acc = _walk(300)
    p = _write(tmp_path / "partial.csv", t, acc)
    p.write_bytes(p.read_bytes().replace(f"{acc[50, 2]:.8f}".encode(), b"None", 1))
    with pytest.raises(RecordingError, match="some of x, y, z and not all") as e:
        read_sensibility(str(p))
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)
    lin = 3.0 * (acc - acc.mean(axis=0))  # gravity removed
    with pytest.raises(RecordingError, match="linear acceleration without gravity"):
        read_sensibility(str(_write(tmp_path / "linear.csv", t, lin)))
    q = _write(tmp_path / "allnone.csv", t[:0], acc[:0], n_none=5)
    with pytest.raises(RecordingError, match="no accelerometer samples"):
        read_sensibility(str(q))
    r = _write(tmp_path / "other.csv", t, acc, header="Time,X,Y,Z")  # not this layout (case matters)
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        detect_format(r)
    s = tmp_path / "accel.csv"
    s.write_text("Timestamp,Milliseconds,X,Y,Z\n2022-05-19 23:33:19,1,0.1,4.0,9.0\n")
    assert detect_format(s) == ACCEL_CSV
