"""Magnetometer calibration (core.pdr.magcal.MagCalibrator, fit_ellipsoid) and trust (QuasiStaticField).

Synthetic data only, from a small generator here (core.quaternion; not the
desktop simulator): a phone's attitude sequence, the Earth's field
``h_n = F (sin az cos dip, cos az cos dip, -sin dip)`` seen in the body frame
as ``m_b = R(q)^T h_n``, distorted as ``m_raw = A^-1 m_b + b`` plus white
noise.  All randomness is seeded; the tolerances are stated in each test.
"""

import dataclasses
import math

import numpy as np
import pytest

from core import quaternion as quat
from core.pdr.magcal import (
    MAGCAL_STATES, QSF_REASONS, EllipsoidFitError, MagCalibrator, QuasiStaticField, fit_ellipsoid, fit_sphere,
)

RATE_HZ = 50.0
HARD_IRON_UT = np.array([20.0, -35.0, 12.0])
# a symmetric soft iron with axis gains 0.9-1.1 and cross terms (axis ratio about 1.27)
SOFT_IRON = np.array([[1.10, 0.05, -0.03], [0.05, 0.92, 0.04], [-0.03, 0.04, 1.00]])
FIELD_UT = 48.0
DIP_DEG = 63.0


# ---------------------------------------------------------------------------
# synthetic generator


def field_n(field_uT=FIELD_UT, dip_deg=DIP_DEG, azimuth_deg=0.0):
    """Earth's field in ENU: magnetic north ``azimuth_deg`` east of +y, pointing down by ``dip_deg``."""
    d, a = math.radians(dip_deg), math.radians(azimuth_deg)
    return field_uT * np.array([math.sin(a) * math.cos(d), math.cos(a) * math.cos(d), -math.sin(d)])


def attitudes(rng, duration_s, omega_rad_s=2.0, axis=None, rate_hz=RATE_HZ, t0_ns=5_000_000_000):
    """``t_ns`` (n,), ``q`` (n, 4): a smooth random tumble (body rate a random walk of about
    ``omega_rad_s``), or a constant rotation about one body ``axis``."""
    n = int(round(duration_s * rate_hz))
    dt = 1.0 / rate_hz
    w = rng.normal(size=3) * omega_rad_s
    q = (1.0, 0.0, 0.0, 0.0)
    out = np.empty((n, 4))
    for i in range(n):
        out[i] = q
        if axis is None:
            w = 0.98 * w + rng.normal(size=3) * 0.2 * omega_rad_s
        else:
            w = np.asarray(axis, dtype=float) * omega_rad_s
        angle = float(np.linalg.norm(w)) * dt
        if angle > 0:
            q = quat.normalize(quat.multiply(q, quat.from_axis_angle(tuple(w), angle)))
    t_ns = t0_ns + np.round(np.arange(n) * dt * 1e9).astype(np.int64)
    return t_ns, out


def body_field(q, h_n):
    """``R(q)^T h_n`` for every quaternion (n, 4); ``h_n`` (3,) or (n, 3)."""
    r = quat.to_matrix_array(q)
    return np.einsum("nji,nj->ni", r, np.broadcast_to(h_n, (len(q), 3)))


def raw_readings(rng, m_b, noise_uT=0.4, soft_iron=SOFT_IRON, hard_iron=HARD_IRON_UT):
    return m_b @ np.linalg.inv(soft_iron).T + hard_iron + rng.normal(scale=noise_uT, size=m_b.shape)


def normalised(soft_iron):
    """The soft iron scaled to det 1 and the field it implies (the fit's convention)."""
    c = np.linalg.det(soft_iron) ** (1.0 / 3.0)
    return soft_iron / c, FIELD_UT / c


def tumbling_recording(seed, duration_s=60.0, noise_uT=0.4):
    rng = np.random.default_rng(seed)
    t, q = attitudes(rng, duration_s)
    return t, raw_readings(rng, body_field(q, field_n()), noise_uT=noise_uT)


def _astuple_equal(a, b):
    np.testing.assert_equal(dataclasses.astuple(a), dataclasses.astuple(b))  # NaN == NaN here


