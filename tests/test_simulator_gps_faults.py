"""desktop.simulator's GPS faults (GpsFault): jumps, drift, noise, outages and lying fixes, with their truth.

Each fault's injected error is checked on the truth against its settings, on seeded walks.  The walks
use a 10 Hz IMU and a 2 Hz truth grid (the GPS does not depend on them) to keep the file quick.  The
statistical tolerances are stated beside each assertion, in standard errors (SE) of the sample.
"""

import math

import numpy as np
import pytest

from core.geodesy import geodetic_to_enu
from desktop.simulator import GpsFault, GpsModel, simulate_walk

KW = dict(rate_hz=10.0, truth_rate_hz=2.0)
#: a straight walk of about 11 minutes (1.8 steps/s of about 0.7 m)
ROUTE = [(0.0, 0.0), (0.0, 900.0)]


def walk(faults=(), seed=1, **model):
    return simulate_walk(ROUTE, gps=GpsModel(faults=tuple(faults), **model), seed=seed, **KW)


@pytest.fixture(scope="module")
def clean():
    return walk()


def rel_s(w, t_ns):
    """Simulation time (s): fault windows count from the clock's start (``clock_start_ns``), like ``first_fix_s``."""
    return (np.asarray(t_ns) - w.recording.metadata["clock_start_ns"]) * 1e-9


def reported_error_en(w):
    """Reported minus true horizontal position of each fix, from the stream itself (m), (n, 2)."""
    g = w.recording.streams["gps"].values
    e, n = geodetic_to_enu(g[:, 0], g[:, 1], w.truth.origin_lat_lon)
    return np.stack([e, n], axis=1) - w.truth.gps.pos_enu_m[:, :2]


def rows_at(w, t_ns):
    return np.searchsorted(w.truth.gps.t_ns, t_ns)


