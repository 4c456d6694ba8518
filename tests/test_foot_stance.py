"""Stance detectors: batch = streaming, window in seconds (same result at 100-400 Hz), axes found, bad numbers."""

import math

import numpy as np
import pytest

from core.foot.navigator import FootNavigator, FootSettings
from core.foot.stance import DETECTORS, StanceDetector, StanceSettings, infer_foot_axes
from desktop.foot_simulator import footprints, simulate_foot
from tests._foot_helpers import run_streaming

THRESHOLDS = {"shoe": 1e5, "song": 1.0, "amv": 0.1, "are": 0.1, "learned": math.nan}  # learned: its file's


def _walk(rate_hz=200.0, seed=0):
    return simulate_foot(footprints([(8.4, 0.0), (4.2, math.pi / 2)]), rate_hz=rate_hz, acc_noise_m_s2=0.05,
                         gyro_noise_rad_s=0.01, seed=seed)


def _f1(pred, ref):
    tp = np.sum(pred & ref)
    return 2 * tp / (np.sum(pred) + np.sum(ref))


@pytest.mark.parametrize("detector", DETECTORS)
def test_streaming_equals_batch(detector):
    w = _walk()
    # "learned" recomputes ~1.1 s of features per streamed sample: its first 5 s (several strides) suffice
    n = 1000 if detector == "learned" else len(w.t_ns)
    t_ns = w.t_ns[:n]
    acc, gyr = w.recording.streams["acc"].values[:n], w.recording.streams["gyro"].values[:n]
    st = StanceSettings(detector=detector, threshold=THRESHOLDS[detector], acc_axes=(1, 2), gyro_axes=(1, 0))
    det = StanceDetector(st)
    batch = det.detect(t_ns, acc, gyr)
    stream = det.stream()
    out = []
    for t, a, g in zip(t_ns.tolist(), acc.tolist(), gyr.tolist()):
        out += stream.update(t, a, g)
    out += stream.flush()
    assert [o[0] for o in out] == t_ns.tolist()
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
    stream = run_streaming(fs, w.recording)
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


# -- the moving minimum, the adaptive threshold, the paper's detector (issue #27) ---------------------------

from core.foot.stance import song_terms, window_min  # noqa: E402


def test_window_min_equals_brute_force():
    rng = np.random.default_rng(5)
    for n in (1, 2, 7, 64, 301):
        x = rng.normal(size=n)
        lo = rng.integers(0, n, size=n)
        hi = np.minimum(lo + 1 + rng.integers(0, n, size=n), n)
        expect = np.array([x[a:b].min() for a, b in zip(lo, hi)])
        assert np.array_equal(window_min(x, lo, hi), expect)


def _shaky_walk(seed=0):
    """A walk whose stances are not still (gyro noise 0.4 rad/s: the SHOE statistic ~1.6e5 > 1e5 in stance, as in running)."""
    return simulate_foot(footprints([(8.4, 0.0)]), rate_hz=200.0, acc_noise_m_s2=0.3, gyro_noise_rad_s=0.4,
                         seed=seed)


def test_adaptive_threshold_follows_a_raised_floor_and_leaves_a_quiet_walk_alone():
    fixed = StanceSettings(detector="shoe", threshold=1e5, adaptive_floor_factor=0.0, adaptive_ceiling_ratio=0.0)
    assert StanceSettings().floor_factor == 2.0  # the default (chosen on the PyShoe tuning split)
    adaptive = StanceSettings(detector="shoe", threshold=1e5, adaptive_floor_factor=3.0,
                              adaptive_floor_window_s=1.2, adaptive_ceiling_ratio=0.0)
    w = _shaky_walk()
    acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values
    f_fixed = _f1(StanceDetector(fixed).detect(w.t_ns, acc, gyr).stance, w.stance)
    res = StanceDetector(adaptive).detect(w.t_ns, acc, gyr)
    assert f_fixed < 0.3, f_fixed
    assert _f1(res.stance, w.stance) > 0.8, _f1(res.stance, w.stance)
    assert np.all(res.thresholds >= 1e5) and np.max(res.thresholds) > 1e5
    q = _walk()  # quiet: the floor far below 1e5 / 3, the same decisions as the fixed threshold
    acc, gyr = q.recording.streams["acc"].values, q.recording.streams["gyro"].values
    assert np.array_equal(StanceDetector(fixed).detect(q.t_ns, acc, gyr).stance,
                          StanceDetector(adaptive).detect(q.t_ns, acc, gyr).stance)


def _hard_landings(ring_rad_s, seed=3):
    """A fast walk (swing 0.35 s, pitch 1.4 rad: peak rate ~25 rad/s) whose every landing rings: a 25 Hz
    oscillation of ``ring_rad_s`` about the foot's x axis decaying over 0.08 s from the start of each stance
    (the foot stays put: the truth stance includes the ringing)."""
    from core.foot.stance import runs

    w = simulate_foot(footprints([(8.4, 0.0)]), rate_hz=200.0, acc_noise_m_s2=0.05, gyro_noise_rad_s=0.01,
                      swing_s=0.35, pitch_rad=1.4, seed=seed)
    acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values.copy()
    t = (w.t_ns - w.t_ns[0]) * 1e-9
    for a, b in runs(w.stance)[1:]:  # the first stance is the standing start: no landing
        tt = t[a:b + 1] - t[a]
        gyr[a:b + 1, 0] += ring_rad_s * np.exp(-tt / 0.08) * np.sin(2 * np.pi * 25.0 * tt)
    return w, acc, gyr