# ---------------------------------------------------------------------------
# fit_ellipsoid / fit_sphere (pure)


def test_fit_ellipsoid_recovers_hard_and_soft_iron():
    """Full tumble, 0.4 uT noise, 3000 samples: offset within 0.2 uT per axis, the det-1 soft iron within
    0.01 per entry, the field within 0.2 uT and the residual equal to the noise (0.3-0.5 uT)."""
    _, raw = tumbling_recording(1)
    offset, a, field, resid = fit_ellipsoid(raw)
    a_true, f_true = normalised(SOFT_IRON)
    np.testing.assert_allclose(offset, HARD_IRON_UT, atol=0.2)
    np.testing.assert_allclose(a, a_true, atol=0.01)
    np.testing.assert_allclose(a, a.T, atol=1e-12)
    assert np.linalg.det(a) == pytest.approx(1.0, abs=1e-9)
    assert field == pytest.approx(f_true, abs=0.2)
    assert 0.3 < resid < 0.5
    # the calibrated readings lie on a sphere of radius field
    norms = np.linalg.norm((raw - offset) @ a.T, axis=1)
    assert np.std(norms) < 0.5


def test_fit_ellipsoid_is_exact_without_noise_and_ignores_non_finite_rows():
    """Noise-free data give the model back to 1e-6; NaN/inf rows are dropped, not propagated."""
    rng = np.random.default_rng(2)
    _, q = attitudes(rng, 20.0)
    raw = raw_readings(rng, body_field(q, field_n()), noise_uT=0.0)
    raw[5] = np.nan
    raw[17, 1] = np.inf
    offset, a, field, resid = fit_ellipsoid(raw)
    a_true, f_true = normalised(SOFT_IRON)
    np.testing.assert_allclose(offset, HARD_IRON_UT, atol=1e-6)
    np.testing.assert_allclose(a, a_true, atol=1e-8)
    assert field == pytest.approx(f_true, abs=1e-6)
    assert resid < 1e-6


def test_fit_sphere_recovers_hard_iron_without_soft_iron():
    """Hard iron only, 0.4 uT noise: offset within 0.2 uT, field within 0.2 uT, identity soft iron."""
    rng = np.random.default_rng(3)
    _, q = attitudes(rng, 60.0)
    raw = raw_readings(rng, body_field(q, field_n()), soft_iron=np.eye(3))
    offset, a, field, resid = fit_sphere(raw)
    np.testing.assert_allclose(offset, HARD_IRON_UT, atol=0.2)
    np.testing.assert_array_equal(a, np.eye(3))
    assert field == pytest.approx(FIELD_UT, abs=0.2)
    assert resid < 0.5


def test_fit_ellipsoid_refuses_too_few_or_coplanar_samples():
    """Fewer than 9 samples, or samples on one circle (rotation about one axis, no noise), determine no ellipsoid."""
    with pytest.raises(EllipsoidFitError, match="too few"):
        fit_ellipsoid(np.random.default_rng(4).normal(size=(8, 3)) * 40)
    rng = np.random.default_rng(4)
    _, q = attitudes(rng, 20.0, omega_rad_s=1.0, axis=(0.0, 0.0, 1.0))
    ring = body_field(q, field_n()) + HARD_IRON_UT
    with pytest.raises(EllipsoidFitError):
        fit_ellipsoid(ring)


# ---------------------------------------------------------------------------
# MagCalibrator


