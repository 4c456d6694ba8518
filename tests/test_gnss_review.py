"""Issue #26's review bugs in the GPS fusion, each with a test that failed before its fix."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.gnss.ekf import PdrEkf


def test_dead_reckoning_moves_one_step_length_per_step_while_the_consider_sd_follows_the_heading():
    """Bug 1: ``set_consider_sd`` on every step with a heading-dependent SD, then the step update moved the
    position sideways through the heading-bias cross terms (166-174 m over a 3-minute outage on one walk).
    During an outage each step must move the position by the fused step length (within 1 %)."""
    rng = np.random.default_rng(0)
    ekf = PdrEkf()
    ekf.initialize(0.0, 0.0, 3.0, 0.7, 0.0)
    truth = np.zeros(2)
    ratios = []
    for k in range(600):
        psi = (k // 40) * math.pi / 2 * 0.9  # a 40-step side, then a turn
        ekf.set_consider_sd(math.radians(2.0 + 4.0 * abs(math.sin(psi))), 0.02)
        before = ekf.x[:2].copy()
        ekf.step(0.7, psi + rng.normal(0.0, 0.03))
        truth += 0.7 * np.array([math.cos(psi), math.sin(psi)])
        if k < 200:  # two minutes with GPS, then the outage
            if k % 2 == 0:
                ekf.update_position(*(truth + rng.normal(0.0, 3.0, 2)), 3.0, gate=False)
        else:
            ratios.append(math.hypot(*(ekf.x[:2] - before)) / ekf.x[2])
    assert np.max(np.abs(np.array(ratios) - 1.0)) <= 0.01
    assert np.all(np.linalg.eigvalsh(ekf.P) > -1e-9)


def test_an_epoch_of_gga_rmc_gsv_gsa_gives_one_status_and_the_cn0_rule_keeps_its_fix():
    """Bug 2: GGA and RMC both closed an epoch, so a receiver sending both (most do) gave a second status
    of 0 satellites after every real one, and the C/N0 rule then rejected every live fix."""
    from core.gnss.kubrak import KubrakFusion
    from core.gnss.nmea import NmeaSatelliteStatus
    from tests.test_nmea import _cs, _epoch

    rmc = _cs("GPRMC,123519,A,4807.038,N,01131.000,E,000.5,054.7,230394,003.1,W")
    sats = [(1, 40), (3, 38), (5, 35), (7, 33), (9, 30)]
    for order in ("gga-first", "rmc-first"):
        p = NmeaSatelliteStatus()
        fusion = KubrakFusion()
        statuses = []
        for k in range(5):
            ep = _epoch(sats, [1, 3, 5, 7, 9])  # GSV, GSA, GGA
            sentences = ep + [rmc] if order == "gga-first" else [rmc] + ep
            for s in sentences:
                r = p.update(s)
                if r is not None:
                    statuses.append(r)
                    fusion.add_status(k * 1_000_000_000, r)
            assert fusion._cn0_verdict(k * 1_000_000_000) == ""  # the epoch's fix is not rejected
        assert statuses == [(5.0, 33.0)] * 5, order


def _steps(times_s, length_m=0.7, duration_s=0.5, heading_rad=0.0, freq_hz=2.0):
    """Synthetic pipeline steps at the given times, with eq.-1 regressors (MEAN 0, FREQ, STD 0)."""
    from core.pdr.pipeline import Step
    from core.pdr.stride import StepFeatures

    out = []
    for i, t in enumerate(times_s):
        t_ns = int(round(t * 1e9))
        h = heading_rad(t) if callable(heading_rad) else heading_rad
        f = StepFeatures(t_ns=t_ns, duration_s=duration_s, acc_max_m_s2=11.0, acc_min_m_s2=8.5, acc_var_m2_s4=1.0,
                         window_mean_m_s2=0.0, window_freq_hz=freq_hz, window_std_m_s2=0.0)
        out.append(Step(i, t_ns, length_m, h, 0.0, 0.0, f, True))
    return out


def test_the_first_step_after_a_pause_covers_one_step_duration_not_three():
    """Bug 3: ``t_prev = max(prev, t - 3 dur)`` made Kubrak's first epoch after any pause cover three step
    durations: 40 steps of 0.7 m with one 20-s stop gave 29.4 m against 28.0 m without."""
    from core.gnss.kubrak import KubrakFusion
    from core.pdr.velocity import VelocityModel

    times = [0.5 * k for k in range(1, 21)] + [10.0 + 20.0 + 0.5 * k for k in range(1, 21)]
    walked = {}
    for name, ts in (("walk", [0.5 * k for k in range(1, 41)]), ("pause", times)):
        f = KubrakFusion(velocity_model=VelocityModel(0.0, 0.7, 0.0))  # v = 0.7 m * 2 Hz = 1.4 m/s
        res = f.run(_steps(ts))
        walked[name] = sum(s.length_m for s in res.steps)
        track = np.array([(s.east_m, s.north_m) for s in res.steps])
        assert track[-1, 0] == pytest.approx(walked[name], rel=1e-6)
    assert walked["walk"] == pytest.approx(28.0, abs=0.01)
    assert walked["pause"] == pytest.approx(28.0, abs=0.01)


def test_stride_scale_comes_from_position_chords_not_a_doppler_speed_that_reads_low():
    """Bug 4: the stride scale was trained on the Doppler speed, which on the iOS walks reads 15-25 % low
    (the chord between the end fixes of 30 s is longer in 27 of 29 windows).  Positions right, speed 20 %
    low: the scale must come out right (within 3 %), as the chords say."""
    from core.gnss.training import OnlineTrainer

    rng = np.random.default_rng(3)
    tr = OnlineTrainer()
    dt, heading, scale = 1 / 1.8, 0.4, 1.1
    v = scale * 0.7 / dt
    k = 0
    for i in range(1, int(300 / dt)):
        t = i * dt
        tr.add_step(int(t * 1e9), int((t - dt) * 1e9), 0.7, heading)
        while k + 1 <= t:
            k += 1
            e, n = v * k * math.cos(heading), v * k * math.sin(heading)
            tr.add_fix(int(k * 1e9), e + rng.normal(0, 1.5), n + rng.normal(0, 1.5), 5.0, 0.8 * v, heading)
    assert tr.stride_scale == pytest.approx(scale, rel=0.03)
    assert tr.n_stride_samples >= 5


def test_the_coefficients_revert_keeps_the_covariance_positive_semidefinite():
    """Bug 5a: the coefficient test's revert took ``np.maximum(Pc, keep)`` element by element, which can be
    indefinite; the cover used now is PSD and at least as large as both (Loewner order)."""
    from core.gnss.ekf import covariance_cover

    Pc = np.array([[0.7, -0.1, 2.6], [-0.1, 2.8, -1.9], [2.6, -1.9, 10.9]])
    keep = np.array([[0.3, -1.2, -0.6], [-1.2, 5.9, 3.4], [-0.6, 3.4, 5.0]])
    assert np.linalg.eigvalsh(np.maximum(Pc, keep)).min() < -0.05  # what the revert did
    M = covariance_cover(Pc, keep)
    for other in (None, Pc, keep):
        ev = np.linalg.eigvalsh(M if other is None else M - other)
        assert ev.min() > -1e-9
    np.testing.assert_allclose(covariance_cover(Pc, 0.5 * Pc), Pc, atol=1e-12)  # already covering: unchanged


def test_the_coefficients_revert_in_the_filter_is_positive_semidefinite(monkeypatch):
    """Bug 5a, in the filter: the revert's covariance of the coefficients covers both and stays PSD."""
    from core.gnss.kubrak import COEF, KubrakFusion

    f = KubrakFusion()
    f.kf.initialize(0.0, 0.0, 3.0)
    keep = np.array([[0.3, -1.2, -0.6], [-1.2, 5.9, 3.4], [-0.6, 3.4, 5.0]]) * 1e-3
    Pc = np.array([[0.7, -0.1, 2.6], [-0.1, 2.8, -1.9], [2.6, -1.9, 10.9]]) * 1e-3
    st = f.kf.snapshot()
    st.P[COEF, COEF] = keep
    f.kf.restore(st)
    f._revert_coefficients(f.kf.x[COEF].copy(), Pc, True)
    assert np.linalg.eigvalsh(f.kf.P).min() > -1e-12


