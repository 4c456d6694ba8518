"""The attitude EKF over a whole recording as one compiled loop: a second implementation of
:class:`core.pdr.attitude.AttitudeEKF`.

Deliberately a second implementation (issue #13 item 3): the phone's filter
(``core/pdr/attitude.py``) stays the reference, and this kernel is checked
against it to 1e-9 on real recordings (``tests/test_fast_path.py``).  It
re-implements, on numpy arrays and scalars so that numba can compile it, what
the reference does after its start:

* the gyroscope prediction, eqs. 5-7 and 11 of Tian et al. 2014, with the bias
  removed (``q <- q (x) exp((w - b) T / 2)``, ``P <- F P F^T + Q`` on the
  covariance's blocks in the reference's order of operations);
* the accelerometer direction update, eqs. 12-13 with the adaptive noise of
  eq. 17 (and the turn term), averaged over ``update_interval_s``;
* the magnetometer heading update, eq. 18's noise, as a consider (Schmidt)
  update with the Joseph form, and its relock;
* the field's heading offset, a Gauss-Markov 7th error state when
  ``mag_offset_sd_rad > 0`` (the covariance ``P`` is 7 x 7 then, 6 x 6 else);
* the zero-rate update, the running references (|g|, |h|, dip) and the
  trailing windows (noise variances, stillness);
* the vertical hard-iron offset from an outdoor site's field (the WMM
  strength and dip a GPS fix gives, ``set_site_field``), and a site's
  settings changed between two events (:meth:`KernelState.new_settings`: the
  pipeline's ``apply_site`` at its first anchoring fix).

What it does not re-implement, and why:

* the start (TRIAD from the first accelerometer and magnetometer readings, or
  gravity and ``initial_yaw_rad``): a handful of events, run by the reference
  itself (:func:`start_with_reference`), whose state is then handed over;
* the online magnetometer calibration (:class:`core.pdr.magcal.MagCalibrator`,
  ellipsoid fits): it sees only the raw readings, never the attitude, so it is
  run over the magnetometer stream beforehand (:func:`calibrate_magnetometer`:
  its per-reading part compiled, its fits core's Python) and the kernel gets the
  calibrated readings;
* the quasi-static field detector and ``mag_mode="full"``: not used by the
  default pipeline; the fast path refuses a filter configured with them
  (:func:`check_supported`);
* the replay heading smoother (``Pipeline(heading_smoother="rts" | "start")``,
  :mod:`core.pdr.heading_smoother`, issue #27): it needs the forward run's history
  (the filter's ``keep_history``, ``start_heading``), which the kernel does not keep;
  refused, so ``--engine auto`` runs the reference and says why.  Not mirrored on
  purpose: it is off by default and the live app never runs it.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np

from core.pdr.attitude import CHI2_1_MEDIAN, AttitudeSettings, AttitudeState, IntervalSum, Outcome
from desktop.fast.jit import kernel, kernel_or
from desktop.fast.magcal import calibrate_stream

# event kinds of the merged arrays
GYRO_K, ACC_K, MAG_K = 0, 1, 2

#: the outcomes of a reading (core's Outcome) the kernel gives, by code; AttitudeEKF.acc_reasons / mag_reasons
#: count their text
ACC_OUTCOMES = (Outcome.USED, Outcome.INITIALISING, Outcome.NORM_OFF, Outcome.PENDING, Outcome.GATE, Outcome.NUMERICAL)
MAG_OUTCOMES = (Outcome.USED, Outcome.INITIALISING, Outcome.INVALID_RANGE, Outcome.NORM_OFF, Outcome.DIP_OFF,
                Outcome.GATE, Outcome.NUMERICAL, Outcome.FIELD_VERTICAL, Outcome.CALIBRATING, Outcome.MAGNETOMETER_OFF)
ACC_REASONS = tuple(o.value for o in ACC_OUTCOMES)
MAG_REASONS = tuple(o.value for o in MAG_OUTCOMES)
A_USED, A_NORM, A_PENDING, A_GATE, A_NUM = (ACC_OUTCOMES.index(o) for o in (
    Outcome.USED, Outcome.NORM_OFF, Outcome.PENDING, Outcome.GATE, Outcome.NUMERICAL))
M_USED, M_RANGE, M_NORM, M_DIP, M_GATE, M_NUM, M_VERTICAL, M_CALIBRATING, M_OFF = (MAG_OUTCOMES.index(o) for o in (
    Outcome.USED, Outcome.INVALID_RANGE, Outcome.NORM_OFF, Outcome.DIP_OFF, Outcome.GATE, Outcome.NUMERICAL,
    Outcome.FIELD_VERTICAL, Outcome.CALIBRATING, Outcome.MAGNETOMETER_OFF))
C_USED, C_GATE, C_NUM = 0, 1, 2

# -- the slot tables: derived from the fields of core's settings and state ---------------------------
#
# Every field of AttitudeSettings and of AttitudeState says here how the kernel gets it; the slot numbers
# follow the fields' order.  A field added to either dataclass and not named here fails at import (below),
# instead of drifting until tests/test_fast_path.py finds a 1e-9 difference.

#: how each setting reaches the kernel: "f" a slot of the float array, "ns" a period in ns of the int array
#: (or "ns/hz": the period of a rate), "i" the int array, "range" two float slots (its low and high ends);
#: or why the kernel needs none
SETTINGS_USE = {
    "gyro_noise_rad_sqrt_s": "f", "gyro_scale_noise_sqrt_s": "f", "gyro_bias_walk_rad_s_sqrt_s": "f",
    "gyro_bias_sd_rad_s": "the start (the reference's)", "max_gyro_bias_rad_s": "f",
    "initial_tilt_sd_rad": "the start (the reference's)", "initial_yaw_sd_rad": "the start (the reference's)",
    "update_interval_s": "f", "swing_rate_rad_s": "f", "swing_rate_time_s": "f", "swing_update_interval_s": "f",
    "swing_min_s": "f", "acc_noise_base": "f", "k_a1": "f", "k_a2": "f", "k_a3": "f", "mag_noise_base": "f",
    "k_m1": "f", "k_m2": "f", "variance_window_s": "ns", "acc_reject_m_s2": "f", "acc_gate_nis": "f",
    "mag_mode": "refused unless 'heading' (check_supported)",
    "mag_unsteady_noise_scale": "used with a field detector only (refused by check_supported)",
    "mag_requires_calibration": "i", "mag_reject_ratio": "f", "mag_reject_dip_rad": "f", "mag_valid_range_uT": "range",
    "mag_gate_nis": "f", "mag_relock_s": "f", "mag_relock_spread_rad": "f", "reference_update_s": "ns",
    "reference_still_rate_hz": "ns/hz", "declination_rad": "f", "site_field_uT": "f", "site_dip_rad": "f",
    "vertical_offset_dip_error_rad": "f", "vertical_offset_norm_error": "f", "vertical_offset_min_s": "f",
    "vertical_offset_ridge": "f", "initial_yaw_rad": "the start (the reference's)", "use_magnetometer": "i",
    "mag_wait_s": "the start (the reference's)", "still_window_s": "ns", "still_acc_sd_m_s2": "f",
    "still_acc_direction_rad": "f", "still_gyro_sd_rad_s": "f", "zero_rate_noise_rad_s": "f",
    "max_gyro_gap_s": "f", "no_gyro_random_walk_rad_sqrt_s": "f", "noise_scale_rate": "f", "noise_scale_min": "f",
    "mag_offset_sd_rad": "f", "mag_offset_time_s": "f", "unobserved_bias_swing_rate_rad_s": "f",
}

#: how each field of AttitudeState reaches the kernel: "f" a slot of the float state array, "f3?" three float
#: slots and a has-flag (None), "sum" an IntervalSum (its floats in the float array, its ints in the int array),
#: "i" a slot of the int state array (bool as 0/1), "i?" a value and a has-flag (None), "vo"/"vo?" the same in
#: the vertical offset's int array; "own" arrays of its own (KernelState); or why the kernel needs none
STATE_USE = {
    "initialized": "true at the hand-over", "n_skipped_nonfinite": "the fast pipeline drops non-finite rows first",
    "t_ns": "i", "t_gyro_ns": "i?", "acc_reading": "f3?", "mag_reading": "the start (the reference's)",
    "first_acc_ns": "the start (the reference's)", "ref_next_ns": "i?", "refs": "own", "gravity_m_s2": "f",
    "field_uT": "f", "dip_rad": "f", "q": "own", "b": "own", "P_tt": "own", "P_tb": "own", "P_bt": "own",
    "P_bb": "own", "acc_var": "own", "mag_var": "own", "gyro_win": "own", "accdir_win": "own", "acc_norm_win": "own",
    "next_zero_rate_ns": "i?", "ref_still_next_ns": "i?", "vo_S": "own", "vo_r": "own", "vo_next_ns": "vo?",
    "vo_t0_ns": "vo?", "vo_active": "vo", "raw_dip_med": "own", "raw_norm_med": "own", "vertical_offset_uT": "own",
    "h_ref": "mag_mode='full' only (refused)", "alpha_ref": "f", "w2": "f", "w2_mean": "f", "swing_s": "f", "acc_sum": "sum", "mag_sum": "sum",
    "gated": "own", "n_heading_relocks": "i", "n_holes": "i", "hole_open": "i", "yaw_unobserved": "i", "acc_sigma2": "f", "mag_sigma2": "f",
    "mag_rejected": "i", "acc_rejected": "not kept by the kernel (the pipeline reads mag_rejected)",
    "last_acc": "one event's flags: not made by the kernel", "last_mag": "one event's flags: not made by the kernel",
    "mag_reasons": "own", "acc_reasons": "own", "n_gyro": "i", "n_zero_rate": "i", "n_numerical_rejects": "i",
    "nis_sum": "own", "nis_n": "own", "noise_scale": "f",
    "mag_offset_rad": "f", "P_to": "own (P's 7th column)", "P_bo": "own (P's 7th column)", "P_oo": "own (P's 7th column)",
}


def _check_covered(cls, use: dict) -> None:
    names = [f.name for f in fields(cls)]
    missing, extra = [n for n in names if n not in use], [n for n in use if n not in names]
    if missing or extra:
        raise ImportError(f"desktop.fast.attitude is out of step with core's {cls.__name__}: fields without a slot "
                          f"{missing}, slots without a field {extra} (say in SETTINGS_USE / STATE_USE how the kernel "
                          f"gets each one)")


_check_covered(AttitudeSettings, SETTINGS_USE)
_check_covered(AttitudeState, STATE_USE)
_SUM_FIELDS = [(f.name, f.type) for f in fields(IntervalSum)]
_STATE_TYPES = {f.name: f.type for f in fields(AttitudeState)}


def _numbered(names) -> dict:
    return {n: i for i, n in enumerate(names)}


#: slot numbers of the settings' float array (the float settings in their order, then the valid range's ends)
_SETTINGS = [f.name for f in fields(AttitudeSettings)]
SF = _numbered([n for n in _SETTINGS if SETTINGS_USE[n] == "f"] + ["mag_valid_range_uT.lo", "mag_valid_range_uT.hi"])
#: ... and of their int array
SI = _numbered([n for n in _SETTINGS if SETTINGS_USE[n] in ("i", "ns", "ns/hz")])
_fs, _is, _vo = [], [], []
for _name in _STATE_TYPES:
    _how = STATE_USE[_name]
    if _how == "f":
        _fs.append(_name)
    elif _how == "f3?":
        _fs += [f"{_name}.{k}" for k in range(3)]
        _is.append("has:" + _name)
    elif _how == "sum":
        _fs += [f"{_name}.{n}" for n, tp in _SUM_FIELDS if tp == "float"]
        _is += [f"{_name}.{n}" for n, tp in _SUM_FIELDS if tp == "int"]
    elif _how in ("i", "i?"):
        _is += [_name] + (["has:" + _name] if _how == "i?" else [])
    elif _how in ("vo", "vo?"):
        _vo += [_name] + (["has:" + _name] if _how == "vo?" else [])
#: slot numbers of the float state array, the int state array (plus the gated list's length) and the vertical
#: offset's int array
FS = _numbered(_fs)
IS = _numbered(_is + ["gated.n"])
VO = _numbered(_vo)
N_FSTATE, N_ISTATE = len(FS), len(IS)

# the names the kernel uses (module constants: numba compiles them in)
(S_GN, S_GS, S_BW, S_MAXB, S_UPD, S_A0, S_KA1, S_KA2, S_KA3, S_M0, S_KM1, S_KM2, S_ACC_REJ, S_ACC_GATE, S_MAG_RATIO,
 S_MAG_DIP, S_MAG_LO, S_MAG_HI, S_MAG_GATE, S_RELOCK_S, S_RELOCK_SPREAD, S_DECL, S_STILL_ACC_SD, S_STILL_DIR,
 S_STILL_GYRO, S_ZR_NOISE, S_MAX_GAP, S_NO_GYRO_RW, S_SITE_F, S_SITE_DIP, S_VO_DIP_ERR, S_VO_NORM_ERR, S_VO_MIN_S,
 S_VO_RIDGE) = (SF[n] for n in (
    "gyro_noise_rad_sqrt_s", "gyro_scale_noise_sqrt_s", "gyro_bias_walk_rad_s_sqrt_s", "max_gyro_bias_rad_s",
    "update_interval_s", "acc_noise_base", "k_a1", "k_a2", "k_a3", "mag_noise_base", "k_m1", "k_m2",
    "acc_reject_m_s2", "acc_gate_nis", "mag_reject_ratio", "mag_reject_dip_rad", "mag_valid_range_uT.lo",
    "mag_valid_range_uT.hi", "mag_gate_nis", "mag_relock_s", "mag_relock_spread_rad", "declination_rad",
    "still_acc_sd_m_s2", "still_acc_direction_rad", "still_gyro_sd_rad_s", "zero_rate_noise_rad_s", "max_gyro_gap_s",
    "no_gyro_random_walk_rad_sqrt_s", "site_field_uT", "site_dip_rad", "vertical_offset_dip_error_rad",
    "vertical_offset_norm_error", "vertical_offset_min_s", "vertical_offset_ridge"))
S_NS_RATE, S_NS_MIN = SF["noise_scale_rate"], SF["noise_scale_min"]
S_OFF_SD, S_OFF_TAU = SF["mag_offset_sd_rad"], SF["mag_offset_time_s"]
S_SWING_RATE, S_SWING_TAU, S_SWING_UPD, S_SWING_MIN = (SF[n] for n in (
    "swing_rate_rad_s", "swing_rate_time_s", "swing_update_interval_s", "swing_min_s"))
F_W2_MEAN, F_SWING_S = FS["w2_mean"], FS["swing_s"]
S_UNOBS_BIAS_RATE = SF["unobserved_bias_swing_rate_rad_s"]
F_MAG_OFFSET = FS["mag_offset_rad"]
SI_REF_UPDATE_NS, SI_STILL_REF_NS, SI_USE_MAG, SI_REQUIRE_CAL, SI_VAR_WIN_NS, SI_STILL_WIN_NS = (SI[n] for n in (
    "reference_update_s", "reference_still_rate_hz", "use_magnetometer", "mag_requires_calibration",
    "variance_window_s", "still_window_s"))
(F_GRAV, F_FIELD, F_DIP, F_ALPHA_REF, F_W2, F_ACC_S2, F_MAG_S2, F_LAST_ACC0, F_LAST_ACC1, F_LAST_ACC2,
 F_ASUM0, F_MSUM0, F_NOISE_SCALE) = (FS[n] for n in ("gravity_m_s2", "field_uT", "dip_rad", "alpha_ref", "w2",
                                                     "acc_sigma2", "mag_sigma2", "acc_reading.0", "acc_reading.1",
                                                     "acc_reading.2", "acc_sum.x", "mag_sum.x", "noise_scale"))
(I_TNS, I_TGYRO, I_HAS_TGYRO, I_REF_NEXT, I_HAS_REF_NEXT, I_ZR_NEXT, I_HAS_ZR_NEXT, I_STILL_NEXT, I_HAS_STILL_NEXT,
 I_ACC_N, I_ACC_T0, I_MAG_N, I_MAG_T0, I_GATED_N, I_YAW_UNOBS, I_MAG_REJ, I_N_ZR, I_N_NUM, I_N_RELOCK, I_N_GYRO,
 I_HAS_LAST_ACC, I_N_HOLES, I_HOLE_OPEN) = (IS[n] for n in (
    "t_ns", "t_gyro_ns", "has:t_gyro_ns", "ref_next_ns", "has:ref_next_ns", "next_zero_rate_ns",
    "has:next_zero_rate_ns", "ref_still_next_ns", "has:ref_still_next_ns", "acc_sum.n", "acc_sum.t0_ns", "mag_sum.n",
    "mag_sum.t0_ns", "gated.n",
    "yaw_unobserved", "mag_rejected", "n_zero_rate", "n_numerical_rejects", "n_heading_relocks", "n_gyro",
    "has:acc_reading", "n_holes", "hole_open"))
VO_NEXT, VO_HAS_NEXT, VO_T0, VO_HAS_T0, VO_ACTIVE = (VO[n] for n in (
    "vo_next_ns", "has:vo_next_ns", "vo_t0_ns", "has:vo_t0_ns", "vo_active"))
# the interval sums' floats are consecutive (x, y, z, sigma2), as interval_add reads them
assert [FS[f"acc_sum.{n}"] - F_ASUM0 for n in ("x", "y", "z", "sigma2")] == [0, 1, 2, 3]
assert [FS[f"mag_sum.{n}"] - F_MSUM0 for n in ("x", "y", "z", "sigma2")] == [0, 1, 2, 3]
assert F_LAST_ACC1 == F_LAST_ACC0 + 1 and F_LAST_ACC2 == F_LAST_ACC0 + 2


# -- plain-float quaternion algebra (the same formulas as core.quaternion, for the compiler) -----------

@kernel
def q_multiply(p, q):
    pw, px, py, pz = p[0], p[1], p[2], p[3]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    out = np.empty(4)
    out[0] = pw * qw - px * qx - py * qy - pz * qz
    out[1] = pw * qx + px * qw + py * qz - pz * qy
    out[2] = pw * qy - px * qz + py * qw + pz * qx
    out[3] = pw * qz + px * qy - py * qx + pz * qw
    return out


@kernel
def q_normalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    s = 1.0 / n
    out = np.empty(4)
    for i in range(4):
        out[i] = q[i] * s
    return out


@kernel
def q_from_rotation_vector(ax, ay, az):
    theta = math.sqrt(ax * ax + ay * ay + az * az)
    out = np.empty(4)
    if theta < 1e-12:
        out[0], out[1], out[2], out[3] = 1.0, 0.5 * ax, 0.5 * ay, 0.5 * az
        return q_normalize(out)
    s = math.sin(0.5 * theta) / theta
    out[0], out[1], out[2], out[3] = math.cos(0.5 * theta), ax * s, ay * s, az * s
    return out


@kernel
def q_to_matrix(q):
    """R(q) body -> ENU, as core.quaternion.to_matrix."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R