def test_calibrator_recovers_hard_and_soft_iron_from_a_tumble():
    """60 s of tumbling at 50 Hz with 0.4 uT noise: calibrated with the full model; offset within 0.3 uT
    per axis, soft iron (det 1) within 0.015 per entry, field within 0.3 uT; the calibrated readings of the
    whole recording have a norm std below 0.5 uT (raw: several uT)."""
    t, raw = tumbling_recording(5)
    cal = MagCalibrator()
    trace = cal.run(t, raw)
    st = cal.status
    assert st.state == "calibrated"
    assert st.reason == "accepted" or st.reason.startswith("kept"), st.reason
    assert st.model == "hard+soft iron"
    a_true, f_true = normalised(SOFT_IRON)
    np.testing.assert_allclose(st.offset_uT, HARD_IRON_UT, atol=0.3)
    np.testing.assert_allclose(np.array(st.soft_iron), a_true, atol=0.015)
    assert st.field_uT == pytest.approx(f_true, abs=0.3)
    assert st.residual_uT < 0.02 * st.field_uT
    assert st.coverage >= cal.min_coverage and st.fit_coverage >= cal.min_coverage_soft_iron
    assert st.n_valid == len(t) and st.n_invalid == 0
    assert st.n_samples <= cal.n_bins * cal.samples_per_bin
    # the first fit comes within the recording, well before its end
    assert 0 < (st.t_first_fit_ns - t[0]) * 1e-9 < 40.0
    cal_all = cal.apply(raw)
    assert np.std(np.linalg.norm(cal_all, axis=1)) < 0.5
    assert np.std(np.linalg.norm(raw, axis=1)) > 5.0
    # the streamed output switches from identity to the calibration at the first fit
    first = int(np.argmax(trace.fit_index > 0))
    np.testing.assert_array_equal(trace.mag_cal_b[:first], raw[:first])
    assert len(trace.fits) == st.n_accepted and trace.fits[0].t_fit_ns == st.t_first_fit_ns


def test_refits_are_rate_limited():
    """At most one fit attempt per refit_interval_s: 60 s of tumbling gives at most 60 fits (one kernel call
    per sample otherwise costs a few dozen float operations)."""
    t, raw = tumbling_recording(6)
    cal = MagCalibrator(refit_interval_s=1.0)
    cal.run(t, raw)
    assert cal.status.n_fits <= 60


@pytest.mark.parametrize("axis", [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.3, 0.2, 0.93)])
def test_rotation_about_one_axis_gives_no_fit_and_says_why(axis):
    """Turning the phone about one body axis only (60 s, 1 rad/s, 0.4 uT noise) cannot determine the offset
    along that axis: no fit is accepted, apply() stays the identity, and the reason names the coverage."""
    rng = np.random.default_rng(7)
    t, q = attitudes(rng, 60.0, omega_rad_s=1.0, axis=np.array(axis) / np.linalg.norm(axis))
    raw = raw_readings(rng, body_field(q, field_n()))
    cal = MagCalibrator()
    cal.run(t, raw)
    st = cal.status
    assert st.state in ("collecting", "rejected fit") and st.state in MAGCAL_STATES
    assert st.n_accepted == 0 and not cal.calibrated
    assert st.reason.startswith("coverage"), st.reason
    assert st.coverage < cal.min_coverage
    assert math.isnan(st.field_uT)
    np.testing.assert_array_equal(cal.apply(raw[:10]), raw[:10])


def _wobbling(spin_axis, spin_rad_s, wobble_axes, wobble_deg, duration_s=60.0):
    """Attitudes spinning about a (nav-frame) axis while wobbling about body axes by +-wobble_deg."""
    n = int(duration_s * RATE_HZ)
    s = np.arange(n) / RATE_HZ
    q = np.empty((n, 4))
    for i, si in enumerate(s):
        w = (1.0, 0.0, 0.0, 0.0)
        for k, ax in enumerate(wobble_axes):
            angle = math.radians(wobble_deg) * math.sin((0.9 + 0.4 * k) * si + k)
            w = quat.multiply(w, quat.from_axis_angle(ax, angle))
        q[i] = quat.multiply(quat.from_axis_angle(spin_axis, spin_rad_s * si), w)
    return 5_000_000_000 + np.round(s * 1e9).astype(np.int64), q


