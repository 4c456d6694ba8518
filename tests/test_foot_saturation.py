"""Clipped gyroscope readings and their repair (core.foot.saturation, issue #27)."""

import math
from dataclasses import replace as dc_replace

import numpy as np

from core.foot.navigator import FootNavigator, FootSettings
from core.foot.saturation import GyroClipRepair, clipped_runs
from core.recording import make_stream
from desktop.foot_simulator import footprints, simulate_foot
from tests._foot_helpers import run_streaming


def _pulses(seed=0, n=4000, rate=200.0):
    """Swing-like rate pulses (raised cosines of 9-12 rad/s, 0.3 s) on three axes plus white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    w = rng.normal(0.0, 0.01, (n, 3))
    for ax, sgn, c, amp in ((1, -1, 2.0, 11.0), (1, -1, 5.1, 9.6), (0, 1, 8.0, 10.0), (2, -1, 12.0, 12.0),
                            (1, 1, 15.0, 9.2), (1, -1, 19.99, 11.0)):  # the last one cut by the end
        u = np.clip((t - c) / 0.3, -0.5, 0.5)
        w[:, ax] += sgn * amp * 0.5 * (1.0 + np.cos(2.0 * math.pi * u))
    return (t * 1e9).astype(np.int64), w


def test_repair_recovers_most_of_the_clipped_rotation():
    t, w = _pulses()
    rng_rad_s = 9.0
    clipped = np.clip(w, -rng_rad_s, rng_rad_s)
    rep = GyroClipRepair(rng_rad_s)
    fixed = rep.repair(t, clipped)
    assert rep.n_repaired == 5  # the 9.2 rad/s pulse clips too (1 % margin); the last one is cut
    dt = 1 / 200.0
    for ax, i, j in clipped_runs(clipped, rep.level):
        if j >= len(t) - 3:
            assert np.array_equal(fixed[i:j, ax], clipped[i:j, ax])  # no trailing flank: left alone
            continue
        lost = abs(np.sum(w[i - 3:j + 3, ax] - clipped[i - 3:j + 3, ax])) * dt
        left = abs(np.sum(w[i - 3:j + 3, ax] - fixed[i - 3:j + 3, ax])) * dt
        assert lost > 0.0 and left < 0.2 * lost, (ax, i, lost, left)
        assert np.all(np.abs(fixed[i:j, ax]) >= np.abs(clipped[i:j, ax]))  # never below a clipped reading
    off = np.abs(clipped) < rep.level
    assert np.array_equal(fixed[off], clipped[off])  # readings below the level are untouched


def test_streaming_equals_batch_and_no_range_passes_through():
    t, w = _pulses(seed=2)
    clipped = np.clip(w, -9.0, 9.0)
    batch = GyroClipRepair(9.0).repair(t, clipped)
    s = GyroClipRepair(9.0)
    out = []
    for k in range(len(t)):
        out += s.update(int(t[k]), tuple(clipped[k]))
    out += s.flush()
    assert [o[0] for o in out] == list(t)
    assert np.allclose(np.array([o[1] for o in out]), batch, atol=1e-12, rtol=0)
    off = GyroClipRepair(math.nan)
    assert np.array_equal(off.repair(t, clipped), clipped) and off.update(5, (1.0, 2.0, 3.0)) == [(5, (1.0, 2.0, 3.0))]


def test_a_stuck_gyroscope_is_released_as_it_comes_and_left_as_it_reads():
    """A gyroscope at full scale for 2 s (stuck, or spinning past its range) is no swing peak: the batch leaves
    it, and the stream releases it within the 0.25-s run limit instead of holding the live track (and a growing
    list) until it ends; a swing's short run before it is still repaired, the same in both."""
    t, w = _pulses(seed=3, n=1600)
    clipped = np.clip(w, -9.0, 9.0)
    clipped[600:1000, 2] = 9.0  # 2 s at 200 Hz
    batch = GyroClipRepair(9.0).repair(t, clipped)
    assert np.array_equal(batch[600:1000, 2], clipped[600:1000, 2])
    s = GyroClipRepair(9.0)
    out, most_held = [], 0
    for k in range(len(t)):
        out += s.update(int(t[k]), tuple(clipped[k]))
        most_held = max(most_held, k + 1 - len(out))
    out += s.flush()
    assert most_held <= 0.25 * 200 + 5  # the run limit plus the flank, never the stuck run's 400 readings
    assert [o[0] for o in out] == list(t)
    assert np.allclose(np.array([o[1] for o in out]), batch, atol=1e-12, rtol=0)
    assert s.n_repaired >= 1 and not np.array_equal(batch[:600], clipped[:600])  # the earlier swings repaired