# -- small dense algebra, written out: a BLAS or LAPACK call costs more than these matrices' arithmetic ----

@kernel_or(np.matmul)
def mm(a, b):
    """``a @ b`` of small matrices (without numba: ``np.matmul`` itself)."""
    n, k = a.shape
    m = b.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for r in range(k):
                acc += a[i, r] * b[r, j]
            out[i, j] = acc
    return out


@kernel_or(np.matmul)
def mv(a, x):
    """``a @ x`` of a small matrix and a vector (without numba: ``np.matmul`` itself)."""
    out = np.zeros(a.shape[0])
    for i in range(a.shape[0]):
        acc = 0.0
        for r in range(a.shape[1]):
            acc += a[i, r] * x[r]
        out[i] = acc
    return out


@kernel
def inverse(S):
    """Inverse of a 1 x 1 or 3 x 3 innovation covariance (adjugate over determinant); None if singular."""
    m = S.shape[0]
    out = np.empty((m, m))
    if m == 1:
        if S[0, 0] == 0.0:
            return out, False
        out[0, 0] = 1.0 / S[0, 0]
        return out, True
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 0], S[1, 1], S[1, 2]
    g, h, i = S[2, 0], S[2, 1], S[2, 2]
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    det = a * c00 + d * c01 + g * c02
    if det == 0.0 or not math.isfinite(det):
        return out, False
    out[0, 0], out[0, 1], out[0, 2] = c00 / det, c01 / det, c02 / det
    out[1, 0], out[1, 1], out[1, 2] = (f * g - d * i) / det, (a * i - c * g) / det, (c * d - a * f) / det
    out[2, 0], out[2, 1], out[2, 2] = (d * h - e * g) / det, (b * g - a * h) / det, (a * e - b * d) / det
    return out, True