def test_the_reset_variant_reports_the_innovation_before_the_reset():
    """Bug 5b: Chen's ``filter="reset"`` computed its innovation after jumping to the fix: always 0."""
    from core.gnss.fusion import GpsFusion

    f = GpsFusion(filter="reset")
    f.ekf.initialize(10.0, -4.0, 2.0, 0.7, 0.0)
    res = f._update_position(0, 13.0, 0.0, 3.0, True)
    assert res.innovation == pytest.approx((3.0, 4.0))
    assert res.correction_m == pytest.approx(5.0)
    assert (f.ekf.x[0], f.ekf.x[1]) == (13.0, 0.0)


def test_fix_predictions_do_not_snap_back_to_the_last_step():
    """Bug 5d: Kubrak's prediction of a fix more than 1.5 s after the last epoch fell back to that epoch
    (Chen's after two step durations): the prediction must be continuous in the fix's time."""
    from core.gnss.ekf import PdrEkf
    from core.gnss.fusion import GpsFusion
    from core.gnss.kubrak import KubrakFusion
    from core.pdr.velocity import VelocityModel

    k = KubrakFusion(velocity_model=VelocityModel(0.0, 0.7, 0.0))
    k.run(_steps([0.5 * i for i in range(1, 11)]))
    t_last = k.kf.t_ns
    pred = [k.kf.fix_prediction(t_last + int(s * 1e9))[0][0] for s in np.arange(0.0, 4.0, 0.05)]
    assert np.max(np.abs(np.diff(pred))) < 0.1  # 1.4 m/s * 0.05 s = 0.07 m at most
    assert np.all(np.diff(pred) >= -1e-9)

    c = GpsFusion()
    c.run(_steps([0.5 * i for i in range(1, 11)]))
    pred = [PdrEkf.fix_prediction(c.ekf.x, c._fraction(c.last_step_ns + int(s * 1e9)))[0]
            for s in np.arange(0.0, 3.0, 0.05)]
    assert np.max(np.abs(np.diff(pred))) < 0.1
    assert np.all(np.diff(pred) >= -1e-9)


def test_the_gps_course_is_compared_with_the_heading_of_its_time():
    """Bug 5c: the GPS course lags our heading by about 1.5 s (the receiver's smoothing): through a turn the
    course of a fix is the heading 1.5 s earlier, and as a measurement of the last step's heading it gets
    the turn since then added."""
    from core.gnss.kubrak import KubrakFusion

    def heading(t):  # a 90-degree turn over 3 s at t = 10 s
        return float(np.clip((t - 10.0) / 3.0, 0.0, 1.0)) * math.pi / 2

    f = KubrakFusion(course_latency_s=1.5)
    for s in _steps([0.5 * i for i in range(1, 25)], heading_rad=heading):
        f.add_step(s)
    t = f.last_step_ns
    c = f.course_now(t, heading(t * 1e-9 - 1.5))
    assert c == pytest.approx(heading(t * 1e-9), abs=1e-9)
    off = KubrakFusion(course_latency_s=0.0)
    assert off.course_now(t, 0.3) == 0.3
