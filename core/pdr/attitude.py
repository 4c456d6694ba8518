"""Attitude and gyroscope bias of the phone: an error-state (multiplicative) EKF.

This is the product's attitude filter.  It keeps the measurement ideas of
Tian et al. 2014, section 4 -- gyroscope prediction (eqs. 5-7, 11), the
accelerometer and magnetometer as direction measurements (eqs. 12-15), the
adaptive noise of eqs. 17-18 -- but estimates the error of the attitude
instead of the quaternion itself, and adds the gyroscope bias to the state.
The paper's 4-state quaternion EKF stays available for comparison as
:class:`core.pdr.attitude_qekf.QuaternionEKF`.

State
=====
Nominal state: the attitude quaternion ``q`` (body -> ENU, see :mod:`core`)
and the gyroscope bias ``b`` (rad/s, body frame).  Error state (6)::

    dx = (dtheta_n, db),   R_true = exp([dtheta_n]x) R(q),   b_true = b + db

``dtheta_n`` is a small rotation expressed in the **navigation frame**, so
its third component is the heading error about Up and the first two are the
tilt: the magnetometer can be made to correct the heading alone, and the
accelerometer sees only the tilt.  (The paper's state is the quaternion
itself, whose 4 x 4 covariance is singular along ``q`` and mixes heading and
tilt.)  After each update the error is folded into the nominal state,
``q <- exp(dtheta_n / 2) (x) q``, ``b <- b + db``, and reset to zero.

Reset.  The update's estimate ``d = dtheta_n`` of the error leaves the true
error ``e = dtheta_n - d`` about it, with covariance ``P+``.  Folding ``d`` in
moves the nominal attitude to ``R+ = exp([d]x) R``; the error about the new
nominal, ``e+``, is defined by ``R_true = exp([e+]x) R+``, so
``exp([e+]x) = exp([d + e]x) exp(-[d]x)``.  To first order in ``e`` and
second in the rotations (Baker-Campbell-Hausdorff, ``[[a]x, [b]x] = [a x b]x``)::

    e+ = (d + e) - d + 1/2 (d + e) x (-d) = e + 1/2 d x e,   G = I + [d / 2]x

and ``P <- G P+ G^T`` with ``G = blockdiag(I + [d / 2]x, I)`` (the bias error is
additive, its reset the identity).  The sign is where our convention differs
from the usual one: with a body-frame error (``R_true = R exp([e]x)``, the
ESKF reset of Sola 2017, arXiv:1711.02508),
``exp([e+]x) = exp(-[d]x) exp([d + e]x)``, the commutator changes sign and
``G = I - [d / 2]x``.  The rest is the ``[d]x^2 / 6`` term of
SO(3)'s left Jacobian, about 3 % of the covariance at a 0.4 rad correction
(``tests/test_attitude_reset.py`` checks it against a Monte Carlo).

Prediction (eqs. 5-7 with the bias removed), on every gyroscope event with
the measured time step ``T``::

    q <- q (x) exp((w_meas - b) T / 2)
    F = [[I, -R T], [0, I]],   Q = diag(sigma_g^2 T I, sigma_bw^2 T I)
    P <- F P F^T + Q

since ``d(dtheta_n)/dt = -R db - R n_g`` and ``d(db)/dt = n_bw``.  ``sigma_g``
is the angle random walk (rad/sqrt(s)), ``sigma_bw`` the bias random walk
(rad/s/sqrt(s)).

Accelerometer (eqs. 12-13, 17): the unit specific force ``z = a / |a|``
against ``h = R^T u``, ``u = (0, 0, 1)``.  With the error above
``R_true^T u = R^T (I - [dtheta]x) u = h + R^T [u]x dtheta``, so::

    H = [R^T [u]x, 0]    (3 x 6; [u]x dtheta = u x dtheta)

``R = sigma_a^2 I`` with the adaptive ``sigma_a^2`` of eq. 17.  A direction
has two degrees of freedom: the innovation along ``h`` is second order, so
the expected normalised innovation squared (NIS) is 2.

Magnetometer, heading only (default, ``mag_mode="heading"``): the field is
rotated into the navigation frame, ``m_n = R m_b = (E, N, U)``, and its
horizontal direction ``alpha = atan2(N, E)`` is compared with that of the
reference ``h_n`` (eq. 14 turned by the declination).  Since
``m_n = h_n - dtheta x h_n`` to first order::

    y = wrap(alpha_ref - alpha_meas) = H dtheta,
    H = [-E U / (E^2 + N^2), -N U / (E^2 + N^2), 1, 0, 0, 0]

with noise ``sigma_m^2 / c^2`` (eq. 18's ``sigma_m^2`` of the unit vector,
``c`` = horizontal fraction of ``m_n``: the angle is that much noisier than
the vector).  The first two entries say how a tilt error moves the measured
azimuth (large at a steep dip); they enter the innovation covariance ``S``,
but the update is a *consider* (Schmidt) update: the gain's tilt rows are set
to zero and its bias rows are projected on the body-frame vertical, so a
magnetometer reading corrects the heading and the bias about the vertical,
never roll or pitch, however the field is bent.  The covariance uses the
Joseph form, which is right for any gain.  ``mag_mode="full"`` is the
paper's vector update (eq. 12 with ``v = h``; Jacobian as for the
accelerometer), kept for comparison.

Heading without a magnetometer: started without one (``use_magnetometer=False``
or no reading within ``mag_wait_s``), the heading is relative to
``initial_yaw_rad`` and nothing observes it.  The accelerometer's Jacobian with
respect to it is zero, but its correlation with the tilt and the bias would
let every tilt or zero-rate correction shrink its variance; so until a
magnetometer reading corrects it (:attr:`AttitudeEKF.yaw_unobserved`) those
updates treat it as a consider state: its gain row is zero and its variance
only grows.

Zero-rate update: when the phone has been truly still for
``still_window_s`` (accelerometer norm and direction steady, gyroscope spread
at its noise floor), the mean gyroscope reading over the window is a
measurement of the bias, ``z = b + n`` with ``H = [0, I]``.  A hand that
drifts slowly fails the direction test; the residual motion that passes is
covered by ``zero_rate_noise_rad_s``.

Magnetometer trust: a reading is used only if its norm is geomagnetic
(``mag_valid_range_uT``), its norm and dip are near the running references,
the field is quasi-static in the navigation frame (optional detector, see
:mod:`core.pdr.magcal`) and its NIS passes the gate.  Readings pass through
the online hard/soft-iron calibration first where one is given, and, outdoors
with the site's World Magnetic Model field, the removal of an offset along the
never-rotated vertical axis (:meth:`AttitudeEKF._vertical_offset`).  The
running references take a still phone's readings at most once a second.  When
the gate has rejected agreeing readings for ``mag_relock_s``, the estimate is
what is wrong: the heading is released and the next reading sets it.  Every
rejection is counted by reason (:attr:`AttitudeEKF.mag_reasons`).

Accelerometer and magnetometer readings are averaged over
``update_interval_s`` (0.1 s) into one update each: the walking hand's
linear acceleration and the bent field are correlated over a step, so one
update per reading would count them as hundreds of independent measurements.
The accelerometer noise adds a turn term ``k_a3 |w|^2`` to eq. 17 (the
centripetal acceleration of a turning walker).

A swinging phone (issue #25): a hand swinging at the side moves the phone on
an arc at the stride frequency; its tangential and centripetal acceleration
are as large as gravity (3 rad/s on a 0.6 m arm: 5 m/s^2 centripetal), so a
0.1-s mean of the specific force is no gravity direction, and the simulator's
swinging hand tilted the estimate by 20 deg (median) and let the heading
wander by 30 deg (SD), through the tilt's coupling into the magnetometer's
heading.  The phone comes back to where it was once per swing period, so in
the navigation frame its acceleration averages to zero over one period: while
the RMS rotation rate (a running mean of ``|w - b|^2`` over
``swing_rate_time_s``, 1 s) is above ``swing_rate_rad_s`` (2 rad/s: the
simulator's swing 2.4, a real trouser pocket 1.3, a phone held in the hand
0.3-0.7) for at least ``swing_min_s`` (5 s: putting the real tuning walk's
phone into the pocket turned it that fast for up to 4 s), the accelerometer's
interval is ``swing_update_interval_s`` (1 s, about a stride) instead: tilt
2 deg, heading SD 2 deg on the same walks (``tests/test_attitude_swing.py``).
Otherwise the filter is the one before, bit for bit.

The bias of a swinging phone without a magnetometer (issue #25 section 3, #27):
with no heading measurement the gyroscope bias is seen only through the tilt,
and a swinging phone's 0.1-s accelerometer means carry the arm's tangential
and centripetal acceleration, an error correlated over the swing that the
update's white noise (eq. 17 with the turn term) does not describe.  The
update then corrects part of that "tilt" into the bias (its tilt-bias
covariance is large while the phone turns fast), the phone's rotation carries
it onto the vertical, and nothing pulls it back: on the simulator's swinging
hand, 300 s without a magnetometer, the bias about the true vertical went 0.004-
0.025 rad/s off (true 0.0015) and the heading turned 8-56 deg/min.  Freezing
only the vertical component does not help (the horizontal components rotate
into it: 128 deg/min on the worst walk).  So while
:attr:`AttitudeEKF.yaw_unobserved` and the RMS rotation rate is above
``unobserved_bias_swing_rate_rad_s`` (1.5 rad/s: a swinging arm, not a pocket
or a hand; off by default, ``inf``: no real tuning walk shows a gain and the
two real report walks without a magnetometer got worse) the accelerometer update treats the whole bias as a consider state
(its gain rows zero, the Joseph form keeps the covariance right): the bias
keeps what the still start's zero-rate update and the slower motion learnt,
0.0015-0.0085 rad/s off about the vertical on the same walks, the heading
turning 1-27 deg/min (the rest: the swing's tilt error itself, and the still
start's zero-rate update reading a hanging hand's slow drift as bias, 0.008
rad/s on the worst two).  ``tests/test_attitude_swing.py``.

Noise floors that learn their scale (issue #27): the constant parts of the
noise -- the gyroscope's angle random walk and rate-proportional term, eq. 17's
``s_a0`` and turn term, eq. 18's ``s_m0`` -- were set for real phones indoors
(bent fields, scale-factor and timing errors), where the median NIS of the
heading updates sits at that of chi2(1).  A phone whose heading innovations are
smaller than those floors predict would be reported 2-3 times less certain than
it is (the simulator: heading NEES 0.27).  So all five are multiplied by one
scale ``kappa`` in ``[noise_scale_min, 1]``, moved after every heading update by
a quantile tracker, ``ln kappa += rate (1[NIS > 0.455] - 1/2)``: it settles
where half the NIS lie above chi2(1)'s median, is robust to the bent field's
heavy NIS tail, and never widens the floors (capped at 1).  eq. 17-18's
measured terms (``k_1`` deviation, ``k_2`` variance) are not scaled: they are
the phone's own evidence.  On the simulator ``kappa`` goes to its minimum and
the heading NEES is 0.91 (95 % band [0.72, 1.32], 84 epochs of 12 walks);
indoors it dips where the field is clean.  Off by default
(``noise_scale_rate = 0``, the floors as given): mixed on the IPIN tuning
split, its landmark error worse (see the setting).

The field's heading offset (issue #27, ``mag_offset_sd_rad > 0``, a 7th error
state): indoors a building bends the field's azimuth by 10-30 deg, alike over
metres (IPIN tuning routes: per-segment heading errors correlated over several
segments), which a white measurement noise cannot describe: the heading
follows each bent stretch and the vertical gyroscope bias learns its ramps.
The field's azimuth is modelled as ``alpha_ref + o``, ``o`` a first-order
Gauss-Markov process (stationary sd ``sigma_o``, correlation time ``tau``)::

    o <- phi o + w,   phi = exp(-T / tau),   var(w) = sigma_o^2 (1 - phi^2)

(the exact discretisation of ``do/dt = -o / tau + n``).  The heading update
becomes ``y = wrap(alpha_ref + o_hat - alpha_meas) = H dtheta - do`` (the
7th entry of ``H`` is -1, derived as above with the field turned by ``o``),
``F`` gets ``phi`` on the offset's diagonal and ``Q`` its ``var(w)``; the
offset is additive (its reset the identity).  Only the sum of heading and
offset is measured: which of the two takes a change is decided by their
dynamics -- the gyroscope's small random walk against the offset's -- so a
stretch of bent field (shorter than ``tau``) moves the offset, and the
heading follows the field only on average over ``tau``.  A relock releases
the heading and its covariance with the offset.  Outdoors (a site's field
given, :meth:`AttitudeEKF.set_site_field`) the state is dropped: no building
bends the field there.  The fast path mirrors it
(its kernel's covariance is 7 x 7 then).

A hole in the recording (issue #27, h13/gapatt): when every stream has been silent for longer than
``max_gyro_gap_s`` (a logger that stalled; RIDI's ``huayi_bag2`` has 4.4 s), nothing measured how the phone
turned.  The first event after it grows the tilt and heading variance once over the real elapsed time
(``no_gyro_random_walk_rad_sqrt_s``; the offset state decays over it) and drops what was collected before: the open
accelerometer and magnetometer intervals, whose readings were of the phone before the hole, rotated into the
navigation frame with the attitude it had then (closed by the first reading after it, eleven of them to one at
200 Hz, they measured the old attitude again as if new and took the hole's uncertainty back at once, so a phone
that had turned far in the hole had its first fresh magnetometer readings gated until the relock), and the relock's
gated innovations.  A gap of the gyroscope alone grows the variance only over the time the other streams' events
have not (it grew twice before); the events within 0.1 s of the last gyroscope reading do not grow it (as between
two gyroscope readings), so up to 0.1 s of such a gap is not grown (a 2-s gap: about 5 % less than the random walk
over it, where the double count made 94 % more).  Gaps one after another (a magnetometer alone at 1 Hz) are one
hole: the intervals opened after the first are kept.  :attr:`AttitudeEKF.counters` counts the holes.  No hole, no
change.  The growth is :class:`AttitudeFilterBase`'s, shared with the paper's
:class:`core.pdr.attitude_qekf.QuaternionEKF` (which grew twice too: a hole met first by the accelerometer, and a gap
of the gyroscope alone; it keeps no intervals to drop).

Replays (issue #27): ``AttitudeEKF(keep_history=True)`` keeps what the RTS
smoother needs (:mod:`core.pdr.heading_smoother`, ``Pipeline(heading_smoother=...)``);
the forward filter is the same bit for bit, and :meth:`AttitudeEKF.smoothed_heading`
runs the backward pass.  ``start_heading`` starts a second pass from a smoothed start.

Bad numbers: a non-finite input, or one no phone sensor gives (beyond 1e4 m/s^2,
1e3 rad/s, 1e6 uT), is skipped and counted; an update whose
correction or covariance would not be finite is discarded (the prior state
is kept) and counted.  Nothing non-finite ever enters the state.

Sign conventions: ENU with heading counter-clockwise from East, so a positive
``dtheta_n[2]`` turns the phone to the left and increases the heading.
"""

