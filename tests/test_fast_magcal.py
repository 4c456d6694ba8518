"""The fast path's magnetometer calibration with compiled fit attempts against core's, reading by reading.

:func:`desktop.fast.magcal.calibrate_stream` with ``compiled_attempts=True`` runs the fit attempts in
:func:`desktop.fast.magcal.attempt_to_fit` (before a fit is in force the bootstrap sphere with trimming, then
the re-binning) as far as the rejections before a fit, and hands the attempts that reach a fit to core's
``attempt``.  Held here to
``core.pdr.magcal.MagCalibrator.update`` fed reading by reading: every calibrated reading and the fit parameters
within ``TOL`` (relative; the bootstrap centre differs from core's by rounding, about 1e-15 relative, as the
least squares is a QR and not LAPACK's SVD), the same accept and reject decisions (reasons, states, counters),
and the same final private store.  The inputs: the IPIN cut (compass waving, then a walk: the calibrator fits
early and keeps refitting), the ETH walk held flat (bootstrap attempts only), simulated walks (hand-held,
pocket; one with a hard and soft iron and a calibration waving) and a synthetic stream with broken readings, a
still phone and an offset jump.  Seeded; each case runs the kernels as plain Python in CI (no numba) in a few
seconds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.pdr.magcal import MagCalibrator, MagCalStatus
from desktop.fast.magcal import _lstsq4, _pairwise, calibrate_stream
from desktop.simulator import simulate_walk
from test_fast_path import _load  # tests/ is on sys.path: the real recordings, cached, skipped where absent

TOL = 1e-9  # relative, on the calibrated readings and every float of the status and the fits
IPIN = "ipin2023_track3/logfiles/IPIN2023_T3_TrainingTrial01_repetition01.txt.gz"
ETH = "sensorlogger_gps_walk_ethz/2023-03-17_15-50-47"


def _mag(rec, start_s: float = 0.0, end_s: float = math.inf):
    s = rec.streams["mag"]
    t = np.asarray(s.t_ns, dtype=np.int64)
    v = np.asarray(s.values, dtype=np.float64)[:, :3]
    keep = (t >= t[0] + start_s * 1e9) & (t <= t[0] + end_s * 1e9)
    return t[keep], v[keep]


def _close(a, b) -> bool:
    """Floats within TOL (relative, nan equal to nan); anything else equal; tuples element by element."""
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return abs(a - b) <= TOL * max(1.0, abs(a), abs(b))
    return a == b


def _same_status(a: MagCalStatus, b: MagCalStatus) -> bool:
    return all(_close(getattr(a, f), getattr(b, f)) for f in MagCalStatus.__dataclass_fields__)


def _check(t, v, **settings) -> MagCalibrator:
    """The compiled attempts against ``update`` reading by reading; returns the reference calibrator."""
    ref = MagCalibrator(**settings)
    rows, flags = [], []
    for ti, (x, y, z) in zip(t.tolist(), v.tolist()):
        rows.append(ref.update(ti, x, y, z))
        flags.append(ref.calibrated)
    rows = np.array(rows, dtype=np.float64).reshape(len(t), 3)
    cal = MagCalibrator(**settings)
    out, ok = calibrate_stream(cal, t, v, compiled_attempts=True)
    fin = np.isfinite(rows)
    assert np.array_equal(fin, np.isfinite(out))
    assert np.all(np.abs(out[fin] - rows[fin]) <= TOL * np.maximum(1.0, np.abs(rows[fin])))
    assert ok.tolist() == flags
    assert len(cal._fits) == len(ref._fits) and all(_same_status(x, y) for x, y in zip(cal._fits, ref._fits))
    assert _same_status(cal.status, ref.status)
    # the private state a further update would start from: the store, the reservoir, the centre, the counters
    assert list(cal._slot_t) == list(ref._slot_t) and list(cal._slot_m) == list(ref._slot_m)
    assert cal._bin_count == ref._bin_count and (cal._n_stored, cal._occupied) == (ref._n_stored, ref._occupied)
    assert list(cal._recent) == list(ref._recent) and list(cal._recent_m) == list(ref._recent_m)
    assert (cal._centre is None) == (ref._centre is None)
    if ref._centre is not None:
        assert _close(tuple(cal._centre), tuple(ref._centre))
    assert (cal._t_last_attempt, cal._new_since, cal._new_bins_since, cal._t_prev, cal._attempted_fit) == (
        ref._t_last_attempt, ref._new_since, ref._new_bins_since, ref._t_prev, ref._attempted_fit)
    return ref


def test_pairwise_sum_is_numpys():
    rng = np.random.default_rng(7)
    for n in list(range(0, 300)) + [517, 1031, 2500]:
        a = rng.normal(size=n) * 10.0 ** rng.normal(size=n)
        assert _pairwise(a, 0, n) == (float(np.add.reduce(a)) if n else 0.0)


def test_qr_least_squares_against_lapacks():
    # the sphere's design (2x, 2y, 2z, 1) from samples spread over the sphere down to nearly one plane: the QR's
    # solution within 1e-11 of numpy.linalg.lstsq's (relative); an exactly flat one (rank 3) is left to core
    rng = np.random.default_rng(8)
    for flat in (1.0, 1e-2, 1e-4):
        x = rng.normal(size=(300, 3)) * [1.0, 1.0, flat]
        design = np.column_stack([2.0 * x, np.ones(300)])
        rhs = (x * x).sum(axis=1) + rng.normal(scale=0.01, size=300)
        want = np.linalg.lstsq(design, rhs, rcond=None)[0]
        got = np.empty(4)
        assert _lstsq4(design.copy(), rhs.copy(), 300, got) == 4
        assert np.abs(got - want).max() <= 1e-11 * np.abs(want).max()
    design[:, 2] = 0.0
    assert _lstsq4(design.copy(), rhs.copy(), 300, got) == -1  # core's attempt decides (gelsd: rank 3)


def test_ipin_cut_waving_then_walking():
    ref = _check(*_mag(_load(IPIN), 0.0, 90.0))
    assert ref.n_accepted >= 1 and ref.n_fits > 5  # bootstrap attempts, then fits by core's attempt


def test_eth_walk_held_flat_bootstrap_only():
    ref = _check(*_mag(_load(ETH), 0.0, 200.0))
    assert ref.n_accepted == 0 and ref.status.reason  # the phone turned about one axis: no fit, only attempts


@pytest.mark.parametrize("placement, seed", [("handheld", 3), ("pocket", 4)])
def test_simulated_walks(placement, seed):
    path = [(0.0, 0.0), (30.0, 0.0), (30.0, 20.0), (0.0, 20.0), (0.0, 0.0)]
    rec = simulate_walk(path, seed=seed, placement=placement, rate_hz=50.0).recording
    _check(*_mag(rec))


def test_simulated_walk_with_iron_and_calibration_waving():
    rec = simulate_walk([(0.0, 0.0), (25.0, 0.0), (25.0, 15.0)], seed=11, rate_hz=50.0, calibration_motion_s=15.0,
                        mag_hard_iron_uT=(12.0, -7.0, 20.0),
                        mag_soft_iron=((1.05, 0.02, 0.0), (0.02, 0.97, 0.01), (0.0, 0.01, 1.0))).recording
    ref = _check(*_mag(rec))
    assert ref.n_accepted >= 1


def test_synthetic_stream_broken_readings_still_phone_and_offset_jump():
    # a phone turned at random about all axes (50 Hz), first still for 20 s (the sphere through coinciding
    # samples fails), broken readings (nan, too large), then the offset jumps (the trimming's newest starts)
    rng = np.random.default_rng(12)
    n = 50 * 150
    t = 1_000_000_000 + np.cumsum(rng.integers(18_000_000, 22_000_000, size=n)).astype(np.int64)
    d = rng.normal(size=(n, 3))
    d = np.cumsum(d * 0.05, axis=0)
    d[: 50 * 20] = d[50 * 20]
    u = np.array([np.cos(d[:, 0]) * np.cos(d[:, 1]), np.sin(d[:, 0]) * np.cos(d[:, 1]), np.sin(d[:, 1])]).T
    offset = np.where(np.arange(n)[:, None] < 50 * 90, [[15.0, -5.0, 30.0]], [[-20.0, 10.0, 5.0]])
    v = 45.0 * u + offset + rng.normal(scale=0.4, size=(n, 3))
    v[rng.integers(0, n, size=20)] = np.nan
    v[rng.integers(0, n, size=5)] = 5000.0
    ref = _check(t, v)
    assert ref.n_invalid == int(np.count_nonzero(~np.isfinite(v).all(axis=1) | (np.abs(v) > 1000).any(axis=1)))
