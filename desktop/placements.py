"""How the phone is carried (issue #17): the simulator's placements other than the hand-held one.

``simulate_walk(..., placement=...)`` (:mod:`desktop.simulator`) takes the names of
``core.conventions.CARRY_MODES``; "handheld" is the simulator's own model, the others are built here on the
same walk: the same path, heel strikes, step lengths, step-length envelope and timeline (the same seed
gives the same walk in every placement), with the phone on another body segment.
:func:`simulate_still` makes the recordings of "not walking" (placement "still").  Like the simulator,
nothing here uses a filter, step model or detector of :mod:`core.pdr`: each placement is a closed-form
(or spline) function of time, the accelerometer is the second derivative of the phone's position and the
gyroscope the rate of its attitude, both by the simulator's own central differences (:class:`desktop.
simulator._WalkModel` samples them; the acceleration is within 2e-3 m/s^2 of the exact one, 5e-3 for the
bag, whose spline's third derivative jumps at its 2 ms knots).

The walking frame is (forward, left, up), turned to ENU by the walker's smoothed heading ``h``; ``u`` is
the step phase (heel strike ``k`` at ``u = k``), ``k`` the step-length envelope relative to the mean step
(0 at rest, so every gait motion fades in and out with the walk).  The left foot strikes at even ``u``,
the right at odd ``u`` (``WalkTruth.step_foot``): the simulator's lateral sway puts the body over the left
foot after an even heel strike.  Each placement draws its choices (side, grip, orientation, bag, ...)
from its own generator ``default_rng([seed, tag])`` unless ``placement_options`` gives them; they are in
``truth.placement_info`` and the recording's metadata.

The trunk
    The placements on the body's trunk (pocket via the hip, swinging via the shoulder, bag, ear) move with
    the centre of mass: the simulator's inverted-pendulum vertical motion, fore-aft speed swing and
    lateral sway with gain 1 and no lag (the hand-held phone has gain 0.85 and a 30 ms lag), and heel-strike
    transients of the placement's own size (below).

"pocket": a front trouser pocket
    The phone moves with the thigh.  Thigh angle to the vertical in the sagittal plane (flexion forward
    positive) over the pocket leg's gait cycle ``c`` (0 at its heel strike): ``6 + 19 cos 2 pi c - 4 cos 4
    pi c - 3 sin 4 pi c`` deg times ``k``: about +20 deg at heel strike, the most extension (-18 deg) at
    52 % of the cycle (end of stance), the most flexion (+23 deg) at 91 % (end of swing): a fit to the
    shape of the thigh's sagittal angle in Perry & Burnfield, "Gait Analysis: Normal and Pathological
    Function" (2nd ed. 2010): about 20 deg of apparent hyperextension at terminal stance and 25 deg
    flexion in swing; the slow extension in stance and the quick flexion in swing make it asymmetric.
    The pelvis turns +-4 deg about the vertical (the swinging side forward) and tilts +-4 deg (the swing
    side drops) at the stride frequency (the order of the pelvic rotation and list of Saunders, Inman &
    Eberhart 1953, "The major determinants in normal and pathological gait", J Bone Joint Surg 35-A).  The hip
    joints are ``0.05 height`` left and right of the centre at the leg length (``0.53 height``); the phone
    is ``0.13 height`` (0.23 m) down the thigh and ``0.04 height`` in front of its axis.  The phone is
    upright in the pocket: device y along the thigh (to the hip or to the knee), the screen facing
    forward or toward the thigh, turned 5-25 deg about the thigh axis toward the outside (a front pocket
    sits on the front-outer side), plus a fixed tilt of up to 5 deg about each axis.  Heel-strike
    transients: 4 m/s^2 at the phone for the pocket leg's heel strikes, 1.5 m/s^2 for the other leg's
    (the impact comes up the loaded leg; at the other thigh only through the pelvis) -- stated assumptions
    of the right order (thigh impacts are a fraction of the shank's few g).
    The phone also turns about the thigh's long axis by ``+-12 k`` deg over the gait cycle (the hip's axial
    rotation and the phone's play in the pocket; the size calibrated on the tuning walk thomasdingemanse_lopen,
    issue #25: without it the gyroscope's main-axis share was 0.92-0.96 against the real 0.74, with it 0.73;
    ``python -m benchmarks.placement_calibration``).
    Options: ``side`` ("left"/"right"), ``top`` ("hip"/"knee"), ``screen`` ("out"/"in").

"swinging": in a hand hanging at the side, the arm swinging
    The shoulder joint (``0.818 height`` up, ``0.10 height`` to the side, inside Winter's shoulder width of
    ``0.259 height``: segment proportions of Winter, "Biomechanics and Motor Control of Human Movement", 4th
    ed. 2009) rides on the trunk, which turns +-4 deg about the
    vertical at the stride frequency (the carrying shoulder forward when that arm is forward).  Upper arm
    (``0.186 height``) at ``-5 k + A_u cos(pi (u - p))`` deg from the vertical (forward positive), the
    forearm a further ``10 + 10 k + A_e cos(pi (u - p))`` deg of elbow flexion, the phone ``0.196 height``
    down the forearm (forearm plus half the hand); ``p`` puts the arm forward at the opposite foot's heel
    strike (arm and opposite leg swing together).  ``A_u = 20 g``, ``A_e = 12 g`` deg with ``g = k v /
    1.26 m/s`` (``v`` the cruise speed; at most 1.6): the forearm swings +-32 deg at 1.26 m/s, growing
    with speed.  Murray, Sepic & Barnard (1967, "Patterns of sagittal rotation of the upper limbs in
    walking", Physical Therapy 47:272-284) report shoulder and elbow arcs of a few tens of degrees that grow
    with walking speed; the numbers here are assumptions of that order, and give gyro peaks of 3-4 rad/s
    at 1.26 m/s.  The arm is abducted 8 deg (the hand clears the thigh) and the forearm twists
    ``+-8 g`` deg (pronation) about a fixed offset (uniform in +-15 deg).  Grip: device y along the forearm to the fingers
    ("down") or across the hand pointing forward ("forward"), the screen facing the thigh; a fixed tilt of up
    to 10 deg; the hand drift of ``hand_drift_deg_s`` on top.  Heel-strike transients 1 m/s^2 (the arm
    damps them).  Options: ``side``, ``grip``, ``twist_deg`` (the forearm's twist amplitude at the reference
    swing, 8 by default; issue #25: a hand that twists the phone 20-30 deg as it swings spreads the rotation over
    two axes, main-axis share 0.5-0.7 against 0.9; no real swinging walk of the tuning split calibrates it, so
    the default is unchanged), ``swing_scale`` (the swing's amplitudes times this, 1 by default;
    issue #25: a phone swung hard in the hand, the held-back clip's 9 rad/s, is ``swing_scale`` 2.5, whose
    gyroscope peaks at 8.9 rad/s; the default arm's peaks are 3.6 rad/s at the reference speed).

"bag": a shoulder bag or a backpack, loosely coupled to the trunk
    The bag hangs from an anchor on the trunk (backpack: 0.15 m behind at ``0.70 height``; shoulder bag:
    0.18 m to the side at ``0.55 height``) and follows it through a damped spring, the same in every axis:
    ``r'' + 2 zeta w r' + w^2 r = -a_anchor`` for the bag's displacement ``r`` from the anchor, natural
    frequency uniform in 3-6 Hz and damping ratio in 0.2-0.4 (assumed; drawn per seed).  ``r`` is solved
    exactly for a piecewise-linear input on a 2 ms grid (the state-transition of the linear system) and
    the phone's position is the anchor plus the C2 quintic through ``r, r', r''`` at the grid points, so the
    accelerometer is still the exact second derivative of the position.  The bag tilts with its swing
    (``r`` horizontal over a 0.3 m strap, in rad) and wobbles slowly (8 sinusoids per axis, 0.3-1.2 Hz, 3 deg
    RMS, times ``k``).  The phone lies in the bag in a fixed orientation: one of the six faces down
    (uniform), any yaw, tilted up to 10 deg.  Heel-strike transients 2 m/s^2 at the anchor, filtered by the
    spring.  The spring's resonance sits on the second and third step harmonics, so the bag's acceleration
    swings as much as the hand's or more (norm s.d. 2.5-3.3 against 1.8 m/s^2 at the defaults) while its
    content above 10 Hz is a sixth to a tenth of the pocket's.
    Options: ``kind`` ("backpack"/"shoulder"), ``side`` (shoulder bag), ``natural_hz``, ``damping``.

"ear": held at the ear during a call
    The head rides on the trunk (vertical gain 1, less damped than the hand's 0.85) at ``0.89 height``
    (the phone's centre, below the ear), 0.09 m to the side and 0.05 m forward; it yaws +-2 deg at the
    stride frequency and pitches +-1.5 deg at the step frequency (the head is stabilized; assumed).  The
    phone is upright along the cheek: device y up and tilted 20-40 deg backward (its bottom toward the
    mouth), the screen facing the head (device z to the right at the left ear, to the left at the right
    ear), turned up to 15 deg about the vertical; the hand drift of ``hand_drift_deg_s`` on top.
    Heel-strike transients 1.2 m/s^2.  Options: ``side``, ``tilt_deg``.

"still" (:func:`simulate_still`): not walking
    ``"table"``: lying still, screen up or down, any yaw, tilted up to 1 deg: sensor noise and bias only.
    ``"hand_standing"``: held in front while standing (pitch 15-45 deg, any yaw): the hand drift of
    ``hand_drift_deg_s``, postural sway (sinusoids at 0.1-0.5 Hz, 5 mm RMS per axis) and physiological
    tremor (sinusoids at 8-12 Hz: 15 um and 0.03 deg RMS per axis, about 0.06 m/s^2 and 0.03 rad/s; 8-12 Hz
    is physiological tremor's band, Elble & Koller, "Tremor", 1990; the amplitudes are assumed).  ``"vehicle"``: in a car, bus or tram: the vehicle drives a
    sequence of stops, accelerations (0.5-2 m/s^2) to 6-14 m/s, cruising with turns (90 deg at 0.1-0.25
    rad/s, the lateral acceleration at most 2 m/s^2) and braking (0.5-2 m/s^2), each a half-sine pulse,
    integrated on a 10 ms grid and interpolated by C2 quintics through position, velocity and acceleration;
    the body pitches 0.5 deg per m/s^2 (the nose dips braking) and rolls 0.5 deg per m/s^2 out of turns;
    road vibration is 24 sinusoids per axis at 5-30 Hz (acceleration 0.3 m/s^2 RMS vertical and 0.15
    horizontal, angle 0.01 deg RMS: 0.6-2 deg/s) times the speed over 10 m/s (at most 1.5), plus an idle
    engine's 0.05 / 0.03 m/s^2 at 25-30 Hz; bumps (potholes, joints, rails) come about every 3 s while
    driving faster than 2 m/s, each a vertical acceleration peak of 1-3 m/s^2 up or down, 15-40 ms wide
    (Gaussian), the most step-like thing in a vehicle (all assumed, of the order of ride measurements); the
    phone sits in a fixed orientation (one of six faces down, any yaw, tilted up to 15 deg).  ``heading_at``
    is the vehicle's heading, ``position_at`` its position.  No heel strikes.
"""