from __future__ import annotations

import math
import enum
from dataclasses import dataclass, field, fields, replace

import numpy as np

from core import kalman
from core import quaternion as quat
from core.conventions import STANDARD_GRAVITY_M_S2, wrap_angle
from core.kalman import skew  # noqa: F401  (re-exported: core.foot and older callers import it from here)
from core.dsp import RunningMedian, WindowMeanSpread, WindowVariance
from core.pdr.heading_smoother import AttitudeHistory, HeadingSmoothing, StartHeading

_I3 = np.eye(3)
_I3.flags.writeable = False
#: a bias axis of zero length: ``_correct(bias_axis=_ZERO3)`` corrects no bias component
_ZERO3 = np.zeros(3)
_ZERO3.flags.writeable = False
#: median of chi2 with 1 degree of freedom (scipy.stats.chi2.ppf(0.5, 1))
CHI2_1_MEDIAN = 0.454936423119572

#: per-component magnitudes no phone sensor reports (m/s^2, rad/s, uT): such readings are skipped like
#: non-finite ones (squared, they would overflow to inf and poison the running windows)
_ACC_IMPOSSIBLE = 1e4
_GYRO_IMPOSSIBLE = 1e3
_MAG_IMPOSSIBLE = 1e6


def _plausible(x: float, y: float, z: float, lim: float) -> bool:
    """All three finite and within +-lim (False for NaN too)."""
    return -lim <= x <= lim and -lim <= y <= lim and -lim <= z <= lim


def direction_jacobian(mat_nb, v_n) -> np.ndarray:
    """``d (R_true^T v) / d dtheta_n`` = ``R^T [v]x`` (3 x 3) for ``R_true = exp([dtheta]x) R``."""
    return np.asarray(mat_nb).T @ skew(v_n)


def heading_jacobian(m_n) -> np.ndarray:
    """``d alpha / d dtheta_n`` (3,) of the horizontal azimuth ``alpha = atan2(N, E)`` of ``R_true m_b``.

    ``alpha_meas = alpha_ref - H dtheta`` for ``m_n = R m_b`` (see the module docstring).
    """
    e, n, u = m_n
    h2 = e * e + n * n
    return np.array([-e * u / h2, -n * u / h2, 1.0])


# 3 x 3 matrices as 9-tuples (row-major) for the per-gyroscope-event prediction: plain floats, because
# numpy's per-call overhead (about a microsecond per operation) dominates at this size