def test_phone_held_flat_while_walking_gives_no_fit():
    """Like the ETH walk: the phone held flat turns with the walker (0.5 rad/s about the vertical) and tilts
    +-25 deg about both horizontal body axes: the offset along the screen normal is not observable, and the
    directions cover less than min_coverage (0.4) -- no fit, 'coverage' given as the reason."""
    rng = np.random.default_rng(17)
    t, q = _wobbling((0.0, 0.0, 1.0), 0.5, [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)], 25.0)
    raw = raw_readings(rng, body_field(q, field_n()), soft_iron=np.eye(3))
    cal = MagCalibrator()
    cal.run(t, raw)
    assert cal.status.n_accepted == 0 and cal.status.reason.startswith("coverage"), cal.status.reason
    assert cal.status.coverage < 0.3


def test_directions_close_to_one_plane_are_rejected_by_the_spread_bound():
    """Spinning about the body x axis (1 rad/s) with a +-15 deg wobble about z, horizontal field: the
    directions form a band about one great circle that fills > 40 % of the bins, but their spread across
    the band (about 0.18) is below min_direction_spread = 0.25 -- rejected; without the bound a fit with a
    field 3.5 uT too weak would be accepted."""
    rng = np.random.default_rng(18)
    t, _ = _still(60.0)
    # the wobble about the vertical, then the spin about the body x axis
    q = np.array([quat.multiply(quat.from_axis_angle((0.0, 0.0, 1.0), math.radians(15.0) * math.sin(0.9 * si)),
                                quat.from_axis_angle((1.0, 0.0, 0.0), 1.0 * si))
                  for si in (t - t[0]) * 1e-9])
    raw = raw_readings(rng, body_field(q, field_n(dip_deg=0.0)), soft_iron=np.eye(3))
    cal = MagCalibrator()
    cal.run(t, raw)
    st = cal.status
    assert st.n_accepted == 0 and st.reason.startswith("direction spread"), st.reason
    assert st.coverage >= cal.min_coverage
    loose = MagCalibrator(min_direction_spread=0.0)
    loose.run(t, raw)
    assert loose.status.state == "calibrated" and abs(loose.status.field_uT - FIELD_UT) > 2.0


def test_still_phone_collects_without_fitting():
    """A phone at rest for 30 s: nothing to fit, the state stays 'collecting'."""
    rng = np.random.default_rng(8)
    t = 5_000_000_000 + np.arange(1500) * 20_000_000
    raw = np.tile(field_n() + HARD_IRON_UT, (1500, 1)) + rng.normal(scale=0.4, size=(1500, 3))
    cal = MagCalibrator()
    cal.run(t, raw)
    assert cal.status.state == "collecting" and cal.status.n_fits == 0


def test_field_outside_the_geomagnetic_range_is_rejected():
    """A clean tumble in a 120 uT field (next to a magnet) fits well but is no geomagnetic field."""
    rng = np.random.default_rng(9)
    t, q = attitudes(rng, 40.0)
    raw = raw_readings(rng, body_field(q, field_n(field_uT=120.0)), soft_iron=np.eye(3))
    cal = MagCalibrator()
    cal.run(t, raw)
    assert cal.status.state == "rejected fit" and cal.status.n_accepted == 0
    assert cal.status.reason.startswith("field 12") and "outside 20-70" in cal.status.reason


def test_strong_soft_iron_is_rejected_by_the_axis_ratio_bound():
    """Axis gains 1.5 / 0.8 (ratio 1.9) exceed max_axis_ratio = 1.3; allowing 2.0 accepts the same data."""
    rng = np.random.default_rng(10)
    t, q = attitudes(rng, 60.0)
    soft = np.diag([1.5, 1.0, 0.8])
    raw = raw_readings(rng, body_field(q, field_n()), soft_iron=soft)
    cal = MagCalibrator()
    cal.run(t, raw)
    assert cal.status.n_accepted == 0 and cal.status.reason.startswith("axis ratio")
    loose = MagCalibrator(max_axis_ratio=2.0)
    loose.run(t, raw)
    assert loose.status.state == "calibrated"
    np.testing.assert_allclose(np.array(loose.status.soft_iron), normalised(soft)[0], atol=0.02)


def test_noisy_fit_is_rejected_by_the_residual_bound():
    """5 uT noise on a 48 uT field (10 %) exceeds max_residual_fraction = 6 %."""
    t, raw = tumbling_recording(11, noise_uT=5.0)
    cal = MagCalibrator(outlier_fraction=1.0)
    cal.run(t, raw)
    assert cal.status.n_accepted == 0 and cal.status.reason.startswith("residual"), cal.status.reason


