"""Issue #26: a phone's fix error is correlated in time.  The reported covariance (``PdrEkf(reported_fix_bias_share)``,
on by default) and the fixes' decorrelation (``GpsFusion(gps_error_correlation_s)``, off,
:class:`core.gnss.base.FixDecorrelation`) keep the sigma honest where white fixes collapse it (each consistency test
failed before the change: the white filter's own P was what the fused track reported)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.gnss.base import FixDecorrelation
from core.gnss.ekf import PdrEkf, sigma_max_m

STEP_M = 0.7
STEP_S = 0.6
FIX_EVERY = 2  # a fix every second step: 1.2 s apart


def test_the_noise_scale_is_the_gauss_markov_mean_s_and_forgets_after_a_gap():
    tau, dt = 45.0, 1.0
    d = FixDecorrelation(tau)
    assert d.noise_scale(0) == 1.0  # the first fix counts whole
    for k in range(1000):
        d.used(int(k * dt * 1e9))
    rho = math.exp(-dt / tau)
    # fixes dt apart: each is worth (1 - rho) / (1 + rho) of an independent one
    assert d.noise_scale(int(1000 * dt * 1e9)) == pytest.approx((1.0 + rho) / (1.0 - rho), rel=1e-9)
    # after ten correlation times without a fix, a fix is nearly independent of the last ones again
    assert d.noise_scale(int((1000 + 10 * tau) * 1e9)) < 1.01
    assert d.summary()["fixes_used"] == 1000 and d.summary()["noise_scale_max"] == pytest.approx(
        (1.0 + rho) / (1.0 - rho), rel=1e-6)
    white = FixDecorrelation(0.0)
    white.used(0)
    assert white.noise_scale(1) == 1.0
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            FixDecorrelation(bad)


def _gm_errors(rng, n, sigma, tau, dt):
    """``n`` fix errors (n, 2) of a first-order Gauss-Markov process with per-axis SD ``sigma``, ``dt`` apart."""
    a = math.exp(-dt / tau)
    g = rng.normal(0.0, sigma, 2)
    out = np.empty((n, 2))
    for k in range(n):
        out[k] = g
        g = a * g + rng.normal(0.0, math.sqrt(1.0 - a * a) * sigma, 2)
    return out


def _run(seed: int, tau_model: float, n_steps: int = 240, sigma: float = 5.0, tau_true: float = 45.0):
    """A straight walk East, a fix every 1.2 s off by a Gauss-Markov error (per-axis ``sigma``, ``tau_true``), the
    filter's fix variance scaled by a :class:`FixDecorrelation` of ``tau_model`` (0: white).  Returns the NEES of
    the position at every 20th fix after the first 20 (the error against the covariance, 2 dof)."""
    rng = np.random.default_rng(seed)
    dt = FIX_EVERY * STEP_S
    errs = _gm_errors(rng, n_steps // FIX_EVERY + 1, sigma, tau_true, dt)
    ekf = PdrEkf()
    start = rng.normal(0.0, 10.0, 2)
    ekf.initialize(*start, 10.0, STEP_M, 0.0, heading_sd_rad=math.radians(2.0), bias_sd_rad=1e-4, scale_sd=1e-4)
    dec = FixDecorrelation(tau_model)
    truth = np.zeros(2)
    nees = []
    for k in range(n_steps):
        ekf.set_consider_sd(1e-4, 1e-4)
        ekf.step(STEP_M, rng.normal(0.0, math.radians(4.0)))
        truth += (STEP_M, 0.0)
        if k % FIX_EVERY:
            continue
        j = k // FIX_EVERY
        t_ns = int(j * dt * 1e9)
        z = truth + errs[j]
        r = ekf.update_position(z[0], z[1], sigma, gate=False, noise_scale=dec.noise_scale(t_ns))
        assert r.accepted
        dec.used(t_ns)
        if j >= 20 and j % 20 == 0:
            d = ekf.x[:2] - truth
            nees.append(float(d @ np.linalg.solve(ekf.P[:2, :2], d)))
    assert np.all(np.isfinite(ekf.x)) and np.all(np.linalg.eigvalsh(ekf.P) > -1e-9)
    return nees


def test_white_fixes_with_a_correlated_error_are_overconfident_and_the_decorrelated_ones_consistent():
    """Fixes off by a Gauss-Markov error (5 m per axis, 45 s: what the IPIN tuning fixes show) on a walk the steps
    know well: the filter that takes them as white averages 100 of them into a sigma of ~0.6 m while they are off
    together by metres (NEES ~ 30 for a chi-square of 2 dof); scaled by the fixes they share their error with, the
    filter's NEES is in a chi-square band (12 walks x 5 epochs, correlated within a walk: a wide band)."""
    white, decor = [], []
    for seed in range(12):
        white += _run(seed, 0.0)
        decor += _run(seed, 45.0)
    assert np.mean(white) > 10.0  # far too large (the behaviour before)
    assert 0.8 < np.mean(decor) < 3.6
    assert np.mean(np.array(decor) > 5.991) < 0.2  # chi-square 95 % point, 2 dof


