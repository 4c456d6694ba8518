"""Issue #26, indoors: fixes whose error is correlated for minutes must not pull the track, and the EKF's own
track must follow the steps when no fix is taken (each test failed before its fix)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from core.gnss.ekf import FIX_BIAS, PdrEkf, sigma_max_m

STEP_M = 0.7
STEP_S = 0.6


def _walk_with_fixes(ekf, rng, n_steps, fix_error, sigma_m, heading_noise_rad=0.0, consider_sd_rad=math.radians(1.0)):
    """A straight walk East of ``n_steps`` steps, a fix every second step, each off by ``fix_error(k)`` (2,) and
    reported with per-axis SD ``sigma_m``; returns (final position error, final position sigma, NIS list)."""
    truth = np.zeros(2)
    nis = []
    t_prev = None
    for k in range(n_steps):
        ekf.set_consider_sd(consider_sd_rad, 0.01)
        ekf.step(STEP_M, rng.normal(0.0, heading_noise_rad) if heading_noise_rad else 0.0)
        truth += (STEP_M, 0.0)
        if k % 2 == 0:
            t = k * STEP_S
            ekf.propagate_fix_bias(t - t_prev if t_prev is not None else math.inf, sigma_m)
            t_prev = t
            z = truth + fix_error(k)
            r = ekf.update_position(z[0], z[1], sigma_m, gate=False)
            nis.append(r.nis)
    return float(np.hypot(*(ekf.x[:2] - truth))), ekf.position_sigma_m(), nis


def _calibrated_ekf(**kw):
    ekf = PdrEkf(**kw)
    ekf.initialize(0.0, 0.0, 1.0, STEP_M, 0.0, heading_sd_rad=math.radians(2.0), bias_sd_rad=math.radians(2.0),
                   scale_sd=0.01)
    return ekf


@pytest.mark.parametrize("share, stays_on_pdr", [(0.0, False), (0.95, True)])
def test_a_15m_fix_bias_held_for_3_minutes_does_not_pull_a_good_dead_reckoning(share, stays_on_pdr):
    """Indoors the phone's fixes report ~10 m (per-axis SD 6.6 m) and are 15 m off in one direction for minutes
    (IPIN tuning T22r03: 21 m).  Dead reckoning itself is good here (a heading known to 1 degree, no error: its
    own error is 0, its sigma 3 m after the 210 m).  Taking each fix as white, 150 fixes collapse the covariance
    and the track ends at the fixes, 14.8 m off with a sigma of 1.2 m (the behaviour before); with the fixes'
    correlated error modelled, a 15-m bias is what the fixes' error may be, the track moves a quarter of the
    way at most (3.8 m, seed 3) and its reported sigma covers that (3.2 m)."""
    rng = np.random.default_rng(3)
    bias = np.array([15.0 / math.sqrt(2.0), -15.0 / math.sqrt(2.0)])
    ekf = _calibrated_ekf(fix_bias_share=share, fix_bias_tau_s=45.0)
    err, sigma, _ = _walk_with_fixes(ekf, rng, 300, lambda k: bias + rng.normal(0.0, 0.5, 2), 6.6)
    if stays_on_pdr:
        assert err < 0.3 * 15.0
        assert err < 2.0 * sigma  # the filter says so
    else:
        assert err > 0.9 * 15.0 and err > 5.0 * sigma  # the white filter: pulled and overconfident


def test_fixes_drawn_from_the_correlated_model_give_a_consistent_nis_and_sigma():
    """Fixes whose error is the model's own (a Gauss-Markov part of share rho, correlation time tau, plus white):
    the modelled filter's mean NIS is near 2 (2 dof) and its position error is covered by its sigma (NEES about
    2 on average over 12 walks); the white filter on the same fixes is overconfident (NEES far above 2)."""
    rho, tau, sigma, dt = 0.9, 45.0, 5.0, 2 * STEP_S
    nees = {0.0: [], rho: []}
    nis_all = []
    for seed in range(12):
        for share in (0.0, rho):
            rng = np.random.default_rng(seed)
            g = rng.normal(0.0, math.sqrt(rho) * sigma, 2)
            a = math.exp(-dt / tau)
            errs = []
            for _ in range(100):
                errs.append(g + rng.normal(0.0, math.sqrt(1.0 - rho) * sigma, 2))
                g = a * g + rng.normal(0.0, math.sqrt(1.0 - a * a) * math.sqrt(rho) * sigma, 2)
            ekf = _calibrated_ekf(fix_bias_share=share, fix_bias_tau_s=tau)
            start = rng.normal(0.0, 10.0, 2)
            ekf.initialize(*start, 10.0, STEP_M, 0.0, heading_sd_rad=math.radians(2.0), bias_sd_rad=1e-4,
                           scale_sd=1e-4)
            _, _, nis = _walk_with_fixes(ekf, rng, 200, lambda k: errs[k // 2], sigma, math.radians(4.0), 1e-4)
            truth = np.array([200 * STEP_M, 0.0])
            d = ekf.x[:2] - truth
            nees[share].append(float(d @ np.linalg.solve(ekf.P[:2, :2], d)))
            if share:
                nis_all.extend(nis[20:])
    assert 1.6 < np.mean(nis_all) < 2.4  # 960 NIS, correlated over tau: a wide band
    assert 0.8 < np.mean(nees[rho]) < 3.6  # 12 walks: the mean of 12 chi2(2) lies in this band at 99 %
    assert np.mean(nees[0.0]) > 6.0


def test_the_correlated_part_follows_the_reported_accuracy_and_the_covariance_stays_psd():
    ekf = _calibrated_ekf(fix_bias_share=0.9, fix_bias_tau_s=45.0)
    ekf.propagate_fix_bias(math.inf, 4.0)
    assert ekf.P[FIX_BIAS, FIX_BIAS].diagonal() == pytest.approx([0.9 * 16.0] * 2)
    ekf.propagate_fix_bias(1.0, 20.0)  # the receiver says its error grew: at once
    assert ekf.fix_bias_var_m2 == pytest.approx(0.9 * 400.0)
    ekf.propagate_fix_bias(45.0, 4.0)  # ... and shrank: no faster than the error decorrelates
    assert ekf.fix_bias_var_m2 == pytest.approx(0.9 * 400.0 * math.exp(-2.0))
    ekf.place_on_fix(5.0)  # the anchor: the position's error is the fix's
    assert ekf.P[0, 6] == pytest.approx(-0.9 * 25.0)
    assert np.all(np.linalg.eigvalsh(ekf.P) > -1e-9)
    assert np.all(np.isfinite(ekf.x))


def test_the_ekf_heading_follows_a_turn_while_the_heading_model_is_unknown():
    """Indoors the heading model is never trained and its offset is uncertain by 45 degrees (the consider state
    ``b``).  Before the fix the heading state took the step headings as though that uncertainty were new noise at
    every step: after a 90-degree turn it lagged the steps by 30 degrees for 20 steps (IPIN T21r02, no fix at
    all: the EKF's track 8.6 m off at the landmarks against dead reckoning's 2.1 m).  The step headings carry the
    same offset at every step, so a turn is observed exactly: the heading follows within 3 steps."""
    ekf = PdrEkf()
    ekf.initialize(0.0, 0.0, 1.0, STEP_M, 0.0)
    lag = []
    for k in range(60):
        psi = 0.0 if k < 20 else math.pi / 2
        ekf.set_consider_sd(math.radians(45.0), 0.05)
        ekf.step(STEP_M, psi)
        if k >= 23:
            lag.append(abs(ekf.x[3] - psi))
    assert math.degrees(max(lag)) < 3.0
    # and the position's uncertainty carries the unknown offset: after 60 steps of 0.7 m, a 45-degree offset
    assert sigma_max_m((ekf.P[0, 0], ekf.P[0, 1], ekf.P[1, 1])) > 0.5 * 60 * STEP_M * math.radians(45.0)


def _straight_steps(n):
    from core.pdr.pipeline import Step
    return [Step(index=k, t_ns=int((k + 1) * STEP_S * 1e9), length_m=STEP_M, heading_rad=0.0,
                 east_m=(k + 1) * STEP_M, north_m=0.0, features=SimpleNamespace(duration_s=STEP_S),
                 mag_trusted=True) for k in range(n)]


def test_dead_reckoning_sigma_before_the_heading_model_learns_is_the_steps_own_not_the_offset_prior():
    """Issue #26: before its first window the heading model's 45-degree offset prior made 42 m of straight
    dead reckoning look ~30 m uncertain (IPIN tuning: reported sigma 6.6 m for a 2.1 m median error); with the
    untrained SD (10 degrees) it is the steps' own heading error, 42 m x sin(10 deg) ~ 7 m."""
    from core.gnss.fusion import GpsFusion
    steps = _straight_steps(60)
    walked = 60 * STEP_M
    fr = GpsFusion(start=(52.0, 5.0, 0.5), untrained_heading_sd_rad=math.radians(10.0)).run(steps, None, 0)
    sigma = sigma_max_m(fr.steps[-1].cov_en_m2)
    assert 0.1 * walked < sigma < 0.25 * walked
    # the default (None) keeps the model's prior
    fr = GpsFusion(start=(52.0, 5.0, 0.5)).run(steps, None, 0)
    assert sigma_max_m(fr.steps[-1].cov_en_m2) > 0.5 * walked


