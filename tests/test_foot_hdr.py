"""Heuristic drift reduction (HDR, Borenstein et al. 2009) of the foot INS: core.foot.navigator."""

import math
from dataclasses import replace as dc_replace

import numpy as np

from core import quaternion as quat
from core.foot.ins import InsSettings
from core.foot.navigator import FootNavigator, FootSettings
from desktop.foot_simulator import footprints, simulate_foot


def _heading_error(res, w) -> float:
    """Final heading error (rad) of the body y axis, estimate against truth."""
    k = np.flatnonzero(np.isfinite(res.position_n[:, 0]))[-1]
    a = np.asarray(quat.to_matrix(tuple(res.q_wxyz[k])))[:, 1]
    b = np.asarray(quat.to_matrix(tuple(w.q_wxyz[k])))[:, 1]
    return math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])


def test_hdr_reduces_the_heading_drift_of_a_straight_walk_with_a_vertical_gyro_bias():
    """A straight walk with a vertical gyroscope bias (0.003 rad/s, unobservable with ZUPT alone; ZARU off):
    HDR's pseudo-measurements at the straight strides hold the heading (seeded)."""
    bias = (0.0005, -0.0005, 0.003)
    w = simulate_foot(footprints([(42.0, 0.0)]), rate_hz=200.0, acc_noise_m_s2=0.05, gyro_noise_rad_s=0.005,
                      gyro_bias_rad_s=bias, seed=11)
    plain = FootSettings(rts_smoother=False, ins=InsSettings(zero_rate_update=False), hdr_gate_rad=0.0)
    hdr = dc_replace(plain, hdr_gate_rad=math.radians(5.0), hdr_noise_rad=math.radians(0.5))
    nav0, nav1 = FootNavigator(plain), FootNavigator(hdr)
    r0, r1 = nav0.run(w.recording, stance=w.stance), nav1.run(w.recording, stance=w.stance)
    assert r0.counters["hdr_updates"] == 0 and not r0.hdr_updates
    n = len(r1.strides) - 3  # none at the alignment stance, the first stride (no reference) and the final stance
    assert r1.counters["hdr_updates"] >= n - 1, (r1.counters["hdr_updates"], n)
    innov = np.array([u.innovation[0] for u in r1.hdr_updates])
    assert np.all(np.abs(innov) <= math.radians(5.0))
    h0, h1 = abs(_heading_error(r0, w)), abs(_heading_error(r1, w))
    assert h0 > math.radians(3.0) and h1 < 0.6 * h0, (math.degrees(h0), math.degrees(h1))  # 4.1 -> 1.9 deg
    # the relative pseudo-measurements observe the vertical bias (0.003 rad/s; ZUPT alone leaves it near 0)
    assert abs(nav1.ins.bg[2] - bias[2]) < 0.6 * abs(nav0.ins.bg[2] - bias[2]), (nav0.ins.bg, nav1.ins.bg)  # 7e-4 -> 1.9e-3


def test_hdr_gate_refuses_a_turn():
    """A 90 deg turn: the strides' headings differ by more than the gate there, so no update pulls the turn back."""
    w = simulate_foot(footprints([(7.0, 0.0), (7.0, math.pi / 2)]), rate_hz=200.0, seed=3)
    s = FootSettings(rts_smoother=False, hdr_gate_rad=math.radians(5.0), hdr_noise_rad=math.radians(2.0))
    r = FootNavigator(s).run(w.recording, stance=w.stance)
    assert abs(_heading_error(r, w)) < math.radians(1.0), math.degrees(_heading_error(r, w))
    assert 0 < r.counters["hdr_updates"] < len(r.strides) - 2
