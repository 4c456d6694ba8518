"""Butterworth design and filters against scipy (the oracle), and the grid resampler.

scipy.signal is imported in the tests that use it (about 1 s of imports, scipy.stats with it): not at
collection, which every xdist worker does."""

import math

import numpy as np
import pytest

from core.dsp import Biquad, GridResampler, RunningMedian, butter2_group_delay_s, butter2_lowpass


@pytest.mark.parametrize("fc,fs", [(3.0, 50.0), (0.5, 50.0), (3.0, 20.0), (10.0, 400.0), (0.2, 100.0)])
def test_butterworth_coefficients_equal_scipy(fc, fs):
    from scipy import signal

    b, a = butter2_lowpass(fc, fs)
    b_ref, a_ref = signal.butter(2, fc, fs=fs)
    np.testing.assert_allclose(b, b_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(a, a_ref, rtol=1e-12, atol=1e-15)


def test_butterworth_rejects_cutoff_above_nyquist():
    with pytest.raises(ValueError, match="Nyquist"):
        butter2_lowpass(30.0, 50.0)


def test_biquad_equals_lfilter_with_steady_state_start():
    from scipy import signal

    rng = np.random.default_rng(1)
    x = 9.8 + rng.normal(0, 1, 500)
    b, a = butter2_lowpass(3.0, 50.0)
    f = Biquad(b, a)
    f.reset(x[0])
    y = [f.step(v) for v in x]
    y_ref, _ = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-12)


def test_group_delay_matches_scipy_at_low_frequency():
    from scipy import signal

    b, a = butter2_lowpass(0.5, 50.0)
    _, gd = signal.group_delay((b, a), w=[0.01], fs=50.0)
    assert butter2_group_delay_s(0.5) == pytest.approx(gd[0] / 50.0, rel=0.01)


@pytest.mark.parametrize("rate", [20.0, 100.0, 400.0])
def test_grid_resampler_reproduces_a_slow_sine_at_any_input_rate(rate):
    rng = np.random.default_rng(2)
    dt = 1.0 / rate * (1 + 0.05 * rng.standard_normal(int(rate * 5)))
    t = np.cumsum(np.clip(dt, 0.2 / rate, None))
    t_ns = (1e12 + t * 1e9).astype(np.int64)
    x = np.sin(2 * math.pi * 1.0 * (t_ns - t_ns[0]) * 1e-9)
    r = GridResampler(rate_hz=50.0)
    out = [p for ti, xi in zip(t_ns.tolist(), x.tolist()) for p in r.update(ti, xi)]
    tg = np.array([p[0] for p in out])
    xg = np.array([p[1] for p in out])
    assert np.all(np.diff(tg) == 20_000_000)
    truth = np.sin(2 * math.pi * 1.0 * (tg - t_ns[0]) * 1e-9)
    # box averaging over 20 ms (fast phones) delays by about half a grid period (10 ms): |error| <= 2 pi f * 16 ms
    assert np.max(np.abs(xg - truth)) < 0.1
    assert len(out) == pytest.approx((t_ns[-1] - t_ns[0]) / 20e6, abs=2)


def test_grid_resampler_restarts_after_a_gap():
    r = GridResampler(rate_hz=50.0, max_gap_s=0.5)
    r.update(0, 1.0)
    r.update(10_000_000, 1.0)
    out = r.update(2_000_000_000, 2.0)
    assert r.restarted and out == [(2_000_000_000, 2.0)]


def test_running_median_equals_the_histogram_bin_where_the_cumulative_count_reaches_half():
    """The median kept between queries (it walks from the last median's bin) is the first bin whose cumulative
    count reaches half, exactly (np.cumsum and searchsorted the oracle): for values drifting up and down, jumping,
    outside the range, and for counts set from outside (the desktop fast path restores them)."""
    rng = np.random.default_rng(7)
    rm = RunningMedian(0.0, 40.0, 0.01)
    centre, checked = 9.8, 0
    for k in range(3000):
        if k % 500 == 0:
            centre = rng.uniform(-5.0, 45.0)  # a jump, sometimes outside the range (those values are not counted)
        centre += rng.normal(0.0, 0.05)
        rm.add(float(rng.normal(centre, rng.choice((0.005, 0.3, 3.0)))))
        if k == 1700:
            c = list(rm.counts)
            c[:1000] = [0] * 1000  # set from outside: the values under 10 forgotten
            rm.counts, rm.n = c, sum(c)
        if k % 7 == 0 and rm.n:
            cum = np.cumsum(rm.counts)
            i = int(np.searchsorted(cum, 0.5 * rm.n, side="left"))
            assert rm.median() == 0.0 + (i + 0.5) * 0.01, k
            checked += 1
    assert checked > 300 and rm.n < 3000  # some values fell outside the range