from __future__ import annotations

import math

import numpy as np

from core import quaternion as quat
from core.conventions import CARRY_BAG, CARRY_EAR, CARRY_POCKET, CARRY_STILL, CARRY_SWINGING
from desktop.simulator import (FORE_AFT_SPEED_SWING, LATERAL_SWAY_M, LEG_LENGTH_RATIO, _TURN_SMOOTH_S, SimulatedWalk,
                               _central_slopes, _positive, _Quintic, _vertical_coefficients, _WalkModel,
                               simulate_walk)

__all__ = ["simulate_still", "placement_model", "STILL_KINDS", "REFERENCE_SPEED_M_S"]

#: the kinds of :func:`simulate_still`
STILL_KINDS = ("table", "hand_standing", "vehicle")
#: the walking speed at which the swinging arm has its nominal amplitude (0.70 m x 1.8 steps/s)
REFERENCE_SPEED_M_S = 1.26
_SIDES = ("left", "right")
_DEG = math.pi / 180.0

# pocket
THIGH_ANGLE_DEG = (6.0, 19.0, 0.0, -4.0, -3.0)  #: mean, cos, sin of the 1st and 2nd gait-cycle harmonics (deg)
PELVIS_YAW_DEG = 4.0
PELVIS_LIST_DEG = 4.0
HIP_HALF_WIDTH_RATIO = 0.05
POCKET_DOWN_RATIO = 0.13
POCKET_FRONT_RATIO = 0.04
POCKET_IMPACT_M_S2 = (4.0, 1.5)  #: heel-strike transients at the phone: the pocket leg's, the other leg's
#: the phone's turn about the thigh's long axis over the gait cycle (deg): the hip's axial rotation plus the phone
#: turning in a loose pocket; calibrated on the tuning walk thomasdingemanse_lopen (issue #25): its gyroscope's
#: main-axis share is 0.74, the simulator's pocket without it 0.92-0.96 (benchmarks.placement_calibration)
THIGH_AXIAL_DEG = 12.0
# swinging arm
SHOULDER_HEIGHT_RATIO = 0.818
SHOULDER_HALF_WIDTH_RATIO = 0.10
UPPER_ARM_RATIO = 0.186
FOREARM_GRIP_RATIO = 0.196
ARM_SWING_DEG = (20.0, 12.0)  #: upper-arm and elbow amplitudes at the reference speed
THORAX_YAW_DEG = 4.0
ARM_ABDUCTION_DEG = 8.0
ARM_TWIST_DEG = 8.0
# bag
BAG_NATURAL_HZ = (3.0, 6.0)
BAG_DAMPING = (0.2, 0.4)
BAG_STRAP_M = 0.3
BAG_WOBBLE_DEG = 3.0
BAG_WOBBLE_HZ = (0.3, 1.2)
_BAG_GRID_S = 2e-3
# ear
EAR_HEIGHT_RATIO = 0.89
EAR_TILT_DEG = (20.0, 40.0)
# vehicle
VEHICLE_SPEED_M_S = (6.0, 14.0)
VEHICLE_ACC_M_S2 = (0.5, 2.0)
VEHICLE_TURN_RATE_RAD_S = (0.1, 0.25)
VEHICLE_VIBRATION_DEG = 0.01  #: RMS per axis of the body's angular vibration
VEHICLE_BUMPS_PER_S = 0.3  #: rate of road bumps (kept only while moving, at least 0.5 s apart)
VEHICLE_LATERAL_M_S2 = 2.0  #: the turn rate is limited so that the lateral acceleration stays below this
_VEHICLE_GRID_S = 0.01


