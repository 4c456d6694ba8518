"""benchmarks.ipin_decompose: each counterfactual removes exactly the error it names (synthetic walks, known truth)."""

import math

import numpy as np
import pytest

from benchmarks.datasets.base import Landmarks
from benchmarks.ipin_decompose import counterfactuals
from core import metrics as M


def _square_walk(step_m=0.6, steps_per_side=20, dt_s=0.6):
    """A closed 12 m square walked counter-clockwise: landmarks at the corners, steps between them."""
    side = step_m * steps_per_side
    corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], dtype=float)
    n = 4 * steps_per_side
    t_ns = (np.arange(1, n + 1) * dt_s * 1e9).astype(np.int64)
    heading = np.repeat(np.arange(4) * math.pi / 2, steps_per_side)
    lm_t = (np.arange(5) * steps_per_side * dt_s * 1e9).astype(np.int64)
    lm = Landmarks(t_ns=lm_t, east_m=corners[:, 0], north_m=corners[:, 1])
    return t_ns, np.full(n, step_m), heading, lm


def _metrics(t_ns, L, h, lm):
    e, n = M.dead_reckon(L, h)
    le = M.landmark_errors(t_ns, e, n, h, lm.t_ns, lm.east_m, lm.north_m)
    return le.mean_m, le.loop_closure_pct


def test_a_heading_error_is_removed_by_the_true_heading_only():
    t, L, h, lm = _square_walk()
    h_bad = h + np.radians(np.repeat([10.0, -5.0, 15.0, 0.0], 20))  # a bent field, segment by segment
    cf = counterfactuals(t, L, h_bad, lm)
    ours = _metrics(t, *cf["ours"], lm)
    assert ours[0] > 0.5 and ours[1] > 1.0
    assert _metrics(t, *cf["heading true"], lm) == pytest.approx((0.0, 0.0), abs=1e-9)
    # the lengths are right already: scaling them changes nothing
    assert _metrics(t, *cf["length true"], lm) == pytest.approx(ours, abs=1e-9)


def test_a_length_error_is_removed_by_the_true_length_only():
    t, L, h, lm = _square_walk()
    L_bad = L * np.repeat([0.8, 1.1, 1.0, 0.9], 20)  # short strides on the first side, long on the second
    cf = counterfactuals(t, L_bad, h, lm)
    ours = _metrics(t, *cf["ours"], lm)
    assert ours[0] > 0.5
    assert _metrics(t, *cf["length true"], lm) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert _metrics(t, *cf["heading true"], lm) == pytest.approx(ours, abs=1e-9)


def test_a_constant_heading_offset_is_removed_by_the_mean_and_a_drift_by_the_line():
    t, L, h, lm = _square_walk()
    cf = counterfactuals(t, L, h + math.radians(12.0), lm)
    assert _metrics(t, *cf["heading - mean"], lm)[0] == pytest.approx(0.0, abs=1e-9)
    drift = math.radians(0.2) * (t * 1e-9)  # 12 deg/min from the start
    cf = counterfactuals(t, L, h + drift, lm)
    assert _metrics(t, *cf["ours"], lm)[0] > 0.5
    # the line is fitted to the segments' mean errors: exact for a drift linear in time
    assert _metrics(t, *cf["heading - linear"], lm)[0] == pytest.approx(0.0, abs=1e-6)