# -- running statistics on arrays (the reference's deques and histograms) --------------------------

def _median_of_numpy(counts, n, lo, width):
    """:func:`median_of` without numba: the cumulative counts and the search in two numpy calls."""
    i = int(np.searchsorted(np.cumsum(counts), 0.5 * n, side="left"))  # the first bin with cum >= n / 2
    return lo + (i + 0.5) * width if i < len(counts) else math.nan


@kernel_or(_median_of_numpy)
def median_of(counts, n, lo, width):
    """Median of a fixed-bin histogram: the first bin whose cumulative count reaches half."""
    half = 0.5 * n
    cum = 0
    for i in range(len(counts)):
        cum += counts[i]
        if cum >= half:
            return lo + (i + 0.5) * width
    return math.nan


@kernel
def median_add(counts, n_arr, lo, width, x):
    i = int((x - lo) / width)
    if 0 <= i < len(counts):
        counts[i] += 1
        n_arr[0] += 1


@kernel
def winvar_update(wt, wx, ptr, s, window_ns, t, x):
    """Trailing-window variance (core.dsp.WindowVariance.update): push, drop the old, return the variance."""
    hi = ptr[1]
    wt[hi] = t
    wx[hi] = x
    ptr[1] = hi + 1
    s1 = s[0] + x
    s2 = s[1] + x * x
    limit = t - window_ns
    lo = ptr[0]
    while wt[lo] < limit:
        old = wx[lo]
        lo += 1
        s1 -= old
        s2 -= old * old
    ptr[0] = lo
    s[0], s[1] = s1, s2
    n = ptr[1] - lo
    if n < 2:
        return 0.0
    mean = s1 / n
    v = s2 / n - mean * mean
    return 0.0 if 0.0 > v else v


@kernel
def winvar_variance(ptr, s):
    n = ptr[1] - ptr[0]
    if n < 2:
        return 0.0
    mean = s[0] / n
    return max(s[1] / n - mean * mean, 0.0)


@kernel
def winspread_update(wt, wv, ptr, s, window_ns, t, x, y, z):
    """Trailing-window per-axis sums of a 3-vector (core.dsp.WindowMeanSpread.update)."""
    hi = ptr[1]
    wt[hi] = t
    wv[hi, 0], wv[hi, 1], wv[hi, 2] = x, y, z
    ptr[1] = hi + 1
    s0, s1, s2_ = s[0] + x, s[1] + y, s[2] + z
    q0, q1, q2 = s[3] + x * x, s[4] + y * y, s[5] + z * z
    limit = t - window_ns
    lo = ptr[0]
    while wt[lo] < limit:
        x, y, z = wv[lo, 0], wv[lo, 1], wv[lo, 2]
        lo += 1
        s0 -= x
        s1 -= y
        s2_ -= z
        q0 -= x * x
        q1 -= y * y
        q2 -= z * z
    ptr[0] = lo
    s[0], s[1], s[2], s[3], s[4], s[5] = s0, s1, s2_, q0, q1, q2


@kernel
def winspread_sd(ptr, s):
    """Largest per-axis standard deviation of the window (the mean is s[0:3] / n)."""
    n = ptr[1] - ptr[0]
    m0, m1, m2 = s[0] / n, s[1] / n, s[2] / n
    a = math.sqrt(max(s[3] / n - m0 * m0, 0.0))
    b = math.sqrt(max(s[4] / n - m1 * m1, 0.0))
    c = math.sqrt(max(s[5] / n - m2 * m2, 0.0))
    out = a
    if b > out:
        out = b
    if c > out:
        out = c
    return out


# -- the Kalman update and the injection of the error -----------------------------------------------

@kernel
def inject(q, b, P, dx, Pn, keep_yaw, max_bias, fs):
    """Fold the error ``dx`` into ``q`` and ``b`` (and the field's heading offset, a 7th state) and reset it
    (the reference's ``_inject``); in place."""
    dq = q_from_rotation_vector(dx[0], dx[1], dx[2])
    qn = q_normalize(q_multiply(dq, q))
    for i in range(4):
        q[i] = qn[i]
    for i in range(3):
        v = b[i] + dx[3 + i]
        m = -max_bias
        if v > m:
            m = v
        r = max_bias
        if m < r:
            r = m
        b[i] = r
    if len(dx) == 7:
        fs[F_MAG_OFFSET] += dx[6]
    G = np.eye(len(dx))
    sk = np.zeros((3, 3))
    sk[0, 1], sk[0, 2] = -dx[2], dx[1]
    sk[1, 0], sk[1, 2] = dx[2], -dx[0]
    sk[2, 0], sk[2, 1] = -dx[1], dx[0]
    for i in range(3):
        for j in range(3):
            G[i, j] += 0.5 * sk[i, j]  # I + [dtheta / 2]x (navigation-frame error)
    if keep_yaw:
        G[2, 0] = 0.0
        G[2, 1] = 0.0
    Pg = mm(mm(G, Pn), G.T)
    Ps = 0.5 * (Pg + Pg.T)
    P[:, :] = Ps


@kernel
def correct(q, b, P, y, H, Rm, gate, consider_tilt, bias_axis, use_bias_axis, measures_yaw, max_bias, is_,
            nis_sum, nis_n, slot, fs):
    """Kalman update of the error state and its bookkeeping (the reference's ``_correct`` and ``_record``).

    Returns the outcome's code and the NIS (nan when none); the NIS goes into ``nis_sum[slot]``/``nis_n[slot]``, a numerical failure into
    the state's counter, a used heading measurement ends ``yaw_unobserved``.
    """
    code, nis = _correct(q, b, P, y, H, Rm, gate, consider_tilt, bias_axis, use_bias_axis, measures_yaw,
                         is_[I_YAW_UNOBS] != 0, max_bias, fs)
    if code == C_USED and measures_yaw:
        is_[I_YAW_UNOBS] = 0
    if code == C_NUM:
        is_[I_N_NUM] += 1
    if nis == nis:
        nis_sum[slot] += nis
        nis_n[slot] += 1
    return code, nis


@kernel
def adapt_noise_scale(fs, sf, nis):
    """The reference's ``_adapt_noise_scale``: one quantile-tracker step of the noise floors' scale."""
    if not (nis == nis) or sf[S_NS_RATE] <= 0.0:
        return
    k = fs[F_NOISE_SCALE] * math.exp(sf[S_NS_RATE] * (0.5 if nis > CHI2_1_MEDIAN else -0.5))
    fs[F_NOISE_SCALE] = min(1.0, max(sf[S_NS_MIN], k))


