"""The RTS smoother of the error-state filters (core.kalman.RtsSmoother, ZuptEKF history, FootNavigator replays)."""

import math

import numpy as np

from core import kalman
from core import quaternion as quat
from core.foot.ins import InsSettings
from core.foot.navigator import FootNavigator, FootSettings
from desktop.foot_simulator import footprints, simulate_foot
from tests._foot_helpers import run_streaming


def test_rts_equals_the_batch_least_squares_solution_on_a_linear_model():
    """A linear constant-velocity model run as an error-state filter (every update injected into the
    nominal state, reset G = I): nominal + smoothed error must equal the batch (all measurements at once)
    maximum a posteriori estimate, and the smoothed covariance the inverse of the batch information."""
    rng = np.random.default_rng(7)
    n, T, q, r = 40, 0.1, 0.3, 0.2
    Phi = np.array([[1.0, T], [0.0, 1.0]])
    Q = q * q * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]])
    P0 = np.diag([1.0, 0.5])
    x0 = np.array([0.3, -0.2])
    z = rng.normal(size=n) * r + np.linspace(0, 2, n)
    H = np.array([[1.0, 0.0]])
    sm = kalman.RtsSmoother(2, att=slice(0, 0))
    sm.start()
    x, P, nominal = x0.copy(), P0.copy(), []
    for k in range(n):
        if k > 0:
            sm.predict(P, Phi, Q)
            nominal.append(x.copy())
            x, P = Phi @ x, Phi @ P @ Phi.T + Q
        if k % 3 != 1:  # some epochs without a measurement
            c = kalman.correct(P, np.array([z[k] - x[0]]), H, np.array([[r * r]]))
            x, P = x + c.dx, c.P
            sm.inject(c.dx, np.eye(2))
    nominal.append(x.copy())
    e, Ps = sm.smooth(P)
    smoothed = np.array(nominal) + e
    # batch: minimise |x_0 - x0|^2_P0 + sum |x_k+1 - Phi x_k|^2_Q + sum |z_k - x_k[0]|^2_r
    N = 2 * n
    A, b, w = [], [], []
    L0 = np.linalg.cholesky(np.linalg.inv(P0)).T
    row = np.zeros((2, N)); row[:, 0:2] = L0; A.append(row); b.append(L0 @ x0)
    LQ = np.linalg.cholesky(np.linalg.inv(Q)).T
    for k in range(n - 1):
        row = np.zeros((2, N)); row[:, 2 * k + 2:2 * k + 4] = LQ; row[:, 2 * k:2 * k + 2] = -LQ @ Phi
        A.append(row); b.append(np.zeros(2))
    for k in range(n):
        if k % 3 != 1:
            row = np.zeros((1, N)); row[0, 2 * k] = 1.0 / r; A.append(row); b.append(np.array([z[k] / r]))
    A, b = np.vstack(A), np.concatenate(b)
    info = A.T @ A
    xb = np.linalg.solve(info, A.T @ b).reshape(n, 2)
    cov = np.linalg.inv(info)
    assert np.allclose(smoothed, xb, atol=1e-9)
    for k in (0, n // 2, n - 1):
        assert np.allclose(Ps[k], cov[2 * k:2 * k + 2, 2 * k:2 * k + 2], atol=1e-9)


def _runs(seed, smoother):
    rate = 200.0
    legs = [(2.1, 0.0), (1.05, math.pi / 2), (2.1, math.pi / 2)]
    w = simulate_foot(footprints(legs), rate_hz=rate, acc_noise_m_s2=0.02 * math.sqrt(rate),
                      gyro_noise_rad_s=0.002 * math.sqrt(rate), seed=100 + seed)
    # priors that match the simulation: tilt from 2 s of still samples, the heading given exactly
    fs = FootSettings(initial_heading_rad=-math.pi / 2, rts_smoother=smoother,
                      ins=InsSettings(initial_tilt_sd_rad=0.0015, initial_heading_sd_rad=1e-4))
    nav = FootNavigator(fs)
    return w, nav, nav.run(w.recording, stance=w.stance)


def _tilt_errors(w, q_wxyz):
    dq = quat.multiply_array(w.q_wxyz, np.asarray(q_wxyz) * np.array([1.0, -1.0, -1.0, -1.0]))
    return quat.to_rotation_vector_array(dq)


def test_smoothed_walk_is_closer_to_the_truth_and_consistent():
    """Simulator, true stance, 4 seeds: the smoothed velocity, tilt and position errors (RMS over every
    sample) are smaller than the filter's; at the walk's middle sample the smoothed attitude (3 dof) and
    horizontal position (2 dof) NEES, averaged over the seeds, lie in their 95 % chi-square bands
    (chi2(12) / 4: [1.10, 5.84]; chi2(8) / 4: [0.55, 4.38])."""
    err = {k: [] for k in ("vf", "vs", "af", "as", "pf", "ps")}
    nees_att, nees_pos = [], []
    for seed in range(4):
        w, _, filt = _runs(seed, False)
        w, nav, sm = _runs(seed, True)
        ok = np.isfinite(filt.position_n[:, 0])
        for lab, r in (("f", filt), ("s", sm)):
            err["v" + lab].append(np.sum((r.velocity_n[ok] - w.velocity_n[ok]) ** 2, axis=1))
            err["a" + lab].append(np.sum(_tilt_errors(w, r.q_wxyz)[ok, :2] ** 2, axis=1))
            err["p" + lab].append(np.sum((r.position_n[ok] - w.position_n[ok]) ** 2, axis=1))
        q, v, p, Ps = nav.ins.smoothed()
        k = len(nav.out_epoch) // 2
        j = nav.out_epoch[k]
        assert np.allclose(p[j], sm.position_n[k])
        e = w.position_n[k, :2] - p[j, :2]
        nees_pos.append(float(e @ np.linalg.solve(Ps[j, 6:8, 6:8], e)))
        a = _tilt_errors(w, sm.q_wxyz)[k]
        nees_att.append(float(a @ np.linalg.solve(Ps[j, 0:3, 0:3], a)))
    rms = {k: math.sqrt(float(np.mean(np.concatenate(v)))) for k, v in err.items()}
    assert rms["vs"] < 0.8 * rms["vf"], rms
    assert rms["as"] < 0.9 * rms["af"], rms
    assert rms["ps"] < rms["pf"], rms
    assert 1.10 < np.mean(nees_att) < 5.84, nees_att
    assert 0.55 < np.mean(nees_pos) < 4.38, nees_pos


def test_smoother_streaming_equals_batch_and_keeps_the_strides():
    """A replay smoothed after streaming equals the batch one; stride positions are the smoothed samples'."""
    rate = 200.0
    w = simulate_foot(footprints([(2.1, 0.0), (1.05, math.pi / 2)]), rate_hz=rate, acc_noise_m_s2=0.2,
                      gyro_noise_rad_s=0.02, seed=3)
    fs = FootSettings(rts_smoother=True)
    batch = FootNavigator(fs).run(w.recording)
    stream = run_streaming(fs, w.recording)
    ok = np.isfinite(batch.position_n[:, 0])
    assert np.allclose(stream.position_n[ok], batch.position_n[ok], atol=1e-9)
    for s in batch.strides:
        k = int(np.searchsorted(batch.t_ns, s.t_end_ns))
        assert np.allclose(s.position_n, batch.position_n[k])
    plain = FootNavigator(FootSettings(rts_smoother=False)).run(w.recording)
    assert not np.allclose(plain.position_n[ok], batch.position_n[ok], atol=1e-4)  # the smoother did something


def test_smoother_refuses_a_recording_longer_than_its_memory_cap():
    w = simulate_foot(footprints([(2.1, 0.0)]), rate_hz=200.0, seed=1)
    res = FootNavigator(FootSettings(rts_smoother=True, rts_max_samples=500)).run(w.recording, stance=w.stance)
    plain = FootNavigator(FootSettings(rts_smoother=False)).run(w.recording, stance=w.stance)
    assert res.counters["smoother_skipped_too_long"] == 1
    ok = np.isfinite(plain.position_n[:, 0])
    assert np.array_equal(res.position_n[ok], plain.position_n[ok])


def test_smoother_stays_finite_over_gaps_and_bad_samples():
    """A 0.3 s hole in the data (longer than ``max_dt_s``: the state held, the covariance grown) and a few
    non-finite readings: the smoothed track is finite wherever the filter's is, and ends where it ends."""
    from dataclasses import replace as dc_replace

    from core.recording import make_stream

    w = simulate_foot(footprints([(2.8, 0.0)]), rate_hz=200.0, acc_noise_m_s2=0.2, gyro_noise_rad_s=0.02, seed=4)
    rec = w.recording
    acc, gyro = rec.streams["acc"], rec.streams["gyro"]
    t = acc.t_ns
    hole = (t > t[0] + int(3.3e9)) & (t < t[0] + int(3.6e9))
    keep = ~hole
    a = acc.values[keep].copy()
    a[700:703] = np.nan
    streams = dict(rec.streams)
    streams["acc"] = make_stream("acc", t[keep], a)
    streams["gyro"] = make_stream("gyro", gyro.t_ns[keep], gyro.values[keep])
    rec2 = dc_replace(rec, streams=streams)
    plain = FootNavigator(FootSettings(rts_smoother=False)).run(rec2)
    sm = FootNavigator(FootSettings(rts_smoother=True)).run(rec2)
    ok = np.all(np.isfinite(plain.position_n), axis=1)
    assert ok.sum() > 0.8 * len(ok)
    assert np.array_equal(ok, np.all(np.isfinite(sm.position_n), axis=1))
    assert np.allclose(sm.position_n[ok][-1], plain.position_n[ok][-1], atol=1e-9)
    assert np.all(np.isfinite(sm.position_sd_m[ok]))
