"""Walking direction from the acceleration: the heading offset between the device and the walk (issue #17).

A phone held in front of the chest points its top edge (device ``y``) where
the walker goes, and the pipeline's step heading is the smoothed heading of
that axis (:class:`core.pdr.heading.RotationSmoother`).  In a pocket, a bag, a
swinging hand or at the ear the device axis the smoother follows (``y``, or
the back ``-z`` while the phone stands upright) is off the walking direction
by an angle that is constant as long as the phone stays where it is.
:class:`WalkingDirection` estimates that angle, the **offset**, from the
acceleration, so that ``step heading = smoothed device heading + offset``.

Per stride (two steps)
----------------------
On the pipeline's grid, the acceleration goes to ENU (``a_n = R(q) a_b``,
``R`` from the attitude EKF); the vertical component's slow mean (gravity and
any scale error) is removed.  Each sample's horizontal part is expressed in
the frame of the smoothed device heading *at the same time*: the smoother lags
by its group delay ``delay_s``, so a sample is paired with the smoothed forward
vector ``delay_s`` later (a short buffer).  Over a stride (from one step event
to the next but one: left and right steps both in, so the left/right sway
averages out):

* **axis**: the principal direction (eigenvector of the larger eigenvalue) of
  a 2x2 covariance of the horizontal acceleration.  Which covariance
  (``axis_method="auto"``, the default) depends on the stride:

  - where one direction dominates the raw covariance (eigenvalue ratio at
    least ``pca_min_anisotropy``, 8): that raw covariance.  A limb swings the
    phone in the sagittal plane (an arm swinging at the side, a thigh with a
    pocket): the swing at the stride frequency is along the walk and
    outweighs everything else;
  - else the covariance of the part of the horizontal acceleration that moves
    with the vertical: ``g g' + h h'`` with ``g``, ``h`` the horizontal
    acceleration's correlation vectors with the vertical velocity and the
    vertical acceleration.  On the trunk (belt, bag, hand at the chest, ear)
    the lateral sway at the stride frequency is as large as the fore-aft
    motion at the step frequency and pulls the raw axis sideways (10 deg
    median on the IPOL waist walks); over a whole stride it is uncorrelated
    with the vertical motion, which is at the step frequency, and drops out
    (5 deg).  On the simulator the rule picks the raw axis for the swinging
    arm and the pocket and the coherent one for the rest, each the better of
    the two there.

  The stride is rejected where the axis is ill-defined: the chosen matrix's
  eigenvalue ratio below ``min_anisotropy``, horizontal acceleration below
  ``min_horizontal_std_m_s2`` (standing, pure vertical motion), the device
  heading turning more than ``max_stride_turn_rad`` within the stride, a
  stride outside ``[min_stride_s, max_stride_s]`` or a device axis too near
  the vertical to have a heading.
* **sign** (forward or backward along the axis): from the phase between the
  vertical and the forward acceleration, see below.
* the stride's offset: the signed axis relative to the device heading
  (``walking heading - device heading``, wrapped with
  :func:`core.conventions.wrap_angle`).

The sign rule: gait physics
---------------------------
The trunk moves as an inverted pendulum over the stance leg: kinetic and
potential energy are exchanged, the body is highest and slowest in mid-stance
and lowest and fastest around the double support (just after a heel strike).
So the forward speed ``v_f`` and the height ``z`` swing in opposition at the
step frequency: ``v_f = V - k z`` (``k > 0``) up to a constant, and therefore

    ``a_f = dv_f/dt = -k v_z``.

With ``z = -Z cos(w t)`` (lowest at ``t = 0``, the double support) this is
``a_z = Z w^2 cos(w t)`` (the upward acceleration peaks at the heel strike),
``v_z = Z w sin(w t)`` and ``a_f = -k Z w sin(w t)``: the trunk decelerates
forward (``a_f < 0``) while it rises after the heel strike (``v_z > 0``), and
speeds up while it falls towards the next one.  The forward acceleration is a
quarter of a step *ahead* of the vertical acceleration, in quadrature: its
in-phase covariance with ``a_z`` is zero (and its sign differs from walker to
walker: on the IPOL waist walks it took both signs), while its covariance
with the vertical *velocity* is reliably negative.  So along the stride's axis
``e`` the forward direction is the one where

    ``cov(a_h . e, v_z) < 0``.

``v_z`` is the vertical acceleration, its slow mean removed (time constant
``mean_time_s``), through a leaky integrator (time constant
``vz_leak_time_s``): at the step frequency (1.6-2 Hz) the pair turns the
phase by about 82 deg instead of 90 (5 deg lost to the leak, 2-3 deg to the
mean removal), far from the 90 deg off where the sign would be lost.  (The
heel-strike impact, an upward jolt with a backward one at the moment ``v_z``
crosses zero, adds to the in-phase covariance with ``a_z``, not to this one.)  No sign of our ENU
conventions enters: up is +z of ENU and the accelerometer reads ``+g`` up at
rest, so ``a_n = R(q) a_b`` minus its mean is the upward acceleration.  On the
IPOL lower-back walks (sensor x up, z out of the back: ``-z`` is forward;
tuning split) the rule took the wrong direction on 1 of 814 accepted strides,
and on none of the simulator's trunk placements (bag, ear, hand at the chest)
or the pocket.  Its weak spot is the hand swinging at the side: the arm's own
swing, at the stride frequency, dominates the horizontal acceleration and
leaves little trunk motion in quadrature with the vertical; on the simulator
about a fifth of those strides get the wrong sign and a fifth of the walks
end with the wrong direction (``benchmarks/WALKDIR_RESULTS.md``).

The sign rule of a limb: the swing's asymmetry (issue #25)
----------------------------------------------------------
The trunk's phase relation does not hold where a limb carries the phone.  On the real tuning walk
``phone_walks_more/thomasdingemanse_lopen`` (an iPhone on its long edge, probably in a trouser pocket; its
device axis within 1 deg of the GPS course) the phase rule took 98 % of the 296 accepted strides backwards
(``cov(a_f, v_z) > 0`` along the true forward), and so the whole walk (mean course minus step heading 171
deg).  A limb's own gait gives another cue: it swings forward faster than it comes back (the thigh's swing
phase is about 40 % of the stride, its stance 60 %; an arm follows the opposite leg), so the phone's
horizontal velocity relative to the walker -- a short, fast forward burst, a long slow return -- is skewed
towards the front.  ``sign_method="skew"``: per stride, the skewness of the horizontal velocity (the
acceleration in the device-heading frame, its ``mean_time_s`` running mean removed, through a leaky
integrator of ``velocity_leak_time_s``) along the stride's axis, clipped to +-1 (``/ skew_scale``), is the
sign evidence.  On the lopen walk it is right on 76 % of the strides (78 % of the raw-axis ones), enough
for the accumulated sign; on the IPOL waist walks (the trunk, tuning) it is right on 204 of 211 strides of
every fourth trial, where the phase rule is right on 210.  ``sign_method="auto"`` keeps both evidences and
uses the skew where most of the remembered strides (forgetting weight) took the raw axis -- a limb, by the
axis rule above -- else the phase: on the trunk it is the phase rule bit for bit.  ``"phase"`` is the rule of
the section above alone.  The third moments are O(1) sums per sample like the others.

One decision per placement (issue #25)
--------------------------------------
Which evidence decides the sign is a property of where the phone is, not of one stride: with
``sign_method="auto"`` each device axis's state carries a **limb** flag, set once the remembered (forgetting
weight) share of raw-axis strides reaches ``limb_enter_share`` (a half) and cleared only when it falls below
``limb_exit_share`` (a quarter).  The rule before switched the evidence at a half, stride by stride: on the
tuning walk ``thomasdingemanse_lopen`` (a limb; 71 % raw-axis strides, the share between 0.43 and 0.83 over a
minute) every dip below a half handed the sign to the trunk's phase rule, which points backwards on a limb,
and the step heading walked backwards in groups of 2-8 steps (e.g. 185-189 s and 231-240 s): a 30-s mean
hides them, an outage does not.  A limb's axis is, with ``limb_raw_axis``, the circular mean of every
stride's raw-covariance axis: the coherent axis of a limb's less anisotropic strides lay 20-35 deg to one
side of the raw one on that walk (the trunk's rule for the trunk's motion), and mixing them pulled the offset
by about 8 deg.  On the trunk nothing changes (the flag stays off: the phase rule and each stride's axis).

The quadrature phase (issue #25, h13/quadrature)
------------------------------------------------
The leaky integrator and the mean removal turn ``a_z`` by about 82 deg, not 90: ``v_z = c a_z + v_perp``
per stride, ``c = cov(a_z, v_z) / var(a_z)`` (a small in-phase part; ``v_perp`` uncorrelated with ``a_z``
over the stride).  So ``cov(a_h, v_z) = cov(a_h, v_perp) + c cov(a_h, a_z)``: where the horizontal
acceleration has a large in-phase term ``cov(a_h, a_z)`` (the ``h`` vector: a back pocket, a bag swinging
sideways) ``g`` leans towards it (27 deg in the synthetic back pocket of the tests).  With
``quadrature_phase`` each stride projects it out (one more running sum, ``sum a_z v_z``):

    ``g' = -(cov(a_h, v_z) - cov(a_h, a_z) cov(a_z, v_z) / var(a_z)) / sqrt(var_h var(v_perp))``,
    ``var(v_perp) = var(v_z) - cov(a_z, v_z)^2 / var(a_z)``,

the covariance with the part of ``v_z`` in exact quadrature with ``a_z`` (the least-squares residual of
``v_z`` on ``a_z``), normalised to a correlation as ``g`` is.  ``g'`` replaces ``g`` everywhere: the phase
axis, the sign evidence and the coherent axis's ``g g'`` term (``h h'`` stays).  For the pendulum's pure
quadrature ``a_f`` nothing changes but the normalisation; only the in-phase leak goes.

The symmetric axis (issue #25, h14/bagaxis)
-------------------------------------------
Along the walk the trunk moves alike in the left and the right step (it brakes and pushes at every step: the
step frequency); across it the sway alternates (the stride frequency).  A bag swinging sideways (RIDI
``dan_bag1``, tuning: horizontal acceleration RMS forward 1.6, sideways 3.1 m/s^2, the sideways part partly in
phase with the vertical) pulls the coherent axis across the walk (74 deg off per stride, median; the whole walk
100 deg off its truth), and the same in-phase pull turns a back pocket's (Tyrex, tuning: 53 and 71 deg).  With
``symmetric_axis_below_ratio`` each coherent stride is tested: the amplitudes of the stride's first harmonic (the
stride frequency) and second (the step frequency) of the horizontal acceleration along its axis and across it,

    ``ratio = (across_1 / across_2) / (along_1 / along_2)``

(below 1: the motion across the axis is the more step-periodic, so the axis lies across the walk; a stride that
took the phase axis is tested on its coherent axis too), and its
**symmetric axis** is the principal axis of ``sum_i a_i a_(i+n/2)'`` over the stride's ``n`` samples (each sample
against the one half a stride later, the other step: the covariance of the part alike in both steps, ``(a + b) /
2``, less that of the alternating part, ``(a - b) / 2``, is half of it).  Per stride the ratio is not reliable (a
trouser pocket's thigh swings forward at the stride frequency: RIDI ``dan_leg1`` has 30 % of its strides below 1,
and its symmetric axis is wrong there), so the decision is per placement, as the limb's: the forgetting-weighted
mean of each stride's log ratio (clipped to +-log 3; a stride of the raw axis counts as +log 3) below
``log(symmetric_axis_below_ratio)`` (after ``auto_min_strides`` strides) turns it on, above its negative off;
while on, the offset's axis is the circular mean of every stride's symmetric axis (a stride of the raw axis: its
own).  The sign evidence is unchanged.  The stride's samples are kept (at most ``max_stride_s`` of the grid)
and the harmonics summed at its close.

Smoothing: circular means with forgetting
-----------------------------------------
Turns rotate the walk and the device together, so the offset is a constant
to be averaged, and each stride is already expressed relative to the device
heading.  Two accumulators, each a vector sum with the forgetting factor
``exp(-1 / memory_strides)`` per accepted stride:

* the axis: unit vectors of **twice** the stride's axis angle (an axis has no
  sign; doubling makes ``theta`` and ``theta + pi`` the same vector), each of
  weight 1;
* the sign evidence: the normalised covariance vector ``-cov(a_h, v_z) /
  sqrt(var_h var_v)`` of each stride (a 2-vector pointing forward).

The offset is the axis of the first, turned by ``pi`` when the second points
the other way along it.  Its uncertainty ``offset_sigma_rad`` is the circular
spread of the axes (``sqrt(-2 ln R2) / 2``, ``R2`` the mean resultant length of
the doubled angles) over the square root of the effective number of strides;
``sign_confidence`` is the component of the sign evidence along the axis over
its total weight (0: undecided, 1: every stride perfectly in quadrature).

After ``reset_after_gap_s`` without an accepted stride (a pause, a ride, the
waving of a compass calibration before the walk) the estimate is forgotten:
the phone may be elsewhere when the walk goes on.

The axis accumulator is kept per device axis of the smoother (``y`` or the
back ``-z`` of ``forward_b="auto"``): the offset of one axis means nothing for
the other, and a phone going upright and back does not lose either.

Cost: O(1) per grid sample in plain Python (a few microseconds; the
benchmark measures it), with a buffer of ``delay_s`` of samples.  Non-finite
input is skipped and counted; nothing non-finite reaches the state.
"""