@kernel
def _correct(q, b, P, y, H, Rm, gate, consider_tilt, bias_axis, use_bias_axis, measures_yaw, yaw_unobs, max_bias,
             fs):
    """The Kalman update itself; returns (code, nis)."""
    PHt = mm(P, H.T)
    S = mm(H, PHt) + Rm
    Sinv, ok = inverse(S)
    if not ok:
        return C_NUM, math.nan
    ySinv = mv(Sinv.T, y)
    nis = 0.0
    for k in range(len(y)):
        nis += ySinv[k] * y[k]
    if not math.isfinite(nis):
        return C_NUM, nis
    if nis > gate:
        return C_GATE, nis
    K = mm(PHt, Sinv)
    m = K.shape[1]
    if consider_tilt:
        K[0:2, :] = 0.0
    yaw_consider = yaw_unobs and not measures_yaw
    if yaw_consider:
        K[2, :] = 0.0
    if use_bias_axis:
        proj = mv(K[3:6, :].T, bias_axis)
        for i in range(3):
            for j in range(m):
                K[3 + i, j] = bias_axis[i] * proj[j]
    dx = mv(K, y)
    IKH = np.eye(P.shape[0]) - mm(K, H)
    Pn = mm(mm(IKH, P), IKH.T) + mm(mm(K, Rm), K.T)  # Joseph form
    if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(Pn))):
        return C_NUM, nis
    inject(q, b, P, dx, Pn, yaw_consider, max_bias, fs)
    return C_USED, nis


@kernel
def random_walk(P, rate2, dt, fs, sf):
    """Covariance growth of the attitude without gyroscope (``_random_walk``)."""
    c = rate2 * dt
    for i in range(3):
        for j in range(3):
            P[i, j] += c * (1.0 if i == j else 0.0)
    if P.shape[0] == 7:
        decay_offset(P, fs, sf, math.exp(-dt / sf[S_OFF_TAU]), np.bool_(True))  # not a literal: see run_attitude


@kernel
def decay_offset(P, fs, sf, phi, cross):
    """The field's heading offset over one step of its Gauss-Markov process (the reference's ``_decay_offset``)."""
    fs[F_MAG_OFFSET] *= phi
    if cross:
        for i in range(3):
            P[i, 6] = phi * P[i, 6]
            P[6, i] = P[i, 6]
    for i in range(3, 6):
        P[i, 6] = phi * P[i, 6]
        P[6, i] = P[i, 6]
    P[6, 6] = phi * phi * P[6, 6] + sf[S_OFF_SD] ** 2 * (1.0 - phi * phi)


# typed block offsets for block3 (a literal argument would compile it once per value: see desktop.fast.jit)
_I0, _I3 = np.int64(0), np.int64(3)


def _block3_numpy(P, r, c):
    """:func:`block3` without numba: one slice's ``tolist`` (the same floats)."""
    (a, b, c_), (d, e, f), (g, h, i) = P[r:r + 3, c:c + 3].tolist()
    return a, b, c_, d, e, f, g, h, i


@kernel_or(_block3_numpy)
def block3(P, r, c):
    """The 3 x 3 block of ``P`` at row ``r``, column ``c`` as nine floats (row-major): read once into locals, as
    plain Python reads an array's elements one by one at about a microsecond each."""
    return (float(P[r, c]), float(P[r, c + 1]), float(P[r, c + 2]), float(P[r + 1, c]), float(P[r + 1, c + 1]),
            float(P[r + 1, c + 2]), float(P[r + 2, c]), float(P[r + 2, c + 1]), float(P[r + 2, c + 2]))


@kernel
def predict(q, b, P, wx, wy, wz, dt, sf, noise_scale, fs):
    """eqs. 5-7 and 11: ``q <- q (x) exp((w - b) dt / 2)``, ``P <- F P F^T + Q`` (the reference's block order).

    Written out in scalars (the formulas of core.quaternion): it runs on every gyroscope event.
    """
    # the inputs as floats: a no-op for numba; without it Python's float arithmetic, not numpy scalars' (slower)
    w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    wx, wy, wz, dt = float(wx), float(wy), float(wz), float(dt)
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    ax, ay, az = (wx - b0) * dt, (wy - b1) * dt, (wz - b2) * dt
    theta = math.sqrt(ax * ax + ay * ay + az * az)  # the rotation vector's quaternion
    if theta < 1e-12:
        pw, px, py, pz = 1.0, 0.5 * ax, 0.5 * ay, 0.5 * az
        nrm = math.sqrt(pw * pw + px * px + py * py + pz * pz)
        sc = 1.0 / nrm
        pw, px, py, pz = pw * sc, px * sc, py * sc, pz * sc
    else:
        sc = math.sin(0.5 * theta) / theta
        pw, px, py, pz = math.cos(0.5 * theta), ax * sc, ay * sc, az * sc
    mw = w * pw - x * px - y * py - z * pz  # q (x) p, eq. 7
    mx = w * px + x * pw + y * pz - z * py
    my = w * py - x * pz + y * pw + z * px
    mz = w * pz + x * py - y * px + z * pw
    sc = 1.0 / math.sqrt(mw * mw + mx * mx + my * my + mz * mz)
    q[0], q[1], q[2], q[3] = mw * sc, mx * sc, my * sc, mz * sc
    # every element of P this step reads, once, as a float (block3): the arithmetic and its order are those of
    # the loops over P's elements these lines replaced, which without numba cost about a microsecond per access
    d00, d01, d02 = r00 * dt, r01 * dt, r02 * dt  # R dt
    d10, d11, d12 = r10 * dt, r11 * dt, r12 * dt
    d20, d21, d22 = r20 * dt, r21 * dt, r22 * dt
    t00, t01, t02, t10, t11, t12, t20, t21, t22 = block3(P, _I0, _I0)  # Ptt
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = block3(P, _I0, _I3)  # Ptb
    u00, u01, u02, u10, u11, u12, u20, u21, u22 = block3(P, _I3, _I0)  # Pbt
    e00, e01, e02, e10, e11, e12, e20, e21, e22 = block3(P, _I3, _I3)  # Pbb
    # A = Ptt - Rdt Pbt, B = Ptb - Rdt Pbb
    a00 = t00 - (d00 * u00 + d01 * u10 + d02 * u20)
    a01 = t01 - (d00 * u01 + d01 * u11 + d02 * u21)
    a02 = t02 - (d00 * u02 + d01 * u12 + d02 * u22)
    a10 = t10 - (d10 * u00 + d11 * u10 + d12 * u20)
    a11 = t11 - (d10 * u01 + d11 * u11 + d12 * u21)
    a12 = t12 - (d10 * u02 + d11 * u12 + d12 * u22)
    a20 = t20 - (d20 * u00 + d21 * u10 + d22 * u20)
    a21 = t21 - (d20 * u01 + d21 * u11 + d22 * u21)
    a22 = t22 - (d20 * u02 + d21 * u12 + d22 * u22)
    b00 = c00 - (d00 * e00 + d01 * e10 + d02 * e20)
    b01 = c01 - (d00 * e01 + d01 * e11 + d02 * e21)
    b02 = c02 - (d00 * e02 + d01 * e12 + d02 * e22)
    b10 = c10 - (d10 * e00 + d11 * e10 + d12 * e20)
    b11 = c11 - (d10 * e01 + d11 * e11 + d12 * e21)
    b12 = c12 - (d10 * e02 + d11 * e12 + d12 * e22)
    b20 = c20 - (d20 * e00 + d21 * e10 + d22 * e20)
    b21 = c21 - (d20 * e01 + d21 * e11 + d22 * e21)
    b22 = c22 - (d20 * e02 + d21 * e12 + d22 * e22)
    w2 = (wx - b0) ** 2 + (wy - b1) ** 2 + (wz - b2) ** 2
    fs[F_W2_MEAN] += (1.0 - math.exp(-dt / sf[S_SWING_TAU])) * (w2 - fs[F_W2_MEAN])
    fs[F_SWING_S] = fs[F_SWING_S] + dt if fs[F_W2_MEAN] > sf[S_SWING_RATE] ** 2 else 0.0
    qg = (sf[S_GN] ** 2 + sf[S_GS] ** 2 * w2) * noise_scale * dt
    qb = sf[S_BW] ** 2 * dt
    # Ptt = A - B Rdt^T + qg I
    P[0, 0] = (a00 - (b00 * d00 + b01 * d01 + b02 * d02)) + qg
    P[0, 1] = a01 - (b00 * d10 + b01 * d11 + b02 * d12)
    P[0, 2] = a02 - (b00 * d20 + b01 * d21 + b02 * d22)
    P[1, 0] = a10 - (b10 * d00 + b11 * d01 + b12 * d02)
    P[1, 1] = (a11 - (b10 * d10 + b11 * d11 + b12 * d12)) + qg
    P[1, 2] = a12 - (b10 * d20 + b11 * d21 + b12 * d22)
    P[2, 0] = a20 - (b20 * d00 + b21 * d01 + b22 * d02)
    P[2, 1] = a21 - (b20 * d10 + b21 * d11 + b22 * d12)
    P[2, 2] = (a22 - (b20 * d20 + b21 * d21 + b22 * d22)) + qg
    P[0, 3], P[0, 4], P[0, 5] = b00, b01, b02  # Ptb = B, Pbt = B^T
    P[1, 3], P[1, 4], P[1, 5] = b10, b11, b12
    P[2, 3], P[2, 4], P[2, 5] = b20, b21, b22
    P[3, 0], P[3, 1], P[3, 2] = b00, b10, b20
    P[4, 0], P[4, 1], P[4, 2] = b01, b11, b21
    P[5, 0], P[5, 1], P[5, 2] = b02, b12, b22
    P[3, 3], P[4, 4], P[5, 5] = e00 + qb, e11 + qb, e22 + qb
    if P.shape[0] == 7:  # the offset's row of F is (0, 0, phi): P_to <- (P_to - R dt P_bo) phi
        phi = math.exp(-dt / sf[S_OFF_TAU])
        o3, o4, o5 = float(P[3, 6]), float(P[4, 6]), float(P[5, 6])
        to0 = phi * (float(P[0, 6]) - (d00 * o3 + d01 * o4 + d02 * o5))
        to1 = phi * (float(P[1, 6]) - (d10 * o3 + d11 * o4 + d12 * o5))
        to2 = phi * (float(P[2, 6]) - (d20 * o3 + d21 * o4 + d22 * o5))
        P[0, 6], P[1, 6], P[2, 6] = to0, to1, to2
        P[6, 0], P[6, 1], P[6, 2] = to0, to1, to2
        decay_offset(P, fs, sf, phi, np.bool_(False))  # not a literal: see run_attitude
    return w2