def _rot(axis: int, angle) -> np.ndarray:
    return quat.about_axis_array(axis, angle)


def _chain(*qs) -> np.ndarray:
    """The product ``q1 (x) q2 (x) ...`` of quaternion arrays (broadcasting)."""
    out = qs[0]
    for q in qs[1:]:
        out = quat.multiply_array(out, q)
    return out


def _mount(columns_w) -> np.ndarray:
    """Quaternion of the rotation whose columns are the device x, y, z axes in the walking frame."""
    return np.array(quat.from_matrix(np.asarray(columns_w, float).T.tolist()))


#: one of the six faces down: the rotation putting device -z, +z, -y, +y, -x, +x down (screen up first)
_FACE_DOWN = tuple(_rot(a, ang) for a, ang in ((0, 0.0), (1, math.pi), (0, -0.5 * math.pi), (0, 0.5 * math.pi),
                                               (1, 0.5 * math.pi), (1, -0.5 * math.pi)))


def _random_orientation(rng: np.random.Generator, tilt_deg: float) -> tuple[np.ndarray, dict]:
    """A phone lying on one of its six faces (uniform), any yaw, tilted up to ``tilt_deg`` about x and y."""
    face = int(rng.integers(6))
    yaw = rng.uniform(-math.pi, math.pi)
    tx, ty = rng.uniform(-tilt_deg, tilt_deg, 2) * _DEG
    q = _chain(_rot(2, yaw), _rot(0, tx), _rot(1, ty), _FACE_DOWN[face])
    names = ("-z", "+z", "-y", "+y", "-x", "+x")  # the device axis pointing up
    return q, {"face_up": names[face], "yaw_deg": math.degrees(yaw)}


def _sinusoids(rng: np.random.Generator, n_axes: int, terms: int, band_hz: tuple[float, float],
               rms: float) -> np.ndarray:
    """(axes, terms, [amplitude, frequency Hz, phase]) of sums of sinusoids with log-uniform frequencies
    in ``band_hz`` and random phases, ``rms`` per axis."""
    freq = np.exp(rng.uniform(math.log(band_hz[0]), math.log(band_hz[1]), (n_axes, terms)))
    phase = rng.uniform(0.0, 2.0 * np.pi, (n_axes, terms))
    amp = np.full((n_axes, terms), rms * math.sqrt(2.0 / terms))
    return np.stack([amp, freq, phase], axis=-1)