from __future__ import annotations

import math
from collections import deque

from core.conventions import CARRY_HANDHELD, CARRY_STILL, wrap_angle
from core.quaternion import to_matrix

#: why strides were rejected (keys of :attr:`WalkingDirection.rejected`)
REJECT_REASONS = ("duration", "samples", "still", "incoherent", "isotropic", "turning", "vertical_axis")
#: the rejection of a stride whose device heading turned too much (:attr:`WalkingDirection.gap_keeps_turning`)
REJECT_TURNING = REJECT_REASONS[5]
#: how a stride's axis is found (see the module docstring)
AXIS_METHODS = ("auto", "pca", "coherent", "phase")
#: how a stride's sign (forward or backward along its axis) is found (see the module docstring)
SIGN_METHODS = ("phase", "skew", "auto")
#: ``symmetric_axis_below_ratio``: a stride's log periodicity ratio is clipped to +-this (a ratio of 3 or 1/3), and a
#: stride without one (the raw axis of a limb, an undefined ratio) counts as this: not pulled
_LOG_RATIO_CLIP = math.log(3.0)
#: the pipeline's ``walking_direction`` settings (:meth:`WalkingDirection.step_heading`)
WALKING_DIRECTIONS = ("auto", "device", "acceleration")


def _anisotropy(cxx: float, cyy: float, cxy: float) -> float:
    """Ratio of the larger to the smaller eigenvalue of the symmetric 2x2 matrix [[cxx, cxy], [cxy, cyy]] (1e12 for
    a singular one, 1 for zero)."""
    tr = cxx + cyy
    d = math.hypot(cxx - cyy, 2.0 * cxy)
    l1, l2 = 0.5 * (tr + d), 0.5 * (tr - d)
    if l1 <= 0.0:
        return 1.0
    return l1 / l2 if l2 > 1e-12 * l1 else 1e12