@kernel
def set_field_reference(fs, decl):
    """The reference field's azimuth (eq. 14 turned by the declination)."""
    fs[F_ALPHA_REF] = math.atan2(math.cos(decl), math.sin(decl))


@kernel
def update_references(fs, g_counts, g_n, h_counts, h_n, dip_counts, dip_n, decl):
    if g_n[0]:
        fs[F_GRAV] = median_of(g_counts, g_n[0], 0.0, 0.01)
    if h_n[0]:
        fs[F_FIELD] = median_of(h_counts, h_n[0], 0.0, 0.1)
        fs[F_DIP] = median_of(dip_counts, dip_n[0], -math.pi / 2, math.radians(0.1))
    set_field_reference(fs, decl)


@kernel
def refresh_references(fs, is_, si, ti, g_counts, g_n, h_counts, h_n, dip_counts, dip_n, decl):
    """The running references, refreshed every ``reference_update_s`` (or while |h| has readings but no value)."""
    if not is_[I_HAS_REF_NEXT] or ti >= is_[I_REF_NEXT] or (h_n[0] and fs[F_FIELD] != fs[F_FIELD]):
        is_[I_REF_NEXT] = ti + si[SI_REF_UPDATE_NS]
        is_[I_HAS_REF_NEXT] = 1
        update_references(fs, g_counts, g_n, h_counts, h_n, dip_counts, dip_n, decl)


@kernel
def bridge_hole(P, is_, rw2, ti, fs, sf):
    """A hole in the recording (every stream silent for over ``max_gyro_gap_s``): the reference's ``_bridge_hole``
    -- the uncertainty grown once over the elapsed time, the open intervals and the gated innovations dropped."""
    if (ti - is_[I_TNS]) * 1e-9 <= sf[S_MAX_GAP]:
        is_[I_HOLE_OPEN] = 0
        return
    random_walk(P, rw2, (ti - is_[I_TNS]) * 1e-9, fs, sf)
    is_[I_TNS] = ti
    if is_[I_HOLE_OPEN]:  # gaps one after another: one hole, the intervals since it kept
        return
    is_[I_HOLE_OPEN] = 1
    for k in range(4):
        fs[F_ASUM0 + k] = 0.0
        fs[F_MSUM0 + k] = 0.0
    is_[I_ACC_N] = 0
    is_[I_ACC_T0] = 0
    is_[I_MAG_N] = 0
    is_[I_MAG_T0] = 0
    is_[I_GATED_N] = 0
    is_[I_N_HOLES] += 1


@kernel
def propagate_without_gyro(P, is_, rw2, ti, fs, sf):
    """A measurement at ``ti``: without a gyroscope event for 0.1 s only the attitude's uncertainty grows."""
    if (not is_[I_HAS_TGYRO]) or ti - is_[I_TGYRO] > 100_000_000:
        dtn = (ti - is_[I_TNS]) * 1e-9
        if dtn > 0:
            random_walk(P, rw2, dtn, fs, sf)
    if ti > is_[I_TNS]:
        is_[I_TNS] = ti


@kernel
def interval_add(fs, is_, base, n_i, t0_i, ti, a, b, c, sigma2, interval_s, out):
    """One reading's navigation-frame vector ``(a, b, c)`` and variance into the running interval's sums.

    When ``interval_s`` has passed since the interval's first reading: the means into ``out`` (x, y, z,
    sigma2), the sums reset, and the count returned; 0 while the interval is open.
    """
    if is_[n_i] == 0:
        is_[t0_i] = ti
    fs[base] += a
    fs[base + 1] += b
    fs[base + 2] += c
    fs[base + 3] += sigma2
    is_[n_i] += 1
    if (ti - is_[t0_i]) * 1e-9 < interval_s:
        return 0
    n = is_[n_i]
    for k in range(4):
        out[k] = fs[base + k] / n
        fs[base + k] = 0.0
    is_[n_i] = 0
    is_[t0_i] = 0
    return n


@kernel
def count(counts, first, code, k):
    """``reasons[code] += k``, remembering the order in which codes first appeared (the dict's key order)."""
    if first[code] < 0:
        first[code] = first[len(first) - 1]
        first[len(first) - 1] += 1
    counts[code] += k


@kernel
def vertical_offset(R, x, y, z, ti, sf, vo_S, vo_r, vo_i, vo_b, rd_counts, rd_n, rn_counts, rn_n, fs,
                    h_counts, h_n, dip_counts, dip_n):
    """A reading with the hard-iron offset along the directions the phone held vertical removed, from the site's
    field (``AttitudeEKF._vertical_offset``: ``up_b . (m - b) = -F sin d`` by ridge least squares, applied while
    the readings' median dip and strength are off the site's; its references restarted at each switch)."""
    u0, u1, u2 = R[2, 0], R[2, 1], R[2, 2]
    nm = math.sqrt(x * x + y * y + z * z)
    median_add(rd_counts, rd_n, -math.pi / 2, math.radians(0.1),
               math.asin(max(-1.0, min(1.0, -(u0 * x + u1 * y + u2 * z) / nm))))
    rhs = u0 * x + u1 * y + u2 * z + sf[S_SITE_F] * math.sin(sf[S_SITE_DIP])
    u = (u0, u1, u2)
    for i in range(3):
        vo_r[i] += u[i] * rhs
        for j in range(3):
            vo_S[i, j] += u[i] * u[j]
    if not vo_i[VO_HAS_NEXT] or ti >= vo_i[VO_NEXT]:
        vo_i[VO_NEXT] = ti + 1_000_000_000
        vo_i[VO_HAS_NEXT] = 1
        if not vo_i[VO_HAS_T0]:
            vo_i[VO_T0] = ti
            vo_i[VO_HAS_T0] = 1
        median_add(rn_counts, rn_n, 0.0, 0.1, nm)
        dip_err = abs(median_of(rd_counts, rd_n[0], -math.pi / 2, math.radians(0.1)) - sf[S_SITE_DIP])
        norm_err = abs(median_of(rn_counts, rn_n[0], 0.0, 0.1) / sf[S_SITE_F] - 1.0)
        if vo_i[VO_ACTIVE]:  # hysteresis: stays on until the dip is clearly right
            active = dip_err > 0.5 * sf[S_VO_DIP_ERR]
        else:
            active = (dip_err > sf[S_VO_DIP_ERR] and norm_err > sf[S_VO_NORM_ERR]
                      and (ti - vo_i[VO_T0]) * 1e-9 >= sf[S_VO_MIN_S])
        if active:
            ridge = sf[S_VO_RIDGE] * (vo_S[0, 0] + vo_S[1, 1] + vo_S[2, 2]) / 3.0
            A = np.empty((3, 3))
            for i in range(3):
                for j in range(3):
                    A[i, j] = vo_S[i, j] + ridge * (1.0 if i == j else 0.0)
            rr = np.empty(3)
            for i in range(3):
                rr[i] = vo_r[i]
            sol = np.linalg.solve(A, rr)
            if math.isfinite(sol[0]) and math.isfinite(sol[1]) and math.isfinite(sol[2]):
                for i in range(3):
                    vo_b[i] = sol[i]
        if active != (vo_i[VO_ACTIVE] != 0):  # the references were of the other field: start them again
            vo_i[VO_ACTIVE] = 1 if active else 0
            h_counts[:] = 0
            h_n[0] = 0
            dip_counts[:] = 0
            dip_n[0] = 0
            fs[F_FIELD] = math.nan
            fs[F_DIP] = math.nan
            if not active:
                for i in range(3):
                    vo_b[i] = 0.0
    if not vo_i[VO_ACTIVE]:
        return x, y, z
    return x - vo_b[0], y - vo_b[1], z - vo_b[2]