def _eval_sinusoids(s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n, axes) values at times ``t`` of :func:`_sinusoids`."""
    return np.stack([np.sin(2.0 * np.pi * np.outer(t, ax[:, 1]) + ax[:, 2]) @ ax[:, 0] for ax in s], axis=1)


class _Carried(_WalkModel):
    """The walk of :class:`_WalkModel` with the phone on another body segment.

    The inherited gait motion (``_gait``) is made the trunk's (centre of mass, gain 1, no lag) with the
    placement's heel-strike transients; subclasses give the phone's position in the walking frame relative
    to the walker's ground point (``offset_w``) and its attitude relative to the walking frame
    (``attitude_w``)."""

    placement = ""
    impact_m_s2 = 2.0  #: heel-strike transient at the phone (full step)
    choices: dict = {}  #: option name -> allowed values (None: any number)

    def __init__(self, *, rng: np.random.Generator, options: dict, total_s: float, **kw):
        super().__init__(**kw)
        unknown = set(options) - set(self.choices)
        if unknown:
            raise ValueError(f"unknown placement_options for {self.placement!r}: {sorted(unknown)}; "
                             f"known: {sorted(self.choices)}")
        for name, allowed in self.choices.items():
            if name in options and allowed is not None and options[name] not in allowed:
                raise ValueError(f"placement_options[{name!r}] must be one of {allowed}, got {options[name]!r}")
        self.height_m = self.leg_m / LEG_LENGTH_RATIO
        self.total_s = float(total_s)
        f = self.f
        self.vert_coef = _vertical_coefficients(f, gain=1.0, lag_s=0.0)
        self.vert_crest_phase = self._crest_phase(self.vert_coef)
        self.vert_crest = float(self._vertical_unit(np.array([self.vert_crest_phase]))[0])
        self.fwd_amp = FORE_AFT_SPEED_SWING * self.step_length_m / (2.0 * np.pi) + 0j
        self.lat_amp = LATERAL_SWAY_M + 0j
        self.hs_amp = self.impact_m_s2 * self.bounce_scale * self.step_lengths / self.step_length_m
        self.speed_gain = self.step_length_m * f / REFERENCE_SPEED_M_S
        self.side = None
        self.info: dict = {}
        self._setup(rng, dict(options))

    def _setup(self, rng: np.random.Generator, options: dict) -> None:
        raise NotImplementedError

    def _pick(self, rng: np.random.Generator, options: dict, name: str):
        """The option ``name`` if given, else a uniform draw among its allowed values (always drawn, so a
        given option moves no other draw)."""
        drawn = self.choices[name][int(rng.integers(len(self.choices[name])))]
        value = options.get(name, drawn)
        self.info[name] = value
        return value

    def _uniform(self, rng: np.random.Generator, options: dict, name: str, lo: float, hi: float) -> float:
        drawn = rng.uniform(lo, hi)
        value = _positive(name, options.get(name, drawn))
        self.info[name] = value
        return value

    def _heading(self, t: np.ndarray) -> np.ndarray:
        return self.path.smooth_heading(self.warped(t), _TURN_SMOOTH_S)

    def quat(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        return quat.multiply_array(_rot(2, self._heading(t)), self.attitude_w(t))

    def attitude_w(self, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _side_sign(self) -> float:
        return 1.0 if self.side == "left" else -1.0


class _Pocket(_Carried):
    placement = CARRY_POCKET
    choices = {"side": _SIDES, "top": ("hip", "knee"), "screen": ("out", "in")}

    def _setup(self, rng, options):
        self.side = self._pick(rng, options, "side")
        top = self._pick(rng, options, "top")
        screen = self._pick(rng, options, "screen")
        twist = rng.uniform(5.0, 25.0)
        tilt = rng.uniform(-5.0, 5.0, 3)
        self.info.update(twist_out_deg=twist, tilt_deg=tilt.tolist())
        sgn = self._side_sign()
        # thigh vertical, pocket facing forward: device y up the thigh, screen (z) forward, x = y x z (left)
        q = _mount([(0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])
        if top == "knee":
            q = quat.multiply_array(q, _rot(2, math.pi))
        if screen == "in":
            q = quat.multiply_array(q, _rot(1, math.pi))
        self.mount = _chain(_rot(2, sgn * twist * _DEG), _rot(0, tilt[0] * _DEG), _rot(1, tilt[1] * _DEG),
                            _rot(2, tilt[2] * _DEG), q)
        self.leg_phase = 0.0 if self.side == "left" else 1.0  # the left foot strikes at even step phases
        # the pocket leg's heel strikes are felt more strongly
        k = np.arange(1, len(self.hs_amp) + 1)
        strong = (k % 2) == (0 if self.side == "left" else 1)
        self.hs_amp = self.hs_amp / self.impact_m_s2 * np.where(strong, *POCKET_IMPACT_M_S2)

    def _angles(self, t):
        u = self.phase(t)
        k = self.rel_length(t)
        c = 0.5 * (u - self.leg_phase)  # the pocket leg's gait cycle (its heel strike at integers)
        m, a1, b1, a2, b2 = THIGH_ANGLE_DEG
        th = k * _DEG * (m + a1 * np.cos(2 * np.pi * c) + b1 * np.sin(2 * np.pi * c) + a2 * np.cos(4 * np.pi * c)
                         + b2 * np.sin(4 * np.pi * c))
        sgn = self._side_sign()
        # pelvis: the swinging side forward (most at that leg's heel strike), the swing side drops
        yaw = -sgn * PELVIS_YAW_DEG * _DEG * k * np.cos(np.pi * (u - self.leg_phase))
        roll = PELVIS_LIST_DEG * _DEG * k * np.sin(np.pi * u)
        # about the thigh's axis: outward in swing, inward through stance (the shape assumed, the size calibrated)
        axial = sgn * THIGH_AXIAL_DEG * _DEG * k * np.sin(2 * np.pi * c)
        return th, yaw, roll, axial

    def offset_w(self, t):
        th, yaw, roll, axial = self._angles(t)
        sgn = self._side_sign()
        hgt = self.height_m
        trunk = self._gait(t)
        down, front = POCKET_DOWN_RATIO * hgt, POCKET_FRONT_RATIO * hgt
        # in the pelvis frame: the hip joint, then the pocket on the thigh turned forward by th (flexion)
        fx, fy = front * np.cos(axial), front * np.sin(axial)  # the pocket turned about the thigh's axis
        p = np.stack([fx * np.cos(th) + down * np.sin(th), sgn * HIP_HALF_WIDTH_RATIO * hgt + fy,
                      fx * np.sin(th) - down * np.cos(th)], axis=1)
        r = quat.to_matrix_array(quat.multiply_array(_rot(2, yaw), _rot(0, roll)))
        return trunk + np.einsum("nij,nj->ni", r, p) + np.array([0.0, 0.0, self.leg_m])

    def attitude_w(self, t):
        th, yaw, roll, axial = self._angles(t)
        return _chain(_rot(2, yaw), _rot(0, roll), _rot(1, -th), _rot(2, axial), self.mount)


class _Swinging(_Carried):
    placement = CARRY_SWINGING
    impact_m_s2 = 1.0
    choices = {"side": _SIDES, "grip": ("down", "forward"), "swing_scale": None, "twist_deg": None}

    def _setup(self, rng, options):
        self.side = self._pick(rng, options, "side")
        grip = self._pick(rng, options, "grip")
        self.twist_amp_deg = float(options.get("twist_deg", ARM_TWIST_DEG))
        if not 0.0 <= self.twist_amp_deg <= 90.0:
            raise ValueError(f"placement_options['twist_deg'] must be in [0, 90], got {self.twist_amp_deg!r}")
        self.info["twist_amp_deg"] = self.twist_amp_deg
        self.swing_scale = float(options.get("swing_scale", 1.0))
        if not 0.0 < self.swing_scale <= 4.0:
            raise ValueError(f"placement_options['swing_scale'] must be in (0, 4], got {self.swing_scale!r}")
        self.info["swing_scale"] = self.swing_scale
        twist0 = rng.uniform(-15.0, 15.0)
        tilt = rng.uniform(-10.0, 10.0, 2)
        self.info.update(twist_deg=twist0, tilt_deg=tilt.tolist())
        medial = np.array([0.0, -self._side_sign(), 0.0])  # toward the body
        y = np.array([0.0, 0.0, -1.0]) if grip == "down" else np.array([1.0, 0.0, 0.0])
        q = _mount([np.cross(y, medial), y, medial])
        self.mount = _chain(_rot(2, twist0 * _DEG), _rot(0, tilt[0] * _DEG), _rot(1, tilt[1] * _DEG), q)
        # the arm is forward at the opposite foot's heel strike: the right arm at the left's (even phases)
        self.arm_phase = 0.0 if self.side == "right" else 1.0

    def _angles(self, t):
        u = self.phase(t)
        k = self.rel_length(t)
        g = np.minimum(k * self.speed_gain, 1.6) * self.swing_scale
        swing = np.cos(np.pi * (u - self.arm_phase))
        upper = (-5.0 * k + ARM_SWING_DEG[0] * g * swing) * _DEG
        fore = upper + (10.0 + 10.0 * k + ARM_SWING_DEG[1] * g * swing) * _DEG
        thorax = self._side_sign() * -THORAX_YAW_DEG * _DEG * k * swing  # the carrying shoulder forward
        twist = self.twist_amp_deg * _DEG * g * np.sin(np.pi * (u - self.arm_phase))
        return upper, fore, thorax, twist

    def offset_w(self, t):
        upper, fore, thorax, _ = self._angles(t)
        hgt = self.height_m
        lu, lf = UPPER_ARM_RATIO * hgt, FOREARM_GRIP_RATIO * hgt
        abd = self._side_sign() * ARM_ABDUCTION_DEG * _DEG
        # the arm in the shoulder's frame (forward, left, up), then abducted and turned with the thorax
        arm = np.stack([lu * np.sin(upper) + lf * np.sin(fore), np.zeros_like(upper),
                        -lu * np.cos(upper) - lf * np.cos(fore)], axis=1)
        arm = np.stack([arm[:, 0], -math.sin(abd) * arm[:, 2], math.cos(abd) * arm[:, 2]], axis=1)
        shoulder = np.array([0.0, self._side_sign() * SHOULDER_HALF_WIDTH_RATIO * hgt, 0.0]) + arm
        c, s = np.cos(thorax), np.sin(thorax)
        turned = np.stack([c * shoulder[:, 0] - s * shoulder[:, 1], s * shoulder[:, 0] + c * shoulder[:, 1],
                           shoulder[:, 2]], axis=1)
        return self._gait(t) + turned + np.array([0.0, 0.0, SHOULDER_HEIGHT_RATIO * hgt])

    def attitude_w(self, t):
        upper, fore, thorax, twist = self._angles(t)
        abd = self._side_sign() * ARM_ABDUCTION_DEG * _DEG
        drift = _chain(*(_rot(a, self._drift(t, a)) for a in range(3)))
        return _chain(_rot(2, thorax), _rot(0, np.full_like(fore, abd)), _rot(1, -fore), _rot(2, twist),
                      drift, self.mount)


class _Ear(_Carried):
    placement = CARRY_EAR
    impact_m_s2 = 1.2
    choices = {"side": _SIDES, "tilt_deg": None}

    def _setup(self, rng, options):
        self.side = self._pick(rng, options, "side")
        tilt = self._uniform(rng, options, "tilt_deg", *EAR_TILT_DEG) * _DEG
        turn = rng.uniform(-15.0, 15.0)
        self.info.update(turn_deg=turn)
        y = np.array([-math.sin(tilt), 0.0, math.cos(tilt)])  # up, the bottom forward toward the mouth
        z = np.array([0.0, -self._side_sign(), 0.0])  # the screen faces the head
        self.mount = quat.multiply_array(_rot(2, turn * _DEG), _mount([np.cross(y, z), y, z]))

    def offset_w(self, t):
        return self._gait(t) + np.array([0.05, self._side_sign() * 0.09, EAR_HEIGHT_RATIO * self.height_m])

    def attitude_w(self, t):
        u = self.phase(t)
        k = self.rel_length(t)
        yaw = 2.0 * _DEG * k * np.sin(np.pi * u + 0.4) + self._drift(t, 0)
        pitch = 1.5 * _DEG * k * np.sin(2.0 * np.pi * u + 1.0) + self._drift(t, 1)
        roll = self._drift(t, 2)
        return _chain(_rot(2, yaw), _rot(1, pitch), _rot(0, roll), self.mount)


class _Bag(_Carried):
    placement = CARRY_BAG
    choices = {"kind": ("backpack", "shoulder"), "side": _SIDES, "natural_hz": None, "damping": None}

    def _setup(self, rng, options):
        kind = self._pick(rng, options, "kind")
        side = self._pick(rng, options, "side")
        if kind == "backpack":
            del self.info["side"]
            self.anchor = np.array([-0.15, 0.0, 0.70 * self.height_m])
        else:
            self.anchor = np.array([0.0, (0.18 if side == "left" else -0.18), 0.55 * self.height_m])
        wn = 2.0 * math.pi * self._uniform(rng, options, "natural_hz", *BAG_NATURAL_HZ)
        zeta = self._uniform(rng, options, "damping", *BAG_DAMPING)
        self.mount, orient = _random_orientation(rng, 10.0)
        self.info.update(orient)
        self.wobble = _sinusoids(rng, 3, 8, BAG_WOBBLE_HZ, BAG_WOBBLE_DEG * _DEG)
        self._solve_spring(wn, zeta)

    def offset_w(self, t):
        """The anchor on the trunk."""
        return self._gait(t) + self.anchor

    def _solve_spring(self, wn: float, zeta: float) -> None:
        """The bag's displacement from its anchor: ``r'' + 2 zeta wn r' + wn^2 r = -a_anchor`` on a 2 ms grid,
        exact for an input linear between grid points (the discretized linear system, diagonalized and run
        in blocks), at rest before walking and until 3 s after it ends (it has died away by then)."""
        h = _BAG_GRID_S
        t0, t1 = self.walk_start_s - 0.5, min(self.walk_end_s + 3.0, self.total_s + 1.0)
        t = t0 + h * np.arange(int(math.ceil(max(t1 - t0, 4 * h) / h)) + 1)
        p = super().position(np.concatenate([t - h, t, t + h]))  # the anchor
        n = len(t)
        u = -(p[:n] - 2.0 * p[n:2 * n] + p[2 * n:]) / (h * h)  # (n, 3) input: minus the anchor's acceleration
        a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
        # exp of the augmented system [[A, B, 0], [0, 0, 1], [0, 0, 0]] h: state (r, r'), input u and its slope
        m = np.zeros((4, 4))
        m[:2, :2], m[1, 2], m[2, 3] = a, 1.0, 1.0
        e, term = np.eye(4), np.eye(4)
        for j in range(1, 20):
            term = term @ (m * h) / j
            e = e + term
        phi, g0, g1 = e[:2, :2], e[:2, 2], e[:2, 3] / h
        lam, vec = np.linalg.eig(phi)
        inv = np.linalg.inv(vec)
        drive = g0[:, None, None] * u[None, :-1] + g1[:, None, None] * np.diff(u, axis=0)[None]  # (2, n-1, 3)
        b = np.einsum("ij,jnk->nik", inv, drive)
        z = np.zeros((n, 2, 3), complex)  # modal states; r = Re(V z)
        block = 256
        powers = lam[None, :] ** np.arange(block + 1)[:, None]  # (block+1, 2)
        for s0 in range(0, n - 1, block):
            s1 = min(s0 + block, n - 1)
            bb = b[s0:s1]  # inputs of steps s0 .. s1-1
            pw = powers[:s1 - s0 + 1]
            # z[s0 + j] = lam^j (z[s0] + sum_{i<j} lam^(-1-i) b[s0 + i])
            acc = np.concatenate([np.zeros((1, 2, 3), complex), np.cumsum(bb / pw[1:, :, None], axis=0)])
            z[s0:s1 + 1] = pw[:, :, None] * (z[s0][None] + acc)
        state = np.einsum("ij,njk->nik", vec, z).real  # (n, 2, 3): r, r'
        r, rd = state[:, 0], state[:, 1]
        rdd = u - 2.0 * zeta * wn * rd - wn * wn * r
        self._spring = [_Quintic(t, r[:, i], rd[:, i], rdd[:, i]) for i in range(3)]
        self._spring_span = (t[0], t[-1])

    def _r(self, t):
        inside = (t > self._spring_span[0]) & (t < self._spring_span[1])
        return np.stack([np.where(inside, q(t), 0.0) for q in self._spring], axis=1)

    def position(self, t):
        t = np.asarray(t, float)
        return super().position(t) + self._r(t)

    def attitude_w(self, t):
        k = self.rel_length(t)
        h = self._heading(t)
        r = self._r(t)
        c, s = np.cos(h), np.sin(h)
        fwd, left = c * r[:, 0] + s * r[:, 1], -s * r[:, 0] + c * r[:, 1]
        wob = k[:, None] * _eval_sinusoids(self.wobble, t)
        # the bag swings on its strap: displaced forward, its bottom leads (pitch about left), sideways: roll
        return _chain(_rot(2, wob[:, 0]), _rot(1, fwd / BAG_STRAP_M + wob[:, 1]),
                      _rot(0, -left / BAG_STRAP_M + wob[:, 2]), self.mount)


class _Still(_Carried):
    placement = CARRY_STILL
    choices = {"kind": STILL_KINDS}

    def _setup(self, rng, options):
        if self.n_steps:
            raise ValueError("the still placement is for standing only: use simulate_still (a single waypoint)")
        if "kind" not in options:
            raise ValueError(f"placement 'still' needs placement_options={{'kind': ...}}, one of {STILL_KINDS}")
        self.kind = options["kind"]
        self.info["kind"] = self.kind
        getattr(self, "_setup_" + self.kind)(rng)

    # -- table -------------------------------------------------------------------------------------
    def _setup_table(self, rng):
        down = bool(rng.integers(2))
        yaw = rng.uniform(-math.pi, math.pi)
        tx, ty = rng.uniform(-1.0, 1.0, 2) * _DEG
        self.mount = _chain(_rot(2, yaw), _rot(0, tx), _rot(1, ty), _FACE_DOWN[1 if down else 0])
        self.info.update(screen="down" if down else "up", yaw_deg=math.degrees(yaw))
        self.place = np.array([0.3, 0.0, 0.75])

    # -- held while standing -----------------------------------------------------------------------
    def _setup_hand_standing(self, rng):
        pitch = rng.uniform(15.0, 45.0)
        yaw = rng.uniform(-math.pi, math.pi)
        self.info.update(pitch_deg=pitch, yaw_deg=yaw / _DEG)
        self.mount = _chain(_rot(2, yaw), _rot(0, pitch * _DEG))
        self.sway = _sinusoids(rng, 3, 8, (0.1, 0.5), 0.005)
        self.tremor = _sinusoids(rng, 3, 12, (8.0, 12.0), 15e-6)
        self.tremor_ang = _sinusoids(rng, 3, 12, (8.0, 12.0), 0.03 * _DEG)
        self.place = np.array([0.3, 0.0, 0.75 * self.height_m])

    # -- in a vehicle ------------------------------------------------------------------------------
    def _setup_vehicle(self, rng):
        self.mount, orient = _random_orientation(rng, 15.0)
        self.info.update(orient)
        h = _VEHICLE_GRID_S
        t = np.arange(-1.0, self.total_s + 2.0, h)
        acc = np.zeros_like(t)
        yaw_rate = np.zeros_like(t)
        start = rng.uniform(1.0, 5.0)  # the vehicle sets off
        events = []
        while start < self.total_s:
            v_top = rng.uniform(*VEHICLE_SPEED_M_S)
            a_up, a_dn = rng.uniform(*VEHICLE_ACC_M_S2, 2)
            # half-sine pulses: of acceleration (peak a, lasting pi dv / 2a) and of yaw rate (90 deg)
            t_up = 0.5 * math.pi * v_top / a_up
            t_dn = 0.5 * math.pi * v_top / a_dn
            rate = min(rng.uniform(*VEHICLE_TURN_RATE_RAD_S), VEHICLE_LATERAL_M_S2 / v_top)
            t_turn = 0.25 * math.pi ** 2 / rate
            cruise = max(rng.uniform(8.0, 25.0), t_turn + 2.0)
            events.append((start, t_up, a_up, cruise, t_dn, a_dn))
            turn_at = start + t_up + rng.uniform(0.0, cruise - t_turn)
            rate *= rng.choice((-1.0, 1.0))
            yaw_rate += np.where((t >= turn_at) & (t < turn_at + t_turn),
                                 rate * np.sin(np.pi * np.clip((t - turn_at) / t_turn, 0.0, 1.0)), 0.0)
            for t_s, dur, a_pk in ((start, t_up, a_up), (start + t_up + cruise, t_dn, -a_dn)):
                pulse = a_pk * np.sin(np.pi * np.clip((t - t_s) / dur, 0.0, 1.0))
                acc += np.where((t >= t_s) & (t < t_s + dur), pulse, 0.0)
            start += t_up + cruise + t_dn + rng.uniform(3.0, 10.0)
        self.info["legs"] = len(events)
        # speed, yaw and position by trapezoid integration on the grid; interpolated by quintics through the
        # exact derivatives at the grid points (so the accelerometer is the position's second derivative)
        speed = np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * h)])
        speed = np.maximum(speed, 0.0)
        yaw = np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * h)])
        vel = speed[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        pos = np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * h, axis=0)])
        a_n = acc[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], axis=1) + (speed * yaw_rate)[:, None] * np.stack(
            [-np.sin(yaw), np.cos(yaw)], axis=1)
        self.veh = [_Quintic(t, pos[:, i], vel[:, i], a_n[:, i]) for i in range(2)]
        self.veh_yaw = _Quintic(t, yaw, yaw_rate, _central_slopes(t, yaw_rate, 0.0, 0.0))
        self.veh_speed = _Quintic(t, speed, acc, _central_slopes(t, acc, 0.0, 0.0))
        self.veh_acc = _Quintic(t, acc, _central_slopes(t, acc, 0.0, 0.0))
        self.veh_lat = _Quintic(t, speed * yaw_rate, _central_slopes(t, speed * yaw_rate, 0.0, 0.0))
        self.vib = _sinusoids(rng, 3, 24, (5.0, 30.0), 1.0)
        self.vib_ang = _sinusoids(rng, 3, 24, (5.0, 30.0), 1.0)
        self.idle = _sinusoids(rng, 3, 4, (25.0, 30.0), 1.0)
        self.place = np.array([0.5, 0.3, 1.0])
        # bumps (potholes, joints, tram rails): a Poisson process while moving faster than 2 m/s, at least
        # 0.5 s apart; each a Gaussian dip of the height: a vertical acceleration peak of 1-3 m/s^2 either way
        n = int(rng.poisson(VEHICLE_BUMPS_PER_S * self.total_s))
        tb = np.sort(rng.uniform(0.0, self.total_s, n))
        amp = rng.uniform(1.0, 3.0, n) * rng.choice((-1.0, 1.0), n)
        sig = rng.uniform(0.015, 0.04, n)
        keep = (np.interp(tb, t, speed) > 2.0) & (np.diff(tb, prepend=-np.inf) > 0.5)
        self.bump_t, self.bump_amp, self.bump_sig = tb[keep], amp[keep], sig[keep]
        self.info["bumps"] = int(keep.sum())

    def _vibration(self, t, s, acc_rms):
        """Displacement (n, 3) of sinusoids ``s`` scaled so that their acceleration has ``acc_rms`` per axis."""
        scaled = s.copy()
        scaled[..., 0] = s[..., 0] / (2.0 * np.pi * s[..., 1]) ** 2
        return _eval_sinusoids(scaled, t) * acc_rms

    def walker(self, t):
        if self.kind != "vehicle":
            return super().walker(t)
        t = np.asarray(t, float)
        x, y = (q(t) for q in self.veh)
        return x, y, self.veh_yaw(t), self.veh_speed(t), np.zeros_like(t)

    def position(self, t):
        t = np.asarray(t, float)
        if self.kind == "table":
            return np.tile(self.place, (len(t), 1))
        if self.kind == "hand_standing":
            return (self.place + _eval_sinusoids(self.sway, t) + _eval_sinusoids(self.tremor, t))
        x, y, yaw, speed, _ = self.walker(t)
        moving = np.clip(speed / 10.0, 0.0, 1.5)[:, None]
        shake = moving * self._vibration(t, self.vib, np.array([0.15, 0.15, 0.3])) + self._vibration(
            t, self.idle, np.array([0.03, 0.03, 0.05]))
        if len(self.bump_t):  # the bumps just before and after t are enough (at most 4 sigma wide, 0.5 s apart)
            j = np.searchsorted(self.bump_t, t)
            for off in (-1, 0):
                jj = np.clip(j + off, 0, len(self.bump_t) - 1)
                valid = (j + off >= 0) & (j + off < len(self.bump_t))
                sig2 = self.bump_sig[jj] ** 2
                x2 = np.minimum((t - self.bump_t[jj]) ** 2 / sig2, 200.0)
                shake[:, 2] -= np.where(valid, self.bump_amp[jj] * sig2 * np.exp(-0.5 * x2), 0.0)
        c, s = np.cos(yaw), np.sin(yaw)
        d = self.place
        return np.stack([x + c * d[0] - s * d[1], y + s * d[0] + c * d[1], np.full_like(x, d[2])], axis=1) + shake

    def quat(self, t):
        t = np.asarray(t, float)
        if self.kind == "table":
            return np.tile(self.mount, (len(t), 1))
        if self.kind == "hand_standing":
            tr = _eval_sinusoids(self.tremor_ang, t)
            return _chain(*(_rot(a, self._drift(t, a) + tr[:, a]) for a in (2, 0, 1)), self.mount)
        _, _, yaw, speed, _ = self.walker(t)
        moving = np.clip(speed / 10.0, 0.0, 1.5)
        vib = moving[:, None] * _eval_sinusoids(self.vib_ang, t) * (VEHICLE_VIBRATION_DEG * _DEG)
        pitch = 0.5 * _DEG * self.veh_acc(t) + vib[:, 0]  # the nose dips when braking
        roll = 0.5 * _DEG * self.veh_lat(t) + vib[:, 1]  # the body leans out of the turn
        return _chain(_rot(2, yaw + vib[:, 2]), _rot(1, -pitch), _rot(0, roll), self.mount)


_MODELS = {m.placement: m for m in (_Pocket, _Swinging, _Ear, _Bag, _Still)}


def placement_model(placement: str, options: dict, rng: np.random.Generator, **model_kw) -> _WalkModel:
    """The model of ``placement`` (not "handheld") for :func:`desktop.simulator.simulate_walk`."""
    if placement not in _MODELS:
        raise ValueError(f"no placement model {placement!r}; known: {sorted(_MODELS)}")
    if not isinstance(options, dict):
        raise ValueError(f"placement_options must be a dict, got {type(options).__name__}")
    return _MODELS[placement](rng=rng, options=options, **model_kw)


def simulate_still(kind: str, duration_s: float = 60.0, *, seed: int = 0, **kw) -> SimulatedWalk:
    """A recording of not walking (placement "still", no heel strikes): ``kind`` one of :data:`STILL_KINDS`
    ("table", "hand_standing", "vehicle"; see the module docstring), lasting ``duration_s``.

    Any other keyword of :func:`desktop.simulator.simulate_walk` applies (sensor noise and biases, rates,
    ``gps``, ``hand_drift_deg_s``, ``origin_lat_lon``, ...)."""
    if kind not in STILL_KINDS:
        raise ValueError(f"kind must be one of {', '.join(STILL_KINDS)}, got {kind!r}")
    duration_s = _positive("duration_s", duration_s)
    return simulate_walk([(0.0, 0.0)], still_start_s=duration_s, still_end_s=0.0, placement=CARRY_STILL,
                         placement_options={"kind": kind}, seed=seed, **kw)