def test_the_gate_and_the_nis_see_one_fix_s_spread_not_the_inflated_one():
    """The decorrelation weakens a fix's pull, not the gate: a fix 60 m off is refused whatever the scale, and the
    NIS of an accepted fix is the same with and without it (what the judge's NIS window compares)."""
    ekf = PdrEkf()
    ekf.initialize(0.0, 0.0, 2.0, STEP_M, 0.0)
    far = ekf.update_position(60.0, 0.0, 3.0, noise_scale=90.0)
    assert not far.accepted and np.all(ekf.x[:2] == 0.0)
    a, b = PdrEkf(), PdrEkf()
    for f in (a, b):
        f.initialize(0.0, 0.0, 2.0, STEP_M, 0.0)
    ra, rb = a.update_position(3.0, 1.0, 3.0), b.update_position(3.0, 1.0, 3.0, noise_scale=90.0)
    assert ra.accepted and rb.accepted and ra.nis == pytest.approx(rb.nis)
    assert 0.0 < rb.correction_m < 0.1 * ra.correction_m  # 90 fixes' worth of correlated error: a small pull
    for bad in (math.nan, math.inf, 0.5):
        r = b.update_position(3.0, 1.0, 3.0, noise_scale=bad)
        assert not r.accepted and np.all(np.isfinite(b.x))


def _standing_walk():
    """20 steps East, then the walker stands 60 s while the receiver gives 40 identical fixes 5 m off (IPIN T01r04's
    standstill, tuning: one position 5.3 m off for 30 s, where the white filter's sigma fell to 0.5 m)."""
    from types import SimpleNamespace

    from core.geodesy import enu_to_geodetic
    from core.pdr.pipeline import Step
    from core.recording import make_stream

    steps = [Step(index=k, t_ns=int((k + 1) * STEP_S * 1e9), length_m=STEP_M, heading_rad=0.0,
                  east_m=(k + 1) * STEP_M, north_m=0.0, features=SimpleNamespace(duration_s=STEP_S),
                  mag_trusted=True) for k in range(20)]
    stop, t_end = 20 * STEP_M, 20 * STEP_S
    steps.append(Step(index=20, t_ns=int((t_end + 60.0) * 1e9), length_m=0.0, heading_rad=0.0, east_m=stop,
                      north_m=0.0, features=SimpleNamespace(duration_s=STEP_S), mag_trusted=True))
    t = t_end + 1.0 + np.arange(40)
    lat, lon = enu_to_geodetic(np.full(40, stop - 4.0), np.full(40, 3.0), (52.0, 5.0))
    fixes = make_stream("gps", (t * 1e9).astype(np.int64),
                        np.column_stack([lat, lon, np.zeros(40), np.full(40, 4.0), np.zeros(40), np.full(40, np.nan)]))
    return steps, fixes, stop


