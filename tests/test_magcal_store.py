"""MagCalibrator's sample store: the per-reading binning and the vectorised re-binning agree (issue #13).

``MagCalibrator.update`` bins and stores each reading with plain floats (the
phone's per-reading path); a fit attempt re-bins the store about a new centre
with numpy (``_refill`` through ``_bins``).  The two are separate code for the
same formula, so they are held to each other here: every stored reading sits
in the bin ``_bins`` gives it, with and without a soft iron, and re-binning the
readings keeps in each bin the same newest readings the streaming store keeps.
Synthetic readings only (seeded); well under a second.
"""

import math

import numpy as np

from core.pdr.magcal import MagCalibrator

SOFT = ((1.08, 0.04, -0.02), (0.04, 0.95, 0.03), (-0.02, 0.03, 0.97))


def _readings(n=3000, seed=3):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    m = np.array([12.0, -30.0, 5.0]) + 45.0 * u + rng.normal(scale=0.4, size=(n, 3))
    m[::97] = (12.0, -30.0, 5.0)  # at the centre: no direction, never stored
    t = 1_000_000_000 + 20_000_000 * np.arange(n, dtype=np.int64)
    return t, m


def _streamed(t, m, soft):
    """A calibrator that only stores (no attempt: the interval is longer than the stream) about a fixed centre."""
    cal = MagCalibrator(refit_interval_s=1e9)
    cal._centre, cal._centre_a = (12.0, -30.0, 5.0), soft
    for ti, (x, y, z) in zip(t.tolist(), m.tolist()):
        cal.update(ti, x, y, z)
    return cal


def _by_bin(cal):
    """{bin: set of the t_ns stored in it} of the calibrator's store."""
    per = cal.samples_per_bin
    out = {}
    for j, tj in enumerate(cal._slot_t):
        if tj >= 0:
            out.setdefault(j // per, set()).add(tj)
    return out


def test_streamed_readings_sit_in_the_bins_the_rebinning_gives():
    t, m = _readings()
    for soft in (None, SOFT):
        cal = _streamed(t, m, soft)
        st, sm = cal._stored()
        assert len(st) > 0.8 * cal.n_bins * cal.samples_per_bin
        bins = cal._bins(sm)
        per = cal.samples_per_bin
        slots = [j for j, tj in enumerate(cal._slot_t) if tj >= 0]
        assert bins.tolist() == [j // per for j in slots]
        # and the bin is the documented one: equal-z bands, equal azimuth sectors of the calibrated direction
        d = (sm - np.array(cal._centre)) @ (np.eye(3) if soft is None else np.array(soft)).T
        r = np.linalg.norm(d, axis=1)
        band = np.minimum(((d[:, 2] / r + 1.0) / 2.0 * cal.bin_bands).astype(int), cal.bin_bands - 1)
        sector = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) + math.pi) / (2 * math.pi) * cal.n_sectors).astype(int),
                            cal.n_sectors - 1)
        assert np.mean(bins == band * cal.n_sectors + sector) > 0.999
        assert np.all(cal._bins(np.array([cal._centre])) == -1)


def test_rebinning_keeps_the_newest_readings_per_bin():
    t, m = _readings()
    for soft in (None, SOFT):
        cal = _streamed(t, m, soft)
        streamed = _by_bin(cal)
        n_stored, occupied, counts = cal._n_stored, cal._occupied, list(cal._bin_count)
        rt, rm = cal._refill(t, m)  # all readings, about the same centre
        assert _by_bin(cal) == streamed
        assert (cal._n_stored, cal._occupied, cal._bin_count) == (n_stored, occupied, counts)
        st, sm = cal._stored()
        assert np.array_equal(st, rt) and np.array_equal(sm, rm)  # returned in slot order
        # within a bin, newest first
        per = cal.samples_per_bin
        for k in range(cal.n_bins):
            ts = [x for x in cal._slot_t[k * per:(k + 1) * per] if x >= 0]
            assert ts == sorted(ts, reverse=True)