def test_calibration_follows_a_jump_of_the_offset():
    """After a calibrated minute the offset jumps by (15, 0, -10) uT (an OS recalibration, a magnet in a case)
    while the tumbling goes on: within 30 s the calibration follows to within 0.5 uT."""
    rng = np.random.default_rng(12)
    t, q = attitudes(rng, 90.0)
    m_b = body_field(q, field_n())
    raw = raw_readings(rng, m_b, soft_iron=np.eye(3))
    jump = np.array([15.0, 0.0, -10.0])
    k = int(60 * RATE_HZ)
    raw[k:] += jump
    cal = MagCalibrator()
    cal.run(t[:k], raw[:k])
    np.testing.assert_allclose(cal.status.offset_uT, HARD_IRON_UT, atol=0.5)
    cal.run(t[k:], raw[k:])
    np.testing.assert_allclose(cal.status.offset_uT, HARD_IRON_UT + jump, atol=0.5)


def test_nan_and_inf_are_skipped_and_counted():
    """12 broken readings (NaN, +-inf, a 1e6 uT spike) among 3000: all counted in n_invalid, returned
    non-finite or unchanged-through-the-calibration, and the calibration equals the clean run's within 0.05 uT."""
    t, raw = tumbling_recording(13)
    bad = raw.copy()
    idx = np.arange(100, 3000, 250)[:12]
    for j, i in enumerate(idx):
        bad[i] = [(np.nan, 1.0, 2.0), (np.inf, 0.0, 0.0), (0.0, -np.inf, 3.0), (1e6, 0.0, 0.0)][j % 4]
    clean = MagCalibrator()
    clean.run(np.delete(t, idx), np.delete(raw, idx, axis=0))
    cal = MagCalibrator()
    trace = cal.run(t, bad)
    st = cal.status
    assert st.n_invalid == len(idx) and st.n_valid == len(t) - len(idx)
    assert st.state == "calibrated"
    np.testing.assert_allclose(st.offset_uT, clean.status.offset_uT, atol=0.05)
    np.testing.assert_allclose(np.array(st.soft_iron), np.array(clean.status.soft_iron), atol=0.002)
    nonfinite = ~np.all(np.isfinite(bad[idx]), axis=1)
    assert not np.any(np.all(np.isfinite(trace.mag_cal_b[idx[nonfinite]]), axis=1))
    good = np.ones(len(t), dtype=bool)
    good[idx] = False
    assert np.all(np.isfinite(trace.mag_cal_b[good]))


def test_batch_equals_streaming_in_chunks_of_any_size():
    """update() sample by sample, run() on the whole stream and run() on random chunks (1-400 samples) give
    bit-identical outputs and statuses."""
    t, raw = tumbling_recording(14, duration_s=50.0)
    raw[333] = np.nan
    stream = MagCalibrator()
    out = np.array([stream.update(int(ti), *mi) for ti, mi in zip(t, raw)])
    whole = MagCalibrator().run(t, raw)
    chunked = MagCalibrator()
    rng = np.random.default_rng(15)
    parts, fit_idx, fits, i = [], [], [], 0
    while i < len(t):
        n = int(rng.integers(1, 400))
        tr = chunked.run(t[i:i + n], raw[i:i + n])
        parts.append(tr.mag_cal_b)
        fit_idx.append(tr.fit_index)
        fits.extend(tr.fits)
        i += n
    np.testing.assert_array_equal(out, whole.mag_cal_b)
    np.testing.assert_array_equal(np.concatenate(parts), whole.mag_cal_b)
    np.testing.assert_array_equal(np.concatenate(fit_idx), whole.fit_index)
    assert stream.status.state == "calibrated"
    _astuple_equal(stream.status, whole.status)
    _astuple_equal(chunked.status, whole.status)
    assert len(fits) == len(whole.fits)
    for a, b in zip(fits, whole.fits):
        _astuple_equal(a, b)