def test_stride_peak_ceiling_finds_the_ringing_stances_a_fixed_threshold_misses():
    """The default SHOE threshold also follows the swing's peak (``adaptive_ceiling_ratio``): on hard landings
    it finds the stance a fixed threshold (old 1e5, or the new 3e4 alone) loses to the ringing, without
    taking swing samples; on a gentle walk it loses nothing."""
    from core.foot.stance import ThresholdSource

    assert StanceSettings().ceiling_ratio == 0.01 and StanceSettings().threshold_value == 3e4
    assert StanceSettings(detector="are").ceiling_ratio == 0.0
    w, acc, gyr = _hard_landings(3.0)
    old = StanceDetector(threshold=1e5, adaptive_ceiling_ratio=0.0).detect(w.t_ns, acc, gyr).stance
    low = StanceDetector(adaptive_ceiling_ratio=0.0).detect(w.t_ns, acc, gyr).stance
    res = StanceDetector().detect(w.t_ns, acc, gyr)

    def recall(p):
        return np.sum(p & w.stance) / np.sum(w.stance)

    assert recall(old) < 0.87 and recall(low) < 0.84, (recall(old), recall(low))
    assert recall(res.stance) > 0.93, recall(res.stance)
    assert np.sum(res.stance & ~w.stance) <= np.sum(old & ~w.stance) + 2  # no swing taken
    assert np.mean(res.threshold_source[w.stance] == ThresholdSource.CEILING) > 0.5
    q, qa, qg = _hard_landings(0.0)  # the same walk landing softly: nothing lost against the old threshold
    assert _f1(StanceDetector().detect(q.t_ns, qa, qg).stance, q.stance) >= _f1(
        StanceDetector(threshold=1e5, adaptive_ceiling_ratio=0.0).detect(q.t_ns, qa, qg).stance, q.stance)
    with pytest.raises(ValueError, match="adaptive_ceiling_ratio"):
        StanceSettings(adaptive_ceiling_ratio=-0.1)


@pytest.mark.parametrize("causal", [False, True])
def test_adaptive_streaming_equals_batch_with_its_stated_delay(causal):
    w = _shaky_walk(1)
    acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values
    st = StanceSettings(detector="shoe", threshold=1e5, adaptive_floor_factor=3.0, adaptive_floor_window_s=1.2,
                        adaptive_floor_causal=causal)
    det = StanceDetector(st)
    assert det.delay_s == pytest.approx(0.05 if causal else 0.65)
    batch = det.detect(w.t_ns, acc, gyr)
    stream = det.stream()
    out, lag = [], []
    for t, a, g in zip(w.t_ns.tolist(), acc.tolist(), gyr.tolist()):
        d = stream.update(t, a, g)
        lag += [(t - o[0]) * 1e-9 for o in d]
        out += d
    out += stream.flush()
    assert [o[0] for o in out] == w.t_ns.tolist()
    assert np.array_equal(np.array([o[1] for o in out]), batch.stance)
    assert max(lag) <= det.delay_s + 0.006  # one sample interval at 200 Hz beyond the stated delay


def test_song_is_the_paper_detector_acceleration_in_g_trailing_window():
    """Eq. 6 as written: J <= 1 finds the stance; no term decides alone (in SI units the acceleration
    terms are g^2..g^4 times larger and would); the window is k - k0 .. k (no later sample counts)."""
    w = _walk()
    acc, gyr = w.recording.streams["acc"].values, w.recording.streams["gyro"].values
    ax = infer_foot_axes(acc, gyr)
    st = StanceSettings(detector="song", window_s=0.15, acc_axes=ax["acc_axes"], gyro_axes=ax["gyro_axes"])
    assert st.threshold_value == 1.0 and st.trailing and StanceDetector(st).delay_s == 0.0
    res = StanceDetector(st).detect(w.t_ns, acc, gyr)
    assert _f1(res.stance, w.stance) > 0.8, _f1(res.stance, w.stance)
    # in stance the rate term A_r is the largest of the five in most samples: every term takes part
    terms = song_terms(st, w.t_ns, acc, gyr)
    assert np.mean(np.argmax(terms, axis=1)[w.stance] == 4) > 0.6
    # read in SI units, P_a (g^4 times larger) decides alone and J <= 1 marks almost nothing
    si_st = StanceSettings(**{**st.__dict__, "song_acc_unit_m_s2": 1.0})
    si = song_terms(si_st, w.t_ns, acc, gyr)
    assert np.mean(np.argmax(si, axis=1)[w.stance] == 1) > 0.9
    assert np.mean(StanceDetector(si_st).detect(w.t_ns, acc, gyr).stance[w.stance]) < 0.01
    later = acc.copy()
    later[600:] += 5.0
    assert np.array_equal(StanceDetector(st).detect(w.t_ns[:600], acc[:600], gyr[:600]).statistic,
                          StanceDetector(st).detect(w.t_ns, later, gyr).statistic[:600])
