"""The leave-out-every-10th measure of benchmarks.gnss_faults (issue #26): which fixes are good, and the longest
stretch in which they were all rejected, on a stream whose answer is known."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.gnss_faults import good_fixes, leave_out_measure
from core.geodesy import enu_to_geodetic

ORIGIN = (47.37, 8.54)


def test_good_fixes_are_fine_and_agree_with_their_neighbours():
    t = (np.arange(10) * 1e9).astype(np.int64)
    en = np.column_stack([1.4 * np.arange(10), np.zeros(10)])
    hacc = np.full(10, 4.0)
    en[5, 1] = 30.0  # a 30-m jump of one fix
    hacc[7] = 15.0  # too coarse
    g = good_fixes(t, en, hacc)
    assert not g[5] and not g[7]
    assert g[[0, 1, 2, 3, 8, 9]].all()


def test_the_leave_out_measure_on_a_track_that_follows_the_fixes_until_it_rejects_them():
    n = 200
    t = (np.arange(n) * 1e9).astype(np.int64)
    e = 1.4 * np.arange(n)
    lat, lon = enu_to_geodetic(e, np.zeros(n), ORIGIN)
    cols = ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg")
    v = np.column_stack([lat, lon, np.zeros(n), np.full(n, 5.0), np.full(n, 1.4), np.zeros(n)])
    gps = SimpleNamespace(t_ns=t, values=v, columns=cols)
    left = (np.arange(n) % 10) == 9
    steps = [SimpleNamespace(t_ns=int(x), east_m=1.4 * k + 2.0, north_m=0.0) for k, x in enumerate(t)]  # 2 m ahead
    fixes = [SimpleNamespace(t_ns=int(x), accepted=not (100 <= k < 180), reason="" if not (100 <= k < 180) else
                             "innovation gate") for k, x in enumerate(t) if not left[k]]
    m = leave_out_measure(SimpleNamespace(origin_lat_lon=ORIGIN, steps=steps, fixes=fixes), gps, left)
    assert m["median_m"] == pytest.approx(2.0, abs=1e-6)
    assert m["ratio"] == pytest.approx(0.4, abs=1e-6)
    assert m["longest_lost_s"] == 78.0  # fixes 100..178 rejected (179 is left out, not counted)
    assert m["good_fixes"] == n - left.sum() and m["good_fixes_accepted"] == n - left.sum() - 72