def test_status_is_frozen_data_and_reset_forgets():
    t, raw = tumbling_recording(16, duration_s=40.0)
    cal = MagCalibrator()
    cal.run(t, raw)
    st = cal.status
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.state = "x"
    assert st.state == "calibrated"
    cal.reset()
    assert cal.status.state == "collecting" and cal.status.n_valid == 0 and not cal.calibrated
    np.testing.assert_array_equal(cal.apply(raw[:3]), raw[:3])


# ---------------------------------------------------------------------------
# QuasiStaticField


def _still(duration_s, q=(1.0, 0.0, 0.0, 0.0), t0_ns=5_000_000_000):
    n = int(round(duration_s * RATE_HZ))
    return t0_ns + np.round(np.arange(n) / RATE_HZ * 1e9).astype(np.int64), np.tile(q, (n, 1))


def _drifting(q_true, t_ns, yaw_rate_deg_s=0.5, roll_rate_deg_s=0.02):
    """The gyro-propagated estimate: the true attitude turned by a slowly growing error, mostly in yaw
    (gravity bounds the tilt error of an attitude filter, nothing bounds its yaw)."""
    dt = (t_ns - t_ns[0]) * 1e-9
    out = np.empty_like(q_true)
    for i, (qi, s) in enumerate(zip(q_true, dt)):
        err = quat.multiply(quat.from_axis_angle((0.0, 0.0, 1.0), math.radians(yaw_rate_deg_s) * s),
                            quat.from_axis_angle((1.0, 0.0, 0.0), math.radians(roll_rate_deg_s) * s))
        out[i] = quat.multiply(err, tuple(qi))
    return out


def test_steady_field_under_a_rotating_phone_with_drifting_gyro_attitude_is_trusted():
    """Phone tumbling at about 1 rad/s for 30 s, 0.3 uT noise, gyro attitude drifting 0.5 deg/s in yaw and
    0.02 deg/s in roll: after the 0.75 s window and the 2 s reference warm-up, >= 98 % of readings are trusted
    ('steady'), and the learnt reference is the field (within 0.3 uT, 1 deg)."""
    rng = np.random.default_rng(20)
    t, q = attitudes(rng, 30.0, omega_rad_s=1.0)
    m_b = body_field(q, field_n()) + rng.normal(scale=0.3, size=(len(t), 3))
    qsf = QuasiStaticField()
    tr = qsf.run(t, m_b, _drifting(q, t))
    after = (t - t[0]) * 1e-9 > 3.0
    assert np.mean(tr.trusted[after]) >= 0.98
    assert set(tr.reason[after]) <= {"steady", "direction moving", "norm moving"}
    assert set(tr.reason) <= set(QSF_REASONS)
    assert np.all(tr.reason[(t - t[0]) * 1e-9 < 0.7] == "warming up")
    st = qsf.status
    assert st.reference_field_uT == pytest.approx(FIELD_UT, abs=0.3)
    assert st.reference_dip_deg == pytest.approx(DIP_DEG, abs=1.0)
    assert np.all(tr.dir_spread_deg[after] < 2.5)


def test_turning_field_under_a_still_phone_is_not_quasi_static():
    """Phone still; the field is steady for 5 s, then its azimuth turns at 20 deg/s for 5 s (a magnet going
    by; at a dip of 63 deg the direction turns 9 deg/s): once the 0.75 s window holds the turn, no reading is
    trusted, the reason is 'direction moving' and the spread is above 3 deg."""
    rng = np.random.default_rng(21)
    t, q = _still(10.0)
    s = (t - t[0]) * 1e-9
    az = np.where(s < 5.0, 0.0, 20.0 * (s - 5.0))
    h = np.array([field_n(azimuth_deg=a) for a in az])
    m_b = body_field(q, h) + rng.normal(scale=0.3, size=(len(t), 3))
    tr = QuasiStaticField().run(t, m_b, q)
    assert np.mean(tr.trusted[(s > 3.0) & (s < 5.0)]) == 1.0
    turning = s > 5.75
    assert not np.any(tr.trusted[turning])
    assert np.all(tr.reason[turning] == "direction moving")
    assert np.all(tr.dir_spread_deg[turning] > 3.0)