def _clipped_walk(seed, fraction=0.8, legs=((5.6, 0.0), (2.8, math.pi / 2))):
    w = simulate_foot(footprints(list(legs)), rate_hz=200.0, pitch_rad=1.3, swing_s=0.4,
                      acc_noise_m_s2=0.05, gyro_noise_rad_s=0.005, seed=seed)
    g = w.recording.streams["gyro"]
    level = fraction * float(np.max(np.abs(g.values)))
    streams = dict(w.recording.streams)
    streams["gyro"] = make_stream("gyro", g.t_ns, np.clip(g.values, -level, level))
    return w, dc_replace(w.recording, streams=streams), level


def test_a_walk_whose_swings_clip_navigates_with_the_range_declared():
    """Simulated swings faster than the gyroscope's range (clipped at 80 % of the peak rate): with the range
    declared the track is close to the one from unclipped readings; without it, far worse (seeded)."""
    errs = {"clean": [], "clipped": [], "repaired": []}
    for seed in (1, 2):
        w, rec, level = _clipped_walk(seed)
        fs = FootSettings(rts_smoother=False)
        for name, r, s in (("clean", w.recording, fs), ("clipped", rec, fs),
                           ("repaired", rec, dc_replace(fs, gyro_range_rad_s=level / 0.995))):
            res = FootNavigator(s).run(r, stance=w.stance)
            ok = np.isfinite(res.position_n[:, 0])
            e = np.linalg.norm(res.position_n[ok, :2] - w.position_n[ok, :2], axis=1)
            errs[name].append(float(np.sqrt(np.mean(e ** 2))))
            if name == "repaired":
                assert res.counters["gyro_clipped_runs_repaired"] >= 5  # a run per stride
    clean, clipped, repaired = (float(np.mean(errs[k])) for k in ("clean", "clipped", "repaired"))
    assert repaired < 0.2 * clipped, errs  # 0.002 against 0.157 m, clean 0.002 m (0.017 m without the clipped-rate noise)
    assert repaired < clean + 0.3 * (clipped - clean), errs


def _horizontal_rms(res, w) -> float:
    ok = np.isfinite(res.position_n[:, 0])
    return float(np.sqrt(np.mean(np.sum((res.position_n[ok, :2] - w.position_n[ok, :2]) ** 2, axis=1))))


def test_clipped_rate_noise_puts_the_missing_rotation_at_the_clip():
    """Swings clipped at 60 % of their peak rate, where the parabola's repair misses part of the rotation: with
    the clipped steps' rate uncertain (``clipped_gyro_sd_rad_s``, the default 1 rad/s) the next stance's ZUPT and
    the smoother put the attitude error at the clip, not over the whole stride (seeded, true stance; forward
    filter 0.064 -> 0.004 m horizontal RMS, smoothed 0.094 -> 0.005 m)."""
    w, rec, level = _clipped_walk(1, fraction=0.6, legs=((4.2, 0.0), (1.4, math.pi / 2)))
    fs = FootSettings(gyro_range_rad_s=level / 0.995)
    assert fs.clipped_gyro_sd_rad_s == 1.0 and fs.rts_smoother  # the defaults
    forward = dc_replace(fs, rts_smoother=False)
    off = _horizontal_rms(FootNavigator(dc_replace(forward, clipped_gyro_sd_rad_s=0.0)).run(rec, stance=w.stance), w)
    res = FootNavigator(forward).run(rec, stance=w.stance)
    on = _horizontal_rms(res, w)
    smoothed = _horizontal_rms(FootNavigator(fs).run(rec, stance=w.stance), w)
    assert res.counters["gyro_clipped_steps"] > 0 and res.counters["gyro_clipped_runs_repaired"] >= 4
    assert on < 0.15 * off and on < 0.01 and smoothed < 0.01, (off, on, smoothed)