def _sub_mm3(c, a, b) -> tuple:
    """``c - a @ b`` of 3 x 3 matrices given as 9-tuples (row-major)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (c[0] - (a0 * b0 + a1 * b3 + a2 * b6), c[1] - (a0 * b1 + a1 * b4 + a2 * b7),
            c[2] - (a0 * b2 + a1 * b5 + a2 * b8), c[3] - (a3 * b0 + a4 * b3 + a5 * b6),
            c[4] - (a3 * b1 + a4 * b4 + a5 * b7), c[5] - (a3 * b2 + a4 * b5 + a5 * b8),
            c[6] - (a6 * b0 + a7 * b3 + a8 * b6), c[7] - (a6 * b1 + a7 * b4 + a8 * b7),
            c[8] - (a6 * b2 + a7 * b5 + a8 * b8))


def _transpose3(a) -> tuple:
    return (a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8])


@dataclass(frozen=True)
class AttitudeSettings:
    """Settings of :class:`AttitudeEKF` (units in the names; unitless noise is of unit vectors).

    The defaults were chosen on the simulator and on the tuning split of the
    benchmark only (IPIN 2023 routes 01, 02, 21, 22; odd Microsoft traces):
    the noise of eqs. 17-18 so that the median NIS of walking updates equals
    the chi-square median of its dimension there (accelerometer 1.39 of 2 dof,
    magnetometer 0.42 of 1 dof); the gyroscope noise and the gates by a small
    grid search on the landmark and loop-closure errors (``benchmarks.tune``,
    see ``benchmarks/RESULTS.md``).
    """

    #: angle random walk of the gyroscope, widened for timing and vibration (rad/sqrt(s))
    gyro_noise_rad_sqrt_s: float = 0.002
    #: rate-proportional angle random walk (scale-factor and timing errors), per rad/s of rate (1/sqrt(s))
    gyro_scale_noise_sqrt_s: float = 0.01
    #: random walk of the gyroscope bias (rad/s/sqrt(s))
    gyro_bias_walk_rad_s_sqrt_s: float = 2e-5
    #: prior standard deviation of each bias component (rad/s)
    gyro_bias_sd_rad_s: float = 0.01
    #: the bias estimate is clamped to this magnitude per axis (rad/s)
    max_gyro_bias_rad_s: float = 0.1
    #: prior standard deviation of roll and pitch after initialisation (rad)
    initial_tilt_sd_rad: float = math.radians(3.0)
    #: prior standard deviation of the heading after initialisation from the magnetometer (rad)
    initial_yaw_sd_rad: float = math.radians(15.0)
    #: accelerometer and magnetometer readings are averaged over this long per update (s)
    update_interval_s: float = 0.1
    #: a swinging phone (issue #25): while the RMS rotation rate (the running mean of the squared rate over
    #: ``swing_rate_time_s``) is above ``swing_rate_rad_s``, the accelerometer is averaged over
    #: ``swing_update_interval_s`` per update instead (about a stride: see "A swinging phone" in the module
    #: docstring); ``inf``: never, the default: the rule helped the simulator's swinging hand (step heading error
    #: 36 -> 3 deg) but no real tuning walk swings, and on the IPIN tuning routes the compass-calibration waving
    #: trips it (loop closure 4.01 -> 4.18 %); 2.0 is the value measured with
    swing_rate_rad_s: float = math.inf
    swing_rate_time_s: float = 1.0
    swing_update_interval_s: float = 1.0
    #: ... once the rate has stayed above ``swing_rate_rad_s`` this long (s): a walk swings for minutes, a phone
    #: being handled (taken out, put into a pocket) turns as fast for a few seconds
    swing_min_s: float = 5.0
    #: without a magnetometer (while :attr:`AttitudeEKF.yaw_unobserved`) and while the RMS rotation rate (the
    #: running mean of ``swing_rate_time_s``) is above this, the accelerometer update does not correct the gyroscope
    #: bias (a consider state: its gain rows are zero); see "The bias of a swinging phone without a magnetometer" in
    #: the module docstring.  1.5 rad/s: a swinging arm (the simulator's 2.4), not a trouser pocket (1.3) nor a
    #: phone held in the hand (0.3-0.7); ``inf``: never, **the default** (h11/swingbias, the lead's review): the
    #: simulator's defect is fixed, but the real TUNING split shows no gain (identical: no tuning walk swings), so the
    #: rule of real tuning data keeps it off; disclosed, the two REPORT walks it was built for, seen once, got worse
    #: with it (liatoutou_walk2 reversed steps 35 -> 49 %, 3-min 113 -> 132 %; bahramib_walk_beni1 11.5 -> 18.1 %)
    unobserved_bias_swing_rate_rad_s: float = math.inf
    #: eq. 17: s_a0 (base sd of the unit accelerometer vector), k_a1 (per m/s^2), k_a2 (per (m/s^2)^2)
    acc_noise_base: float = 0.0025
    k_a1: float = 0.001
    k_a2: float = 0.002
    #: not in the paper: weight of the squared rotation rate (per (rad/s)^2): a turning walker's
    #: centripetal acceleration (v w) and the hand's rotation tilt the specific force
    k_a3: float = 0.004
    #: eq. 18: s_m0 (base sd of the unit magnetometer vector), k_m1 (per uT), k_m2 (per uT^2)
    mag_noise_base: float = 0.019
    k_m1: float = 0.00045
    k_m2: float = 0.0009
    #: trailing window of the variances of eqs. 17-18 (s)
    variance_window_s: float = 1.0
    #: accelerometer readings whose norm is further than this from |g| are not used (m/s^2)
    acc_reject_m_s2: float = 4.0
    #: accelerometer updates with a larger NIS (2 dof) are not used
    acc_gate_nis: float = 50.0
    #: "heading": the magnetometer corrects heading and vertical bias only; "full": the paper's eq. 12
    mag_mode: str = "heading"
    #: with a quasi-static field detector: readings it does not call steady get this many times the
    #: variance (inf: they are not used)
    mag_unsteady_noise_scale: float = math.inf
    #: with a calibrator: use no reading before its first accepted fit (for uncalibrated streams)
    mag_requires_calibration: bool = False
    #: magnetometer readings with | |m| - |h| | > ratio |h| are not used
    mag_reject_ratio: float = 0.4
    #: magnetometer readings whose dip differs from the reference by more than this are not used (rad)
    mag_reject_dip_rad: float = math.radians(23.0)
    #: readings outside this range are no geomagnetic field at all (the Earth's is 22-67 uT) (uT)
    mag_valid_range_uT: tuple = (10.0, 150.0)
    #: heading updates with a larger NIS (1 dof) are not used
    mag_gate_nis: float = 9.0
    #: when every heading update of this long was gated and their innovations agree within
    #: ``mag_relock_spread_rad``, the heading estimate (not the field) is wrong: the heading is
    #: released (its variance set to pi^2) so the next reading sets it (s)
    mag_relock_s: float = 3.0
    mag_relock_spread_rad: float = math.radians(10.0)
    #: the references |g|, |h| and dip are running medians of every reading, refreshed this often (s)
    reference_update_s: float = 1.0
    #: while the phone is still, magnetometer readings enter the references at most this often (Hz); inf (the
    #: default since issue #27's ablation, benchmarks/ABLATION_RESULTS.md): no limit -- at 1 Hz it changed
    #: nothing on the tuning split and the ETH walk it was made for did better without it (18.6 against 19.3 m)
    reference_still_rate_hz: float = math.inf
    #: magnetic declination, east of true north positive (rad); 0: headings relative to magnetic north
    declination_rad: float = 0.0
    #: the site's field strength (uT) and dip (rad, below the horizontal positive) from the World
    #: Magnetic Model (core.geodesy.magnetic_field), for walks outdoors (where the location is known
    #: from a good GPS fix); nan: unknown or indoors.  With them, an offset along the never-rotated
    #: (vertical) body axis is estimated (see _vertical_offset)
    site_field_uT: float = math.nan
    site_dip_rad: float = math.nan
    #: the vertical offset is removed only while the readings' median dip is this far off the site's (rad)
    vertical_offset_dip_error_rad: float = math.radians(30.0)
    #: ... and their median strength this far off (fraction of the site's): both are signs of a
    #: miscalibration, where a bent indoor field moves one or the other
    vertical_offset_norm_error: float = 0.3
    #: ... and only after this long with readings (s): a short stretch determines no offset
    vertical_offset_min_s: float = 60.0
    #: ridge of the vertical-offset least squares, as a fraction of the mean excitation
    vertical_offset_ridge: float = 0.01
    #: heading of the device y axis at the start when there is no magnetometer (rad, CCW from East)
    initial_yaw_rad: float = math.pi / 2
    #: False ignores magnetometer events (heading relative to the start)
    use_magnetometer: bool = True
    #: wait this long for a first magnetometer reading before starting without one (s)
    mag_wait_s: float = 1.0
    #: a zero-rate update needs the phone still for this long (s)
    still_window_s: float = 2.0
    #: stillness: accelerometer norm sd (m/s^2), direction spread (rad), gyroscope per-axis sd (rad/s)
    still_acc_sd_m_s2: float = 0.05
    still_acc_direction_rad: float = math.radians(0.3)
    still_gyro_sd_rad_s: float = 0.005
    #: motion left in a "still" phone that the zero-rate update allows for (rad/s)
    zero_rate_noise_rad_s: float = 0.002
    #: the noise floors (gyro_noise_rad_sqrt_s, gyro_scale_noise_sqrt_s, acc_noise_base, k_a3, mag_noise_base) are
    #: wide, for real phones indoors; all five are multiplied by a scale ``kappa`` in [noise_scale_min, 1] that the
    #: filter learns from its heading updates: after each, ``ln kappa += rate (1[NIS > chi2_1 median] - 1/2)``, so
    #: kappa settles where the median NIS is that of chi2(1) (issue #27: a cleaner phone than the floors assume
    #: reports a heading sigma as small as its errors).  0 (the default): the floors as given.  At 0.05 the
    #: heading NEES on the simulator is 0.91 (band [0.72, 1.32]); the IPIN TUNING split was mixed (landmark median
    #: 2.52 -> 2.55 m, worse; loop closure 4.60 -> 3.96 %, better), and the landmark error is #27's headline: off.
    #: The REPORT split, seen afterwards, was worse on both (landmark 2.00 -> 2.50 m, loop 4.88 -> 6.46 %;
    #: benchmarks/ABLATION_RESULTS.md)
    noise_scale_rate: float = 0.0
    noise_scale_min: float = 1e-3
    #: the indoor field's heading offset (issue #27): a building bends the field's azimuth by 10-30 deg, alike over
    #: metres; the heading update measures ``heading + offset``, the offset a Gauss-Markov state of this stationary
    #: sd (rad) and correlation time (s), so a bent stretch pulls the offset before the heading and the vertical
    #: gyroscope bias (see the module docstring).  0: no offset state (the field's error is white).  Chosen on the
    #: IPIN TUNING split (reference engine, PDR alone; without it landmark median 2.52 m, loop closure 4.60 %):
    #: (0.1, 30 s) 2.29 m / 4.01 % (means 3.71 -> 3.36 m, 5.40 -> 4.96 %: the largest sum of the four relative
    #: gains, and the only real gain in landmark error); (0.07, 45) 2.49 / 3.54,
    #: (0.1, 60) 2.52 / 3.91, (0.17, 60) 2.52 / 3.34, (0.17, 30) 2.39 / 4.90, (0.1, 90) 2.66 / 3.95,
    #: (0.17, 120) 2.73 / 4.11, (0.26, 20) 3.00 / 5.94, (0.26, 60) 3.35 / 4.03, (0.35, 10) 3.54 / 6.20
    mag_offset_sd_rad: float = 0.1
    mag_offset_time_s: float = 30.0
    #: gyroscope gaps longer than this are not integrated, only the uncertainty grows (s); every stream silent
    #: this long is a hole in the recording (see the module docstring): the open intervals are dropped too
    max_gyro_gap_s: float = 0.5
    #: attitude random walk assumed while no gyroscope event comes (rad/sqrt(s))
    no_gyro_random_walk_rad_sqrt_s: float = 0.5

    def __post_init__(self):
        if self.mag_mode not in ("heading", "full"):
            raise ValueError(f"mag_mode must be 'heading' or 'full', not {self.mag_mode!r}")
        if not (self.mag_offset_sd_rad >= 0.0 and math.isfinite(self.mag_offset_sd_rad)):
            raise ValueError(f"mag_offset_sd_rad must be a number >= 0, not {self.mag_offset_sd_rad!r}")
        for name in ("gyro_noise_rad_sqrt_s", "acc_noise_base", "mag_noise_base", "variance_window_s",
                     "still_window_s", "reference_update_s", "mag_offset_time_s", "swing_rate_time_s",
                     "swing_update_interval_s"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be a positive number, not {v!r}")


class Outcome(enum.Enum):
    """What one accelerometer or magnetometer reading did (:attr:`UpdateFlags.outcome`).

    The filter decides on these; the counters (:attr:`AttitudeEKF.acc_reasons`, ``mag_reasons``) and
    :attr:`UpdateFlags.reason` carry their text.
    """

    USED = "used"  #: used (the magnetometer's: also while its interval is still open)
    PENDING = "pending"  #: an accelerometer reading in an interval still open
    INITIALISING = "initialising"  #: before the filter's start
    NON_FINITE = "non-finite"  #: not finite, or beyond any phone sensor's range
    NORM_OFF = "norm off"  #: its norm too far from the reference's
    GATE = "gate"  #: its update's NIS beyond the gate
    NUMERICAL = "numerical"  #: its update would not have been finite
    MAGNETOMETER_OFF = "magnetometer off"
    CALIBRATING = "calibrating"  #: the online calibration has no fit yet (``mag_requires_calibration``)
    INVALID_RANGE = "invalid range"  #: no geomagnetic field (``mag_valid_range_uT``)
    NOT_QUASI_STATIC = "not quasi-static"  #: the field detector does not call it steady
    DIP_OFF = "dip off"  #: its dip too far from the reference's
    FIELD_VERTICAL = "field vertical"  #: the field nearly vertical: no azimuth to measure
    NONE_YET = "none yet"  #: no reading yet


_VERDICT_OUTCOME = {kalman.Verdict.USED: Outcome.USED, kalman.Verdict.GATE: Outcome.GATE,
                    kalman.Verdict.NUMERICAL: Outcome.NUMERICAL}


@dataclass(frozen=True)
class UpdateFlags:
    """What one measurement did (returned by every ``update_*`` call)."""

    kind: str  #: "acc", "mag" or "zero_rate"
    t_ns: int
    used: bool
    reason: str  #: the outcome's text, "used" or why not (see :attr:`AttitudeEKF.mag_reasons`), with any detail
    nis: float = math.nan  #: normalised innovation squared (nan when not computed)
    dof: int = 0  #: its expected value when the filter is consistent
    sigma2: float = math.nan  #: measurement variance used (eqs. 17-18; heading: of the angle, rad^2)
    innovation: tuple = ()
    outcome: Outcome | None = None  #: ``reason`` as an :class:`Outcome` (without its detail)

    def __init__(self, kind: str, t_ns: int, used: bool, reason: str, nis: float = math.nan, dof: int = 0,
                 sigma2: float = math.nan, innovation: tuple = (), outcome: Outcome | None = None):
        # one is made per accelerometer and magnetometer event: filling __dict__ at once is about twice
        # as fast as the frozen dataclass's generated __init__ (one object.__setattr__ per field)
        self.__dict__.update(kind=kind, t_ns=t_ns, used=used, reason=reason, nis=nis, dof=dof, sigma2=sigma2,
                             innovation=innovation, outcome=outcome)


@dataclass(frozen=True)
class AttitudeStatus:
    """A snapshot of the filter: state, uncertainty and counters."""

    t_ns: int | None
    initialized: bool
    q_wxyz: tuple
    gyro_bias_rad_s: tuple
    gyro_bias_sd_rad_s: tuple
    tilt_sd_rad: float  #: sqrt of the larger tilt variance
    heading_sd_rad: float
    mag_trusted: bool  #: whether the last magnetometer reading was used
    counters: dict = field(default_factory=dict)


class FieldReferences:
    """|g|, |h| and the magnetic dip as running medians of the readings (used by both attitude filters)."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.g = RunningMedian(0.0, 40.0, 0.01)
        self.reset_field()

    def reset_field(self) -> None:
        self.h = RunningMedian(0.0, 200.0, 0.1)
        self.dip = RunningMedian(-math.pi / 2, math.pi / 2, math.radians(0.1))

    def add_acc(self, acc) -> None:
        self.g.add(math.sqrt(acc[0] ** 2 + acc[1] ** 2 + acc[2] ** 2))

    def add_mag(self, acc, mag) -> None:
        """A magnetometer reading and the accelerometer reading beside it (dip against the measured "up")."""
        na = math.sqrt(acc[0] ** 2 + acc[1] ** 2 + acc[2] ** 2)
        nm = math.sqrt(mag[0] ** 2 + mag[1] ** 2 + mag[2] ** 2)
        if na > 0 and nm > 0:
            sin_dip = -(acc[0] * mag[0] + acc[1] * mag[1] + acc[2] * mag[2]) / (na * nm)
            self.dip.add(math.asin(max(-1.0, min(1.0, sin_dip))))
            self.h.add(nm)