def test_field_strength_step_is_flagged_moving_then_off():
    """Steady 48 uT for 6 s, then 36 uT (same direction): while the window spans the step, 'norm moving';
    afterwards the field is steady again but 12 uT from the learnt reference, 'norm off' (checked for 4 s)."""
    rng = np.random.default_rng(22)
    t, q = _still(12.0)
    s = (t - t[0]) * 1e-9
    h = np.where((s < 6.0)[:, None], field_n(), field_n(field_uT=36.0))
    m_b = body_field(q, h) + rng.normal(scale=0.3, size=(len(t), 3))
    tr = QuasiStaticField().run(t, m_b, q)
    assert np.all(tr.trusted[(s > 3.0) & (s < 6.0)])
    spans = (s >= 6.0) & (s < 6.7)
    assert np.all(tr.reason[spans] == "norm moving") and not np.any(tr.trusted[spans])
    after = (s > 6.8) & (s < 10.8)
    assert np.all(tr.reason[after] == "norm off") and np.all(tr.steady[after])
    assert np.all(np.abs(tr.norm_uT[after] - 36.0) < 0.3)


def test_dip_change_is_flagged_dip_off():
    """Same norm, dip 63 -> 45 deg: after the window, steady but 'dip off' (18 deg > 10 deg)."""
    rng = np.random.default_rng(23)
    t, q = _still(10.0)
    s = (t - t[0]) * 1e-9
    h = np.where((s < 5.0)[:, None], field_n(), field_n(dip_deg=45.0))
    m_b = body_field(q, h) + rng.normal(scale=0.3, size=(len(t), 3))
    tr = QuasiStaticField().run(t, m_b, q)
    after = (s > 5.8) & (s < 9.0)
    assert np.all(tr.reason[after] == "dip off")
    assert np.all(np.abs(tr.dip_deg[after] - 45.0) < 1.0)


def test_fixed_reference_and_set_reference():
    """A given reference is used from the first full window (no learning warm-up) and never drifts."""
    rng = np.random.default_rng(24)
    t, q = _still(5.0)
    m_b = body_field(q, field_n(field_uT=40.0)) + rng.normal(scale=0.3, size=(len(t), 3))
    tr = QuasiStaticField(reference_field_uT=48.0, reference_dip_deg=63.0).run(t, m_b, q)
    s = (t - t[0]) * 1e-9
    assert np.all(tr.reason[s > 0.8] == "norm off")
    qsf = QuasiStaticField()
    qsf.set_reference(field_uT=40.0, dip_deg=63.0)
    tr = qsf.run(t, m_b, q)
    assert np.all(tr.trusted[s > 0.8])
    assert qsf.status.reference_field_uT == 40.0


def test_qsf_invalid_input_and_gaps():
    """NaN readings or quaternions are 'invalid input' (counted); a gap > max_gap_s restarts the window."""
    rng = np.random.default_rng(25)
    t, q = _still(8.0)
    m_b = body_field(q, field_n()) + rng.normal(scale=0.3, size=(len(t), 3))
    m_b[150] = np.nan
    q = q.copy()
    q[160] = np.nan
    t = t.copy()
    t[250:] += 2_000_000_000  # a 2 s gap at sample 250
    qsf = QuasiStaticField()
    tr = qsf.run(t, m_b, q)
    assert tr.reason[150] == "invalid input" and tr.reason[160] == "invalid input"
    assert qsf.status.n_invalid == 2
    assert tr.trusted[170]
    assert np.all(tr.reason[250:250 + 35] == "warming up")
    assert np.all(tr.trusted[250 + 40:])


