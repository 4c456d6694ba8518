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


def test_a_failed_run_counts_in_the_headlines_never_dropped():
    import math

    from benchmarks.gnss_faults import headlines

    def ipin(name, pdr, chen, kubrak=None, errors=None):
        cols = {"pdr": {"lm_mean_m": pdr}, "chen": {"lm_mean_m": chen, "lm_nees": [1.0, math.nan]}}
        if kubrak is not None:
            cols["kubrak"] = {"lm_mean_m": kubrak, "lm_nees": [1.0]}
        return {"name": name, "split": "tuning", "gnss": {"good": True}, "columns": cols, "errors": errors or {}}

    data = {"sim": [], "real": [], "loo": [],
            "ipin": [ipin("a", 1.0, 1.0, 1.0), ipin("b", 2.0, 2.0, errors={"kubrak": "ValueError"}),
                     ipin("c", 3.0, math.nan, 3.0)],
            "failed": [{"item": ["ipin", ["root", 7]], "split": "tuning", "error": "boom"}]}
    h = headlines(data)
    assert h["gps_failed_runs"] == 1
    assert h["ipin_pdr_landmark_median_m_tuning"] == 2.5  # (1, 2, 3, inf)
    assert h["ipin_fused_landmark_median_m_tuning_chen"] == math.inf  # (1, 2, inf: nan, inf: failed)
    assert h["ipin_fused_landmark_median_m_tuning_kubrak"] == math.inf  # (1, inf: kubrak failed on b, 3, inf)
    assert h["ipin_fused_nees_beyond_95pct_share_tuning_chen"] == 0.5  # a non-finite error is beyond, not dropped