def test_fixes_outside_the_faults_are_the_fixes_without_faults(clean):
    faults = [GpsFault("noise", 60, 60), GpsFault("outage", 120, 120), GpsFault("jump", 300, 30),
              GpsFault("drift", 360, 180), GpsFault("lying", 560, 40, fraction=0.5)]
    w = walk(faults)
    g, c = w.truth.gps, clean.truth.gps
    out = g.fault_index < 0
    k = rows_at(clean, g.t_ns)
    np.testing.assert_array_equal(clean.truth.gps.t_ns[k], g.t_ns)  # every fix of the faulty walk is a clean fix
    np.testing.assert_array_equal(clean.recording.streams["gps"].values[k][out], w.recording.streams["gps"].values[out])
    # inside the faults only the fault's part differs: the normal error is the clean walk's
    np.testing.assert_allclose(g.error_en_m - g.fault_en_m, c.error_en_m[k], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(g.fault_en_m[out], 0.0)
    # the truth's error is the stream's (through latitude/longitude and back: nanometres)
    np.testing.assert_allclose(reported_error_en(w), g.error_en_m, rtol=0, atol=1e-6)
    np.testing.assert_allclose(g.error_m, np.hypot(*g.error_en_m.T), rtol=0, atol=0)
    assert set(np.unique(g.fault_kind)) == {"", "noise", "jump", "drift", "lying"}
    for i, f in enumerate(faults):
        t = rel_s(w, g.t_ns[g.fault_index == i])
        assert f.kind == "outage" or (t.min() >= f.start_s and t.max() < f.end_s)
    clock0 = w.recording.metadata["clock_start_ns"]
    np.testing.assert_array_equal(g.fault_t_ns - clock0, [[f.start_s * 10**9, f.end_s * 10**9] for f in faults])
    # the metadata lists the faults; a model without faults keeps its header as before
    assert [f["kind"] for f in w.recording.metadata["gps"]["faults"]] == [f.kind for f in faults]
    assert "faults" not in clean.recording.metadata["gps"]


def test_outage_has_no_fixes_and_the_walker_keeps_walking(clean):
    w = walk([GpsFault("noise", 100, 60), GpsFault("outage", 160, 120)])
    t = rel_s(w, w.recording.streams["gps"].t_ns)
    assert not np.any((t >= 160) & (t < 280))
    # the clean walk has its ~120 fixes there (1 Hz) and the faulty one has them right before and after
    tc = rel_s(clean, clean.recording.streams["gps"].t_ns)
    assert np.sum((tc >= 160) & (tc < 280)) == pytest.approx(120, abs=1)
    assert t[t < 160].max() > 159.0 and t[t >= 280].min() < 281.0
    # the walker walked on: about 1.25 m/s times 120 s between the last fix before and the first after
    p = w.truth.gps.pos_enu_m
    i = int(np.flatnonzero(t < 160)[-1])
    assert np.hypot(*(p[i + 1, :2] - p[i, :2])) > 100.0
    assert len(w.recording.streams["gps"]) == len(w.truth.gps.t_ns) == len(clean.truth.gps.t_ns) - (
        np.sum((tc >= 160) & (tc < 280)))


def test_jumps_are_constant_offsets_of_20_to_200_m_with_an_under_reported_accuracy():
    # 40 jumps of 5 s each in one walk: one offset each, uniform magnitude in [20, 200] m
    faults = [GpsFault("jump", 10.0 + 15.0 * i, 5.0) for i in range(40)]
    w = walk(faults, seed=2)
    g, s = w.truth.gps, w.recording.streams["gps"]
    mags = np.hypot(*g.fault_offset_en_m.T)
    assert np.all((mags >= 20.0) & (mags <= 200.0))
    assert mags.mean() == pytest.approx(110.0, abs=4 * 52.0 / math.sqrt(40))  # uniform: SD 52 m; 4 SE
    ang = np.arctan2(g.fault_offset_en_m[:, 1], g.fault_offset_en_m[:, 0])
    assert abs(np.mean(np.exp(1j * ang))) < 4 / math.sqrt(40)  # uniform direction: the mean resultant ~ 1/sqrt(n)
    for i in range(40):
        rows = g.fault_index == i
        assert rows.sum() == pytest.approx(5, abs=1)
        np.testing.assert_array_equal(g.fault_en_m[rows], np.tile(g.fault_offset_en_m[i], (rows.sum(), 1)))
    jump = g.fault_kind == "jump"
    # the receiver under-reports: the normal accuracy (with its jitter) times hacc_multipath_factor, ~8 m
    assert np.median(s.values[jump, 3]) == pytest.approx(1.5 * g.hacc_normal_m[0], rel=0.1)
    assert np.all(s.values[jump, 3] < 0.5 * g.error_m[jump].clip(20.0))
    # speed and course are Doppler: untouched by a jump
    clean = walk(seed=2)
    k = rows_at(clean, g.t_ns)
    np.testing.assert_array_equal(s.values[:, 4], clean.recording.streams["gps"].values[k, 4])


def test_drift_grows_at_5_m_per_min_in_one_direction_and_snaps_back():
    f = GpsFault("drift", 100.0, 300.0)
    w = walk([f], seed=3)
    g, s = w.truth.gps, w.recording.streams["gps"]
    rows = g.fault_kind == "drift"
    t = rel_s(w, g.t_ns[rows])
    dist = np.hypot(*g.fault_en_m[rows].T)
    np.testing.assert_allclose(dist, 5.0 / 60.0 * (t - 100.0), rtol=0, atol=1e-9)  # exactly 5 m/min
    unit = g.fault_offset_en_m[0] / np.hypot(*g.fault_offset_en_m[0])
    np.testing.assert_allclose(g.fault_en_m[rows][1:] / dist[1:, None], np.tile(unit, (rows.sum() - 1, 1)), atol=1e-12)
    assert np.hypot(*g.fault_offset_en_m[0]) == pytest.approx(25.0)  # 5 min at 5 m/min
    after = rel_s(w, g.t_ns) >= 400.0
    np.testing.assert_array_equal(g.fault_en_m[after], 0.0)  # gone after the window
    # the reported accuracy stays the normal one (it does not see the drift)
    np.testing.assert_array_equal(s.values[rows, 3] / g.hacc_normal_m[rows] > 0.4, True)
    assert np.median(s.values[rows, 3]) == pytest.approx(g.hacc_normal_m[0], rel=0.1)


@pytest.mark.parametrize("hacc", ["honest", "normal"])
def test_noise_has_sd_30_m_per_axis_and_honest_or_lying_accuracy(hacc):
    f = GpsFault("noise", 30.0, 600.0, hacc=hacc)  # 600 fixes: 1200 samples of the per-axis noise
    w = walk([f], seed=4)
    g, s = w.truth.gps, w.recording.streams["gps"]
    rows = g.fault_kind == "noise"
    assert rows.sum() == pytest.approx(600, abs=1)
    x = g.fault_en_m[rows]
    se_sd = 30.0 / math.sqrt(2 * len(x))  # SE of a Gaussian SD estimate: sigma / sqrt(2 n) = 0.87 m per axis
    np.testing.assert_allclose(x.std(axis=0), [30.0, 30.0], atol=4 * se_sd)
    np.testing.assert_allclose(x.mean(axis=0), [0.0, 0.0], atol=4 * 30.0 / math.sqrt(len(x)))  # 4 SE: 4.9 m
    assert abs(np.corrcoef(x[1:, 0], x[:-1, 0])[0, 1]) < 4 / math.sqrt(len(x))  # white
    err, rep = g.error_m[rows], s.values[rows, 3]
    if hacc == "honest":
        # the 68 % radius of the total error: 68 % of the fixes within it (binomial SE 1.9 %; 4 SE)
        assert np.mean(err <= rep) == pytest.approx(0.68, abs=4 * math.sqrt(0.68 * 0.32 / len(err)))
        assert np.median(rep) > 40.0
    else:
        assert np.median(rep) == pytest.approx(g.hacc_normal_m[0], rel=0.1)  # about 5 m while ~35 m off
        assert np.median(err) > 30.0
    # the Doppler velocity is noisy too: against the clean walk's (same draws but the fault's), the velocity
    # (from speed and course, where both walks have a course) differs by the fault's 1 m/s per axis
    clean = walk(seed=4)
    k = rows_at(clean, g.t_ns[rows])

    def vel(v):
        return v[:, 4:5] * np.stack([np.sin(np.radians(v[:, 5])), np.cos(np.radians(v[:, 5]))], axis=1)

    dv = vel(s.values[rows]) - vel(clean.recording.streams["gps"].values[k])
    dv = dv[np.isfinite(dv).all(axis=1)]
    assert len(dv) > 0.9 * rows.sum()  # speeds below 0.3 m/s have no course
    np.testing.assert_allclose(dv.std(axis=0), [1.0, 1.0], atol=4 / math.sqrt(2 * len(dv)) + 0.05)  # 4 SE + bias


def test_lying_fixes_report_3_to_5_m_while_30_to_80_m_off():
    f = GpsFault("lying", 30.0, 500.0, fraction=0.3)
    w = walk([f], seed=5)
    g, s = w.truth.gps, w.recording.streams["gps"]
    in_window = (rel_s(w, g.t_ns) >= 30.0) & (rel_s(w, g.t_ns) < 530.0)
    lying = g.fault_kind == "lying"
    n = in_window.sum()
    assert lying.sum() == pytest.approx(0.3 * n, abs=4 * math.sqrt(0.3 * 0.7 * n))  # binomial, 4 SE = 41
    off = np.hypot(*g.fault_en_m[lying].T)
    assert np.all((off >= 30.0) & (off <= 80.0))
    assert off.mean() == pytest.approx(55.0, abs=4 * 14.4 / math.sqrt(lying.sum()))  # uniform: SD 14.4 m
    assert np.all((s.values[lying, 3] >= 3.0) & (s.values[lying, 3] <= 5.0))
    # independent fixes: each its own direction; the total error is 30-80 m give or take the normal error
    assert np.std(g.fault_en_m[lying], axis=0).min() > 25.0
    assert np.all(g.error_m[lying] > 30.0 - 15.0) and np.median(g.error_m[lying]) > 40.0
    np.testing.assert_array_equal(g.fault_en_m[in_window & ~lying], 0.0)  # the others are honest fixes


def test_faults_are_deterministic_and_draw_from_their_own_generators():
    a = walk([GpsFault("jump", 50, 20), GpsFault("noise", 100, 60)], seed=7)
    b = walk([GpsFault("jump", 50, 20), GpsFault("noise", 100, 60)], seed=7)
    np.testing.assert_array_equal(a.recording.streams["gps"].values, b.recording.streams["gps"].values)
    # changing the second fault does not move the first fault's draws
    c = walk([GpsFault("jump", 50, 20), GpsFault("lying", 100, 60)], seed=7)
    np.testing.assert_array_equal(a.truth.gps.fault_offset_en_m[0], c.truth.gps.fault_offset_en_m[0])
    d = walk([GpsFault("jump", 50, 20)], seed=8)
    assert not np.array_equal(a.truth.gps.fault_offset_en_m[0], d.truth.gps.fault_offset_en_m[0])


def test_invalid_faults_are_rejected():
    with pytest.raises(ValueError, match="kind"):
        GpsFault("spoof", 0, 10)
    with pytest.raises(ValueError, match="duration_s"):
        GpsFault("jump", 0, 0)
    with pytest.raises(ValueError, match="overlap"):
        GpsModel(faults=(GpsFault("noise", 0, 60), GpsFault("outage", 59, 120)))
    with pytest.raises(ValueError, match="hacc"):
        GpsFault("noise", 0, 60, hacc="sometimes")
    with pytest.raises(ValueError, match="fraction"):
        GpsFault("lying", 0, 60, fraction=1.5)
    with pytest.raises(ValueError, match="GpsFault"):
        GpsModel(faults=({"kind": "jump"},))
    # back to back is fine: the paper's noisy minute right before a 2-minute outage
    GpsModel(faults=(GpsFault("noise", 0, 60), GpsFault("outage", 60, 120)))
