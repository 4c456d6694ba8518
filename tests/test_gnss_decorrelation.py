"""Issue #26: a phone's fix error is correlated in time; the fixes' decorrelation (``GpsFusion(gps_error_correlation_s)``,
:class:`core.gnss.base.FixDecorrelation`) keeps the filter's sigma honest where white fixes collapse it (each
consistency test failed before the change: the setting did not exist)."""

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


def test_the_fusion_reports_its_decorrelation_and_a_standing_walker_keeps_an_honest_sigma():
    """GpsFusion end to end (IPIN T01r04's standstill, tuning: the receiver held one position 5.3 m off for 30 s and
    the white filter's sigma fell to 0.5 m): 40 identical fixes 5 m off while the walker stands; white, the
    position sigma ends below 1 m, 5 m from the truth; decorrelated (45 s), the sigma covers the error."""
    from core.geodesy import enu_to_geodetic
    from core.gnss.fusion import GpsFusion
    from core.recording import make_stream
    from types import SimpleNamespace
    from core.pdr.pipeline import Step

    steps = [Step(index=k, t_ns=int((k + 1) * STEP_S * 1e9), length_m=STEP_M, heading_rad=0.0,
                  east_m=(k + 1) * STEP_M, north_m=0.0, features=SimpleNamespace(duration_s=STEP_S),
                  mag_trusted=True) for k in range(20)]
    stop = 20 * STEP_M
    t_end = 20 * STEP_S
    steps.append(Step(index=20, t_ns=int((t_end + 60.0) * 1e9), length_m=0.0, heading_rad=0.0, east_m=stop,
                      north_m=0.0, features=SimpleNamespace(duration_s=STEP_S), mag_trusted=True))
    t = t_end + 1.0 + np.arange(40)
    lat, lon = enu_to_geodetic(np.full(40, stop - 4.0), np.full(40, 3.0), (52.0, 5.0))
    fixes = make_stream("gps", (t * 1e9).astype(np.int64),
                        np.column_stack([lat, lon, np.zeros(40), np.full(40, 4.0), np.zeros(40), np.full(40, np.nan)]))
    out = {}
    for tau in (0.0, 45.0):
        f = GpsFusion(start=(52.0, 5.0, 0.5), judge=None, untrained_heading_sd_rad=math.radians(10.0),
                      gps_error_correlation_s=tau)
        fr = f.run(steps, fixes, 0)
        last = fr.steps[-1]
        err = math.hypot(last.east_m - stop, last.north_m)
        out[tau] = (err, sigma_max_m(last.cov_en_m2), fr.counters["fix_decorrelation"])
    (e0, s0, c0), (e1, s1, c1) = out[0.0], out[45.0]
    assert c0["fixes_used"] == c1["fixes_used"] == 40 and c0["noise_scale_max"] == 1.0
    assert c1["noise_scale_max"] > 30.0
    assert s0 < 1.0 and e0 > 3.0 * s0  # white: overconfident
    assert e1 < 2.5 * s1  # decorrelated: the sigma covers the error (2-D, 95 %: 2.45 sigma)
    with pytest.raises(ValueError):
        GpsFusion(gps_error_correlation_s=-5.0)