@kernel
def run_attitude(kind, t, v, cal_ok, i0, tick_event, j0, sf, si, fs, is_, q, b, P,
                 g_counts, g_n, h_counts, h_n, dip_counts, dip_n,
                 gw_t, gw_v, gw_p, gw_s, ad_t, ad_v, ad_p, ad_s, an_t, an_v, an_p, an_s,
                 av_t, av_v, av_p, av_s, mv_t, mv_v, mv_p, mv_s, gated_t, gated_v,
                 out_q, out_acc_s2, out_mag_s2, out_mag_rej,
                 acc_counts, acc_first, mag_counts, mag_first, nis_sum, nis_n,
                 vo_S, vo_r, vo_i, vo_b, rd_counts, rd_n, rn_counts, rn_n):
    """The attitude filter from event ``i0`` on (it has started): per grid tick the attitude and the log's columns.

    ``kind``/``t``/``v``: the merged valid events (magnetometer readings already calibrated; ``cal_ok``
    whether the calibrator had a fit); ``tick_event[j]``: the event after which grid tick ``j`` is taken.
    Every array argument is state, updated in place.  With a site's field (``sf[S_SITE_F]``, ``sf[S_SITE_DIP]``)
    each magnetometer reading goes through :func:`vertical_offset` first (``vo_*``, ``rd_*``, ``rn_*``: its state).
    """
    n = len(t)
    j = j0
    n_ticks = len(tick_event)
    still_win_ns = si[SI_STILL_WIN_NS]
    var_win_ns = si[SI_VAR_WIN_NS]
    decl = sf[S_DECL]
    max_bias = sf[S_MAXB]
    rw2 = sf[S_NO_GYRO_RW] ** 2
    site = sf[S_SITE_F] == sf[S_SITE_F] and sf[S_SITE_DIP] == sf[S_SITE_DIP]
    I3 = np.eye(3)
    mean4 = np.empty(4)
    n_p = P.shape[0]  # 7 with the field's heading offset, else 6
    # numba compiles a called kernel once per set of literal (constant) arguments; the flags, slots and
    # indices passed below are typed values (np.bool_, np.int64), not literals, so each callee compiles once
    no, yes, one = np.bool_(False), np.bool_(True), np.int64(1)
    for i in range(i0, n):
        k = kind[i]
        ti = t[i]
        x, y_, z = v[i, 0], v[i, 1], v[i, 2]
        if k == GYRO_K:
            is_[I_N_GYRO] += 1
            winspread_update(gw_t, gw_v, gw_p, gw_s, still_win_ns, ti, x, y_, z)
            bridge_hole(P, is_, rw2, ti, fs, sf)
            t_prev = is_[I_TGYRO] if is_[I_HAS_TGYRO] else is_[I_TNS]
            is_[I_TGYRO] = ti
            is_[I_HAS_TGYRO] = 1
            dt = (ti - t_prev) * 1e-9
            if dt > 0.0:
                if dt > sf[S_MAX_GAP]:
                    rest = (ti - is_[I_TNS]) * 1e-9  # the time not yet propagated (the reference's predict)
                    if rest > 0.0:
                        random_walk(P, rw2, rest, fs, sf)
                else:
                    fs[F_W2] = predict(q, b, P, x, y_, z, dt, sf, fs[F_NOISE_SCALE], fs)
                is_[I_TNS] = ti
        elif k == ACC_K:
            fs[F_LAST_ACC0], fs[F_LAST_ACC1], fs[F_LAST_ACC2] = x, y_, z
            is_[I_HAS_LAST_ACC] = 1
            # references (|g|), then the windows
            median_add(g_counts, g_n, 0.0, 0.01, math.sqrt(x ** 2 + y_ ** 2 + z ** 2))
            refresh_references(fs, is_, si, ti, g_counts, g_n, h_counts, h_n, dip_counts, dip_n, decl)
            na = math.sqrt(x * x + y_ * y_ + z * z)
            if na > 0:
                winspread_update(ad_t, ad_v, ad_p, ad_s, still_win_ns, ti, x / na, y_ / na, z / na)
            winvar_update(an_t, an_v, an_p, an_s, still_win_ns, ti, na)
            bridge_hole(P, is_, rw2, ti, fs, sf)
            propagate_without_gyro(P, is_, rw2, ti, fs, sf)
            # zero-rate update
            if gw_p[1] > gw_p[0] and not (is_[I_HAS_ZR_NEXT] and ti < is_[I_ZR_NEXT]):
                span_g = gw_t[gw_p[1] - 1] - gw_t[gw_p[0]]
                span_a = ad_t[ad_p[1] - 1] - ad_t[ad_p[0]]
                if not (span_g < 0.95 * still_win_ns or span_a < 0.95 * still_win_ns):
                    sd = winspread_sd(gw_p, gw_s)
                    if not (sd > sf[S_STILL_GYRO]) and not (winspread_sd(ad_p, ad_s) > sf[S_STILL_DIR]):
                        if not (an_p[1] - an_p[0] < 5 or math.sqrt(winvar_variance(an_p, an_s)) > sf[S_STILL_ACC_SD]):
                            ng = gw_p[1] - gw_p[0]
                            r2 = sd * sd / ng + sf[S_ZR_NOISE] ** 2
                            yz = np.empty(3)
                            for c in range(3):
                                yz[c] = gw_s[c] / ng - b[c]
                            Hz = np.zeros((3, n_p))
                            for c in range(3):
                                Hz[c, 3 + c] = 1.0
                            code, _ = correct(q, b, P, yz, Hz, r2 * I3, math.inf, no, yz, no, no, max_bias,
                                              is_, nis_sum, nis_n, np.int64(2), fs)
                            if code == C_USED:
                                is_[I_N_ZR] += 1
                            is_[I_ZR_NEXT] = ti + still_win_ns
                            is_[I_HAS_ZR_NEXT] = 1
            var = winvar_update(av_t, av_v, av_p, av_s, var_win_ns, ti, na)
            dev = abs(na - fs[F_GRAV])
            # eq. 17 (+ turn term; the floors scaled by kappa)
            sigma2 = (sf[S_A0] ** 2 + sf[S_KA3] * fs[F_W2]) * fs[F_NOISE_SCALE] + sf[S_KA1] * dev + sf[S_KA2] * var
            fs[F_ACC_S2] = sigma2
            reason = A_PENDING
            if dev > sf[S_ACC_REJ] or na == 0.0:
                reason = A_NORM
            else:
                R = q_to_matrix(q)
                if interval_add(fs, is_, np.int64(F_ASUM0), np.int64(I_ACC_N), np.int64(I_ACC_T0), ti,
                                R[0, 0] * x + R[0, 1] * y_ + R[0, 2] * z, R[1, 0] * x + R[1, 1] * y_ + R[1, 2] * z,
                                R[2, 0] * x + R[2, 1] * y_ + R[2, 2] * z,
                                sigma2, sf[S_SWING_UPD] if fs[F_SWING_S] >= sf[S_SWING_MIN] else sf[S_UPD],
                                mean4):
                    fx, fy, fz, sigma2 = mean4[0], mean4[1], mean4[2], mean4[3]
                    nf = math.sqrt(fx * fx + fy * fy + fz * fz)
                    if nf == 0.0:
                        reason = A_NORM
                    else:
                        ya = np.empty(3)
                        for c in range(3):  # z = R^T f_n / |f_n| against h = R^T u (eqs. 12-13)
                            ya[c] = (R[0, c] * fx + R[1, c] * fy + R[2, c] * fz) / nf - R[2, c]
                        Ha = np.zeros((3, n_p))
                        for c in range(3):  # R^T [u]x
                            Ha[c, 0] = R[1, c]
                            Ha[c, 1] = -R[0, c]
                        # no heading measured and a swinging phone: no bias correction (the reference's
                        # bias_axis=_ZERO3: a zero axis, every bias gain row zero)
                        frozen = is_[I_YAW_UNOBS] != 0 and fs[F_W2_MEAN] > sf[S_UNOBS_BIAS_RATE] ** 2
                        code, _ = correct(q, b, P, ya, Ha, sigma2 * I3, sf[S_ACC_GATE], no, ya * 0.0,
                                          yes if frozen else no, no, max_bias, is_, nis_sum, nis_n, np.int64(0), fs)
                        reason = A_USED if code == C_USED else (A_GATE if code == C_GATE else A_NUM)
            count(acc_counts, acc_first, reason, one)
        else:  # magnetometer
            reason = -1
            n_interval = 0
            if not si[SI_USE_MAG]:
                reason = M_OFF
            elif si[SI_REQUIRE_CAL] and not cal_ok[i]:
                reason = M_CALIBRATING
            else:
                nm = math.sqrt(x * x + y_ * y_ + z * z)
                if not (sf[S_MAG_LO] <= nm <= sf[S_MAG_HI]):
                    reason = M_RANGE
                else:
                    R = q_to_matrix(q)
                    if site:
                        x, y_, z = vertical_offset(R, x, y_, z, ti, sf, vo_S, vo_r, vo_i, vo_b, rd_counts, rd_n,
                                                   rn_counts, rn_n, fs, h_counts, h_n, dip_counts, dip_n)
                        nm = math.sqrt(x * x + y_ * y_ + z * z)
                    # references (|h|, dip; a still phone's readings at most reference_still_rate_hz)
                    if is_[I_HAS_LAST_ACC]:
                        still = (an_p[1] - an_p[0] >= 5
                                 and winvar_variance(an_p, an_s) < sf[S_STILL_ACC_SD] ** 2)
                        due = True
                        if still and h_n[0] != 0:
                            if is_[I_HAS_STILL_NEXT] and ti < is_[I_STILL_NEXT]:
                                due = False
                            else:
                                is_[I_STILL_NEXT] = ti + si[SI_STILL_REF_NS]
                                is_[I_HAS_STILL_NEXT] = 1
                        if due:
                            a0, a1, a2 = fs[F_LAST_ACC0], fs[F_LAST_ACC1], fs[F_LAST_ACC2]
                            nna = math.sqrt(a0 ** 2 + a1 ** 2 + a2 ** 2)
                            nnm = math.sqrt(x ** 2 + y_ ** 2 + z ** 2)
                            if nna > 0 and nnm > 0:
                                sd_ = -(a0 * x + a1 * y_ + a2 * z) / (nna * nnm)
                                median_add(dip_counts, dip_n, -math.pi / 2, math.radians(0.1),
                                           math.asin(max(-1.0, min(1.0, sd_))))
                                median_add(h_counts, h_n, 0.0, 0.1, nnm)
                    refresh_references(fs, is_, si, ti, g_counts, g_n, h_counts, h_n, dip_counts, dip_n, decl)
                    bridge_hole(P, is_, rw2, ti, fs, sf)
                    propagate_without_gyro(P, is_, rw2, ti, fs, sf)
                    var = winvar_update(mv_t, mv_v, mv_p, mv_s, var_win_ns, ti, nm)
                    dev = abs(nm - fs[F_FIELD])
                    sigma2 = sf[S_M0] ** 2 * fs[F_NOISE_SCALE] + sf[S_KM1] * dev + sf[S_KM2] * var  # eq. 18
                    fs[F_MAG_S2] = sigma2
                    u0, u1, u2 = R[2, 0], R[2, 1], R[2, 2]
                    sin_dip = -(u0 * x + u1 * y_ + u2 * z) / nm
                    dip = math.asin(max(-1.0, min(1.0, sin_dip)))
                    if dev > sf[S_MAG_RATIO] * fs[F_FIELD]:
                        reason = M_NORM
                    elif abs(dip - fs[F_DIP]) > sf[S_MAG_DIP]:
                        reason = M_DIP
                    else:
                        inv = 1.0 / nm
                        n_interval = interval_add(fs, is_, np.int64(F_MSUM0), np.int64(I_MAG_N), np.int64(I_MAG_T0),
                                                  ti,
                                                  (R[0, 0] * x + R[0, 1] * y_ + R[0, 2] * z) * inv,
                                                  (R[1, 0] * x + R[1, 1] * y_ + R[1, 2] * z) * inv,
                                                  (R[2, 0] * x + R[2, 1] * y_ + R[2, 2] * z) * inv,
                                                  sigma2, sf[S_UPD], mean4)
                        if n_interval == 0:
                            reason = M_USED
                        else:
                            e, nn, uu, sigma2 = mean4[0], mean4[1], mean4[2], mean4[3]
                            h2 = e ** 2 + nn ** 2
                            c2 = h2 / (h2 + uu ** 2)
                            if c2 < 0.01:
                                reason = M_VERTICAL
                            else:
                                a = fs[F_ALPHA_REF] + fs[F_MAG_OFFSET] - math.atan2(nn, e)
                                ym = np.empty(1)
                                ym[0] = (a + math.pi) % (2.0 * math.pi) - math.pi
                                Hm = np.zeros((1, n_p))
                                if n_p == 7:
                                    Hm[0, 6] = -1.0  # the field's heading offset
                                hh = e * e + nn * nn
                                Hm[0, 0] = -e * uu / hh
                                Hm[0, 1] = -nn * uu / hh
                                Hm[0, 2] = 1.0
                                Rm = np.empty((1, 1))
                                Rm[0, 0] = sigma2 / c2
                                up = np.empty(3)
                                up[0], up[1], up[2] = u0, u1, u2
                                code, nis = correct(q, b, P, ym, Hm, Rm, sf[S_MAG_GATE], yes, up, yes, yes,
                                                    max_bias, is_, nis_sum, nis_n, np.int64(1), fs)
                                adapt_noise_scale(fs, sf, nis)
                                if code == C_USED:
                                    reason = M_USED
                                    is_[I_GATED_N] = 0
                                elif code == C_GATE:
                                    reason = M_GATE
                                    g = is_[I_GATED_N]  # the relock
                                    gated_t[g] = ti
                                    gated_v[g] = ym[0]
                                    g += 1
                                    is_[I_GATED_N] = g
                                    if not ((gated_t[g - 1] - gated_t[0]) * 1e-9 < sf[S_RELOCK_S]):
                                        cs = 0.0
                                        sn = 0.0
                                        for c in range(g):
                                            cs += math.cos(gated_v[c])
                                        for c in range(g):
                                            sn += math.sin(gated_v[c])
                                        cs /= g
                                        sn /= g
                                        spread = math.sqrt(max(-2.0 * math.log(max(math.hypot(cs, sn), 1e-12)), 0.0))
                                        is_[I_GATED_N] = 0
                                        if spread < sf[S_RELOCK_SPREAD]:
                                            P[2, :] = 0.0
                                            P[:, 2] = 0.0
                                            P[2, 2] = math.pi ** 2
                                            is_[I_N_RELOCK] += 1
                                else:
                                    reason = M_NUM
                            if reason != M_USED and n_interval > 1:  # the interval's earlier readings
                                count(mag_counts, mag_first, np.int64(M_USED), -(n_interval - 1))
                                count(mag_counts, mag_first, reason, n_interval - 1)
            is_[I_MAG_REJ] = 0 if reason == M_USED else 1
            count(mag_counts, mag_first, reason, one)
        while j < n_ticks and tick_event[j] == i:
            for c in range(4):
                out_q[j, c] = q[c]
            out_acc_s2[j] = fs[F_ACC_S2]
            out_mag_s2[j] = fs[F_MAG_S2]
            out_mag_rej[j] = is_[I_MAG_REJ] != 0
            j += 1
    return j