def _fixes_along(n, heading_deg, course: bool, hacc_m=4.0):
    """``n`` exact fixes at 1 Hz of a walker going ``STEP_M / STEP_S`` along ``heading_deg`` (CCW from East) from the
    origin (52 N, 5 E); with ``course`` the receiver's bearing of that direction, else nan (indoors: no bearing)."""
    from core.geodesy import enu_to_geodetic
    from core.recording import make_stream
    t = np.arange(1, n + 1) * 1.0
    d = t / STEP_S * STEP_M
    a = math.radians(heading_deg)
    lat, lon = enu_to_geodetic(d * math.cos(a), d * math.sin(a), (52.0, 5.0))
    bearing = (90.0 - heading_deg) % 360.0 if course else math.nan
    v = np.column_stack([lat, lon, np.zeros(n), np.full(n, hacc_m), np.full(n, STEP_M / STEP_S), np.full(n, bearing)])
    return make_stream("gps", (t * 1e9).astype(np.int64), v)


@pytest.mark.parametrize("course", [True, False])
def test_the_honest_dead_reckoning_sd_keeps_the_course_aiding_spread(course):
    """Issue #26 (indoor target): ``untrained_heading_sd_rad`` (15 deg) gives dead reckoning's POSITION an honest
    sigma before the heading model has a sample, but before ``untrained_until_course`` it also narrowed the heading
    that the first GPS courses correct: steps 30 deg off the walked direction, six fixes with the true course, and
    the fused heading learnt 1.7 of the 30 deg (the default 26.8: the guard's ETH 3-min outage went 14.4 -> 19.0 %).
    Now the first course gets the model's prior spread back (the heading as learnt as by default) and, without a
    course (indoors: no bearing), the position's sigma stays the honest one (66 m of dead reckoning: 15.8 m against
    the prior's 19.7 m)."""
    from core.gnss.fusion import GpsFusion
    steps = _straight_steps(100)  # heading 0: 30 deg off the fixes' direction
    fixes = _fixes_along(6, 30.0, course)
    honest = dict(start=(52.0, 5.0, 0.5), judge=None, untrained_heading_sd_rad=math.radians(15.0))
    default = GpsFusion(start=(52.0, 5.0, 0.5), judge=None).run(steps, fixes, 0)
    new = GpsFusion(**honest).run(steps, fixes, 0)
    before = GpsFusion(untrained_until_course=False, **honest).run(steps, fixes, 0)
    assert all(f.accepted for f in new.fixes)
    h_default, h_new, h_before = (math.degrees(r.steps[-1].heading_rad) for r in (default, new, before))
    s_default, s_new = (sigma_max_m(r.steps[-1].cov_en_m2) for r in (default, new))
    if course:
        assert h_default > 20.0 and abs(h_new - h_default) < 1.0  # the course teaches as without the setting
        assert h_before < 5.0  # the behaviour before (the honest SD narrowed the course's gain)
        assert abs(s_new - s_default) < 0.05 * s_default
    else:
        assert s_new < 0.85 * s_default  # indoors the honest sigma holds
        assert sigma_max_m(before.steps[-1].cov_en_m2) == pytest.approx(s_new)


