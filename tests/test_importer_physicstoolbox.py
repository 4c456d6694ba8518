"""Physics Toolbox Sensor Suite's g-Force Meter CSV (issue #25: a counted-step clip of that app's export).

Synthetic files only (the real clip stays outside the repository): the
format is recognised by its header, g is converted to m/s^2, repeated
millisecond times are repaired, a bad line is skipped and counted, and
values in m/s^2 (not this app's g) or a missing column are refused with one
line naming the file.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.conventions import STANDARD_GRAVITY_M_S2
from core.importers import PHYSICS_TOOLBOX, PHYPHOX, detect_format, load_recording, read_physicstoolbox
from core.recording import RecordingError
from tests._csv_helpers import write_lines


def _walk(n: int = 600, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Times (s, ms resolution, some repeated) and a g-force in g: gravity along -y (phone top down), a 2 Hz bounce."""
    rng = np.random.default_rng(seed)
    t = np.round(np.cumsum(rng.choice([0.0, 0.004, 0.005], size=n, p=[0.2, 0.4, 0.4])) + 0.003, 3)
    gf = np.zeros((n, 3))
    gf[:, 1] = -1.0 + 0.3 * np.sin(2 * np.pi * 2.0 * t)
    gf[:, 0] = 0.1 * np.cos(2 * np.pi * 1.0 * t)
    gf[:, 2] = 0.05
    return t, gf


def _write(path, t, gf, header="time,gFx,gFy,gFz,TgF", extra: str = "", gz: bool = False):
    lines = [header] + [f"{ti:.6f},{g[0]:.4f},{g[1]:.4f},{g[2]:.4f},{np.linalg.norm(g):.3f}{extra}"
                        for ti, g in zip(t, gf)]
    return write_lines(path, lines, gz)


def test_g_force_csv_is_recognised_and_converted_to_m_s2(tmp_path):
    t, gf = _walk()
    for gz in (False, True):
        p = _write(tmp_path / ("clip.csv.gz" if gz else "clip.csv"), t, gf, gz=gz)
        assert detect_format(p) == PHYSICS_TOOLBOX
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = load_recording(p)
        acc = rec.streams["acc"]
        # repeated times are repaired: the first event of each time is kept (a stated rule of repair_recording)
        times, first = np.unique(t, return_index=True)
        assert np.array_equal(acc.t_ns, np.round(times * 1e9).astype(np.int64))
        np.testing.assert_allclose(acc.values, np.round(gf[first], 4) * STANDARD_GRAVITY_M_S2, atol=1e-9)
        assert rec.metadata["source_format"] == PHYSICS_TOOLBOX and rec.metadata["unused_columns"] == []
        assert any("repeated" in r for r in rec.repairs)


def test_multi_sensor_header_reads_the_g_force_and_lists_the_rest(tmp_path):
    t, gf = _walk(200)
    p = _write(tmp_path / "suite.csv", t, gf, header="time,gFx,gFy,gFz,TgF,wx,wy,wz", extra=",0.1,0.2,0.3")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_physicstoolbox(str(p))
    assert set(rec.streams) == {"acc"} and rec.metadata["unused_columns"] == ["wx", "wy", "wz"]


def test_a_bad_line_is_skipped_and_counted(tmp_path):
    t, gf = _walk(400)
    p = _write(tmp_path / "clip.csv", t, gf)
    lines = p.read_text().split("\n")
    lines[10] = "0.040000,abc,-1.0,0.0,1.0"
    p.write_text("\n".join(lines))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_physicstoolbox(str(p))
    assert any("1 bad line" in r or "skipped 1" in r for r in rec.repairs), rec.repairs


def test_m_s2_values_and_missing_columns_are_refused_with_the_file_named(tmp_path):
    t, gf = _walk(300)
    p = _write(tmp_path / "ms2.csv", t, gf * STANDARD_GRAVITY_M_S2)
    with pytest.raises(RecordingError, match="writes g") as e:
        read_physicstoolbox(str(p))
    assert str(e.value).startswith(str(p)) and "\n" not in str(e.value)
    q = tmp_path / "nogz.csv"
    q.write_text("time,gFx,gFy\n0.1,0.0,1.0\n")
    with pytest.raises(RecordingError, match="missing column 'gFz'"):
        read_physicstoolbox(str(q))


def test_phyphox_csv_is_not_taken_for_physics_toolbox(tmp_path):
    p = tmp_path / "Accelerometer.csv"
    p.write_text('"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"\n'
                 + "".join(f"{i * 0.01:.3f},0.1,0.2,9.8\n" for i in range(50)))
    assert detect_format(p) == PHYPHOX


def test_a_folder_with_one_g_force_csv_is_read_through_it(tmp_path):
    t, gf = _walk(300)
    folder = tmp_path / "clip"
    folder.mkdir()
    _write(folder / "walking_100.csv", t, gf)
    assert detect_format(folder) == PHYSICS_TOOLBOX
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert len(load_recording(folder).streams["acc"]) == len(np.unique(t))
    _write(folder / "second.csv", t, gf)
    with pytest.raises(RecordingError, match="2 Physics Toolbox g-Force Meter CSVs"):
        read_physicstoolbox(str(folder))