class _AxisState:
    """The two circular accumulators of one device axis (see the module docstring)."""

    __slots__ = ("c2", "s2", "w", "w2", "gx", "gy", "n", "kx", "ky", "wp", "c2r", "s2r", "limb", "fwd", "ws", "c2s",
                 "s2s", "sym")

    #: the float accumulators, in the order :meth:`values` gives them (the fast path's trace stores them)
    FIELDS = ("c2", "s2", "w", "w2", "gx", "gy", "kx", "ky", "wp", "c2r", "s2r", "limb", "fwd", "ws", "c2s", "s2s",
              "sym")

    def __init__(self):
        self.c2 = self.s2 = self.w = self.w2 = 0.0
        self.gx = self.gy = 0.0
        self.n = 0
        #: ``sign_method="auto"``: the skew evidence and the weight of the limb (raw-axis) strides
        self.kx = self.ky = self.wp = 0.0
        #: ``sign_method="auto"``: the raw covariance's axis of every stride (doubled angle) and whether the
        #: placement counts as a limb now (1.0) or the trunk (0.0), with hysteresis (issue #25)
        self.c2r = self.s2r = 0.0
        self.limb = 0.0
        #: ``sign_method="auto"``: the offset after the last stride (rad; nan before any), the direction a
        #: limb's sign holds to until the evidence turns clearly against it
        self.fwd = math.nan
        #: ``symmetric_axis_below_ratio``: the weight of the strides whose axis looked pulled sideways, every
        #: stride's symmetric axis (doubled angle; a stride without one: its own axis) and whether the placement
        #: takes the symmetric axis now (1.0) or each stride's own (0.0), with the limb's hysteresis
        self.ws = self.c2s = self.s2s = self.sym = 0.0

    def values(self) -> tuple:
        """The float accumulators (:data:`FIELDS`)."""
        return tuple(getattr(self, k) for k in self.FIELDS)

    @classmethod
    def from_values(cls, values, n: int) -> "_AxisState":
        """The state of :meth:`values` (a prefix of :data:`FIELDS` is enough) and ``n`` strides."""
        st = cls()
        for k, v in zip(cls.FIELDS, values):  # a prefix: the rest keep their initial values
            setattr(st, k, float(v))
        st.n = int(n)
        return st