def test_qsf_batch_equals_streaming_in_chunks():
    """update() per reading, run() whole and run() in random chunks (1-300) give identical traces."""
    rng = np.random.default_rng(26)
    t, q = attitudes(rng, 20.0, omega_rad_s=1.0)
    s = (t - t[0]) * 1e-9
    h = np.array([field_n(azimuth_deg=0.0 if x < 10 else 30.0 * (x - 10)) for x in s])
    m_b = body_field(q, h) + rng.normal(scale=0.3, size=(len(t), 3))
    m_b[77] = np.inf
    qe = _drifting(q, t)
    stream = QuasiStaticField()
    sts = [stream.update(int(ti), mi, qi) for ti, mi, qi in zip(t, m_b, qe)]
    whole = QuasiStaticField().run(t, m_b, qe)
    assert [x.reason for x in sts] == whole.reason.tolist()
    np.testing.assert_array_equal([x.dir_spread_deg for x in sts], whole.dir_spread_deg)
    chunked = QuasiStaticField()
    traces, i = [], 0
    while i < len(t):
        n = int(rng.integers(1, 300))
        traces.append(chunked.run(t[i:i + n], m_b[i:i + n], qe[i:i + n]))
        i += n
    for name in ("trusted", "steady", "reason", "dir_spread_deg", "norm_spread_uT", "norm_uT", "dip_deg"):
        np.testing.assert_array_equal(np.concatenate([getattr(x, name) for x in traces]), getattr(whole, name))
    _astuple_equal(chunked.status, whole.status)
    assert {"steady", "direction moving", "warming up", "invalid input"} <= set(whole.reason)


def test_fast_path_entry_points_state_and_restore_state():
    """The desktop fast path's way in and out (``kernel_settings``, ``state``, ``restore_state``): ``state`` gives
    the run state a further update starts from, ``restore_state`` puts it into another calibrator (which then goes
    on as the first does, reading for reading) and refuses a setting, what reset derives from them, an unknown
    name and a store of another size (instead of the fast path writing the private fields)."""
    from array import array

    t, m = tumbling_recording(21, duration_s=12.0)
    a, b = MagCalibrator(), MagCalibrator()
    for ti, row in zip(t[:400].tolist(), m[:400].tolist()):
        a.update(ti, *row)
    st = a.state()
    assert {"_slot_t", "_bin_count", "_centre", "_recent", "_t_prev", "n_valid"} <= set(st)
    assert not {"_r_min", "_max_nrm2", "min_samples", "n_bins"} & set(st)
    assert b.kernel_settings == a.kernel_settings and a.kernel_settings["r_min_uT"] == 5.0
    assert a.kernel_settings["recent_dt_ns"] == 100_000_000
    b.restore_state({k: (v[:] if isinstance(v, (array, list)) else v) for k, v in st.items()})  # copies: own store
    for ti, row in zip(t[400:].tolist(), m[400:].tolist()):
        assert a.update(ti, *row) == b.update(ti, *row)
    assert a.status == b.status and a.n_accepted >= 1
    for bad in ({"min_samples": 9}, {"_r_min": 1.0}, {"_no_such_state": 1}):
        with pytest.raises(AttributeError):
            b.restore_state(bad)
    with pytest.raises(ValueError):
        b.restore_state({"_bin_count": [0] * 3})
    assert b.min_samples == 30 and b.kernel_settings == a.kernel_settings


def test_attempt_and_apply_tuple_are_public():
    """``attempt`` (what ``update`` calls when a fit is due; the fast path calls it where its kernel hands over) and
    ``apply_tuple`` (the calibrated reading on floats): an attempt on a tumble's store accepts a fit, and
    ``apply_tuple`` then equals ``apply``."""
    t, m = tumbling_recording(22, duration_s=8.0)
    cal = MagCalibrator(refit_interval_s=1e9)  # update never attempts
    for ti, row in zip(t.tolist(), m.tolist()):
        cal.update(ti, *row)
    assert cal.n_fits == 0 and cal.apply_tuple(1.0, 2.0, 3.0) == (1.0, 2.0, 3.0)
    cal.attempt(int(t[-1]))
    assert cal.calibrated and cal.n_fits == 1 and cal.status.reason == "accepted"
    assert np.allclose(cal.apply_tuple(*m[0].tolist()), cal.apply(m[0]), rtol=0, atol=1e-12)