# -- the Python side: configuration, the reference's start, the hand-over and back -------------------

def check_supported(ekf) -> None:
    """Refuse an attitude filter configured with what the kernel does not implement (see the docstring)."""
    from core.pdr.attitude import AttitudeEKF

    s = getattr(ekf, "settings", None)
    if type(ekf) is not AttitudeEKF:
        raise NotImplementedError(f"the fast path runs core.pdr.attitude.AttitudeEKF only, not {type(ekf).__name__}")
    if s.mag_mode != "heading" or ekf.field_detector is not None:
        raise NotImplementedError("the fast path implements mag_mode='heading' without a field detector")
    if ekf.keep_history or ekf.start_heading is not None:
        raise NotImplementedError("the replay heading smoother (Pipeline(heading_smoother='rts' or 'start')) runs on "
                                  "the reference only: the fast path keeps no history for a backward pass")


def settings_arrays(ekf) -> tuple[np.ndarray, np.ndarray]:
    """The settings as the kernel's float and int arrays (slots :data:`SF`, :data:`SI`)."""
    s = ekf.settings
    sf = np.empty(len(SF), dtype=np.float64)
    si = np.empty(len(SI), dtype=np.int64)
    for name in _SETTINGS:
        how, v = SETTINGS_USE[name], getattr(s, name)
        if how == "f":
            sf[SF[name]] = v
        elif how == "range":
            sf[SF[name + ".lo"]], sf[SF[name + ".hi"]] = v[0], v[1]
        elif how == "ns":
            si[SI[name]] = int(v * 1e9)
        elif how == "ns/hz":
            si[SI[name]] = int(1e9 / v)
        elif how == "i":
            si[SI[name]] = int(v)
    return sf, si


def calibrate_magnetometer(calibrator, t_ns: np.ndarray, mag_b: np.ndarray):
    """The online calibration over the whole magnetometer stream, before the filter (see the docstring).

    The calibrator sees each raw reading and nothing of the attitude, so running it first gives what it gives
    inside the filter: its per-reading part compiled, its fit attempts core's own
    (:func:`desktop.fast.magcal.calibrate_stream`).  Returns the calibrated readings (n, 3) and whether it had
    a fit at each.
    """
    if calibrator is None:
        return np.array(mag_b, dtype=np.float64).reshape(len(t_ns), 3), np.ones(len(t_ns), dtype=np.bool_)
    return calibrate_stream(calibrator, t_ns, mag_b)


def start_with_reference(ekf, kind, t, v, cal_ok, tick_event, out_q, out_acc_s2, out_mag_s2, out_mag_rej,
                         hook_at: int = -1, hook=None) -> tuple:
    """Run the reference filter (no calibrator: ``v`` holds calibrated readings) until it has started.

    Returns ``(i0, j0, j_init)``: the first event and the first grid tick the kernel takes over, and the
    first grid tick taken with the filter started (the smoother's first).  ``hook()``, if given, is called
    before event ``hook_at`` (a GPS site given to the filter, :meth:`core.pdr.pipeline.Pipeline.apply_site`)
    when that comes before the hand-over.
    """
    j = 0
    j_init = -1
    n_ticks = len(tick_event)
    for i in range(len(t)):
        if i == hook_at:
            hook()
        if ekf.initialized:
            return i, j, (j if j_init < 0 else j_init)
        require = ekf.settings.mag_requires_calibration and ekf.settings.use_magnetometer
        k, ti = int(kind[i]), int(t[i])
        x, y, z = float(v[i, 0]), float(v[i, 1]), float(v[i, 2])
        if k == GYRO_K:
            ekf.predict(ti, x, y, z)
        elif k == ACC_K:
            ekf.update_acc(ti, x, y, z)
        elif require and not cal_ok[i]:
            ekf.mag_not_calibrated(ti)
        else:
            ekf.update_mag(ti, x, y, z)
        while j < n_ticks and tick_event[j] == i:
            out_q[j] = ekf.q
            out_acc_s2[j], out_mag_s2[j], out_mag_rej[j] = ekf.acc_sigma2, ekf.mag_sigma2, ekf.mag_rejected
            if j_init < 0 and ekf.initialized:
                j_init = j
            j += 1
    return len(t), j, (j if j_init < 0 else j_init)


