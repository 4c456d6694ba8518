"""The fast desktop path equals the phone's pipeline (issue #13 item 3).

``desktop.fast.run_fast`` is a second implementation of the per-event
kernels (vectorised stages and compiled loops instead of
``Pipeline.update`` once per event), so comparing it with
``Pipeline().run`` is the real batch-against-streaming test: the two share
no per-event code.  On two real recordings (cut to their first minutes, so
that the test stays within its CI budget) and a simulated walk: the same
steps (times, count), lengths, headings and positions within 1e-9 (m, rad),
the attitude log on the grid within 1e-9, the same counters and labels.

The fast path has no carry-mode detection (issue #17's per-mode gates):
``run_fast`` refuses a pipeline that runs one (the default), and both sides
here run with ``carry=False``.

numba is not in the ``test`` extra (compiling the kernels takes longer than
this test may), so in CI the kernels run as plain Python: the same code
path as the compiled one, only slower.  The real recordings are skipped, with
the reason, where ``../shared/data`` is absent; CI has it.
"""

from __future__ import annotations

import math
import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from core.pdr.pipeline import Pipeline
from desktop.fast import run_fast
from desktop.simulator import simulate_walk

TOL = 1e-9  # m, rad, and the log's columns
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: (recording, the seconds kept, from and to): an IPIN 2023 logfile (GetSensorData: compass waving, then
#: walking from 60 s, magnetometer readings gated and relocked) and the ETH Sensor Logger walk (Android, uneven
#: rates) from before the walk, which starts 196 s in
REAL = (("ipin2023_track3/logfiles/IPIN2023_T3_TrainingTrial01_repetition01.txt.gz", 0.0, 90.0),
        ("sensorlogger_gps_walk_ethz/2023-03-17_15-50-47", 160.0, 215.0))


@cache
def _load(rel: str):
    from core.importers import load_recording

    path = DATA / rel
    if not path.exists():
        pytest.skip(f"{path} is absent (the real recordings live in ../shared/data; CI has them)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_recording(path)


def _real(rel: str, start_s: float, end_s: float):
    rec = _load(rel)
    t0 = rec.t0_ns
    return rec.slice_time(t0 + int(start_s * 1e9), t0 + int(end_s * 1e9))


def _assert_same(rec, **params):
    params = {"carry": False, **params}  # the fast path has no carry-mode stage (issue #17): it refuses one
    pipe = Pipeline(**params)
    plain = pipe.run(rec)
    fast = run_fast(rec, **params)
    a, b = plain.track, fast.track
    assert len(a) == len(b) and len(a) > 0
    assert np.array_equal(a.t_ns, b.t_ns)
    assert np.max(np.abs(a.length_m - b.length_m)) <= TOL
    assert np.max(np.abs(a.east_m - b.east_m)) <= TOL
    assert np.max(np.abs(a.north_m - b.north_m)) <= TOL
    dh = np.abs((a.heading_rad - b.heading_rad + math.pi) % (2 * math.pi) - math.pi)
    assert np.max(dh) <= TOL
    assert [s.mag_trusted for s in plain.steps] == [s.mag_trusted for s in fast.steps]
    assert [s.features.window_freq_hz for s in plain.steps] == pytest.approx(
        [s.features.window_freq_hz for s in fast.steps], abs=TOL, nan_ok=True)
    la, lb = plain.attitude, fast.attitude
    assert np.array_equal(la.t_ns, lb.t_ns)
    assert np.array_equal(la.mag_rejected, lb.mag_rejected)
    for name in ("q_wxyz", "heading_rad", "acc_sigma2", "mag_sigma2"):
        x, y = getattr(la, name), getattr(lb, name)
        assert np.array_equal(np.isnan(x), np.isnan(y)), name
        assert np.nanmax(np.abs(x - y), initial=0.0) <= TOL, name
    assert plain.labels == fast.labels
    ca, cb = plain.counters, fast.counters
    assert set(ca) == set(cb)
    for key in ("mag_used", "mag_rejected", "acc_rejected", "peaks_rejected_rotation", "peaks_rejected_bout",
                "nonfinite_skipped", "impossible_skipped", "sensor_health", "mag_all_rejected"):
        assert ca[key] == cb[key], key
    aa, ab = ca["attitude"], cb["attitude"]
    for key in ("mag_reasons", "zero_rate_updates", "heading_relocks", "numerical_rejects", "mag_calibration"):
        assert aa[key] == ab[key], key
    assert ab["gyro_bias_rad_s"] == pytest.approx(aa["gyro_bias_rad_s"], abs=TOL)
    return plain, pipe


@pytest.mark.parametrize("rel,start_s,end_s", REAL, ids=["ipin2023_trial01", "eth_walk"])
def test_fast_equals_plain_on_real_recordings(rel, start_s, end_s):
    plain, _ = _assert_same(_real(rel, start_s, end_s))
    assert len(plain.steps) >= 10


def test_fast_equals_plain_on_the_simulator():
    # a phone in the trouser pocket: upright (the smoother follows the back of the phone) and turned from the
    # walking direction, so the walking-direction stage's offset applies to most steps
    walk = simulate_walk([(0.0, 0.0), (16.0, 0.0), (16.0, 10.0), (0.0, 10.0), (0.0, 0.0)], seed=5,
                         placement="pocket")
    _, pipe = _assert_same(walk.recording)
    assert pipe.walkdir.n_steps_offset > 10


def test_fast_equals_plain_with_other_settings():
    # no magnetometer, a shorter bout and a stricter rotation gate: the other branches of the kernels
    _assert_same(_real(REAL[0][0], 55.0, 90.0), use_magnetometer=False, min_bout_steps=2, max_rotation_rms_rad_s=1.5)


def test_fast_refuses_what_it_does_not_implement():
    walk = simulate_walk([(0.0, 0.0), (5.0, 0.0)], seed=1)
    with pytest.raises(NotImplementedError):
        run_fast(walk.recording, gnss=object(), carry=False)
    with pytest.raises(NotImplementedError):
        run_fast(walk.recording)  # carry-mode detection, on by default


def test_fast_magnetometer_calibration_equals_core_reading_by_reading():
    # the compiled per-reading part with core's fit attempts between its chunks (desktop.fast.magcal) against
    # MagCalibrator.update: the same floats (bit for bit), the same fits and final status; the IPIN cut waves the
    # phone first, so the calibrator bootstraps, fits, and later attempts keep or replace the fit
    from core.pdr.magcal import MagCalibrator
    from desktop.fast.magcal import calibrate_stream

    s = _real(REAL[0][0], 0.0, 90.0).streams["mag"]
    t, v = np.asarray(s.t_ns, dtype=np.int64), np.asarray(s.values, dtype=np.float64)[:, :3]
    ref = MagCalibrator()
    rows, flags = [], []
    for ti, (x, y, z) in zip(t.tolist(), v.tolist()):
        rows.append(ref.update(ti, x, y, z))
        flags.append(ref.calibrated)
    cal = MagCalibrator()
    out, ok = calibrate_stream(cal, t, v)
    assert np.array_equal(np.array(rows).view(np.int64), out.view(np.int64))
    assert ok.tolist() == flags and any(flags)
    assert cal._fits == ref._fits and cal.status == ref.status and ref.n_fits > 5