class WalkingDirection:
    """Heading offset between the smoothed device axis and the walking direction, from the acceleration.

    Parameters (units in the names)
    ----------
    grid_rate_hz : float
        Rate of :meth:`update` calls (Hz): the pipeline's grid.
    delay_s : float
        Group delay of the smoothed device heading (s): a sample's acceleration is compared with the
        smoothed forward vector this much later (the pipeline gives the smoother's ``delay_s``).
    vz_leak_time_s : float
        Time constant of the leaky integrator from vertical acceleration to vertical velocity (s).
    mean_time_s : float
        Time constant of the running mean removed from the vertical acceleration (s).
    min_stride_s, max_stride_s : float
        Strides (two step events) outside this duration are rejected (s).
    min_horizontal_std_m_s2 : float
        A stride whose horizontal acceleration has less standard deviation than this (m/s^2, both axes
        together) is no walking stride (standing, pure vertical motion).
    min_anisotropy : float
        Ratio of the larger to the smaller eigenvalue of the horizontal covariance below which the axis
        is ill-defined and the stride rejected.
    max_stride_turn_rad : float
        A stride over which the smoothed device heading turns more than this is rejected (rad).
    min_forward_norm : float
        Horizontal length of the smoothed device axis below which it has no heading (the sample is
        skipped).
    memory_strides : float
        Effective memory of the circular means (strides): forgetting factor ``exp(-1 / memory_strides)``.
    confident_strides, confident_sigma_rad, confident_sign : float
        :attr:`confident` needs at least this many accepted strides, an offset uncertainty below this
        (rad) and a sign confidence above this.
    auto_min_strides, auto_far_min_strides, auto_min_offset_rad : int, int, float
        The pipeline's ``walking_direction="auto"`` (:meth:`applies`): accepted strides before the
        offset counts in a carry mode that is not hand-held; without a carry-mode detector, the
        strides and the distance from 0 (rad) a confident offset needs to count.
    max_strides_kept : int
        How many per-stride records :attr:`strides` keeps (diagnostics).
    sign_method : str
        ``"phase"`` (the trunk's ``cov(a_f, v_z) < 0``), ``"skew"`` (the limb's forward-skewed velocity) or
        ``"auto"`` (the skew where most remembered strides took the raw axis, else the phase); see the module
        docstring.
    velocity_leak_time_s : float
        Time constant of the leaky integrator from horizontal acceleration to velocity (s), for the skew.
    skew_scale : float
        A stride's skew over this is clipped to +-1 as its sign evidence.
    limb_enter_share, limb_exit_share : float
        ``sign_method="auto"``: the placement becomes a limb once the remembered share of raw-axis strides
        reaches ``limb_enter_share``, and the trunk again once it falls below ``limb_exit_share``
        (hysteresis: one decision per placement, not one per stride; see "One decision per placement").
    limb_raw_axis : bool
        ``sign_method="auto"``: a limb's axis is the mean of every stride's raw-covariance axis (True), or
        the mean of each stride's own choice (False, the rule before issue #25's placement decision).
    limb_sign_margin : float
        ``sign_method="auto"``, a limb: its direction (forward or backward along the axis) holds until the
        mean skew evidence along it (-1..1 per stride, forgetting-weighted) falls below ``-limb_sign_margin``;
        0: the sign of the evidence, stride by stride (the rule before).
    gap_keeps_turning : bool
        A stride rejected only for turning (``max_stride_turn_rad``) restarts the ``reset_after_gap_s`` clock
        as an accepted one does: the walker walks on, turning, and the phone stays where it is (issue #25:
        on the tuning walk ``oxiod_pocket_data1_seq5``, in a 3.5 x 6 m room, 98 of 173 strides turned and the
        estimate was forgotten after 205 s of walking).  False: only an accepted stride does (the rule before).
    phase_axis_below_ratio : float
        A stride that would take the coherent axis takes the phase axis (the direction of ``-cov(a_h, v_z)``)
        instead where the raw horizontal covariance along that phase axis is below this many times the one
        across it (the phase axis lies along the raw ellipse's minor side: the in-phase term that pulls the
        coherent axis rides a larger sideways motion).  0: off (the rule before).  Issue #25, h13/backpocket:
        on the tuning Tyrex back-pocket walks (one walker) the coherent axis was 49-71 deg off per stride
        (median) and the phase axis 31, the raw ratio (median per walk) 0.93-1.09 there and 1.23-3.55 on every
        other tuning truth walk.  Built OFF at first (h13: at 1.2 the back pockets' offset error vs the truth
        66.3 -> 19.9 and 64.3 -> 41.0 deg, but the same walker's front pocket 9.7 -> 18.3, one walker).  **1.2 by
        default** since 2026-12-07 (fourteenth session): with the Tyrex benchmark's iPhone walks (h14/datahunt) the
        tuning split holds 36 truth walks, Jakob's 18 on three phones, 4 back pockets and 4 front pockets that 1.2
        was not chosen on: their back pockets 55-73 -> 10-28 deg, none of the new front pockets worse.  Over the 33
        scored tuning walks, off -> 1.2: median offset error 17.4 -> 16.4 deg, mean 35.4 -> 27.3, one walk worse by > 0.5 deg (the
        Nexus 5 front pocket above); the track's end error after the best rotation median 7.5 -> 7.3 %, mean 8.9 ->
        8.1; the real GPS tuning walks identical.  Leave one walk out picks 1.5 (mean 27.0, end error 7.0 / 7.9 %),
        within 0.3 deg of 1.2 on the real walks, but the simulator's pocket (truth known; seeds 0-11, a 130-m walk)
        pays 5.7 -> 12.9 deg at 1.5 and 5.7 -> 6.3 at 1.2: 1.2, declared before the new walks, is the default.
        Every pocket walk with a truth on the tuning side is still one walker's (``benchmarks/discussion.md``).
    quadrature_phase : bool
        The forward evidence ``g`` (phase axis, sign evidence, the coherent axis's ``g g'`` term) is the pure
        quadrature covariance: the part of ``v_z`` in phase with ``a_z`` projected out per stride (module
        docstring, "The quadrature phase").  False: ``-cov(a_h, v_z)`` through the leaky ``v_z`` (the rule before).
        OFF by default pending the lead's decision (issue #25, h13/quadrature; numbers in
        ``benchmarks/discussion.md``).
    symmetric_axis_below_ratio : float
        The placement's axis is the symmetric axis (the motion alike in both steps less the alternating one) while
        the remembered strides' geometric-mean periodicity ratio (across the coherent axis over along it,
        stride-to-step harmonic amplitude; a stride of the raw axis counts as 3) is below this, until it rises above its reciprocal (module docstring,
        "The symmetric axis").  0: off (the default).  Issue #25, h14/bagaxis: at 0.8 (the helper's default, without
        the phase-axis rule) on the 24 tuning truth walks of the time RIDI ``dan_bag1`` 100.3 -> 8.5 deg off the truth (median), Tyrex back pockets 66.3 -> 42.3
        and 64.3 -> 13.0 (two walkers), every other tuning truth walk, the real GPS walks, the main benchmark, IPOL
        and the simulator identical (0.7: 8.5, 66.3, 13.6; 0.9: 8.5, 26.4, 12.6 with ``dan_leg1``'s p90 17.9 -> 28.1;
        numbers in ``benchmarks/discussion.md``).  **OFF by default** (the lead, 2026-12-07): with the phase-axis
        rule that is now the default (``phase_axis_below_ratio=1.2``) it is mixed on the same tuning walks:
        ``dan_bag1``'s offset error 90.0 -> 12.4 deg but the track's end error after the best rotation 2.0 -> 11.3 %
        of the path, Jakob's back pockets 19.9 -> 20.2 and 41.0 -> 16.3 deg; the report split (seen once, by the
        helper, with the phase rule off) improved no walk and added a sign error on the GPS walks.
    """

    def __init__(self, *, grid_rate_hz: float = 50.0, delay_s: float = 0.45, vz_leak_time_s: float = 1.0,
                 mean_time_s: float = 2.0, min_stride_s: float = 0.6, max_stride_s: float = 2.6,
                 min_horizontal_std_m_s2: float = 0.15, min_anisotropy: float = 1.3,
                 max_stride_turn_rad: float = math.radians(30.0), min_forward_norm: float = 0.2,
                 memory_strides: float = 15.0, confident_strides: int = 5,
                 confident_sigma_rad: float = math.radians(8.0), confident_sign: float = 0.15,
                 auto_min_strides: int = 3, auto_far_min_strides: int = 10,
                 auto_min_offset_rad: float = math.radians(45.0),
                 max_strides_kept: int = 64, axis_method: str = "auto",
                 pca_min_anisotropy: float = 8.0, min_coherence: float = 0.0, reset_after_gap_s: float = 10.0,
                 sign_method: str = "auto", velocity_leak_time_s: float = 0.5, skew_scale: float = 1.0,
                 limb_enter_share: float = 0.5, limb_exit_share: float = 0.25, limb_raw_axis: bool = True,
                 limb_sign_margin: float = 0.1, gap_keeps_turning: bool = False,
                 phase_axis_below_ratio: float = 1.2, quadrature_phase: bool = False,
                 symmetric_axis_below_ratio: float = 0.0):
        self.grid_rate_hz = float(grid_rate_hz)
        self.delay_s = float(delay_s)
        self.vz_leak_time_s = float(vz_leak_time_s)
        self.mean_time_s = float(mean_time_s)
        self.min_stride_s = float(min_stride_s)
        self.max_stride_s = float(max_stride_s)
        self.min_horizontal_std_m_s2 = float(min_horizontal_std_m_s2)
        self.min_anisotropy = float(min_anisotropy)
        self.max_stride_turn_rad = float(max_stride_turn_rad)
        self.min_forward_norm = float(min_forward_norm)
        self.memory_strides = float(memory_strides)
        self.confident_strides = int(confident_strides)
        self.confident_sigma_rad = float(confident_sigma_rad)
        self.confident_sign = float(confident_sign)
        self.auto_min_strides = int(auto_min_strides)
        self.auto_far_min_strides = int(auto_far_min_strides)
        self.auto_min_offset_rad = float(auto_min_offset_rad)
        self.max_strides_kept = int(max_strides_kept)
        if axis_method not in AXIS_METHODS:
            raise ValueError(f"axis_method must be one of {AXIS_METHODS}, got {axis_method!r}")
        self.axis_method = axis_method
        self.pca_min_anisotropy = float(pca_min_anisotropy)
        self.min_coherence = float(min_coherence)
        self.reset_after_gap_s = float(reset_after_gap_s)
        self.gap_keeps_turning = bool(gap_keeps_turning)
        self.phase_axis_below_ratio = float(phase_axis_below_ratio)
        self.quadrature_phase = bool(quadrature_phase)
        self.symmetric_axis_below_ratio = float(symmetric_axis_below_ratio)
        if not 0.0 <= self.symmetric_axis_below_ratio < 1.0:
            # at 1 or more its on threshold (the ratio) lies above its off one (the reciprocal): a flip every stride
            raise ValueError("symmetric_axis_below_ratio must be 0 (off) or in (0, 1), "
                             f"got {symmetric_axis_below_ratio!r}")
        #: keep the open stride's samples (the symmetric axis), at most a longest stride's worth
        self._xy_max = int(self.max_stride_s * self.grid_rate_hz) + 2
        self._log_sym_ratio = math.log(self.symmetric_axis_below_ratio) if self.symmetric_axis_below_ratio > 0 else 0.0
        #: the open stride's running sums: 14, and sum a_z v_z with ``quadrature_phase``
        self._n_sums = 15 if self.quadrature_phase else 14
        if sign_method not in SIGN_METHODS:
            raise ValueError(f"sign_method must be one of {SIGN_METHODS}, got {sign_method!r}")
        self.sign_method = sign_method
        self.velocity_leak_time_s = float(velocity_leak_time_s)
        self.skew_scale = float(skew_scale)
        if not 0.0 <= limb_exit_share <= limb_enter_share <= 1.0:
            raise ValueError(f"need 0 <= limb_exit_share <= limb_enter_share <= 1, got {limb_exit_share}, "
                             f"{limb_enter_share}")
        self.limb_enter_share = float(limb_enter_share)
        self.limb_exit_share = float(limb_exit_share)
        self.limb_raw_axis = bool(limb_raw_axis)
        self.limb_sign_margin = float(limb_sign_margin)
        self._vleak = math.exp(-1.0 / (self.grid_rate_hz * self.velocity_leak_time_s))
        self._gap_ns = int(self.reset_after_gap_s * 1e9)
        dt = 1.0 / self.grid_rate_hz
        self._dt = dt
        self._leak = math.exp(-dt / self.vz_leak_time_s)
        self._mean_alpha = 1.0 - math.exp(-dt / self.mean_time_s)
        self._forget = math.exp(-1.0 / self.memory_strides)
        self._delay_n = max(0, int(round(self.delay_s * self.grid_rate_hz)))
        settings = set(vars(self))
        self.reset()
        #: the names of the state :meth:`reset` makes (what :meth:`restore_state` may set)
        self._state_names = frozenset(vars(self)) - settings

    def reset(self) -> None:
        #: running mean of the vertical acceleration and the leaky vertical velocity
        self._mean_u = math.nan
        self._vz = 0.0
        #: samples waiting for their delayed device heading: (t_ns, a_east, a_north, a_up, v_z, step)
        self._buf = deque()
        # n, sx, sy, sxx, syy, sxy, sv, sxv, syv, svv, su, sxu, syu, suu (, suv with quadrature_phase): open stride
        self._sums = [0.0] * self._n_sums
        #: the horizontal velocity along / left of the device heading (leaky, its running mean removed) and
        #: the open stride's moments of it up to the third: n, vx, vy, vxx, vxy, vyy, vxxx, vxxy, vxyy, vyyy
        self._hmx = self._hmy = self._vx = self._vy = 0.0
        self._vm = [0.0] * 10
        #: ``symmetric_axis_below_ratio``: the open stride's horizontal acceleration (along, left of the device heading)
        self._xy = []
        self._stride_steps = -1  # steps seen in the open stride; -1 before the first step boundary
        self._stride_t0 = 0
        self._stride_fwd0 = None  # device forward unit vector (east, north) at the stride's start
        self._stride_skipped = 0  # samples of the stride without a device heading
        self._axis_key = None
        self._states: dict = {}
        #: the gap clock: the time of the last accepted stride (with ``gap_keeps_turning`` also of the last stride
        #: rejected only for turning), from which ``reset_after_gap_s`` is counted
        self._last_accepted_ns = None
        #: times the estimate was forgotten after a gap of ``reset_after_gap_s`` without an accepted stride
        self.n_gap_resets = 0
        #: :meth:`estimate` just before the last such reset (None before any)
        self.last_estimate = None
        #: per-stride records (dicts), the last ``max_strides_kept``
        self.strides: deque = deque(maxlen=self.max_strides_kept)
        #: strides closed, accepted, and rejected per reason
        self.n_strides = 0
        self.n_accepted = 0
        self.rejected = {r: 0 for r in REJECT_REASONS}
        #: sign decisions of accepted strides that disagreed with the smoothed sign at that time
        self.n_sign_disagreements = 0
        #: grid samples skipped for non-finite input
        self.n_nonfinite = 0
        #: steps whose heading got the offset (:meth:`step_heading`)
        self.n_steps_offset = 0

    # -- per sample ---------------------------------------------------------------
    def update(self, t_ns: int, q, ax: float, ay: float, az: float, fwd_east: float, fwd_north: float,
               step: bool = False, axis=None, mat_nb=None) -> None:
        """One grid sample.

        ``q``: attitude (w, x, y, z) body -> ENU; ``ax, ay, az``: the accelerometer (m/s^2, device
        frame); ``fwd_east, fwd_north``: the smoothed device forward vector now
        (:attr:`core.pdr.heading.RotationSmoother.forward_east`, ``forward_north``); ``step``: a step
        event at this sample; ``axis``: the device axis the smoother follows (its ``forward_b``), so
        that each axis keeps its own offset; ``mat_nb``: ``q``'s rotation matrix (:func:`core.quaternion.to_matrix`)
        if the caller has it already (the pipeline: the attitude filter's), else it is made here.
        """
        if not (math.isfinite(ax) and math.isfinite(ay) and math.isfinite(az)
                and math.isfinite(fwd_east) and math.isfinite(fwd_north)):
            self.n_nonfinite += 1
            return
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = to_matrix(q) if mat_nb is None else mat_nb
        ae = r00 * ax + r01 * ay + r02 * az
        an = r10 * ax + r11 * ay + r12 * az
        au = r20 * ax + r21 * ay + r22 * az
        if not (math.isfinite(ae) and math.isfinite(an) and math.isfinite(au)):
            self.n_nonfinite += 1
            return
        m = self._mean_u
        if m != m:
            m = au
        m += self._mean_alpha * (au - m)
        self._mean_u = m
        self._vz = self._leak * self._vz + (au - m) * self._dt
        last = self._last_accepted_ns
        if last is not None and t_ns - last > self._gap_ns:
            self.last_estimate = self.estimate()
            self._states = {}  # a pause: the phone may have been put elsewhere (or that was no walk)
            self._last_accepted_ns = None
            self.n_gap_resets += 1
        buf = self._buf
        buf.append((t_ns, ae, an, au - m, self._vz, step))
        if axis != self._axis_key:
            self._axis_key = axis
            self._stride_steps = -1  # the open stride mixed two axes: start again at the next step
        if len(buf) > self._delay_n:
            self._paired(buf.popleft(), fwd_east, fwd_north)

    def _paired(self, sample, fe: float, fn: float) -> None:
        """A delayed sample with the smoothed device forward vector of its time."""
        t_ns, ae, an, au, vz, step = sample
        norm = math.hypot(fe, fn)
        if step:
            self._boundary(t_ns, fe, fn, norm)
        if self._stride_steps < 0:
            return
        if norm < self.min_forward_norm:
            self._stride_skipped += 1
            return
        ue, un = fe / norm, fn / norm
        x = ae * ue + an * un  # along the device heading
        y = -ae * un + an * ue  # 90 deg counter-clockwise of it (left)
        if self.sign_method != "phase":
            self._velocity(x, y)
        s = self._sums
        s[0] += 1.0
        s[1] += x
        s[2] += y
        s[3] += x * x
        s[4] += y * y
        s[5] += x * y
        s[6] += vz
        s[7] += x * vz
        s[8] += y * vz
        s[9] += vz * vz
        s[10] += au
        s[11] += x * au
        s[12] += y * au
        s[13] += au * au
        if self.quadrature_phase:
            s[14] += au * vz
        if self.symmetric_axis_below_ratio > 0.0 and len(self._xy) < self._xy_max:
            self._xy.append((x, y))  # a longer stride is rejected for its duration anyway

    def _velocity(self, x: float, y: float) -> None:
        """The phone's horizontal velocity in the device-heading frame (leaky integral of the acceleration, its
        slow mean removed) and the open stride's moments of it (for the ``skew`` sign)."""
        a = self._mean_alpha
        self._hmx += a * (x - self._hmx)
        self._hmy += a * (y - self._hmy)
        k, dt = self._vleak, self._dt
        vx = self._vx = k * self._vx + (x - self._hmx) * dt
        vy = self._vy = k * self._vy + (y - self._hmy) * dt
        m = self._vm
        m[0] += 1.0
        m[1] += vx
        m[2] += vy
        m[3] += vx * vx
        m[4] += vx * vy
        m[5] += vy * vy
        m[6] += vx * vx * vx
        m[7] += vx * vx * vy
        m[8] += vx * vy * vy
        m[9] += vy * vy * vy

    def _skew_along(self, theta: float) -> float:
        """Skewness of the open stride's horizontal velocity along the direction ``theta`` (from the device
        heading); 0 without samples or spread."""
        m = self._vm
        n = m[0]
        if n < 3.0:
            return 0.0
        c, s = math.cos(theta), math.sin(theta)
        e1 = (c * m[1] + s * m[2]) / n
        e2 = (c * c * m[3] + 2.0 * c * s * m[4] + s * s * m[5]) / n
        e3 = (c * c * c * m[6] + 3.0 * c * c * s * m[7] + 3.0 * c * s * s * m[8] + s * s * s * m[9]) / n
        var = e2 - e1 * e1
        if var <= 1e-12:
            return 0.0
        return (e3 - 3.0 * e1 * e2 + 2.0 * e1 * e1 * e1) / var ** 1.5

    def _step_periodicity(self, theta: float) -> tuple[float, float]:
        """The open stride's test of its axis ``theta`` (rad from the device heading) for a sideways pull, and the
        symmetric axis (module docstring, "The symmetric axis"): ``(ratio, theta_sym)``.  ``ratio``: the stride-to-step
        harmonic amplitude ratio of the horizontal acceleration across ``theta`` over the one along it (inf where
        undefined); ``theta_sym``: the symmetric axis, the principal axis of the symmetrised sum of the stride's
        samples times the samples half a stride later (the motion alike in both steps less the alternating one; module
        docstring)."""
        xy = self._xy
        n = len(xy)
        if n < 8:
            return math.inf, theta
        mx = sum(p[0] for p in xy) / n
        my = sum(p[1] for p in xy) / n
        c, s = math.cos(theta), math.sin(theta)
        # the first two harmonics of the stride (k = 1: the stride's frequency, k = 2: the step's) along and across
        acc = [0.0] * 8  # re/im of along k1, across k1, along k2, across k2
        w = 2.0 * math.pi / n
        for i, (x, y) in enumerate(xy):
            a, b = (x - mx) * c + (y - my) * s, -(x - mx) * s + (y - my) * c
            c1, s1, c2, s2 = math.cos(w * i), math.sin(w * i), math.cos(2.0 * w * i), math.sin(2.0 * w * i)
            acc[0] += a * c1
            acc[1] += a * s1
            acc[2] += b * c1
            acc[3] += b * s1
            acc[4] += a * c2
            acc[5] += a * s2
            acc[6] += b * c2
            acc[7] += b * s2
        along1, across1 = math.hypot(acc[0], acc[1]), math.hypot(acc[2], acc[3])
        along2, across2 = math.hypot(acc[4], acc[5]), math.hypot(acc[6], acc[7])
        den = across2 * along1
        ratio = across1 * along2 / den if den > 1e-12 else math.inf
        # the part alike in both steps against the alternating part: sample i with sample i + n // 2 (the other
        # step); (a + b)(a + b)' - (a - b)(a - b)' = 2 (a b' + b a'), so the symmetric axis is that of sum a b'
        h = n // 2
        sxx = syy = sxy = 0.0
        for i in range(h):
            (ax, ay), (bx, by) = xy[i], xy[i + h]
            ax, ay, bx, by = ax - mx, ay - my, bx - mx, by - my
            sxx += ax * bx
            syy += ay * by
            sxy += 0.5 * (ax * by + ay * bx)
        return ratio, 0.5 * math.atan2(2.0 * sxy, sxx - syy)

    def _boundary(self, t_ns: int, fe: float, fn: float, norm: float) -> None:
        """A step event reached the delayed stream: close the stride after two steps."""
        if self._stride_steps < 0 or self._stride_steps + 1 >= 2:
            if self._stride_steps >= 0:
                self._close(t_ns, fe, fn, norm)
            self._stride_steps = 0
            self._stride_t0 = t_ns
            self._stride_fwd0 = (fe / norm, fn / norm) if norm >= self.min_forward_norm else None
            self._stride_skipped = 0
            self._sums = [0.0] * self._n_sums
            if self.sign_method != "phase":
                self._vm = [0.0] * 10
            if self.symmetric_axis_below_ratio > 0.0:
                self._xy = []
        else:
            self._stride_steps += 1

    def _close(self, t_ns: int, fe: float, fn: float, norm: float) -> None:
        self.n_strides += 1
        rec = {"t_ns": int(t_ns), "accepted": False, "reason": "", "axis_offset_rad": math.nan,
               "offset_rad": math.nan, "anisotropy": math.nan, "corr": math.nan, "sign": 0}
        reason = self._judge(t_ns, fe, fn, norm, rec)
        if reason:
            self.rejected[reason] += 1
            rec["reason"] = reason
            if reason == REJECT_TURNING and self.gap_keeps_turning and self._last_accepted_ns is not None:
                self._last_accepted_ns = t_ns  # the walk goes on, turning: the phone stays where it is
        self.strides.append(rec)

    def _judge(self, t_ns: int, fe: float, fn: float, norm: float, rec: dict) -> str:
        dur = (t_ns - self._stride_t0) * 1e-9
        if not self.min_stride_s <= dur <= self.max_stride_s:
            return "duration"
        s = self._sums
        n = s[0]
        if self._stride_fwd0 is None or norm < self.min_forward_norm or self._stride_skipped > 0.2 * (n + 1):
            return "vertical_axis"
        if n < 0.5 * dur * self.grid_rate_hz or n < 10:
            return "samples"
        e0, n0 = self._stride_fwd0
        turn = math.atan2(e0 * fn - n0 * fe, e0 * fe + n0 * fn)  # device heading change over the stride
        rec["turn_rad"] = turn
        if abs(turn) > self.max_stride_turn_rad:
            return REJECT_TURNING
        inv = 1.0 / n
        mx, my, mv = s[1] * inv, s[2] * inv, s[6] * inv
        cxx = max(s[3] * inv - mx * mx, 0.0)
        cyy = max(s[4] * inv - my * my, 0.0)
        cxy = s[5] * inv - mx * my
        cxv = s[7] * inv - mx * mv
        cyv = s[8] * inv - my * mv
        cvv = max(s[9] * inv - mv * mv, 0.0)
        tr = cxx + cyy
        if tr < self.min_horizontal_std_m_s2 ** 2:
            return "still"
        raw_aniso = _anisotropy(cxx, cyy, cxy)
        rec["anisotropy"] = raw_aniso
        mu = s[10] * inv
        cuu = max(s[13] * inv - mu * mu, 0.0)
        if self.quadrature_phase and cuu > 1e-12:
            # the pure quadrature covariance: v_z's part in phase with a_z projected out (module docstring)
            cxu, cyu = s[11] * inv - mx * mu, s[12] * inv - my * mu
            c = (s[14] * inv - mu * mv) / cuu  # cov(a_z, v_z) / var(a_z)
            cxv -= c * cxu
            cyv -= c * cyu
            cvv = max(cvv - c * c * cuu, 0.0)  # var(v_perp) = var(v_z) - cov(a_z, v_z)^2 / var(a_z)
        # forward evidence: -cov(a_h, v_z), normalised to a correlation
        den = math.sqrt(tr * cvv)
        gx, gy = (-cxv / den, -cyv / den) if den > 1e-12 else (0.0, 0.0)
        du = math.sqrt(tr * cuu)
        hx, hy = ((s[11] * inv - mx * mu) / du, (s[12] * inv - my * mu) / du) if du > 1e-12 else (0.0, 0.0)
        # the part of the horizontal acceleration that moves with the vertical: covariance g g' + h h'
        kxx, kyy, kxy = gx * gx + hx * hx, gy * gy + hy * hy, gx * gy + hx * hy
        coherence = kxx + kyy
        rec["coherence"] = coherence
        method = self.axis_method
        if method == "auto":
            method = "pca" if raw_aniso >= self.pca_min_anisotropy else "coherent"
        if method == "coherent" and self.phase_axis_below_ratio > 0.0 and (gx or gy):
            # the raw covariance along the phase axis against across it (the phase axis on the ellipse's minor side)
            g2 = gx * gx + gy * gy
            along_g = (cxx * gx * gx + 2.0 * cxy * gx * gy + cyy * gy * gy) / g2
            if along_g < self.phase_axis_below_ratio * (tr - along_g):
                method = "phase"
        rec["method"] = method
        theta_raw = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)  # the raw covariance's axis, from the device heading
        if method == "pca":
            theta = theta_raw
            aniso = raw_aniso
        else:
            if coherence < self.min_coherence:
                return "incoherent"
            aniso = _anisotropy(kxx, kyy, kxy)
            theta = 0.5 * math.atan2(2.0 * kxy, kxx - kyy) if method == "coherent" else math.atan2(gy, gx)
        rec["axis_anisotropy"] = aniso
        if aniso < self.min_anisotropy:
            return "isotropic"
        theta_sym, log_ratio = theta, _LOG_RATIO_CLIP
        if method != "pca" and self.symmetric_axis_below_ratio > 0.0:
            # the walk is alike in the left and the right step, the sway alternates (module docstring); the test
            # is of the coherent axis, also where a stride took the phase axis (phase_axis_below_ratio)
            theta_coh = theta if method == "coherent" else 0.5 * math.atan2(2.0 * kxy, kxx - kyy)
            ratio, theta_sym = self._step_periodicity(theta_coh)
            if method != "coherent":
                theta_sym = theta  # the phase axis is that stride's answer to the pull already
            rec["periodicity_ratio"] = ratio
            rec["symmetric_axis_rad"] = theta_sym
            log_ratio = max(-_LOG_RATIO_CLIP, min(_LOG_RATIO_CLIP, math.log(ratio))) if ratio > 0.0 else -_LOG_RATIO_CLIP
        rec["axis_offset_rad"] = theta
        ct, st = math.cos(theta), math.sin(theta)
        along = gx * ct + gy * st
        rec["corr"] = along
        rec["axis"] = self._axis_key
        sm = self.sign_method
        kev = 0.0
        if sm != "phase":
            # the forward swing of a limb is the fast one: the velocity's skew is positive forward (module doc)
            k = self._skew_along(theta)
            rec["skew"] = k
            kev = max(-1.0, min(1.0, k / self.skew_scale))
            if sm == "skew" or method == "pca":
                along = kev
            if sm == "skew":
                gx, gy = kev * ct, kev * st
        sign = 1 if along >= 0.0 else -1
        rec["sign"] = sign
        rec["offset_rad"] = theta if sign > 0 else wrap_angle(theta + math.pi)
        self._last_accepted_ns = t_ns
        st_ = self._states.get(self._axis_key)
        if st_ is None:
            st_ = self._states[self._axis_key] = _AxisState()
        smoothed_before = self._offset_of(st_) if st_.n else None
        self._accumulate(st_, theta, gx, gy, kev, method == "pca", theta_raw, theta_sym, log_ratio)
        st_.n += 1
        self.n_accepted += 1
        rec["accepted"] = True
        if smoothed_before is not None and abs(wrap_angle(rec["offset_rad"] - smoothed_before)) > 0.5 * math.pi:
            self.n_sign_disagreements += 1
        return ""

    def _accumulate(self, st: _AxisState, theta: float, gx: float, gy: float, kev: float = 0.0,
                    raw: bool = False, theta_raw: float | None = None, theta_sym: float | None = None,
                    log_ratio: float = 0.0) -> None:
        """One accepted stride into an axis's accumulators: its axis ``theta`` (rad from the device heading),
        its sign evidence ``(gx, gy)`` (the phase's), its skew evidence ``kev`` (-1..1 along ``theta``),
        whether its axis came from the raw covariance (``raw``: a limb's stride), the raw covariance's axis
        ``theta_raw`` (default ``theta``), the symmetric axis ``theta_sym`` (default ``theta``) and the log of
        its periodicity ratio (``symmetric_axis_below_ratio``; clipped).  ``n`` is left to the caller."""
        f = self._forget
        st.c2 = f * st.c2 + math.cos(2.0 * theta)
        st.s2 = f * st.s2 + math.sin(2.0 * theta)
        st.w = f * st.w + 1.0
        st.w2 = f * f * st.w2 + 1.0
        st.gx = f * st.gx + gx
        st.gy = f * st.gy + gy
        if self.symmetric_axis_below_ratio > 0.0:
            ts = theta if theta_sym is None else theta_sym
            st.ws = f * st.ws + log_ratio
            st.c2s = f * st.c2s + math.cos(2.0 * ts)
            st.s2s = f * st.s2s + math.sin(2.0 * ts)
            # one decision per placement, with hysteresis: the remembered strides' geometric mean ratio below the
            # setting (after auto_min_strides) turns it on, above its reciprocal off
            mean = st.ws / st.w
            if st.sym:
                if mean > -self._log_sym_ratio:
                    st.sym = 0.0
            elif mean < self._log_sym_ratio and st.n + 1 >= self.auto_min_strides:
                st.sym = 1.0
        if self.sign_method != "auto":
            return
        tr = theta if theta_raw is None else theta_raw
        st.kx = f * st.kx + kev * math.cos(theta)
        st.ky = f * st.ky + kev * math.sin(theta)
        st.wp = f * st.wp + (1.0 if raw else 0.0)
        st.c2r = f * st.c2r + math.cos(2.0 * tr)
        st.s2r = f * st.s2r + math.sin(2.0 * tr)
        # one decision per placement, with hysteresis: a limb until its share of raw strides falls well below half
        share = st.wp / st.w
        if st.limb:
            if share < self.limb_exit_share:
                st.limb = 0.0
        elif share >= self.limb_enter_share:
            st.limb = 1.0
        st.fwd = self._offset_of(st)

    # -- the estimate -------------------------------------------------------------
    def _sign_vector(self, st: _AxisState) -> tuple[float, float]:
        """The accumulated sign evidence (a 2-vector pointing forward): the phase evidence, or with
        ``sign_method="auto"`` the skew evidence where most of the remembered strides were a limb's."""
        if self.sign_method == "auto" and st.limb:
            return st.kx, st.ky
        return st.gx, st.gy

    def _axis_sums(self, st: _AxisState) -> tuple[float, float]:
        """The doubled-angle sums the offset's axis comes from: with ``sign_method="auto"`` and
        ``limb_raw_axis``, a limb's are every stride's raw-covariance axes; a placement whose axis is pulled
        sideways (``symmetric_axis_below_ratio``) every stride's symmetric axis; else each stride's own choice."""
        if self.sign_method == "auto" and self.limb_raw_axis and st.limb:
            return st.c2r, st.s2r
        if st.sym:
            return st.c2s, st.s2s
        return st.c2, st.s2

    def _offset_of(self, st: _AxisState) -> float:
        c2, s2 = self._axis_sums(st)
        theta = 0.5 * math.atan2(s2, c2)
        gx, gy = self._sign_vector(st)
        along = gx * math.cos(theta) + gy * math.sin(theta)
        if self.sign_method == "auto" and st.limb and st.fwd == st.fwd:
            # a limb holds its direction: the end of the axis nearer the last offset, unless the evidence along
            # it is clearly against it (the mean skew evidence below -limb_sign_margin)
            if math.cos(theta - st.fwd) < 0.0:
                theta += math.pi
                along = -along
            if along < -self.limb_sign_margin * st.w:
                theta += math.pi
            return wrap_angle(theta)
        if along < 0.0:
            theta += math.pi
        return wrap_angle(theta)

    def _state(self):
        st = self._states.get(self._axis_key)
        return st if st is not None and st.n else None

    # -- the desktop fast path's way in and out (desktop/fast/walkdir.py: it runs the updates as one kernel) ----------
    @property
    def kernel_settings(self) -> dict:
        """What ``__init__`` derives from the settings for the per-sample path: ``dt_s`` (grid period), ``leak``
        (the vertical velocity's per-sample leak), ``mean_alpha`` (the vertical mean's per-sample weight),
        ``forget`` (the per-stride forgetting factor), ``delay_n`` (the delay in grid samples), ``gap_ns``
        (``reset_after_gap_s`` in ns)."""
        return {"dt_s": self._dt, "leak": self._leak, "mean_alpha": self._mean_alpha, "forget": self._forget,
                "delay_n": self._delay_n, "gap_ns": self._gap_ns}

    @property
    def axis_key(self):
        """The device axis the current offset belongs to (the smoother's ``forward_b`` key; None before any)."""
        return self._axis_key

    def axis_state(self, axis):
        """The accumulators of ``axis`` (an ``_AxisState``, the object itself: read it, do not change it), or None."""
        return self._states.get(axis)

    def axis_states(self) -> dict:
        """Every axis's accumulators, ``{axis: _AxisState}`` (a new dict of the same objects)."""
        return dict(self._states)

    def set_axis(self, axis, state) -> None:
        """Make ``axis`` current with ``state`` (an ``_AxisState``, or None: no accepted stride) as its only
        accumulators: what :attr:`offset_rad`, :meth:`estimate` and :meth:`step_heading` read (the fast path's state at
        one grid sample, which keeps only the current axis)."""
        self._axis_key = axis
        self._states = {axis: state} if state is not None else {}

    def estimate_with(self, axis, state) -> dict:
        """:meth:`estimate` as it would be after :meth:`set_axis` ``(axis, state)``; this object is left as it was."""
        saved = self._axis_key, self._states
        self.set_axis(axis, state)
        try:
            return self.estimate()
        finally:
            self._axis_key, self._states = saved

    def restore_state(self, values: dict) -> None:
        """Set attributes :meth:`reset` makes, by name (``{name: value}``; the fast path's state after its last grid
        sample, with the same types as :meth:`update` leaves); a name reset() does not make raises."""
        unknown = [n for n in values if n not in self._state_names]
        if unknown:
            raise AttributeError(f"restore_state: {unknown} are not WalkingDirection state")
        for name, value in values.items():
            setattr(self, name, value)

    @property
    def offset_rad(self) -> float:
        """Walking heading minus smoothed device heading (rad, wrapped); 0 before any accepted stride."""
        st = self._state()
        return self._offset_of(st) if st is not None else 0.0

    @property
    def n_used(self) -> int:
        """Accepted strides behind the current axis's offset."""
        st = self._state()
        return st.n if st is not None else 0

    @property
    def axis_resultant(self) -> float:
        """Mean resultant length of the doubled stride axes (1: all strides agree; 0: no axis)."""
        st = self._state()
        return math.hypot(*self._axis_sums(st)) / st.w if st is not None else 0.0

    @property
    def offset_sigma_rad(self) -> float:
        """Standard error of the offset's axis (rad): circular spread over sqrt(effective strides); pi before any."""
        st = self._state()
        if st is None:
            return math.pi
        r = min(max(math.hypot(*self._axis_sums(st)) / st.w, 1e-12), 1.0)
        spread = 0.5 * math.sqrt(-2.0 * math.log(r))
        n_eff = st.w * st.w / st.w2
        return min(spread / math.sqrt(n_eff), math.pi)

    @property
    def sign_confidence(self) -> float:
        """Mean forward correlation along the offset's direction (0..1; 0 before any stride)."""
        st = self._state()
        if st is None:
            return 0.0
        o = self._offset_of(st)
        gx, gy = self._sign_vector(st)
        return max(0.0, (gx * math.cos(o) + gy * math.sin(o)) / st.w)

    @property
    def confident(self) -> bool:
        """Enough strides, a small uncertainty and a clear sign (see the settings)."""
        return (self.n_used >= self.confident_strides and self.offset_sigma_rad <= self.confident_sigma_rad
                and self.sign_confidence >= self.confident_sign)

    def applies(self, setting: str = "auto", carry_mode: str | None = None) -> bool:
        """Whether a step's heading gets the offset (the pipeline's ``walking_direction``).

        ``"device"``: never.  ``"acceleration"``: once a stride was accepted.  ``"auto"``:

        * with a carry-mode detector (``carry_mode`` given): in every mode but hand-held and still, once
          ``auto_min_strides`` strides were accepted -- there the device axis is known not to be the
          walking direction and the estimate is the best there is; never in the hand-held mode, which
          keeps today's heading exactly (a phone read in the hand points its top edge where the walker
          goes, and the estimate's noise would only add to it);
        * without one (``carry_mode`` None): only an estimate that is :attr:`confident` over at least
          ``auto_far_min_strides`` strides and farther than ``auto_min_offset_rad`` from 0.  A phone
          read in the hand points its top edge within 45 deg of the walk, so such an offset means it is
          not held so; the stride count keeps the waving of a compass calibration (periodic, stepping
          in place or not) from passing for a walk.
        """
        if setting == "device" or not self.n_used:
            return False
        if setting == "acceleration":
            return True
        if carry_mode is not None:
            return carry_mode not in (CARRY_HANDHELD, CARRY_STILL) and self.n_used >= self.auto_min_strides
        return (self.n_used >= self.auto_far_min_strides and self.confident
                and abs(self.offset_rad) > self.auto_min_offset_rad)

    def step_heading(self, device_heading_rad: float, setting: str = "auto", carry_mode: str | None = None,
                     axis=None) -> float:
        """A step's heading: the smoothed device heading, plus the offset where :meth:`applies` says so.

        Returns ``device_heading_rad`` itself (bit for bit) where the offset does not apply, and counts
        the steps that got it in :attr:`n_steps_offset`.  ``axis``: the device axis ``device_heading_rad`` is the
        heading of, when it is not the current one (its own offset applies; ``Pipeline(cross_axis_modes)``).
        """
        if axis is not None and axis != self._axis_key:
            saved = self._axis_key
            self._axis_key = axis
            try:
                return self.step_heading(device_heading_rad, setting, carry_mode)
            finally:
                self._axis_key = saved
        if device_heading_rad != device_heading_rad or not self.applies(setting, carry_mode):
            return device_heading_rad
        self.n_steps_offset += 1
        return wrap_angle(device_heading_rad + self.offset_rad)

    def estimate(self) -> dict:
        """The current estimate of the smoother's current axis, as data."""
        return {"offset_rad": self.offset_rad, "offset_sigma_rad": self.offset_sigma_rad,
                "sign_confidence": self.sign_confidence, "axis_resultant": self.axis_resultant,
                "confident": self.confident, "n_used": self.n_used}

    def diagnostics(self) -> dict:
        """The estimate and its counters, as data (``last_estimate``: the one forgotten at the last pause)."""
        return {**self.estimate(), "last_estimate": self.last_estimate, "n_strides": self.n_strides,
                "n_accepted": self.n_accepted, "rejected": dict(self.rejected),
                "n_sign_disagreements": self.n_sign_disagreements, "n_nonfinite": self.n_nonfinite,
                "n_steps_offset": self.n_steps_offset, "n_gap_resets": self.n_gap_resets,
                "axes": {str(k): self._offset_of(v) for k, v in self._states.items() if v.n}}