@dataclass(slots=True)
class IntervalSum:
    """Running sums of one ``update_interval_s`` of readings rotated into the navigation frame."""

    x: float
    y: float
    z: float
    sigma2: float  #: sum of the readings' variances (eqs. 17-18)
    n: int  #: readings in the interval
    t0_ns: int  #: time of its first reading

    @classmethod
    def empty(cls) -> IntervalSum:
        return cls(0.0, 0.0, 0.0, 0.0, 0, 0)


@dataclass(slots=True)
class AttitudeBaseState:
    """What both attitude filters keep for their start, references and time (see :class:`AttitudeFilterBase`)."""

    initialized: bool
    n_skipped_nonfinite: int  #: readings skipped as non-finite or beyond any phone sensor's range
    t_ns: int | None  #: time of the state
    t_gyro_ns: int | None  #: time of the last gyroscope event
    acc_reading: tuple | None  #: the last accelerometer reading (m/s^2)
    mag_reading: tuple | None  #: the last magnetometer reading used (uT)
    first_acc_ns: int | None  #: first accelerometer reading while waiting for a magnetometer
    ref_next_ns: int | None  #: next refresh of the references
    refs: FieldReferences
    gravity_m_s2: float  #: reference |g|
    field_uT: float  #: reference |h| (nan before any reading)
    dip_rad: float  #: reference dip (nan before any reading)
    q: tuple  #: attitude quaternion body -> ENU (w, x, y, z)

    @classmethod
    def initial(cls) -> AttitudeBaseState:
        return cls(initialized=False, n_skipped_nonfinite=0, t_ns=None, t_gyro_ns=None, acc_reading=None,
                   mag_reading=None, first_acc_ns=None, ref_next_ns=None, refs=FieldReferences(),
                   gravity_m_s2=STANDARD_GRAVITY_M_S2, field_uT=math.nan, dip_rad=math.nan, q=(1.0, 0.0, 0.0, 0.0))


@dataclass(slots=True)
class AttitudeState(AttitudeBaseState):
    """Everything :class:`AttitudeEKF` changes as events come: its only state, made by :meth:`initial`.

    Read and set from outside only through :meth:`AttitudeEKF.snapshot` and
    :meth:`AttitudeEKF.restore` (the fast path hands it to its kernel and back).
    """

    b: list  #: gyroscope bias (rad/s, body frame)
    #: error-state covariance as four 3 x 3 blocks (row-major 9-tuples): tilt-heading, cross, its transpose, bias
    P_tt: tuple
    P_tb: tuple
    P_bt: tuple
    P_bb: tuple
    acc_var: WindowVariance  #: eq. 17's trailing variance of |a|
    mag_var: WindowVariance  #: eq. 18's trailing variance of |m|
    gyro_win: WindowMeanSpread  #: stillness: gyroscope mean and spread
    accdir_win: WindowMeanSpread  #: stillness: accelerometer direction spread
    acc_norm_win: WindowVariance  #: stillness: accelerometer norm spread
    next_zero_rate_ns: int | None
    ref_still_next_ns: int | None
    #: vertical hard-iron offset from the site's field (see AttitudeEKF._vertical_offset): normal equations,
    #: next refresh, first reading, whether on, the raw dip and strength medians, the offset removed (uT)
    vo_S: list
    vo_r: list
    vo_next_ns: int | None
    vo_t0_ns: int | None
    vo_active: bool
    raw_dip_med: RunningMedian
    raw_norm_med: RunningMedian
    vertical_offset_uT: tuple
    h_ref: tuple  #: reference field direction (eq. 14 turned by the declination)
    alpha_ref: float  #: its azimuth (rad)
    w2: float  #: squared rotation rate of the last gyroscope event ((rad/s)^2)
    w2_mean: float  #: running mean of ``w2`` over ``swing_rate_time_s`` ((rad/s)^2)
    swing_s: float  #: how long ``w2_mean`` has been above ``swing_rate_rad_s ** 2`` without a break (s)
    acc_sum: IntervalSum
    mag_sum: IntervalSum
    gated: list  #: (t_ns, innovation) of heading updates gated since the last one used
    n_heading_relocks: int
    n_holes: int  #: holes in the recording bridged (every stream silent for over ``max_gyro_gap_s``)
    #: the last event came after a hole or a stretch of such gaps (a magnetometer alone at 1 Hz): the intervals
    #: opened since hold readings of the phone after the hole, kept
    hole_open: bool
    #: no magnetometer reading has corrected the heading since the start without one (see AttitudeEKF._correct)
    yaw_unobserved: bool
    acc_sigma2: float  #: diagnostics: the last measurement variances (eqs. 17-18)
    mag_sigma2: float
    mag_rejected: bool
    acc_rejected: bool
    last_acc: UpdateFlags
    last_mag: UpdateFlags
    mag_reasons: dict
    acc_reasons: dict
    n_gyro: int
    n_zero_rate: int
    n_numerical_rejects: int
    nis_sum: dict
    nis_n: dict
    #: the noise floors' scale kappa (see AttitudeSettings.noise_scale_rate)
    noise_scale: float
    #: the field's heading offset (rad, see AttitudeSettings.mag_offset_sd_rad), its covariance with the
    #: tilt-heading and bias errors (3-tuples) and its variance; all zero without the offset state
    mag_offset_rad: float
    P_to: tuple
    P_bo: tuple
    P_oo: float

    @classmethod
    def initial(cls, settings: AttitudeSettings) -> AttitudeState:  # type: ignore[override]
        s = settings
        rows = np.diag([s.initial_tilt_sd_rad ** 2] * 2 + [s.initial_yaw_sd_rad ** 2]
                       + [s.gyro_bias_sd_rad_s ** 2] * 3).tolist()
        base = AttitudeBaseState.initial()
        return cls(
            **{f.name: getattr(base, f.name) for f in fields(AttitudeBaseState)},
            b=[0.0, 0.0, 0.0],
            P_tt=tuple(rows[0][0:3] + rows[1][0:3] + rows[2][0:3]),
            P_tb=tuple(rows[0][3:6] + rows[1][3:6] + rows[2][3:6]),
            P_bt=tuple(rows[3][0:3] + rows[4][0:3] + rows[5][0:3]),
            P_bb=tuple(rows[3][3:6] + rows[4][3:6] + rows[5][3:6]),
            acc_var=WindowVariance(s.variance_window_s), mag_var=WindowVariance(s.variance_window_s),
            gyro_win=WindowMeanSpread(s.still_window_s), accdir_win=WindowMeanSpread(s.still_window_s),
            acc_norm_win=WindowVariance(s.still_window_s), next_zero_rate_ns=None, ref_still_next_ns=None,
            vo_S=[[0.0] * 3 for _ in range(3)], vo_r=[0.0, 0.0, 0.0], vo_next_ns=None, vo_t0_ns=None,
            vo_active=False, raw_dip_med=RunningMedian(-math.pi / 2, math.pi / 2, math.radians(0.1)),
            raw_norm_med=RunningMedian(0.0, 200.0, 0.1), vertical_offset_uT=(0.0, 0.0, 0.0),
            h_ref=(0.0, 1.0, 0.0), alpha_ref=math.pi / 2, w2=0.0, w2_mean=0.0, swing_s=0.0,
            acc_sum=IntervalSum.empty(), mag_sum=IntervalSum.empty(), gated=[], n_heading_relocks=0, n_holes=0,
            hole_open=False,
            yaw_unobserved=False, acc_sigma2=math.nan, mag_sigma2=math.nan, mag_rejected=False,
            acc_rejected=False, last_acc=UpdateFlags("acc", 0, False, Outcome.NONE_YET.value, outcome=Outcome.NONE_YET),
            last_mag=UpdateFlags("mag", 0, False, Outcome.NONE_YET.value, outcome=Outcome.NONE_YET),
            mag_reasons={}, acc_reasons={},
            n_gyro=0, n_zero_rate=0, n_numerical_rejects=0,
            nis_sum={"acc": 0.0, "mag": 0.0, "zero_rate": 0.0}, nis_n={"acc": 0, "mag": 0, "zero_rate": 0},
            noise_scale=1.0, mag_offset_rad=0.0, P_to=(0.0, 0.0, 0.0), P_bo=(0.0, 0.0, 0.0),
            P_oo=s.mag_offset_sd_rad ** 2)


class AttitudeFilterBase:
    """What both attitude filters share: the start from TRIAD, the field references, time keeping, ``run``.

    A subclass provides ``_param(name)`` (its setting ``mag_wait_s``,
    ``reference_update_s``, ``initial_yaw_rad``, ``use_magnetometer``, ``max_gyro_gap_s``),
    ``_random_walk(dt)`` (covariance growth without a gyroscope),
    ``_set_field_reference()`` (its reference field from ``field_uT`` and
    ``dip_rad``) and may override ``_start_heading(q, from_mag)`` and
    ``_mag_reference_due(t_ns)``.
    """

    _state: AttitudeBaseState

    def _reset_common(self) -> None:
        self._state = AttitudeBaseState.initial()
        self._forget_matrix()

    def _forget_matrix(self) -> None:
        #: :meth:`matrix`'s cache: the last matrix and the quaternion object it is of
        self._R_q = self._R = None

    # -- read-only views of the state (set it through snapshot() / restore()) ---------------------
    @property
    def q(self) -> tuple:
        """Attitude quaternion body -> ENU (w, x, y, z)."""
        return self._state.q

    @q.setter
    def q(self, q) -> None:
        self._state.q = tuple(q)

    initialized = property(lambda self: self._state.initialized)
    t_ns = property(lambda self: self._state.t_ns, doc="Time of the state (ns).")
    n_skipped_nonfinite = property(lambda self: self._state.n_skipped_nonfinite,
                                   doc="Readings skipped as non-finite or beyond any phone sensor's range.")
    gravity_m_s2 = property(lambda self: self._state.gravity_m_s2, doc="Reference |g| (m/s^2).")
    field_uT = property(lambda self: self._state.field_uT, doc="Reference |h| (uT; nan before any reading).")
    dip_rad = property(lambda self: self._state.dip_rad, doc="Reference dip (rad; nan before any reading).")

    def _start_heading(self, q, from_mag: bool):
        """The initial attitude as the filter keeps it (default: as TRIAD gives it)."""
        return q

    def _try_initialize(self, t_ns: int) -> None:
        """Start from the latest accelerometer and magnetometer readings (TRIAD), or after ``mag_wait_s``
        without a magnetometer from gravity and ``initial_yaw_rad``."""
        state = self._state
        acc = state.acc_reading
        if acc is None:
            return
        use_mag = self._param("use_magnetometer")
        mag = state.mag_reading if use_mag else None
        if use_mag and mag is None:
            if state.first_acc_ns is None:
                state.first_acc_ns = t_ns
            if t_ns - state.first_acc_ns < self._param("mag_wait_s") * 1e9:
                return  # wait a little for a magnetometer reading; then start without one
        try:
            if mag is not None:
                q = quat.from_two_vectors_enu(acc, mag)
            else:
                q = quat.from_gravity_yaw(acc, self._param("initial_yaw_rad"))
        except ValueError:
            return
        state.q = self._start_heading(q, mag is not None)
        state.initialized = True
        state.t_ns = t_ns
        self._update_references()

    def _mag_reference_due(self, t_ns: int) -> bool:
        return True

    def _accumulate_references(self, t_ns: int, acc=None, mag=None) -> None:
        """Collect |a|, |m| and the dip angle; refresh the references every ``reference_update_s``."""
        state = self._state
        if acc is not None:
            state.refs.add_acc(acc)
        if mag is not None and state.acc_reading is not None and self._mag_reference_due(t_ns):
            state.refs.add_mag(state.acc_reading, mag)
        if (state.ref_next_ns is None or t_ns >= state.ref_next_ns
                or (state.refs.h.n and state.field_uT != state.field_uT)):
            state.ref_next_ns = t_ns + int(self._param("reference_update_s") * 1e9)
            self._update_references()

    def _update_references(self) -> None:
        refs = self._state.refs
        if refs.g.n:
            self._state.gravity_m_s2 = refs.g.median()
        if refs.h.n:
            self._state.field_uT = refs.h.median()
            self._state.dip_rad = refs.dip.median()
        self._set_field_reference()

    def _propagate_without_gyro(self, t_ns: int) -> None:
        """A measurement at ``t_ns``: without a gyroscope event for 0.1 s, only the uncertainty grows."""
        state = self._state
        if state.t_ns is None:
            state.t_ns = t_ns
            return
        last = state.t_gyro_ns
        if last is None or t_ns - last > 100_000_000:
            dt = (t_ns - state.t_ns) * 1e-9
            if dt > 0:
                self._random_walk(dt)
        state.t_ns = max(state.t_ns, t_ns)

    def _grow_over_hole(self, t_ns: int) -> bool:
        """A hole in the recording before ``t_ns`` -- every stream silent for longer than ``max_gyro_gap_s`` --
        grows the uncertainty once over the real elapsed time (``_random_walk``) and moves the state's time to
        ``t_ns``, whichever stream's event comes first after it (the others then find nothing left to grow).
        True if it was a hole (see the module docstring)."""
        state = self._state
        if state.t_ns is None or (t_ns - state.t_ns) * 1e-9 <= self._param("max_gyro_gap_s"):
            return False
        self._random_walk((t_ns - state.t_ns) * 1e-9)
        state.t_ns = t_ns
        return True

    def _grow_over_gyro_gap(self, t_ns: int) -> None:
        """A gyroscope event after a gap of its own (longer than ``max_gyro_gap_s``): no stale rate is integrated,
        the uncertainty grows over the time not yet propagated -- the other streams' events in the gap (or a hole)
        grew it up to the state's time already -- so once over the real elapsed time, but for the events within
        0.1 s of the last gyroscope reading, which moved the state's time without growing it
        (:meth:`_propagate_without_gyro`)."""
        rest = (t_ns - self._state.t_ns) * 1e-9
        if rest > 0.0:
            self._random_walk(rest)
        self._state.t_ns = t_ns

    def run(self, recording) -> tuple[np.ndarray, np.ndarray]:
        """Attitude after every event of a :class:`core.recording.Recording` (gyro, acc, mag in time order).

        The same kernel as streaming; returns ``(t_ns (n,), q_wxyz (n, 4))``
        with NaN rows before the filter has initialised.
        """
        self.reset()
        names = [n for n in ("gyro", "acc", "mag") if recording.has(n)]
        handlers = {"gyro": self.predict, "acc": self.update_acc, "mag": self.update_mag}
        t_out, q_out = [], []
        nan4 = (math.nan,) * 4
        for name, t, v in recording.events(names):
            handlers[name](t, v[0], v[1], v[2])
            t_out.append(t)
            q_out.append(self._state.q if self._state.initialized else nan4)
        return np.array(t_out, dtype=np.int64), np.array(q_out, dtype=float).reshape(-1, 4)

    def matrix(self):
        """Current rotation matrix body -> ENU (3 row tuples).

        Kept while ``q`` is the same object (a tuple: never changed in place, only replaced): between two
        changes of the attitude it is asked for several times (the next prediction, the accelerometer and
        magnetometer updates, the heading smoother).  The cache is no state: a function of ``q`` alone."""
        q = self._state.q
        if q is not self._R_q:
            self._R = quat.to_matrix(q)
            self._R_q = q
        return self._R