@pytest.mark.parametrize("how", ["white", "reported", "decorrelated"])
def test_a_standing_walker_under_a_steady_fix_error_gets_an_honest_sigma(how):
    """GpsFusion end to end: white (the behaviour before: ``reported_fix_bias_share=0``), the position sigma ends
    below 1 m, 4-5 m from the truth; with the reported covariance (the default) the track is the same and its sigma
    covers the error; decorrelated (45 s) the fixes pull less and the sigma covers the error too."""
    from core.gnss.fusion import GpsFusion

    steps, fixes, stop = _standing_walk()
    kw = dict(start=(52.0, 5.0, 0.5), judge=None, untrained_heading_sd_rad=math.radians(10.0))
    white = GpsFusion(ekf=PdrEkf(reported_fix_bias_share=0.0), **kw).run(steps, fixes, 0)
    fr = {"white": white, "reported": GpsFusion(**kw).run(steps, fixes, 0),
          "decorrelated": GpsFusion(gps_error_correlation_s=45.0, **kw).run(steps, fixes, 0)}[how]
    last = fr.steps[-1]
    err, sigma = math.hypot(last.east_m - stop, last.north_m), sigma_max_m(last.cov_en_m2)
    dec = fr.counters["fix_decorrelation"]
    assert dec["fixes_used"] == 40
    if how == "white":
        assert sigma < 1.0 and err > 3.0 * sigma  # overconfident
    else:
        assert err < 2.5 * sigma  # covered (2-D, 95 %: 2.45 sigma)
    if how == "reported":  # a report, not a filter change: the same track
        assert [(s.east_m, s.north_m) for s in fr.steps] == [(s.east_m, s.north_m) for s in white.steps]
    assert (dec["noise_scale_max"] > 30.0) == (how == "decorrelated")
    with pytest.raises(ValueError):
        GpsFusion(gps_error_correlation_s=-5.0)


def test_the_reported_covariance_is_consistent_under_a_correlated_fix_error_and_leaves_the_track_alone():
    """The white filter's own P against fixes off by a Gauss-Markov error (5 m, 45 s) is far too small (NEES ~ 60);
    the reported covariance (the same gain, the fixes' error modelled as 95 % Gauss-Markov: the error covariance of
    that filter's estimate) is in a chi-square band, and the estimate is the white filter's to the bit."""
    own, rep = [], []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        dt = FIX_EVERY * STEP_S
        errs = _gm_errors(rng, 121, 5.0, 45.0, dt)
        a, b = PdrEkf(reported_fix_bias_share=0.0), PdrEkf(reported_fix_bias_share=0.95)
        start = rng.normal(0.0, 10.0, 2)
        for f in (a, b):
            f.initialize(*start, 10.0, STEP_M, 0.0, heading_sd_rad=math.radians(2.0), bias_sd_rad=1e-4,
                         scale_sd=1e-4)
        truth = np.zeros(2)
        for k in range(240):
            h = rng.normal(0.0, math.radians(4.0))
            truth += (STEP_M, 0.0)
            for f in (a, b):
                f.set_consider_sd(1e-4, 1e-4)
                f.step(STEP_M, h)
            if k % FIX_EVERY:
                continue
            j = k // FIX_EVERY
            z = truth + errs[j]
            for f in (a, b):
                f.propagate_fix_bias(dt if j else math.inf, 5.0)
                assert f.update_position(z[0], z[1], 5.0, gate=False).accepted
            if j >= 20 and j % 20 == 0:
                d = a.x[:2] - truth
                own.append(float(d @ np.linalg.solve(a.P[:2, :2], d)))
                rep.append(float(d @ np.linalg.solve(b.reported_cov[:2, :2], d)))
                assert np.array_equal(a.x, b.x) and np.array_equal(a.P, b.P)
        assert np.all(np.linalg.eigvalsh(b.C) > -1e-9)
    assert np.mean(own) > 10.0  # the white filter's own sigma: far too small (the behaviour before)
    assert 0.8 < np.mean(rep) < 3.6
    assert np.mean(np.array(rep) > 5.991) < 0.15


@pytest.mark.parametrize("psi", [-2.5, 0.0, 1.2])
def test_the_fix_measurement_jacobian_matches_finite_differences(psi):
    from tests._gnss_helpers import num_jac

    x = np.array([3.0, -4.0, 0.72, psi, 0.01, 0.02, 1.5, -2.0])
    for frac in (0.0, 0.4, 1.0):
        np.testing.assert_allclose(PdrEkf.fix_measurement_jacobian(x, frac),
                                   num_jac(lambda v, f=frac: PdrEkf.fix_measurement(v, f), x), atol=1e-7)