def test_navigator_streaming_equals_batch_with_clipping():
    w, rec, level = _clipped_walk(3)
    fs = FootSettings(rts_smoother=False, gyro_range_rad_s=level / 0.995)
    batch = FootNavigator(fs).run(rec)
    stream = run_streaming(fs, rec)
    ok = np.isfinite(batch.position_n[:, 0])
    assert batch.counters["gyro_clipped_runs_repaired"] > 0
    assert stream.counters["gyro_clipped_runs_repaired"] == batch.counters["gyro_clipped_runs_repaired"]
    assert np.allclose(stream.position_n[ok], batch.position_n[ok], atol=1e-9)


def _heading_error(res, w):
    from core import quaternion as quat

    k = np.flatnonzero(np.isfinite(res.position_n[:, 0]))[-1]
    fwd_est = quat.to_matrix(tuple(res.q_wxyz[k]))
    fwd_true = quat.to_matrix(tuple(w.q_wxyz[k]))
    a, b = np.asarray(fwd_est)[:, 1], np.asarray(fwd_true)[:, 1]
    return math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])


def test_gated_zero_rate_update_learns_the_vertical_gyro_bias():
    """A walk with a gyroscope bias (0.003 rad/s about the vertical, unobservable with ZUPT alone) and a start
    too short for the bias: the zero-rate updates of the truly still stance samples learn it, and the heading
    drifts far less (seeded)."""
    from core.foot.ins import InsSettings

    bias = (0.001, -0.0015, 0.003)
    w = simulate_foot(footprints([(7.0, 0.0), (2.8, math.pi / 2), (7.0, math.pi)]), rate_hz=200.0,
                      acc_noise_m_s2=0.05, gyro_noise_rad_s=0.005, gyro_bias_rad_s=bias, seed=5)
    plain = FootSettings(rts_smoother=False, ins=InsSettings(zero_rate_update=False), hdr_gate_rad=0.0)  # ZARU alone
    zaru = dc_replace(plain, ins=InsSettings(zero_rate_update=True, zaru_noise_rad_s=0.02, zaru_gate_rad_s=0.02))
    assert zaru.ins == InsSettings()  # the default
    nav0, nav1 = FootNavigator(plain), FootNavigator(zaru)
    r0, r1 = nav0.run(w.recording, stance=w.stance), nav1.run(w.recording, stance=w.stance)
    assert r1.counters["zero_rate_updates"] > 0.9 * np.sum(w.stance) - 400  # all but the alignment's stance
    b0, b1 = np.array(nav0.ins.bg), np.array(nav1.ins.bg)
    sd1 = np.sqrt(np.diag(nav1.ins.P)[9:12])
    assert abs(b1[2] - bias[2]) < 3 * sd1[2] and abs(b1[2] - bias[2]) < 0.0005, (b1, sd1)
    assert abs(b0[2] - bias[2]) > 0.002, b0  # ZUPT alone does not see it
    h0, h1 = abs(_heading_error(r0, w)), abs(_heading_error(r1, w))
    assert h1 < 0.3 * h0 and h0 > math.radians(1.5), (math.degrees(h0), math.degrees(h1))  # 2.2 -> 0.19 deg


def test_zero_rate_gate_refuses_a_rolling_foot():
    from core.foot.ins import ZuptEKF

    ekf = ZuptEKF(zero_rate_update=True, zaru_noise_rad_s=0.02, zaru_gate_rad_s=0.02)
    ekf.align((0.0, 0.0, 9.81), (0.0, 0.0, 0.0))
    P = ekf.P.copy()
    u = ekf.update_zero_rate((0.3, 0.0, 0.0))  # the heel-to-toe roll: not a bias measurement
    assert not u.used and ekf.bg == (0.0, 0.0, 0.0) and np.array_equal(ekf.P, P) and ekf.n_rejected == 0
    u = ekf.update_zero_rate((0.0, 0.0, 0.01))
    assert u.used and 0.0 < ekf.bg[2] < 0.01 and ekf.P[11, 11] < P[11, 11]