class KernelState:
    """The reference filter's state (:meth:`AttitudeEKF.snapshot`, after its start) as the kernel's arrays, and
    back (:meth:`write_back`, through :meth:`AttitudeEKF.restore`)."""

    def __init__(self, ekf, n_gyro: int, n_acc: int, n_mag: int):
        self.sf, self.si = settings_arrays(ekf)
        st = ekf.snapshot()
        fs = np.full(N_FSTATE, math.nan)
        is_ = np.zeros(N_ISTATE, dtype=np.int64)
        vo_i = np.zeros(len(VO), dtype=np.int64)
        for name, tp in _STATE_TYPES.items():
            how, val = STATE_USE[name], getattr(st, name)
            if how == "f":
                fs[FS[name]] = val
            elif how == "f3?":
                is_[IS["has:" + name]] = val is not None
                if val is not None:
                    fs[FS[name + ".0"]:FS[name + ".0"] + 3] = val
            elif how == "sum":
                for n, t in _SUM_FIELDS:
                    (fs if t == "float" else is_)[(FS if t == "float" else IS)[f"{name}.{n}"]] = getattr(val, n)
            elif how in ("i", "vo"):
                (is_ if how == "i" else vo_i)[(IS if how == "i" else VO)[name]] = int(val)
            elif how in ("i?", "vo?"):
                arr, slot = (is_, IS) if how == "i?" else (vo_i, VO)
                arr[slot["has:" + name]], arr[slot[name]] = (0, 0) if val is None else (1, val)
        self.fs, self.is_, self.vo_i = fs, is_, vo_i
        self.q = np.array(st.q, dtype=np.float64)
        self.b = np.array(st.b, dtype=np.float64)
        self.P = np.ascontiguousarray(ekf.P_full, dtype=np.float64)
        self.medians = []
        for rm in (st.refs.g, st.refs.h, st.refs.dip):
            self.medians += [np.array(rm.counts, dtype=np.int64), np.array([rm.n], dtype=np.int64)]
        # the windows: the reference's deque contents first, room for every later event of their stream
        self.windows = []
        for w, room, vec in ((st.gyro_win, n_gyro, True), (st.accdir_win, n_acc, True),
                             (st.acc_norm_win, n_acc, False), (st.acc_var, n_acc, False),
                             (st.mag_var, n_mag, False)):
            cap = len(w.buf) + room + 1
            wt = np.zeros(cap, dtype=np.int64)
            wv = np.zeros((cap, 3) if vec else cap)
            for k, (tk, xk) in enumerate(w.buf):
                wt[k] = tk
                wv[k] = xk
            ptr = np.array([0, len(w.buf)], dtype=np.int64)
            sums = np.array(list(w.s) + list(w.s2) if vec else [w.s1, w.s2], dtype=np.float64)
            self.windows += [wt, wv, ptr, sums]
        self.gated_t = np.zeros(len(st.gated) + n_mag + 1, dtype=np.int64)
        self.gated_v = np.zeros(len(self.gated_t))
        for k, (tk, vk) in enumerate(st.gated):
            self.gated_t[k], self.gated_v[k] = tk, vk
        is_[I_GATED_N] = len(st.gated)
        # the reasons counted from the hand-over on (added to the reference's in write_back)
        self.acc_counts = np.zeros(len(ACC_REASONS), dtype=np.int64)
        self.mag_counts = np.zeros(len(MAG_REASONS), dtype=np.int64)
        self.acc_first = np.full(len(ACC_REASONS) + 1, -1, dtype=np.int64)
        self.mag_first = np.full(len(MAG_REASONS) + 1, -1, dtype=np.int64)
        self.acc_first[-1] = self.mag_first[-1] = 0
        self.nis_sum = np.zeros(3)
        self.nis_n = np.zeros(3, dtype=np.int64)
        # the vertical offset of a site's field (AttitudeEKF._vertical_offset)
        self.vo_S = np.array(st.vo_S, dtype=np.float64)
        self.vo_r = np.array(st.vo_r, dtype=np.float64)
        self.vo_b = np.array(st.vertical_offset_uT, dtype=np.float64)
        self.vo_medians = []
        for rm in (st.raw_dip_med, st.raw_norm_med):
            self.vo_medians += [np.array(rm.counts, dtype=np.int64), np.array([rm.n], dtype=np.int64)]

    def run(self, kind, t, v, cal_ok, i0, tick_event, j0, out_q, out_acc_s2, out_mag_s2, out_mag_rej) -> int:
        """The kernel over events ``i0 .. len(t) - 1`` (pass the arrays cut short to stop earlier); returns the
        next grid tick."""
        return run_attitude(kind, t, v, cal_ok, i0, tick_event, j0, self.sf, self.si, self.fs, self.is_, self.q,
                            self.b, self.P, *self.medians, *self.windows, self.gated_t, self.gated_v,
                            out_q, out_acc_s2, out_mag_s2, out_mag_rej, self.acc_counts, self.acc_first,
                            self.mag_counts, self.mag_first, self.nis_sum, self.nis_n,
                            self.vo_S, self.vo_r, self.vo_i, self.vo_b, *self.vo_medians)

    def new_settings(self, ekf, refresh_references: bool) -> None:
        """``ekf``'s settings changed between two events (a site from GPS: declination, field): the kernel's
        settings again, and with ``refresh_references`` the references recomputed with the new declination,
        as the reference's ``declination_rad`` setter does (``_update_references``)."""
        self.sf, self.si = settings_arrays(ekf)
        if ekf.settings.mag_offset_sd_rad == 0.0 and len(self.P) == 7:  # the offset state dropped (outdoors)
            self.P = np.ascontiguousarray(self.P[0:6, 0:6])
            self.fs[F_MAG_OFFSET] = 0.0
        if refresh_references:
            update_references(self.fs, *self.medians, self.sf[S_DECL])

    def write_back(self, ekf) -> None:
        """The kernel's final state into the reference object (:meth:`AttitudeEKF.restore`), for its counters and
        the pipeline's labels.  Not written back: the trailing windows (the reference keeps its own from the
        hand-over) and what STATE_USE says the kernel does not keep."""
        st = ekf.snapshot()
        fs, is_, vo_i = self.fs, self.is_, self.vo_i
        for name, tp in _STATE_TYPES.items():
            how = STATE_USE[name]
            if how == "f":
                setattr(st, name, float(fs[FS[name]]))
            elif how == "f3?":
                k = FS[name + ".0"]
                setattr(st, name, tuple(float(x) for x in fs[k:k + 3]) if is_[IS["has:" + name]] else None)
            elif how == "sum":
                setattr(st, name, IntervalSum(**{n: (float(fs[FS[f"{name}.{n}"]]) if t == "float"
                                                     else int(is_[IS[f"{name}.{n}"]])) for n, t in _SUM_FIELDS}))
            elif how in ("i", "vo"):
                v = int((is_ if how == "i" else vo_i)[(IS if how == "i" else VO)[name]])
                setattr(st, name, bool(v) if tp == "bool" else v)
            elif how in ("i?", "vo?"):
                arr, slot = (is_, IS) if how == "i?" else (vo_i, VO)
                setattr(st, name, int(arr[slot[name]]) if arr[slot["has:" + name]] else None)
        st.q = tuple(float(x) for x in self.q)
        st.b = [float(x) for x in self.b]
        rows = self.P.tolist()
        st.P_tt = tuple(rows[0][0:3] + rows[1][0:3] + rows[2][0:3])
        st.P_tb = tuple(rows[0][3:6] + rows[1][3:6] + rows[2][3:6])
        st.P_bt = tuple(rows[3][0:3] + rows[4][0:3] + rows[5][0:3])
        st.P_bb = tuple(rows[3][3:6] + rows[4][3:6] + rows[5][3:6])
        if len(rows) == 7:
            st.P_to, st.P_bo, st.P_oo = tuple(rows[6][0:3]), tuple(rows[6][3:6]), float(rows[6][6])
        st.vo_S = self.vo_S.tolist()
        st.vo_r = self.vo_r.tolist()
        st.vertical_offset_uT = tuple(float(x) for x in self.vo_b)
        for rm, (counts, n) in zip((st.refs.g, st.refs.h, st.refs.dip, st.raw_dip_med, st.raw_norm_med),
                                   zip(*[iter(self.medians + self.vo_medians)] * 2)):
            rm.counts, rm.n = counts.tolist(), int(n[0])
        st.gated = [(int(self.gated_t[k]), float(self.gated_v[k])) for k in range(int(is_[I_GATED_N]))]
        for counts, first, names, reasons in ((self.acc_counts, self.acc_first, ACC_REASONS, st.acc_reasons),
                                              (self.mag_counts, self.mag_first, MAG_REASONS, st.mag_reasons)):
            for code in sorted((c for c in range(len(names)) if first[c] >= 0), key=lambda c: first[c]):
                reasons[names[code]] = reasons.get(names[code], 0) + int(counts[code])
        for k, kind_name in enumerate(("acc", "mag", "zero_rate")):
            st.nis_sum[kind_name] += float(self.nis_sum[k])
            st.nis_n[kind_name] += int(self.nis_n[k])
        ekf.restore(st)