def _offset_stream(n_steps, north_offset_m, hacc_m=5.0):
    """Fixes at 1 Hz that move exactly as the walker of :func:`_straight_steps` does (East at ``STEP_M / STEP_S``, the
    receiver's speed and course agreeing) but ``north_offset_m`` north of it: an indoor receiver's stream, consistent
    among itself and with the steps, off by its building's bias."""
    from core.geodesy import enu_to_geodetic
    from core.recording import make_stream
    t = np.arange(1, int(n_steps * STEP_S)) * 1.0
    lat, lon = enu_to_geodetic(t / STEP_S * STEP_M, np.full(len(t), north_offset_m), (52.0, 5.0))
    v = np.column_stack([lat, lon, np.zeros(len(t)), np.full(len(t), hacc_m), np.full(len(t), STEP_M / STEP_S),
                         np.full(len(t), 90.0)])
    return make_stream("gps", (t * 1e9).astype(np.int64), v)


@pytest.mark.parametrize("mode, limit", [("never", False), ("known_start", True), ("always", True)])
def test_a_consistent_stream_25m_off_a_known_start_relocks_the_track_only_within_dead_reckonings_drift(mode, limit):
    """Issue #26 (indoors, ``relock_stream_drift_limit``): a stream 25 m north of a walker who started at a known
    point (SD 0.5 m) walks East with the steps, so the judge's translation-free tests pass it, and the gate refuses
    it (dead reckoning's honest sigma).  Without the limit the consistent-stream relock put the track on it 23 s in,
    a 25-m jump after 27 m of walking (IPIN tuning T22r03 with the pace check off: 25.6 m after 31 m, the landmark
    error 2.0 -> 16.5 m); with it the offset is more than dead reckoning can have drifted (0.15 x walked + 3 fix
    SDs = 14 m): no relock, and no step of the track jumps ("never": the rule before)."""
    from core.gnss.fusion import GpsFusion
    steps = _straight_steps(60)
    fr = GpsFusion(start=(52.0, 5.0, 0.5), untrained_heading_sd_rad=math.radians(10.0),
                   relock_stream_drift_limit=mode).run(steps, _offset_stream(60, 25.0), 0)
    north = np.array([s.north_m for s in fr.steps])
    largest_jump = float(np.max(np.abs(np.diff(north))))
    if limit:
        assert fr.counters["relocks"] == []
        assert largest_jump < 3.0 and abs(north[-1]) < 3.0  # the dead-reckoned track (north 0 m)
    else:  # the behaviour before: relocked onto the stream
        assert [r["rule"] for r in fr.counters["relocks"]] == ["consistent stream"]
        assert largest_jump > 20.0 and north[-1] > 23.0


def test_relock_stream_drift_limit_refuses_what_it_cannot_obey():
    """``relock_stream_drift_limit``: an unknown mode, and "always" without a ``relock_max_drift`` to obey (it would
    silently limit nothing), are refused; both filters take the three modes with their own drift limit."""
    from core.gnss import make_fusion

    for kind in ("chen", "kubrak"):
        with pytest.raises(ValueError, match="relock_stream_drift_limit"):
            make_fusion(kind, relock_stream_drift_limit="sometimes")
        with pytest.raises(ValueError, match="needs a relock_max_drift"):
            make_fusion(kind, relock_stream_drift_limit="always", relock_max_drift=None)
        for mode in ("never", "known_start", "always"):
            assert make_fusion(kind, relock_stream_drift_limit=mode).relock_stream_drift_limit == mode