class AttitudeEKF(AttitudeFilterBase, kalman.StateSnapshots):
    """Error-state EKF of the attitude and gyroscope bias (see the module docstring).

    Feed events in time order: :meth:`predict` (gyroscope), :meth:`update_acc`,
    :meth:`update_mag`.  The filter initialises itself from the first
    accelerometer and magnetometer readings (TRIAD) and owns its state.

    Parameters
    ----------
    settings : AttitudeSettings, optional
        All settings; keyword arguments override single fields
        (``AttitudeEKF(declination_rad=0.04)``).
    mag_calibrator : optional
        Online hard/soft-iron calibration (:class:`core.pdr.magcal.MagCalibrator`):
        each magnetometer reading goes through its ``update`` first.
    field_detector : optional
        Quasi-static field detector (:class:`core.pdr.magcal.QuasiStaticField`):
        readings it does not call steady are not used.
    """

    State = AttitudeState

    def __init__(self, settings: AttitudeSettings | None = None, *, mag_calibrator=None, field_detector=None,
                 keep_history: bool = False, **overrides):
        s = settings or AttitudeSettings()
        if overrides:
            s = replace(s, **overrides)
        self.settings = s
        self.mag_calibrator = mag_calibrator
        self.field_detector = field_detector
        #: replays only: keep what the RTS heading smoother needs (:mod:`core.pdr.heading_smoother`) from each
        #: :meth:`reset` on; :meth:`smoothed_heading` runs it.  The forward filter is the same either way.
        self.keep_history = bool(keep_history)
        #: replays only (``Pipeline(heading_smoother="start")``): the start as a smoother saw it, or None -- the
        #: heading taken from the magnetometer turned by ``correction_rad``, its prior sd ``sd_rad``, and (with the
        #: field offset state) the offset's start value and sd: a :class:`core.pdr.heading_smoother.StartHeading`
        self.start_heading: StartHeading | None = None
        self.reset()

    # -- read-only views of settings that the pipeline asks for -------------------------------
    @property
    def use_magnetometer(self) -> bool:
        return self.settings.use_magnetometer

    @use_magnetometer.setter
    def use_magnetometer(self, on: bool) -> None:
        self.settings = replace(self.settings, use_magnetometer=bool(on))

    @property
    def initial_yaw_rad(self) -> float:
        return self.settings.initial_yaw_rad

    @property
    def declination_rad(self) -> float:
        return self.settings.declination_rad

    @declination_rad.setter
    def declination_rad(self, d: float) -> None:
        self.settings = replace(self.settings, declination_rad=float(d))
        self._update_references()

    def set_site_field(self, field_uT: float, dip_rad: float) -> None:
        """The site's field strength (uT) and dip (rad) from the World Magnetic Model, for a walk outdoors.

        Only outdoors is the WMM field the field the phone sees (a live app
        knows it is outdoors from a good GPS fix); indoors a building's steel
        bends it by tens of per cent and degrees, and the vertical-offset
        estimate it drives (see the settings) would be wrong: leave it unset there.

        Outdoors: :meth:`set_outdoors` as well.
        """
        self.settings = replace(self.settings, site_field_uT=float(field_uT), site_dip_rad=float(dip_rad))
        self.set_outdoors()

    def set_outdoors(self) -> None:
        """The walk is outdoors (a good GPS fix says so), with or without the site's WMM field.

        No building bends the field there: the field's heading offset state (``mag_offset_sd_rad``) is
        dropped (its estimate and covariance; the error state is 6 again).
        """
        self.settings = replace(self.settings, mag_offset_sd_rad=0.0)
        st = self._state
        st.mag_offset_rad, st.P_to, st.P_bo, st.P_oo = 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0

    @property
    def P(self) -> np.ndarray:
        """Error-state covariance (6 x 6), a new array each time: change it by assigning ``ekf.P = ...``.

        Kept as four 3 x 3 blocks of plain floats (tilt-heading, cross, its transpose, bias): the
        prediction runs on every gyroscope event, where numpy's per-call overhead outweighs the arithmetic.
        """
        tt, tb, bt, bb = self._state.P_tt, self._state.P_tb, self._state.P_bt, self._state.P_bb
        return np.array((tt[0:3] + tb[0:3], tt[3:6] + tb[3:6], tt[6:9] + tb[6:9],
                         bt[0:3] + bb[0:3], bt[3:6] + bb[3:6], bt[6:9] + bb[6:9]))

    @P.setter
    def P(self, P) -> None:
        self._set_blocks(np.asarray(P, dtype=np.float64).reshape(6, 6).tolist())

    def _set_blocks(self, rows: list) -> None:
        """The covariance's four 3 x 3 blocks from its first six rows (lists of floats, 6 or more columns)."""
        self._state.P_tt = tuple(rows[0][0:3] + rows[1][0:3] + rows[2][0:3])
        self._state.P_tb = tuple(rows[0][3:6] + rows[1][3:6] + rows[2][3:6])
        self._state.P_bt = tuple(rows[3][0:3] + rows[4][0:3] + rows[5][0:3])
        self._state.P_bb = tuple(rows[3][3:6] + rows[4][3:6] + rows[5][3:6])

    @property
    def has_mag_offset(self) -> bool:
        """Whether the error state has the field's heading offset (``mag_offset_sd_rad > 0``): 7 states, else 6."""
        return self.settings.mag_offset_sd_rad > 0.0

    @property
    def P_full(self) -> np.ndarray:
        """The whole error-state covariance: :attr:`P` with the field's heading offset as a 7th state (when on)."""
        if not self.has_mag_offset:
            return self.P
        # one array from the blocks' floats (per update: a 6 x 6 array copied into a 7 x 7 costs more)
        st = self._state
        tt, tb, bt, bb, to, bo = st.P_tt, st.P_tb, st.P_bt, st.P_bb, st.P_to, st.P_bo
        return np.array((tt[0:3] + tb[0:3] + to[0:1], tt[3:6] + tb[3:6] + to[1:2], tt[6:9] + tb[6:9] + to[2:3],
                         bt[0:3] + bb[0:3] + bo[0:1], bt[3:6] + bb[3:6] + bo[1:2], bt[6:9] + bb[6:9] + bo[2:3],
                         to + bo + (st.P_oo,)), dtype=np.float64)

    @P_full.setter
    def P_full(self, Pf) -> None:
        rows = np.asarray(Pf, dtype=np.float64).tolist()
        self._set_blocks(rows)
        if len(rows) == 7:
            st = self._state
            st.P_to = (rows[0][6], rows[1][6], rows[2][6])
            st.P_bo = (rows[3][6], rows[4][6], rows[5][6])
            st.P_oo = rows[6][6]

    mag_offset_rad = property(lambda self: self._state.mag_offset_rad,
                              doc="The field's heading offset estimate (rad; 0 without the offset state).")

    def reset(self) -> None:
        self._state = AttitudeState.initial(self.settings)
        self._forget_matrix()
        #: the forward run kept for the replay's heading smoother (None unless ``keep_history``)
        self.history = AttitudeHistory() if self.keep_history else None

    def smoothed_heading(self) -> HeadingSmoothing:
        """The RTS-smoothed heading of the run so far (:class:`core.pdr.heading_smoother.HeadingSmoothing`)."""
        if self.history is None:
            raise ValueError("no history: make the filter with keep_history=True before the run")
        return self.history.smooth()

    # -- read-only views of the state -------------------------------------------------------------
    @property
    def b(self) -> list:
        """Gyroscope bias estimate (rad/s, body frame)."""
        return self._state.b

    @b.setter
    def b(self, b) -> None:
        self._state.b = [float(v) for v in b]

    yaw_unobserved = property(lambda self: self._state.yaw_unobserved,
                              doc="No magnetometer reading has corrected the heading since a start without one.")
    vertical_offset_uT = property(lambda self: self._state.vertical_offset_uT,
                                  doc="Hard-iron offset removed by _vertical_offset (uT, body frame; zero while off).")
    n_heading_relocks = property(lambda self: self._state.n_heading_relocks)
    acc_sigma2 = property(lambda self: self._state.acc_sigma2)
    mag_sigma2 = property(lambda self: self._state.mag_sigma2)
    mag_rejected = property(lambda self: self._state.mag_rejected)
    acc_rejected = property(lambda self: self._state.acc_rejected)
    last_acc = property(lambda self: self._state.last_acc, doc="What the last accelerometer reading did.")
    last_mag = property(lambda self: self._state.last_mag, doc="What the last magnetometer reading did.")
    mag_reasons = property(lambda self: self._state.mag_reasons, doc="Magnetometer readings counted by outcome.")
    acc_reasons = property(lambda self: self._state.acc_reasons, doc="Accelerometer readings counted by outcome.")
    n_gyro = property(lambda self: self._state.n_gyro)
    n_zero_rate = property(lambda self: self._state.n_zero_rate)
    n_numerical_rejects = property(lambda self: self._state.n_numerical_rejects)

    # -- counters kept for the pipeline's summary -----------------------------------------------
    @property
    def n_mag_used(self) -> int:
        return self._state.mag_reasons.get(Outcome.USED.value, 0)

    @property
    def n_mag_rejected(self) -> int:
        skip = (Outcome.USED.value, Outcome.INITIALISING.value)
        return sum(v for k, v in self._state.mag_reasons.items() if k not in skip)

    @property
    def n_acc_rejected(self) -> int:
        return sum(v for k, v in self._state.acc_reasons.items() if k != Outcome.USED.value)

    @property
    def gyro_bias(self) -> tuple:
        return tuple(self._state.b)

    def mean_nis(self) -> dict:
        """Mean NIS per measurement kind over the updates computed so far (nan where none)."""
        return {k: (self._state.nis_sum[k] / n if n else math.nan) for k, n in self._state.nis_n.items()}

    def counters(self) -> dict:
        c = {"mag_used": self.n_mag_used, "mag_rejected": self.n_mag_rejected,
             "acc_rejected": self.n_acc_rejected, "zero_rate_updates": self._state.n_zero_rate,
             "nonfinite_skipped_by_filter": self._state.n_skipped_nonfinite,
             "numerical_rejects": self._state.n_numerical_rejects, "heading_relocks": self._state.n_heading_relocks,
             "holes": self._state.n_holes,
             "mag_reasons": dict(self._state.mag_reasons), "mean_nis": self.mean_nis(),
             "gyro_bias_rad_s": list(self._state.b), "vertical_offset_uT": list(self._state.vertical_offset_uT), "heading_sd_rad": math.sqrt(max(float(self.P[2, 2]), 0.0))}
        if self.mag_calibrator is not None:
            st = self.mag_calibrator.status
            c["mag_calibration"] = getattr(st, "state", str(st))
        return c

    def status(self) -> AttitudeStatus:
        P = self.P
        return AttitudeStatus(self._state.t_ns, self._state.initialized, self._state.q, tuple(self._state.b),
                              tuple(math.sqrt(max(P[i, i], 0.0)) for i in (3, 4, 5)),
                              math.sqrt(max(P[0, 0], P[1, 1], 0.0)), math.sqrt(max(P[2, 2], 0.0)),
                              not self._state.mag_rejected and self.n_mag_used > 0, self.counters())

    # -- initialisation ---------------------------------------------------------------------------
    def _param(self, name: str):
        return getattr(self.settings, name)

    def _start_heading(self, q, from_mag: bool):
        """Turn TRIAD's magnetic north to true north; the heading's prior variance."""
        # without a magnetometer reading the heading is relative to initial_yaw_rad by definition; a
        # magnetometer that starts later is let in by the relock (see _relock)
        P = self.P
        start = self.start_heading if from_mag else None
        turn, sd = (start.correction_rad, start.sd_rad) if start is not None else (0.0, math.nan)
        P[2, 2] = (sd if sd == sd else self.settings.initial_yaw_sd_rad if from_mag else 1e-3) ** 2
        self.P = P
        if start is not None and self.has_mag_offset and start.offset_sd_rad == start.offset_sd_rad:
            self._state.mag_offset_rad, self._state.P_oo = start.offset_rad, start.offset_sd_rad ** 2
        self._state.yaw_unobserved = not from_mag
        if not from_mag:
            return q
        return quat.multiply(quat.from_axis_angle((0.0, 0.0, 1.0), turn - self.settings.declination_rad), q)

    def _mag_reference_due(self, t_ns: int) -> bool:
        """Magnetometer readings of a still phone enter the references at most ``reference_still_rate_hz``.

        A phone left on a table for minutes would otherwise set |h| and the dip
        to the table's field (the ETH walk starts with 100 s of that, at 13 uT
        against the 22 uT of the walk, and the walk's readings were then
        rejected as "norm off").
        """
        w = self._state.acc_norm_win
        still = len(w.buf) >= 5 and w.variance() < self.settings.still_acc_sd_m_s2 ** 2
        if not still or self._state.refs.h.n == 0:
            return True
        if self._state.ref_still_next_ns is not None and t_ns < self._state.ref_still_next_ns:
            return False
        self._state.ref_still_next_ns = t_ns + int(1e9 / self.settings.reference_still_rate_hz)
        return True

    def _set_field_reference(self) -> None:
        dip = self._state.dip_rad if self._state.dip_rad == self._state.dip_rad else math.radians(60.0)
        c, sn = math.cos(dip), math.sin(dip)
        d = self.settings.declination_rad
        # eq. 14, turned by the declination: magnetic north lies D east of true north
        self._state.h_ref = (c * math.sin(d), c * math.cos(d), -sn)
        self._state.alpha_ref = math.atan2(math.cos(d), math.sin(d))

    # -- prediction -------------------------------------------------------------------------------
    def predict(self, t_ns: int, wx: float, wy: float, wz: float) -> None:
        """Propagate with one gyroscope event (rad/s) over the time since the previous one."""
        state = self._state
        if not _plausible(wx, wy, wz, _GYRO_IMPOSSIBLE):
            state.n_skipped_nonfinite += 1
            return
        state.n_gyro += 1
        state.gyro_win.update(t_ns, (wx, wy, wz))
        if not state.initialized:
            state.t_gyro_ns = t_ns
            return
        s = self.settings
        self._bridge_hole(t_ns)
        t_prev = state.t_gyro_ns if state.t_gyro_ns is not None else state.t_ns
        state.t_gyro_ns = t_ns
        dt = (t_ns - t_prev) * 1e-9
        if dt <= 0.0:
            return
        if dt > s.max_gyro_gap_s:  # a gap: do not integrate a stale rate over it, grow the uncertainty once
            self._grow_over_gyro_gap(t_ns)
            return
        b = state.b
        w = ((wx - b[0]) * dt, (wy - b[1]) * dt, (wz - b[2]) * dt)
        (r0, r1, r2), (r3, r4, r5), (r6, r7, r8) = self.matrix()
        state.q = quat.normalize(quat.multiply(state.q, quat.from_rotation_vector(w)))  # eq. 7
        # F = [[I, -R dt], [0, I]] written out: P <- F P F^T + Q, on the covariance's 3 x 3 blocks in
        # plain floats (9-tuples: numpy's per-call overhead dominates for such sizes)
        Rdt = (r0 * dt, r1 * dt, r2 * dt, r3 * dt, r4 * dt, r5 * dt, r6 * dt, r7 * dt, r8 * dt)
        bb = state.P_bb
        A = _sub_mm3(state.P_tt, Rdt, state.P_bt)
        B = _sub_mm3(state.P_tb, Rdt, bb)
        p0, p1, p2, p3, p4, p5, p6, p7, p8 = _sub_mm3(A, B, (r0 * dt, r3 * dt, r6 * dt, r1 * dt, r4 * dt, r7 * dt,
                                                              r2 * dt, r5 * dt, r8 * dt))  # A - B Rdt^T
        w2 = (wx - b[0]) ** 2 + (wy - b[1]) ** 2 + (wz - b[2]) ** 2
        state.w2 = w2
        state.w2_mean += (1.0 - math.exp(-dt / s.swing_rate_time_s)) * (w2 - state.w2_mean)
        state.swing_s = state.swing_s + dt if state.w2_mean > s.swing_rate_rad_s ** 2 else 0.0
        qg = (s.gyro_noise_rad_sqrt_s ** 2 + s.gyro_scale_noise_sqrt_s ** 2 * w2) * state.noise_scale * dt
        qb = s.gyro_bias_walk_rad_s_sqrt_s ** 2 * dt
        state.P_tt = (p0 + qg, p1, p2, p3, p4 + qg, p5, p6, p7, p8 + qg)
        state.P_tb = B
        state.P_bt = _transpose3(B)
        state.P_bb = (bb[0] + qb, bb[1], bb[2], bb[3], bb[4] + qb, bb[5], bb[6], bb[7], bb[8] + qb)
        if s.mag_offset_sd_rad > 0.0:
            # the offset's row of F is (0, 0, phi): P_to <- (P_to - R dt P_bo) phi (with the P_bo before this step)
            to, bo = state.P_to, state.P_bo
            phi = math.exp(-dt / s.mag_offset_time_s)
            state.P_to = (phi * (to[0] - (Rdt[0] * bo[0] + Rdt[1] * bo[1] + Rdt[2] * bo[2])),
                          phi * (to[1] - (Rdt[3] * bo[0] + Rdt[4] * bo[1] + Rdt[5] * bo[2])),
                          phi * (to[2] - (Rdt[6] * bo[0] + Rdt[7] * bo[1] + Rdt[8] * bo[2])))
            self._decay_offset(phi, cross=False)
        if self.history is not None:
            self.history.add_prediction(Rdt, phi if s.mag_offset_sd_rad > 0.0 else 1.0)
        state.t_ns = t_ns

    def _bridge_hole(self, t_ns: int) -> None:
        """A hole in the recording: every stream silent for longer than ``max_gyro_gap_s`` before ``t_ns``.

        The phone may have turned any way in it, and nothing measured how: the attitude's uncertainty grows
        over the real elapsed time (``no_gyro_random_walk_rad_sqrt_s``, once), and what was collected before
        the hole is dropped -- the open accelerometer and magnetometer intervals (readings of the phone before
        the hole, rotated into the navigation frame with the attitude it had then: closed by the first reading
        after it, they would measure the old attitude again as if it were new, and at 200 Hz with eleven
        readings to one) and the relock's gated innovations (of the heading before the hole).  The first
        readings after the hole then meet an honest covariance.  No hole: nothing happens.  Gaps that follow one
        another (a magnetometer alone at 1 Hz while the other streams are silent) are one hole: after the first,
        the uncertainty still grows over each, but the intervals (of readings since the hole) are kept, so such a
        stream still closes its intervals and updates.
        """
        state = self._state
        if state.t_ns is None:
            return
        # no hole, the common case: _grow_over_hole's test written out here (two calls fewer on every event)
        if (t_ns - state.t_ns) * 1e-9 <= self.settings.max_gyro_gap_s or not self._grow_over_hole(t_ns):
            state.hole_open = False
            return
        if state.hole_open:
            return
        state.hole_open = True
        state.acc_sum = IntervalSum.empty()
        state.mag_sum = IntervalSum.empty()
        state.gated = []
        state.n_holes += 1

    def _random_walk(self, dt: float) -> None:
        P = self.P
        P[0:3, 0:3] += (self.settings.no_gyro_random_walk_rad_sqrt_s ** 2 * dt) * _I3
        self.P = P
        phi = math.exp(-dt / self.settings.mag_offset_time_s) if self.has_mag_offset else 1.0
        if self.has_mag_offset:
            self._decay_offset(phi, cross=True)
        if self.history is not None:
            self.history.add_prediction(None, phi)

    def _decay_offset(self, phi: float, cross: bool) -> None:
        """The field's heading offset over one step of its Gauss-Markov process, ``o <- phi o + w``,
        ``phi = exp(-dt / tau)``, ``var(w) = sigma_o^2 (1 - phi^2)`` (first-order Gauss-Markov, exact
        discretisation): the estimate decays towards 0 and its variance towards ``sigma_o^2``.  ``cross``:
        scale its covariances with the other states by ``phi`` too (where their rows of F are the identity)."""
        state = self._state
        state.mag_offset_rad *= phi
        if cross:
            to = state.P_to
            state.P_to = (phi * to[0], phi * to[1], phi * to[2])
        bo = state.P_bo
        state.P_bo = (phi * bo[0], phi * bo[1], phi * bo[2])  # written out: once per gyroscope sample
        state.P_oo = phi * phi * state.P_oo + self.settings.mag_offset_sd_rad ** 2 * (1.0 - phi * phi)

    # -- the update kernel ----------------------------------------------------------------------
    def _correct(self, y: np.ndarray, H: np.ndarray, Rm: np.ndarray, gate: float, *, consider_tilt=False,
                 bias_axis=None, measures_yaw=False):
        """Kalman update of the error state; returns (used, :class:`Outcome`, nis).  ``H`` (m x 6), ``Rm`` (m x m).

        While :attr:`yaw_unobserved` (started without a magnetometer, none used since), an update that
        does not measure the heading (``measures_yaw`` False: accelerometer, zero rate) leaves the
        heading a consider state: its gain row is zero, so neither the heading nor its variance moves.
        Its Jacobian is zero, but its correlation with the tilt and the bias would otherwise let every
        tilt or bias correction shrink the heading's variance, where nothing observes the heading.
        """
        yaw_consider = self._state.yaw_unobserved and not measures_yaw

        def adjust(K):
            if consider_tilt:  # Schmidt update: roll and pitch are not corrected by this measurement
                K[0:2, :] = 0.0
            if yaw_consider:  # Schmidt update: the heading is not corrected (see the docstring)
                K[2, :] = 0.0
            if bias_axis is not None:  # only the bias component about this body axis
                K[3:6, :] = np.outer(bias_axis, bias_axis @ K[3:6, :])

        Pf = self.P_full
        if H.shape[1] < len(Pf):  # a measurement of the first 6 states only: the offset's column is zero
            H = np.hstack((H, np.zeros((len(H), len(Pf) - H.shape[1]))))
        c = kalman.correct(Pf, y, H, Rm, gate, adjust_gain=adjust)
        if c.verdict is kalman.Verdict.NUMERICAL:
            self._state.n_numerical_rejects += 1
        if not c.used:
            return False, _VERDICT_OUTCOME[c.verdict], c.nis
        self._inject(c.dx, c.P, keep_yaw=yaw_consider)
        if measures_yaw:
            self._state.yaw_unobserved = False
        return True, Outcome.USED, c.nis

    def _jacobian(self, m: int) -> np.ndarray:
        """A zero measurement Jacobian of ``m`` rows over the whole error state (7 columns with the offset)."""
        return np.zeros((m, 7 if self.has_mag_offset else 6))

    def _inject(self, dx: np.ndarray, Pn: np.ndarray, keep_yaw: bool = False) -> None:
        """Fold the error into ``q`` and ``b`` and reset it: ``P <- G P G^T`` (:func:`core.kalman.reset_jacobian`,
        ``G = I + [dtheta / 2]x`` for this navigation-frame error; derived in the module docstring)."""
        state = self._state
        if self.history is not None:
            self.history.before_inject(state.t_ns, self.P_full)
        d = dx.tolist()  # plain floats: what follows is per-element arithmetic
        dth = (d[0], d[1], d[2])
        state.q = kalman.inject_rotation(state.q, dth)
        lim = self.settings.max_gyro_bias_rad_s
        b = state.b
        state.b = [min(lim, max(-lim, b[0] + d[3])), min(lim, max(-lim, b[1] + d[4])),
                   min(lim, max(-lim, b[2] + d[5]))]
        if len(d) == 7:  # the field's heading offset: additive, its reset the identity
            state.mag_offset_rad += d[6]
        G = kalman.reset_jacobian(dth, len(dx))
        if keep_yaw:  # a consider heading is carried, not re-linearised: its row stays the identity's
            G[2, 0:2] = 0.0
        self.P_full = kalman.reset_covariance(Pn, dth, G=G)
        if self.history is not None:
            self.history.after_inject(state.t_ns, dx, G, self.P_full, state.q, state.mag_offset_rad)

    def _record(self, kind: str, used: bool, nis: float) -> None:
        if nis == nis:
            self._state.nis_sum[kind] += nis
            self._state.nis_n[kind] += 1

    # -- accelerometer ----------------------------------------------------------------------------
    def update_acc(self, t_ns: int, ax: float, ay: float, az: float) -> UpdateFlags:
        """Accelerometer reading (m/s^2, gravity included): eq. 17, averaged over ``update_interval_s``.

        Each reading is rotated into the navigation frame with the current
        attitude and summed; once per interval the mean specific force
        ``f_n`` gives one direction update ``z = R^T f_n / |f_n|``.  The
        linear acceleration of a walking hand is correlated over a step, so
        updating with every reading at 50-400 Hz would count it as hundreds
        of independent measurements: one update per interval keeps the NIS
        meaningful and the filter the same at every sample rate.
        """
        state = self._state
        if not _plausible(ax, ay, az, _ACC_IMPOSSIBLE):
            state.n_skipped_nonfinite += 1
            return self._acc_flags(t_ns, False, Outcome.NON_FINITE)
        s = self.settings
        state.acc_reading = (ax, ay, az)
        self._accumulate_references(t_ns, acc=state.acc_reading)
        na = math.sqrt(ax * ax + ay * ay + az * az)
        if na > 0:
            state.accdir_win.update(t_ns, (ax / na, ay / na, az / na))
        state.acc_norm_win.update(t_ns, na)
        if not state.initialized:
            self._try_initialize(t_ns)
            return self._acc_flags(t_ns, False, Outcome.INITIALISING)
        self._bridge_hole(t_ns)
        self._propagate_without_gyro(t_ns)
        self._maybe_zero_rate(t_ns)
        var = state.acc_var.update(t_ns, na)
        dev = abs(na - state.gravity_m_s2)
        # eq. 17 (+ turn term; the floors scaled by kappa)
        sigma2 = (s.acc_noise_base ** 2 + s.k_a3 * state.w2) * state.noise_scale + s.k_a1 * dev + s.k_a2 * var
        state.acc_sigma2 = sigma2
        if dev > s.acc_reject_m_s2 or na == 0.0:
            return self._acc_flags(t_ns, False, Outcome.NORM_OFF, sigma2=sigma2)
        acc = state.acc_sum
        R = self.matrix()
        r0, r1, r2 = R
        if acc.n == 0:
            acc.t0_ns = t_ns
        # f_n = R a, written out (a comprehension over range(3) costs more than its arithmetic)
        acc.x += r0[0] * ax + r0[1] * ay + r0[2] * az
        acc.y += r1[0] * ax + r1[1] * ay + r1[2] * az
        acc.z += r2[0] * ax + r2[1] * ay + r2[2] * az
        acc.sigma2 += sigma2
        acc.n += 1
        # a swinging phone: one update per swing period, over which the swing's own acceleration averages out
        interval = s.swing_update_interval_s if state.swing_s >= s.swing_min_s else s.update_interval_s
        if (t_ns - acc.t0_ns) * 1e-9 < interval:
            return self._acc_flags(t_ns, True, Outcome.PENDING, sigma2=sigma2)
        n = acc.n
        fx, fy, fz = acc.x / n, acc.y / n, acc.z / n
        sigma2 = acc.sigma2 / n
        state.acc_sum = IntervalSum.empty()
        nf = math.sqrt(fx * fx + fy * fy + fz * fz)
        if nf == 0.0:
            return self._acc_flags(t_ns, False, Outcome.NORM_OFF, sigma2=sigma2)
        z = tuple(R[0][j] * fx + R[1][j] * fy + R[2][j] * fz for j in range(3))  # R^T f_n
        h = (R[2][0], R[2][1], R[2][2])  # R^T u: the third row of R
        y = np.array((z[0] / nf - h[0], z[1] / nf - h[1], z[2] / nf - h[2]))
        H = self._jacobian(3)
        H[:, 0:3] = direction_jacobian(R, (0.0, 0.0, 1.0))
        # nothing measures the heading and the phone swings: the bias is a consider state (see the setting)
        frozen = state.yaw_unobserved and state.w2_mean > s.unobserved_bias_swing_rate_rad_s ** 2
        used, outcome, nis = self._correct(y, H, sigma2 * _I3, s.acc_gate_nis,
                                           bias_axis=_ZERO3 if frozen else None)
        self._record("acc", used, nis)
        return self._acc_flags(t_ns, used, outcome, nis=nis, sigma2=sigma2, innovation=tuple(y.tolist()))

    def _acc_flags(self, t_ns, used, outcome: Outcome, **kw) -> UpdateFlags:
        state = self._state
        state.acc_rejected = not used
        key = outcome.value  # text only here, at the edge: the counters are keyed by it
        state.acc_reasons[key] = state.acc_reasons.get(key, 0) + 1
        state.last_acc = UpdateFlags("acc", t_ns, used, key, dof=2, outcome=outcome, **kw)
        return state.last_acc

    def _maybe_zero_rate(self, t_ns: int) -> None:
        """Zero-rate update from the mean gyroscope reading when the phone is truly still."""
        state = self._state
        s = self.settings
        g = state.gyro_win
        if not g.buf or (state.next_zero_rate_ns is not None and t_ns < state.next_zero_rate_ns):
            return
        # the cheap tests first, the spans and the norm's spread (it fails on almost every sample of a walk), then
        # the windows' statistics: the tests have no side effects, so in any order they decide the same
        if g.span_ns() < 0.95 * g.window_ns or state.accdir_win.span_ns() < 0.95 * g.window_ns:
            return
        if len(state.acc_norm_win.buf) < 5 or math.sqrt(state.acc_norm_win.variance()) > s.still_acc_sd_m_s2:
            return
        mean, sd, _ = g.stats()
        if sd > s.still_gyro_sd_rad_s:
            return
        _, dir_sd, _ = state.accdir_win.stats()
        if dir_sd > s.still_acc_direction_rad:
            return
        n = len(g.buf)
        r2 = sd * sd / n + s.zero_rate_noise_rad_s ** 2
        y = np.array([mean[i] - state.b[i] for i in range(3)])
        H = self._jacobian(3)
        H[:, 3:6] = _I3
        used, _, nis = self._correct(y, H, r2 * _I3, math.inf)
        self._record("zero_rate", used, nis)
        if used:
            state.n_zero_rate += 1
        state.next_zero_rate_ns = t_ns + g.window_ns  # independent windows

    # -- magnetometer -----------------------------------------------------------------------------
    def update_mag(self, t_ns: int, mx: float, my: float, mz: float) -> UpdateFlags:
        """Magnetometer reading (uT): calibration, trust tests, then one heading (or full) update per interval.

        Trusted readings are rotated into the navigation frame and averaged
        over ``update_interval_s``, as for the accelerometer.
        """
        state = self._state
        s = self.settings
        if not s.use_magnetometer:
            return self._mag_flags(t_ns, False, Outcome.MAGNETOMETER_OFF)
        if not _plausible(mx, my, mz, _MAG_IMPOSSIBLE):
            state.n_skipped_nonfinite += 1
            return self._mag_flags(t_ns, False, Outcome.NON_FINITE)
        if self.mag_calibrator is not None:
            m = self.mag_calibrator.update(t_ns, mx, my, mz)
            if s.mag_requires_calibration and not self.mag_calibrator.calibrated:
                return self._mag_flags(t_ns, False, Outcome.CALIBRATING)
            mx, my, mz = float(m[0]), float(m[1]), float(m[2])
        nm = math.sqrt(mx * mx + my * my + mz * mz)
        lo, hi = s.mag_valid_range_uT
        if not lo <= nm <= hi:
            return self._mag_flags(t_ns, False, Outcome.INVALID_RANGE)
        R = self.matrix()
        if state.initialized and s.site_field_uT == s.site_field_uT and s.site_dip_rad == s.site_dip_rad:
            mx, my, mz = self._vertical_offset(t_ns, R, mx, my, mz)
            nm = math.sqrt(mx * mx + my * my + mz * mz)
        state.mag_reading = (mx, my, mz)
        self._accumulate_references(t_ns, mag=state.mag_reading)
        if not state.initialized:
            self._try_initialize(t_ns)
            return self._mag_flags(t_ns, False, Outcome.INITIALISING)
        self._bridge_hole(t_ns)
        self._propagate_without_gyro(t_ns)
        var = state.mag_var.update(t_ns, nm)
        dev = abs(nm - state.field_uT)
        sigma2 = s.mag_noise_base ** 2 * state.noise_scale + s.k_m1 * dev + s.k_m2 * var  # eq. 18 (floor scaled)
        state.mag_sigma2 = sigma2
        up_b = (R[2][0], R[2][1], R[2][2])
        sin_dip = -(up_b[0] * mx + up_b[1] * my + up_b[2] * mz) / nm
        dip = math.asin(max(-1.0, min(1.0, sin_dip)))
        if self.field_detector is not None:
            st = self.field_detector.update(t_ns, (mx, my, mz), state.q)
            if not st.trusted:
                if not math.isfinite(s.mag_unsteady_noise_scale):
                    return self._mag_flags(t_ns, False, Outcome.NOT_QUASI_STATIC, sigma2=sigma2, detail=st.reason)
                sigma2 *= s.mag_unsteady_noise_scale
        if dev > s.mag_reject_ratio * state.field_uT:
            return self._mag_flags(t_ns, False, Outcome.NORM_OFF, sigma2=sigma2)
        if abs(dip - state.dip_rad) > s.mag_reject_dip_rad:
            return self._mag_flags(t_ns, False, Outcome.DIP_OFF, sigma2=sigma2)
        acc = state.mag_sum
        if acc.n == 0:
            acc.t0_ns = t_ns
        inv = 1.0 / nm
        r0, r1, r2 = R
        # the unit field in the navigation frame, written out (a loop over range(3) costs more than its sums)
        acc.x += (r0[0] * mx + r0[1] * my + r0[2] * mz) * inv
        acc.y += (r1[0] * mx + r1[1] * my + r1[2] * mz) * inv
        acc.z += (r2[0] * mx + r2[1] * my + r2[2] * mz) * inv
        acc.sigma2 += sigma2
        acc.n += 1
        if (t_ns - acc.t0_ns) * 1e-9 < s.update_interval_s:
            return self._mag_flags(t_ns, True, Outcome.USED, sigma2=sigma2)
        n = acc.n
        m_n = (acc.x / n, acc.y / n, acc.z / n)
        sigma2 = acc.sigma2 / n
        state.mag_sum = IntervalSum.empty()
        if s.mag_mode == "full":
            h = state.h_ref
            nmn = math.sqrt(m_n[0] ** 2 + m_n[1] ** 2 + m_n[2] ** 2)
            hb = tuple(R[0][j] * h[0] + R[1][j] * h[1] + R[2][j] * h[2] for j in range(3))  # R^T h
            zb = tuple((R[0][j] * m_n[0] + R[1][j] * m_n[1] + R[2][j] * m_n[2]) / nmn for j in range(3))
            y = np.array((zb[0] - hb[0], zb[1] - hb[1], zb[2] - hb[2]))
            H = self._jacobian(3)
            H[:, 0:3] = direction_jacobian(R, h)
            used, outcome, nis = self._correct(y, H, sigma2 * _I3, s.mag_gate_nis + 4.0, measures_yaw=True)
            self._record("mag", used, nis)
            return self._mag_interval_done(t_ns, n, used, outcome, nis=nis, dof=2, sigma2=sigma2,
                                           innovation=tuple(y.tolist()))
        h2 = m_n[0] ** 2 + m_n[1] ** 2
        c2 = h2 / (h2 + m_n[2] ** 2)
        if c2 < 0.01:  # field nearly vertical: no azimuth to measure
            return self._mag_interval_done(t_ns, n, False, Outcome.FIELD_VERTICAL, sigma2=sigma2)
        offset = self.has_mag_offset
        # with the offset state the field's azimuth is alpha_ref + o: y = H dtheta - do (H's 7th entry -1)
        y = np.array([wrap_angle(state.alpha_ref + state.mag_offset_rad - math.atan2(m_n[1], m_n[0]))])
        H = self._jacobian(1)
        H[0, 0:3] = heading_jacobian(m_n)
        if offset:
            H[0, 6] = -1.0
        r_angle = sigma2 / c2
        used, outcome, nis = self._correct(y, H, np.array([[r_angle]]), s.mag_gate_nis, consider_tilt=True,
                                          bias_axis=np.array(up_b), measures_yaw=True)
        self._record("mag", used, nis)
        self._adapt_noise_scale(nis)
        if used:
            state.gated = []
        elif outcome is Outcome.GATE:
            self._relock(t_ns, float(y[0]))
        return self._mag_interval_done(t_ns, n, used, outcome, nis=nis, dof=1, sigma2=r_angle,
                                       innovation=(float(y[0]),))

    def _adapt_noise_scale(self, nis: float) -> None:
        """One step of the noise floors' scale towards the median NIS of chi2(1) (a quantile tracker, robust to
        the bent field's heavy tail; capped at 1: the floors are never widened)."""
        s = self.settings
        if not (nis == nis) or s.noise_scale_rate <= 0.0:
            return
        state = self._state
        k = state.noise_scale * math.exp(s.noise_scale_rate * (0.5 if nis > CHI2_1_MEDIAN else -0.5))
        state.noise_scale = min(1.0, max(s.noise_scale_min, k))

    def mag_not_calibrated(self, t_ns: int) -> UpdateFlags:
        """A magnetometer reading left out because its calibration has no fit yet (``mag_requires_calibration``):
        what :meth:`update_mag` does with it, for a caller that ran the calibrator beforehand (the fast path)."""
        return self._mag_flags(t_ns, False, Outcome.CALIBRATING)

    def _vertical_offset(self, t_ns: int, R, mx: float, my: float, mz: float):
        """Remove a hard-iron offset along the directions the phone held vertical, from the site's field.

        A phone held flat never turns its z axis, so no calibration from
        rotations can see an offset along it (the ETH walk: Android's
        calibration is about 50 uT off in z; the dip reads -24 deg where the
        World Magnetic Model says +63 deg).  The site's field (strength ``F``
        and dip ``d``, from the WMM where the location is known) fixes it: the
        true field's vertical component is ``up_b . (m - b) = -F sin d``.
        Ridge least squares over every reading, ``(sum u u^T + lambda I) b =
        sum u (u . m + F sin d)``, shrinks the directions that were never
        vertical to no correction.  It is applied only while the readings'
        own median dip is off the site's by more than
        ``vertical_offset_dip_error_rad`` -- a miscalibration; a building's
        bent field moves the dip by 10-20 deg, and is left alone -- and the
        median strength is off by ``vertical_offset_norm_error`` too, after
        ``vertical_offset_min_s`` of readings (a short stretch determines no
        offset).  Once on, it stays on until the dip error is below half the
        threshold.
        """
        state = self._state
        s = self.settings
        u = (R[2][0], R[2][1], R[2][2])  # up in the body frame (R: the current attitude's matrix)
        nm = math.sqrt(mx * mx + my * my + mz * mz)
        state.raw_dip_med.add(math.asin(max(-1.0, min(1.0, -(u[0] * mx + u[1] * my + u[2] * mz) / nm))))
        rhs = u[0] * mx + u[1] * my + u[2] * mz + s.site_field_uT * math.sin(s.site_dip_rad)
        S, r = state.vo_S, state.vo_r
        for i in range(3):
            r[i] += u[i] * rhs
            for j in range(3):
                S[i][j] += u[i] * u[j]
        if state.vo_next_ns is None or t_ns >= state.vo_next_ns:
            state.vo_next_ns = t_ns + 1_000_000_000
            if state.vo_t0_ns is None:
                state.vo_t0_ns = t_ns
            state.raw_norm_med.add(nm)
            dip_err = abs(state.raw_dip_med.median() - s.site_dip_rad)
            norm_err = abs(state.raw_norm_med.median() / s.site_field_uT - 1.0)
            if state.vo_active:  # hysteresis: stays on until the dip is clearly right
                active = dip_err > 0.5 * s.vertical_offset_dip_error_rad
            else:
                active = (dip_err > s.vertical_offset_dip_error_rad and norm_err > s.vertical_offset_norm_error
                          and (t_ns - state.vo_t0_ns) * 1e-9 >= s.vertical_offset_min_s)
            if active:
                A = np.array(S) + (s.vertical_offset_ridge * (S[0][0] + S[1][1] + S[2][2]) / 3.0) * _I3
                b = np.linalg.solve(A, np.array(r))
                if np.all(np.isfinite(b)):
                    state.vertical_offset_uT = tuple(float(v) for v in b)
            if active != state.vo_active:  # the references were of the other field: start them again
                state.vo_active = active
                state.refs.reset_field()
                state.field_uT = state.dip_rad = math.nan
                if not active:
                    state.vertical_offset_uT = (0.0, 0.0, 0.0)
        if not state.vo_active:
            return mx, my, mz
        b = state.vertical_offset_uT
        return mx - b[0], my - b[1], mz - b[2]

    def _mag_interval_done(self, t_ns, n, used, outcome: Outcome, **kw) -> UpdateFlags:
        """Flags of the reading that closed an interval; its ``n - 1`` earlier readings are re-counted if unused."""
        if not used and n > 1:
            r = self._state.mag_reasons
            r[Outcome.USED.value] = r.get(Outcome.USED.value, 0) - (n - 1)
            r[outcome.value] = r.get(outcome.value, 0) + (n - 1)
        return self._mag_flags(t_ns, used, outcome, **kw)

    def _relock(self, t_ns: int, innovation: float) -> None:
        """Release the heading when the gate has rejected agreeing readings for ``mag_relock_s``."""
        state = self._state
        s = self.settings
        g = state.gated
        g.append((t_ns, innovation))
        if (g[-1][0] - g[0][0]) * 1e-9 < s.mag_relock_s:
            return
        c = sum(math.cos(v) for _, v in g) / len(g)
        sn = sum(math.sin(v) for _, v in g) / len(g)
        spread = math.sqrt(max(-2.0 * math.log(max(math.hypot(c, sn), 1e-12)), 0.0))  # circular sd
        state.gated = []
        if spread < s.mag_relock_spread_rad:
            P = self.P.copy()
            P[2, :] = 0.0
            P[:, 2] = 0.0
            P[2, 2] = math.pi ** 2
            self.P = P
            to = state.P_to
            state.P_to = (to[0], to[1], 0.0)  # the released heading is uncorrelated with the offset too
            state.n_heading_relocks += 1

    def _mag_flags(self, t_ns, used, outcome: Outcome, dof=1, detail: str = "", **kw) -> UpdateFlags:
        state = self._state
        state.mag_rejected = not used
        key = outcome.value  # text only here, at the edge: the counters are keyed by it, the flags add the detail
        state.mag_reasons[key] = state.mag_reasons.get(key, 0) + 1
        state.last_mag = UpdateFlags("mag", t_ns, used, f"{key}: {detail}" if detail else key, dof=dof,
                                     outcome=outcome, **kw)
        return state.last_mag