def test_the_reported_covariance_follows_every_change_of_the_filter_s_and_stays_finite():
    """Anchor, relock widening, reset, consider SDs, a non-finite fix: ``C`` moves with ``P`` (its position block
    never below the filter's own after a fix update, PSD, finite)."""
    f = PdrEkf()
    f.initialize(0.0, 0.0, 1.0, STEP_M, 0.0)
    f.place_on_fix(3.0)
    assert f.C[0, 6] == pytest.approx(-0.95 * 9.0) and f.P[0, 6] == 0.0
    for k in range(10):
        f.set_consider_sd(math.radians(5.0), 0.02)
        f.step(STEP_M, 0.0)
        f.propagate_fix_bias(1.2, 3.0)
        f.update_position(STEP_M * (k + 1) + 1.0, 2.0, 3.0)
    assert f.C[0, 0] > f.P[0, 0] and f.C[1, 1] > f.P[1, 1]
    f.widen_position((3.0, -4.0))
    before = f.C.copy()
    assert not f.update_position(math.nan, 0.0, 3.0).accepted and np.array_equal(f.C, before)
    f.propagate_fix_bias(math.nan, 3.0)
    assert np.array_equal(f.C, before)
    f.reset_position(5.0, 5.0, 2.0)
    assert f.C[0, 0] == f.P[0, 0] == 4.0
    assert np.all(np.isfinite(f.C)) and np.all(np.linalg.eigvalsh(f.C) > -1e-9)
    with pytest.raises(ValueError):
        PdrEkf(reported_fix_bias_share=1.0)


# -- dead reckoning's own sigma (issue #26, 2026-12-07: built, off by default) --------------------------------------

def test_matching_widening_brings_one_fix_s_nis_to_its_target():
    from core.gnss.ekf import matching_widening

    rng = np.random.default_rng(7)
    for _ in range(50):
        a = rng.normal(size=(2, 2))
        S = a @ a.T + 0.1 * np.eye(2)
        d = rng.normal(0.0, 10.0, 2)
        nis = float(d @ np.linalg.solve(S, d))
        target = float(rng.uniform(0.5, 6.0))
        o = matching_widening(d, nis, target)
        after = float(d @ np.linalg.solve(S + np.outer(o, o), d))
        assert after == pytest.approx(min(nis, target), rel=1e-9)
    assert not np.any(matching_widening(np.array([3.0, 4.0]), math.nan, 1.0))


def test_a_turn_widens_the_heading_bias_by_the_bias_turn_gain():
    widened = {}
    for gain in (0.0, 0.3):
        ekf = PdrEkf(bias_turn_gain=gain, reported_fix_bias_share=0.0)
        ekf.initialize(0.0, 0.0, 1.0, STEP_M, 0.0)
        ekf.step(STEP_M, 0.0)
        before = ekf.P[4, 4]
        ekf.step(STEP_M, math.pi / 2)  # a 90-degree turn
        widened[gain] = ekf.P[4, 4] - before
    # the step's own update leaves the consider state's variance alone (its gain row is zero)
    assert widened[0.0] == pytest.approx(ekf.bias_walk_rad ** 2, rel=1e-9)
    assert widened[0.3] - widened[0.0] == pytest.approx((0.3 * math.pi / 2) ** 2, rel=1e-9)
    with pytest.raises(ValueError):
        PdrEkf(bias_turn_gain=-1.0)


@pytest.mark.parametrize("scale", [1.0, 90.0])
def test_covariance_matching_lets_a_decorrelated_fix_pull_a_wrong_dead_reckoning(scale):
    """Dead reckoning 15 m off with a 2-m sigma, a 3-m fix at the truth: one fix's spread cannot explain the
    innovation.  Decorrelated (scale 90) the filter hardly moves; with matching the position's variance becomes
    ``d^2 - R`` (one fix's NIS 1) and the fix pulls by ``(d^2 - R) / (d^2 - R + 90 R)`` of the innovation.  Without
    decorrelation (scale 1) matching changes nothing."""
    moved = {}
    for match in (0.0, 1.0):
        ekf = PdrEkf(dr_match_nis=match, gate_nis_2d=math.inf)
        ekf.initialize(0.0, 0.0, 2.0, STEP_M, 0.0)
        res = ekf.update_position(15.0, 0.0, 3.0, noise_scale=scale)
        assert res.accepted
        moved[match] = float(ekf.x[0])
    if scale == 1.0:
        assert moved[1.0] == moved[0.0]
    else:
        assert moved[0.0] < 0.1
        assert moved[1.0] == pytest.approx(15.0 * (225.0 - 9.0) / (225.0 - 9.0 + 90.0 * 9.0), rel=1e-9)
