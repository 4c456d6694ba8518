"""The stride scale's chord samples count by their information (issue #26, Chen et al. 2010 stride calibration).

Before: each chord sample weighed its chord length and the prior 30 m, so one chord between poor fixes just
before an outage moved the scale as much as everything learnt before it (gnss_faults tuning seed 0: one
sample of 1.425 against a truth of 1.126, scale 1.206, 32 m off after the outage).  Now a scalar Kalman update
with the sample's SD from its end fixes' reported accuracies, and a reported SD that covers the error
(``StrideWeighting.INFORMATION``; not the default yet, see ``OnlineTrainer``'s ``stride_weighting``).
"""

import math

import numpy as np
import pytest

from core.gnss.accuracy import HACC_PER_SIGMA
from core.gnss.training import OnlineTrainer, StrideWeighting

DT_S, HEADING = 1 / 1.8, 0.4  # a step every 0.56 s of 0.7 m (model), along a straight line


def _walk(tr: OnlineTrainer, truth: float, seconds: int, rng, axis_sd_m: float = 1.0, hacc_m: float = 3.0,
          bad_fix: tuple[int, float, float] | None = None, shift: tuple[int, float, float] | None = None) -> list:
    """Steps of 0.7 m (model) while the walker covers ``truth`` x 0.7 m a step; a fix a second off by
    ``axis_sd_m`` along the line; ``bad_fix = (second, offset_m, hacc_m)``; ``shift = (second, along_m, across_m)``:
    every fix from then on moved so (a multipath episode that lasts). The stride samples ``(t_s, sample, scale,
    sd)``, one per 30-s stretch (three 10-s windows)."""
    v = truth * 0.7 / DT_S
    out, k, i = [], 0, 0
    while (i + 1) * DT_S <= seconds + 0.5:
        i += 1
        t = i * DT_S
        tr.add_step(int(t * 1e9), int((t - DT_S) * 1e9), 0.7, HEADING)
        while k + 1 <= t:
            k += 1
            d, hacc = v * k + rng.normal(0.0, axis_sd_m), hacc_m
            if bad_fix is not None and k == bad_fix[0]:
                d, hacc = d + bad_fix[1], bad_fix[2]
            across = 0.0
            if shift is not None and k >= shift[0]:
                d, across = d + shift[1], shift[2]
            fl = tr.add_fix(int(k * 1e9), d * math.cos(HEADING) - across * math.sin(HEADING),
                            d * math.sin(HEADING) + across * math.cos(HEADING), hacc, v, HEADING)
            if fl is not None and math.isfinite(fl.scale_sample):
                out.append((k, fl.scale_sample, tr.stride_scale, tr.stride_scale_sd))
    return out


def test_a_noisy_chord_just_before_the_end_moves_the_scale_by_its_information_only():
    """Three good 30-s chords (3-m fixes), then one whose end fix is 8 m long and reports 10 m: the
    sample reads 1.33 against a truth of 1.10.  The scale stays within 0.025 of the truth, and its SD
    covers the error (|error| <= 2 SD) after every sample.  Before (chord-length weights): 1.148."""
    truth = 1.10
    tr = OnlineTrainer(stride_weighting=StrideWeighting.INFORMATION)
    samples = _walk(tr, truth, 121, np.random.default_rng(1), bad_fix=(121, 8.0, 10.0))
    assert len(samples) == 4 and samples[-1][1] > 1.3  # the noisy one is used (not gated), and it is noisy
    for _, _, scale, sd in samples:
        assert abs(scale - truth) <= 2.0 * sd * scale
    assert tr.stride_scale == pytest.approx(truth, abs=0.025)
    old = OnlineTrainer(stride_weighting=StrideWeighting.CHORD_LENGTH)
    _walk(old, truth, 121, np.random.default_rng(1), bad_fix=(121, 8.0, 10.0))
    assert abs(old.stride_scale - truth) > 0.04  # what the chord-length weights did


def test_the_reported_sd_matches_the_errors_over_many_walks():
    """Consistency band: truths drawn from the prior (1.0, SD 0.08), fixes honest (3 m reported, 2 m per
    axis), 2.5 minutes of walking: the normalised errors (scale - truth) / SD have an RMS within
    [0.4, 1.3] over 40 walks and no more than 10 % beyond 2 SD."""
    rng = np.random.default_rng(7)
    z = []
    for _ in range(40):
        truth = 1.0 + 0.08 * rng.normal()
        tr = OnlineTrainer(stride_weighting=StrideWeighting.INFORMATION)
        _walk(tr, truth, 151, rng, axis_sd_m=3.0 / HACC_PER_SIGMA)
        z.append((tr.stride_scale - truth) / (tr.stride_scale_sd * tr.stride_scale))
    z = np.array(z)
    assert 0.4 <= math.sqrt(np.mean(z ** 2)) <= 1.3
    assert np.mean(np.abs(z) > 2.0) <= 0.10


def test_without_samples_the_scale_and_sd_are_the_prior():
    tr = OnlineTrainer(scale_prior=1.05, prior_scale_sd=0.1, stride_weighting=StrideWeighting.INFORMATION)
    assert tr.stride_scale == 1.05 and tr.stride_scale_sd == pytest.approx(0.1)
