"""benchmarks.real_walks' measures on synthetic data with a known answer (issue #25)."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.real_walks import outage_windows, reversed_steps, stability, straight_windows


def test_stability_sd_drift_and_mean_offset():
    # course 0.5 rad; step headings off by 10 deg plus a drift of 2 deg/min and +-3 deg alternating noise
    t0 = 0
    wins, st_t, head = [], [], []
    for k in range(12):
        a = int((k * 30.0) * 1e9)
        b = a + int(29e9)
        wins.append((a, b, 0.5))
        off = math.radians(10.0 + 2.0 * (k * 30.0 + 14.5) / 60.0 + (3.0 if k % 2 else -3.0))
        for j in range(20):
            st_t.append(a + int(j * 1.4e9))
            head.append(0.5 - off)
    s = stability(wins, np.array(st_t, dtype=np.int64), np.array(head), t0)
    assert s["n_windows"] == 12
    assert abs(s["drift_deg_min"] - 2.0) < 0.3  # the +-3 deg alternation adds a little
    assert abs(s["mean_offset_deg"] - (10.0 + 2.0 * (5.5 * 30.0 + 14.5) / 60.0)) < 0.2
    assert 4.5 < s["sd_deg"] < 6.5  # sqrt(spread of the drift ramp^2 + 3^2)
    # wrapping: an offset near 180 deg has no jump in the drift
    s2 = stability(wins, np.array(st_t, dtype=np.int64), np.array(head) + math.radians(170.0), t0)
    assert abs(s2["drift_deg_min"] - s["drift_deg_min"]) < 1e-6
    assert abs(s2["mean_offset_deg"] - (s["mean_offset_deg"] - 170.0)) < 1e-6


def test_straight_windows_keep_straight_and_drop_turns():
    t = (np.arange(121) * 1e9).astype(np.int64)
    e = 1.3 * np.arange(121.0)
    n = np.zeros(121)
    n[60:] = 1.3 * np.arange(61.0)  # from 60 s on: straight north
    e[60:] = e[60]
    n[45:60] = 0.2 * (np.arange(15.0)) ** 2  # a curve inside the second window
    w = straight_windows((t, e, n, np.full(121, 4.0)), 0, int(120e9))
    courses = [round(math.degrees(c)) for _, _, c in w]
    assert 0 in courses and 90 in courses and len(w) == 3  # the curved window (30-60 s) is dropped


def test_outage_windows():
    w = outage_windows(5.0, 306.0)
    assert (65.0, 60.0) in w and (65.0, 180.0) in w and all(a + L <= 291.0 for a, L in w)
    assert not [x for x in w if x[1] == 300.0]


def test_reversed_steps_counts_backward_groups():
    # fixes every second walking north-east at 1.3 m/s; steps every 0.5 s, heading = course - 12 deg, except a
    # group of 8 steps turned by 180 deg (a flipped sign) and a mean offset of 12 deg that must not count
    t = (np.arange(120) * 1e9).astype(np.int64)
    course = math.radians(40.0)
    e, n = 1.3 * np.arange(120.0) * math.cos(course), 1.3 * np.arange(120.0) * math.sin(course)
    st_t = (np.arange(10, 220) * 0.5e9).astype(np.int64)
    head = np.full(len(st_t), course - math.radians(12.0))
    head[100:108] += math.pi
    head[150] = np.nan
    r = reversed_steps((t, e, n, np.full(120, 4.0)), st_t, head, 12.0)
    assert r["n"] == len(st_t) - 1
    assert abs(r["reversed_pct"] - 100.0 * 8 / r["n"]) < 1e-9
    assert reversed_steps(None, st_t, head, 12.0)["reversed_pct"] is None
    still = reversed_steps((t, np.zeros(120), np.zeros(120), np.full(120, 4.0)), st_t, head, 12.0)
    assert still["n"] == 0 and still["reversed_pct"] is None  # no chord: no course, nothing counted
