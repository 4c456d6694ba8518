"""Stance detectors: batch = streaming, window in seconds (same result at 100-400 Hz), axes found, bad numbers."""

import math

import numpy as np
import pytest

from core.foot.navigator import FootNavigator, FootSettings
from core.foot.stance import DETECTORS, StanceDetector, StanceSettings, infer_foot_axes
from desktop.foot_simulator import footprints, simulate_foot

THRESHOLDS = {"shoe": 1e5, "song": 300.0, "amv": 0.1, "are": 0.1}


def _walk(rate_hz=200.0, seed=0):
    return simulate_foot(footprints([(8.4, 0.0), (4.2, math.pi / 2)]), rate_hz=rate_hz, acc_noise_m_s2=0.05,
                         gyro_noise_rad_s=0.01, seed=seed)


def _f1(pred, ref):
    tp = np.sum(pred & ref)
    return 2 * tp / (np.sum(pred) + np.sum(ref))


@pytest.mark.parametrize("detector", DETECTORS)
def test_streaming_equals_batch(detector):
    w = _walk()
    acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values
    st = StanceSettings(detector=detector, threshold=THRESHOLDS[detector], acc_axes=(1, 2), gyro_axes=(1, 0))
    det = StanceDetector(st)
    batch = det.detect(w.t_ns, acc, gyr)
    stream = det.stream()
    out = []
    for t, a, g in zip(w.t_ns.tolist(), acc.tolist(), gyr.tolist()):
        out += stream.update(t, a, g)
    out += stream.flush()
    assert [o[0] for o in out] == w.t_ns.tolist()
    assert np.array_equal(np.array([o[1] for o in out]), batch.stance)
    assert np.allclose(np.array([o[2] for o in out]), batch.statistic, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("detector", DETECTORS)
def test_window_in_seconds_works_at_100_to_400_hz(detector):
    """The same settings find the true stance at every rate (F1 >= 0.85 against the simulator's truth)."""
    st = StanceSettings(detector=detector, threshold=THRESHOLDS[detector])
    for rate in (100.0, 200.0, 400.0):
        w = _walk(rate)
        acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values
        if detector == "song":
            ax = infer_foot_axes(acc, gyr)
            st = StanceSettings(detector="song", threshold=THRESHOLDS["song"], acc_axes=ax["acc_axes"],
                                gyro_axes=ax["gyro_axes"])
        res = StanceDetector(st).detect(w.t_ns, acc, gyr)
        assert _f1(res.stance, w.stance) >= 0.85, (detector, rate, _f1(res.stance, w.stance))


def test_infer_foot_axes_on_the_simulator():
    w = _walk()
    ax = infer_foot_axes(w.recording.streams["acc"].values, w.recording.streams["gyro"].values)
    assert ax["vertical"] == 2 and ax["lateral"] == 0 and ax["forward"] == 1


def test_unknown_detector_is_refused():
    with pytest.raises(ValueError, match="unknown stance detector"):
        StanceSettings(detector="magic")


def test_nan_sample_is_never_stance_and_navigator_survives():
    w = _walk()
    rec = w.recording
    acc = rec.streams["acc"].values
    acc[500] = np.nan
    det = StanceDetector(StanceSettings(threshold=1e5))
    res = det.detect(w.t_ns, acc, rec.streams["gyro"].values)
    assert not res.stance[500]
    out = FootNavigator(FootSettings(stance=StanceSettings(threshold=1e5))).run(rec)
    assert out.counters["skipped_nonfinite"] == 1
    ok = np.isfinite(out.position_n[:, 0])
    assert ok.sum() > 0.9 * len(ok)
    assert np.all(np.isfinite(out.position_n[ok]))


def test_navigator_streaming_equals_batch():
    w = _walk()
    fs = FootSettings(stance=StanceSettings(threshold=1e5, window_s=0.05))
    batch = FootNavigator(fs).run(w.recording)
    nav = FootNavigator(fs)
    for name, t, v in w.recording.events(["gyro", "acc", "mag"]):
        nav.update(name, t, v)
    stream = nav.finish()
    assert np.array_equal(stream.t_ns, batch.t_ns)
    ok = np.isfinite(batch.position_n[:, 0])
    assert np.array_equal(ok, np.isfinite(stream.position_n[:, 0]))
    assert np.allclose(stream.position_n[ok], batch.position_n[ok], atol=1e-9)
    assert len(stream.strides) == len(batch.strides)


def test_streaming_equals_batch_with_separate_gyro_clock_and_delay():
    """Android-like: gyroscope events at their own times (offset 2 ms), paired by interpolation with a delay."""
    from core.recording import Recording, make_stream

    w = _walk()
    rec = w.recording
    g = rec.streams["gyro"]
    rec2 = Recording({"acc": rec.streams["acc"], "gyro": make_stream("gyro", g.t_ns + 2_000_000, g.values)})
    fs = FootSettings(stance=StanceSettings(threshold=1e5), gyro_delay_s=0.003)
    batch = FootNavigator(fs).run(rec2)
    nav = FootNavigator(fs)
    for name, t, v in rec2.events():
        nav.update(name, t, v)
    stream = nav.finish()
    ok = np.isfinite(batch.position_n[:, 0])
    assert np.array_equal(stream.t_ns, batch.t_ns)
    assert np.allclose(stream.position_n[ok], batch.position_n[ok], atol=1e-9)
