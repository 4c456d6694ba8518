"""A hand-held smartphone walk simulator with exact ground truth (numpy only).

:func:`simulate_walk` turns a polyline of waypoints into a
:class:`~core.recording.Recording` (streams ``acc``, ``gyro``, ``mag``, each on
its own jittered clock, and optionally ``gps``) plus a :class:`WalkTruth` (heel strikes, per-step
lengths, positions, walking and device headings, dense attitude, sensor
biases, the true magnetic field).  :func:`demo_walk` is the bundled demo.  All
quantities follow the conventions of :mod:`core` (ENU, Android device frame,
quaternion ``(w, x, y, z)`` body -> ENU, ``t_ns`` int64, SI, uT).

The simulator is deliberately built from its own models, none of the
pipeline's: no low-pass filter, no step-length model and no step detector of
:mod:`core.pdr` is used to make the signals, so a test of the pipeline
against this truth can fail.

The model
=========
Everything is a closed-form (or spline) function of time ``t``; each sensor
is sampled by evaluating those functions at its own integer-nanosecond sample
times, so every sensor is consistent with the truth by construction.

Timeline
    ``[calibration_motion_s]`` (optional phone waving while standing) ->
    ``[still_start_s]`` standing, phone in the walking pose -> walking ->
    ``[still_end_s]`` standing.

Cadence and step length
    The mean step length follows the *walk ratio* (step length / step rate),
    which is nearly constant for a person over the range of normal walking
    speeds: about 0.0064 m/(steps/min) for young adults of about 1.72 m
    (Sekiya & Nagasaki 1998, "Reproducibility of the walking patterns of
    normal young adults: test-retest reliability of the walk ratio",
    Gait & Posture 7(3):225-227).  Scaled with body height here:
    ``step_length = WALK_RATIO_PER_HEIGHT * height * 60 * step_frequency``
    with ``WALK_RATIO_PER_HEIGHT = 0.00372 /min``, i.e. 0.70 m for 1.75 m at
    1.8 steps/s (``step_length_m`` overrides it).

The plan (walker's path)
    The walker follows the polyline at the cruise speed
    ``v = step_frequency_hz * step_length_m``.  Each corner is rounded by a
    circular arc walked at ``turn_rate_deg_s``, radius ``r = v / turn_rate``,
    cutting ``r (2 tan(|turn|/2) - |turn|)`` off the polyline.  A corner may
    use half of each adjacent segment; where the full-speed arc does not fit,
    the walker slows down to the speed whose arc fits, down to turning on the
    spot (U-turn).  Speed changes are cosine ramps lasting 1.5 step periods
    for a change of ``v`` (a peak acceleration of ``pi v f / 3``, 2.4 m/s^2 with
    the defaults); walking starts and ends at rest, so ``n_steps`` is about
    ``path_length / step_length + 1.5``.  The plan lasts a whole
    number ``n_steps`` of nominal step periods (stretched in time by a factor
    within ``1 +- 0.5 / n_steps``); its heel strikes would be at
    ``walk_start + k / step_frequency_hz``.

Step-to-step variability (the actual walk)
    * Heel strike times: ``t_k = walk_start + k / f + d_k``, ``d_k`` i.i.d.
      normal with ``std = step_time_cv / (f sqrt 2)`` (clipped at 15 % of a
      period), so each step's duration has the coefficient of variation
      ``step_time_cv``; the first and last heel strikes are not moved.
    * Distance along the path at heel strike ``k``:
      ``S_k = s_plan(k / f) + e_k`` with ``e_k`` a stationary AR(1) process
      (coefficient 0.7) scaled so that the step lengths ``S_k - S_{k-1}``
      have the coefficient of variation ``step_length_cv`` (lag-one
      correlation -0.15); ``e`` is 0 at the ends and is clipped to 30 % of
      the adjacent plan steps, so the walker never drifts off the plan by more
      than a few cm and ends exactly at the last waypoint.
    * The walker at time ``t`` is at the plan's state at the warped time
      ``w(t)``, a C2 quintic spline through ``(t_k, w_k)`` with
      ``s_plan(w_k) = S_k`` (``w_k`` kept within 10 % of a period of
      ``k / f``, so a turn on the spot is not skipped).  So the truth step
      lengths are exactly the distances walked between heel strikes and they
      sum to the path length; speed and turn rate vary by up to ~10-25 %
      around the plan's within and between steps.

Gait: centre of mass as an inverted pendulum, hand coupled to it
    Leg length ``L = 0.53 height``.  The vertical excursion (peak to peak) of
    the centre of mass (COM) over step ``k`` is the inverted pendulum's,
    ``h_k = L - sqrt(L^2 - (l_k / 2K)^2)`` with ``K = 1.25`` (Zijlstra & Hof
    2003, "Assessment of spatio-temporal gait parameters from trunk
    accelerations during human walking", Gait & Posture 18(2):1-10: step
    length = ``K 2 sqrt(2 L h - h^2)``): 4.3 cm for a 0.7 m step of a 1.75 m
    walker, growing like ``l_k^2``.  So at a fixed cadence the acceleration
    grows like ``l^2 f^2``; Weinberg's fourth-root law is not built in (it
    only comes out where step length grows with cadence, as the walk ratio
    says).  The COM height over a step is ``-(cos th + b cos 2 th) / 2`` with
    ``th = 2 pi (phi - ds/2)``, ``ds = 1 - 1/K`` the double-support fraction
    (lowest in the middle of double support, just after the heel strike,
    highest in mid-stance; ``b = COM_SECOND_HARMONIC`` = 0.1 makes the trough
    sharper than the crest).  Standing height is the crest: walking starts by
    dropping into the first double support and ends by rising out of the
    last one (the vertical phase is softly clamped at the crests before the
    first and after the last heel strike).  The first and last steps vault
    over a full mean step (``END_STEP_FOOT_RATIO``: the feet land a normal
    step apart although the body moves less).  The hand follows the COM's
    vertical motion with the gain ``HAND_VERTICAL_GAIN`` = 0.85 and the lag
    ``HAND_LAG_S`` = 30 ms, times ``bounce_scale``.  The forward speed of the
    body swings by +-``FORE_AFT_SPEED_SWING`` (8 %) around its mean (fastest
    in double support), the body sways ``LATERAL_SWAY_M`` (2 cm) left/right
    at the stride frequency, and every heel strike adds a short impact
    transient at the phone (a Gaussian dip of the displacement: 12 ms,
    ``HEEL_STRIKE_M_S2`` = 1.5 m/s^2 up and 0.6 m/s^2 backwards at the mean
    step length, 10 ms after the heel strike).  The amplitudes follow the
    actual step lengths through C2 envelopes (knots in the middle of each
    step, zero at rest).  With the defaults the raw acceleration norm swings
    by about 5 m/s^2 per step (4-7 m/s^2 for a phone held in front of the
    chest).  The phone's position is ``walker + (0, 0, 0.75 height) +
    Rz(heading_s) (forward, left, up)``; its acceleration in ENU is the exact
    second derivative of that position (central difference over +-0.5 ms,
    error < 2e-3 m/s^2).

Phone attitude (body -> ENU)
    ``R = Rz(yaw) Rx(pitch) Ry(roll)`` (Android's ZXY order) with

    * ``yaw = heading_s - 90 deg + phone_yaw_offset + k sway_yaw sin(pi phi + 0.3) + drift_yaw(t)``,
    * ``pitch = phone_pitch + k sway_pitch sin(2 pi phi + 1) + drift_pitch(t)``,
    * ``roll = phone_roll + k sway_roll sin(pi phi - 0.5) + drift_roll(t)``,

    where ``phi`` is the step phase (a C2 spline through heel strike ``k`` at
    ``phi = k``), ``k`` the step-length envelope relative to the mean step
    length and ``heading_s`` the plan heading averaged over 0.3 s at the warped
    time (a continuous turn rate).  With ``phone_yaw_offset_deg != 0`` the
    device y axis does not point along the walking direction;
    ``truth.device_heading_at`` gives its horizontal projection.  The hand
    drift is a band-limited random process (16 sinusoids per axis, frequencies
    log-uniform in 0.03-0.3 Hz, random phases) with the RMS angular rate
    ``hand_drift_deg_s`` per axis, present while standing too: a one-second
    mean of a still phone's gyroscope is not its bias.  The calibration motion
    multiplies the pose on the right by ``Rz(a) Rx(b) Ry(c)`` with ``a, b, c``
    up to +-90 deg (0.11, 0.30 and 0.15 Hz), tapered in and out over 1.5 s.

Sensors
    * accelerometer: ``R^T (a_n + (0, 0, g)) + acc_bias + noise``, g = 9.80665;
    * gyroscope: ``vee(log(R(t - d)^T R(t + d))) / 2d`` with d = 10 us (the
      exact body rate to ~1e-10 rad/s) ``+ b(t) + noise``; the bias
      ``b(t) = gyro_bias_rad_s + random walk`` (``gyro_bias_walk_rad_s_sqrt_s``
      per sqrt(s), on a 2 Hz grid, linearly interpolated; 0 by default);
    * magnetometer: ``S R^T h_n(p) + hard_iron + noise`` with ``S`` the
      soft-iron matrix and ``h_n(p)`` the Earth field changed by each
      :class:`DisturbanceZone` at the phone's horizontal position ``p``
      (in order): it can turn the horizontal field in azimuth, change the
      dip and the strength, and add a field, all weighted by
      ``(1 + cos(pi d / radius)) / 2`` inside its radius.  A pure rotation
      keeps the norm and the dip, so no gate on either can see it.  ``field_sources``
      (:mod:`desktop.bent_field`) adds the field of a building's magnetised steel, point dipoles, at the
      phone's 3-D position before the zones: a bent indoor field fixed in space.  With
      ``mag_uncalibrated_stream`` set, that stream carries the readings above
      and ``mag`` carries ``R^T h_n + noise`` (the iron removed, as the OS
      calibration would).

    * GPS (``gps=GpsModel(...)``): fixes at ``rate_hz`` of the phone's true position plus white noise, a
      Gauss-Markov bias, multipath episodes (under-reported in ``hacc_m``) and optionally a cold start;
      speed and course from the noisy mean velocity; converted to WGS-84 by
      :func:`core.geodesy.enu_to_geodetic` about ``origin_lat_lon`` (ENU +y is true north).  See
      :class:`GpsModel`; ``truth.gps`` (:class:`GpsTruth`) holds every injected error.  Faults a benchmark
      switches on (``GpsModel(faults=(GpsFault(...), ...))``): multipath jumps, a slow drift, a noisy stretch,
      an outage (no fixes), fixes whose reported accuracy lies; each with its exact truth per fix.

    Noise is white Gaussian with the given per-sample standard deviation.
    Each stream starts at a random phase within its first interval; each
    interval is ``(1 + timestamp_jitter * N(0, 1)) / rate`` (clipped at 10 %
    of the nominal interval); timestamps are integer nanoseconds on a clock
    starting at ``clock_start_ns`` (10**12 by default, like
    ``elapsedRealtimeNanos``) and the physics is evaluated at exactly those
    instants.  All randomness comes from ``numpy.random.SeedSequence(seed)``
    (one child generator per purpose, so the same seed gives the same
    recording and e.g. changing a noise level does not move the timestamps).
    The GPS draws from a tenth child of its own, so adding or changing the GPS leaves
    every other stream unchanged.

Outdoor walks
    :func:`street_route` makes a polyline of city streets (blocks of 40-120 m, mostly 90 deg turns, some
    gentle bends, no reversals); :func:`outdoor_walk` walks one for 10-20 minutes with GPS, a per-seed
    walker and phone pose, a residual hard iron and the site's WMM field (a 20-minute walk takes a few
    seconds to simulate).

Placements (how the phone is carried, issue #17)
    Everything above is the hand-held phone (``placement="handheld"``, the default).  ``placement=``
    "swinging" (in a hand swinging at the side), "pocket" (front trouser pocket, on the thigh), "bag"
    (loosely coupled to the trunk through a damped spring) and "ear" (at the ear in a call) put the phone
    on another body segment of the same walk (same seed: same path, heel strikes and step lengths), and
    :func:`desktop.placements.simulate_still` (also reachable as ``desktop.simulator.simulate_still``)
    records not walking: on a table, in the hand while standing, in a vehicle.  Their models, numbers and
    sources are in :mod:`desktop.placements`' docstring; the truth tells the placement
    (``truth.placement``, ``side``, ``placement_info``), the foot of each heel strike (``step_foot``) and
    the walking direction in the device frame (``forward_in_device_at``).  The hand-held model and its
    recordings are unchanged by them.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from core import __version__
from core import quaternion as quat
from core.conventions import (ACC, CARRY_HANDHELD, CARRY_MODES, GPS, GYRO, MAG, STANDARD_GRAVITY_M_S2, bearing_deg,
                              wrap_angle)
from core.geodesy import enu_to_geodetic, magnetic_field
from core.gnss.accuracy import HACC_PROBABILITY  # the reported accuracy's radius holds the truth this often
from core.recording import Recording, Stream, make_stream

__all__ = ["simulate_walk", "demo_walk", "street_route", "outdoor_walk", "residual_hard_iron_uT", "SimulatedWalk",
           "WalkTruth", "GpsModel", "GpsFault", "GpsTruth", "DisturbanceZone", "SIMULATOR_VERSION",
           "WALK_RATIO_PER_HEIGHT", "default_step_length_m"]


def __getattr__(name: str):
    """``desktop.simulator.simulate_still``: :func:`desktop.placements.simulate_still` (imported on first use:
    desktop.placements builds on this module)."""
    if name == "simulate_still":
        from desktop.placements import simulate_still
        return simulate_still
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Version of the simulation model (stored in ``metadata["simulator"]``); bumped when the same
#: parameters and seed no longer give the same recording.
SIMULATOR_VERSION = "2"

#: Default start of the simulated sensor clock (ns), large like Android's ``elapsedRealtimeNanos``.
DEFAULT_CLOCK_START_NS = 10**12
#: Default ENU origin (WGS-84 deg): Helsinki's centre, and the ground's height there above the ellipsoid (m).
DEFAULT_ORIGIN_LAT_LON = (60.1699, 24.9384)
DEFAULT_ORIGIN_ALT_M = 30.0

#: Walk ratio (step length / step rate) per metre of body height, m / (steps/min) / m: 0.0064 m/(steps/min)
#: for young adults of about 1.72 m (Sekiya & Nagasaki 1998), assumed proportional to height.
WALK_RATIO_PER_HEIGHT = 0.00372
LEG_LENGTH_RATIO = 0.53  #: leg length / body height (anthropometric, e.g. Winter's tables)
PENDULUM_CORRECTION = 1.25  #: Zijlstra & Hof (2003): step length = 1.25 x the inverted-pendulum step
DOUBLE_SUPPORT = 1.0 - 1.0 / PENDULUM_CORRECTION  #: fraction of a step in double support (just after heel strike)
COM_SECOND_HARMONIC = 0.1  #: second harmonic of the COM height: the double-support trough is sharper than the crest
HAND_VERTICAL_GAIN = 0.85  #: the phone's vertical gait motion / the COM's (the elbow gives a little)
HAND_LAG_S = 0.03  #: lag of the hand behind the COM
FORE_AFT_SPEED_SWING = 0.08  #: relative swing of the forward speed of the body within a step
LATERAL_SWAY_M = 0.02  #: left/right sway of the body at the stride frequency (amplitude, m)
END_STEP_FOOT_RATIO = 1.0  #: foot-to-foot distance of the first and last steps / mean step length
HEEL_STRIKE_M_S2 = 1.5  #: peak upward impact acceleration at the phone per heel strike (full step)
HEEL_STRIKE_BRAKE = 0.4  #: backward impact acceleration / upward
HEEL_STRIKE_SIGMA_S = 0.012  #: width of the impact transient
HEEL_STRIKE_DELAY_S = 0.010  #: delay of the impact transient after the heel strike

_G = STANDARD_GRAVITY_M_S2
_GYRO_DIFF_S = 1e-5  # half-width of the central difference for the body rate
_ACC_DIFF_S = 5e-4  # half-width of the second difference for the linear acceleration
_HAND_HEIGHT_RATIO = 0.75  # phone height above the ground / body height (in front of the chest)
_CAL_TAPER_S = 1.5  # taper of the calibration motion at either end (s)
_TURN_SMOOTH_S = 0.3  # the hand's yaw follows the heading averaged over this window (continuous turn rate)
_DRIFT_TERMS = 16  # sinusoids per axis of the hand drift
_DRIFT_BAND_HZ = (0.03, 0.3)
_BIAS_GRID_HZ = 2.0
_RAMP_STEPS = 1.5  # a change of speed by the cruise speed takes this many step periods (start, stop, corners)
_STEP_AR = 0.7  # AR(1) coefficient of the walker's offset from the plan at heel strikes


def default_step_length_m(height_m: float, step_frequency_hz: float) -> float:
    """Mean step length (m) of a walker of ``height_m`` at ``step_frequency_hz`` from the walk ratio
    (Sekiya & Nagasaki 1998): ``WALK_RATIO_PER_HEIGHT * height * 60 * step_frequency``."""
    return WALK_RATIO_PER_HEIGHT * float(height_m) * 60.0 * float(step_frequency_hz)


# ---------------------------------------------------------------------------
# public result types


@dataclass(frozen=True)
class DisturbanceZone:
    """A local magnetic disturbance (e.g. a steel pillar, a radiator, rebar) near ``center_en_m``.

    Inside ``radius_m`` (horizontal distance ``d``) it changes the field ``h`` that reaches it, with the weight
    ``w = (1 + cos(pi d / radius)) / 2`` (1 at the centre, 0 with zero slope at the edge), in this order:

    * ``rotation_deg``: turns the horizontal part of ``h`` by ``w * rotation_deg`` counter-clockwise about
      Up (seen from above).  Norm and dip are kept, so a norm/dip gate cannot see it; a compass heading
      read inside the zone is off by ``-w * rotation_deg``;
    * ``dip_change_deg``: makes the field point ``w * dip_change_deg`` further down (inclination), norm kept;
    * ``strength_scale``: multiplies the norm by ``1 + w (strength_scale - 1)``;
    * ``field_enu_uT``: adds ``w * field_enu_uT`` (ENU, uT).

    Outside the radius it does nothing.  With only ``field_enu_uT`` it is the additive zone of simulator
    version 1.
    """

    center_en_m: tuple[float, float]
    radius_m: float
    field_enu_uT: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: float = 0.0
    dip_change_deg: float = 0.0
    strength_scale: float = 1.0

    def __post_init__(self):
        c = tuple(float(x) for x in self.center_en_m)
        f = tuple(float(x) for x in self.field_enu_uT)
        if len(c) != 2 or len(f) != 3 or not all(map(math.isfinite, c + f)):
            raise ValueError("DisturbanceZone needs center_en_m=(east, north) and field_enu_uT=(e, n, u), finite")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"DisturbanceZone radius_m must be positive, got {self.radius_m}")
        for name in ("rotation_deg", "dip_change_deg", "strength_scale"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"DisturbanceZone {name} must be finite")
        if not float(self.strength_scale) > 0:
            raise ValueError(f"DisturbanceZone strength_scale must be positive, got {self.strength_scale}")
        object.__setattr__(self, "center_en_m", c)
        object.__setattr__(self, "field_enu_uT", f)
        object.__setattr__(self, "radius_m", float(self.radius_m))
        for name in ("rotation_deg", "dip_change_deg", "strength_scale"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def weight(self, east_m, north_m) -> np.ndarray:
        """The taper ``(1 + cos(pi d / radius)) / 2`` inside the radius, 0 outside (same shape as the input)."""
        d = np.hypot(np.asarray(east_m, float) - self.center_en_m[0], np.asarray(north_m, float) - self.center_en_m[1])
        return np.where(d < self.radius_m, 0.5 * (1.0 + np.cos(np.pi * np.minimum(d / self.radius_m, 1.0))), 0.0)

    def field_at(self, east_m, north_m) -> np.ndarray:
        """The *added* field ``w * field_enu_uT`` (n, 3) in ENU (uT) at horizontal positions (n,)."""
        return self.weight(east_m, north_m)[..., None] * np.asarray(self.field_enu_uT)

    def apply(self, field_enu_uT, east_m, north_m) -> np.ndarray:
        """The field (n, 3) ENU (uT) after this zone, for the incoming field (n, 3) at positions (n,)."""
        h = np.array(np.broadcast_to(np.asarray(field_enu_uT, float), np.shape(east_m) + (3,)))
        w = self.weight(east_m, north_m)
        if self.rotation_deg:
            rot = quat.to_matrix_array(quat.about_axis_array(2, w * math.radians(self.rotation_deg)))
            h = np.einsum("nij,nj->ni", rot, h)
        if self.dip_change_deg:
            horiz = np.hypot(h[:, 0], h[:, 1])
            norm = np.linalg.norm(h, axis=1)
            incl = np.arctan2(-h[:, 2], horiz) + w * math.radians(self.dip_change_deg)
            az = np.arctan2(h[:, 1], h[:, 0])
            h = np.stack([norm * np.cos(incl) * np.cos(az), norm * np.cos(incl) * np.sin(az),
                          -norm * np.sin(incl)], axis=1)
        if self.strength_scale != 1.0:
            h = h * (1.0 + w * (self.strength_scale - 1.0))[:, None]
        return h + w[:, None] * np.asarray(self.field_enu_uT)

    def as_dict(self) -> dict:
        return {"center_en_m": list(self.center_en_m), "radius_m": self.radius_m,
                "field_enu_uT": list(self.field_enu_uT), "rotation_deg": self.rotation_deg,
                "dip_change_deg": self.dip_change_deg, "strength_scale": self.strength_scale}


#: the kinds of :class:`GpsFault`
GPS_FAULT_KINDS = ("jump", "drift", "noise", "outage", "lying")
#: what a fault's receiver reports as its accuracy unless told (see :class:`GpsFault`)
_FAULT_HACC_DEFAULT = {"jump": "under", "drift": "normal", "noise": "honest", "outage": "normal", "lying": (3.0, 5.0)}
_FAULT_OFFSET_DEFAULT_M = {"jump": (20.0, 200.0), "lying": (30.0, 80.0)}
_FAULT_HACC_WORDS = ("honest", "normal", "under")


@dataclass(frozen=True)
class GpsFault:
    """One injected GPS fault over ``[start_s, start_s + duration_s)`` of simulation time.

    Times are seconds from the start of the simulation (the sensor clock's ``clock_start_ns``, within
    one sample interval of the recording's first event), like ``GpsModel.first_fix_s``.

    On top of the receiver's normal errors (:class:`GpsModel`), per fix inside the window:

    ``"jump"``
        multipath taken for the direct signal near a wall: one constant offset for the whole window, of
        uniform magnitude in ``offset_m`` (default 20-200 m) and uniform direction; the receiver
        under-reports its accuracy (``hacc="under"``: the normal value times ``hacc_multipath_factor``).
    ``"drift"``
        the solution slides away at ``drift_m_per_min`` (default 5 m/min) in a uniform direction, from 0 at
        the start of the window to ``drift_m_per_min * duration_s / 60`` at its end, and snaps back after
        it; the reported accuracy stays normal (``hacc="normal"``).
    ``"noise"``
        very noisy fixes: white noise of ``noise_sd_m`` per axis per fix (default 30 m) on the position
        and of ``velocity_sd_m_s`` per axis (default 1 m/s) on the Doppler velocity (so speed and course
        scatter too); the reported accuracy is honest by default (``hacc="honest"``: ``c sqrt(noise_sd^2
        + bias_sd^2 + noise_sd_fault^2) J``, the 68 % radius of the total error) or lies with
        ``hacc="normal"`` (the receiver's usual value, as if nothing were wrong).
    ``"outage"``
        no fixes at all: the receiver gives none (the walker keeps walking).
    ``"lying"``
        isolated wrong fixes that claim to be good: each fix in the window lies with probability
        ``fraction`` (default 1: all of them), then it is off by its own offset of uniform magnitude in
        ``offset_m`` (default 30-80 m) and uniform direction, and reports an accuracy uniform in
        ``hacc`` (default 3-5 m).

    ``hacc`` (the reported accuracy during the fault; ``None``: the kind's default above) is one of
    ``"honest"`` (noise: as above; jump, drift, lying: the normal value plus the fault's offset, like a
    cold start), ``"normal"`` (the normal value with its jitter), ``"under"`` (the normal value times
    ``GpsModel.hacc_multipath_factor``), or ``(low, high)``: uniform per fix; it replaces whatever the
    fix would have reported (a random multipath episode's or a cold start's).  Speed and course are
    affected only by ``"noise"``.  Faults may not overlap.  Each fault draws from a generator of its
    own (the ``i``-th child of the GPS generator's fault child), so switching one on or off, or
    changing it, moves no other draw.
    """

    kind: str  #: one of ``GPS_FAULT_KINDS``
    start_s: float  #: start of the window (s of simulation time)
    duration_s: float  #: length of the window (s)
    offset_m: tuple[float, float] | None = None  #: jump, lying: range of the offset's magnitude (m, uniform)
    drift_m_per_min: float = 5.0  #: drift: speed of the drift (m/min)
    noise_sd_m: float = 30.0  #: noise: white position noise per axis per fix (m)
    velocity_sd_m_s: float = 1.0  #: noise: white velocity noise per axis per fix (m/s)
    fraction: float = 1.0  #: lying: probability that a fix in the window lies
    hacc: str | tuple[float, float] | None = None  #: the reported accuracy during the fault (see above)

    def __post_init__(self):
        if self.kind not in GPS_FAULT_KINDS:
            raise ValueError(f"GpsFault.kind must be one of {', '.join(GPS_FAULT_KINDS)}, got {self.kind!r}")
        object.__setattr__(self, "start_s", _non_negative("GpsFault.start_s", self.start_s))
        object.__setattr__(self, "duration_s", _positive("GpsFault.duration_s", self.duration_s))
        for name in ("drift_m_per_min", "noise_sd_m", "velocity_sd_m_s"):
            object.__setattr__(self, name, _non_negative(f"GpsFault.{name}", getattr(self, name)))
        if not 0.0 <= float(self.fraction) <= 1.0:
            raise ValueError(f"GpsFault.fraction must be in [0, 1], got {self.fraction!r}")
        object.__setattr__(self, "fraction", float(self.fraction))
        off = self.offset_m if self.offset_m is not None else _FAULT_OFFSET_DEFAULT_M.get(self.kind, (0.0, 0.0))
        lo, hi = (_non_negative("GpsFault.offset_m", v) for v in off)
        if hi < lo:
            raise ValueError("GpsFault.offset_m must be (low, high) with low <= high")
        object.__setattr__(self, "offset_m", (lo, hi))
        h = _FAULT_HACC_DEFAULT[self.kind] if self.hacc is None else self.hacc
        if isinstance(h, str):
            if h not in _FAULT_HACC_WORDS:
                raise ValueError(f"GpsFault.hacc must be one of {', '.join(_FAULT_HACC_WORDS)} or (low, high), "
                                 f"got {h!r}")
        else:
            lo, hi = (_positive("GpsFault.hacc", v) for v in h)
            if hi < lo:
                raise ValueError("GpsFault.hacc must be (low, high) with low <= high")
            h = (lo, hi)
        object.__setattr__(self, "hacc", h)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def as_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}


@dataclass(frozen=True)
class GpsModel:
    """A phone GNSS receiver: the fixes it reports and how wrong they are (SI units, settings named by unit).

    The antenna is the phone: each fix starts from the phone's true position at the fix time.  Per
    horizontal axis (East, North) the reported position is off by

    * white noise, ``noise_sd_m`` per fix;
    * a bias that wanders: a first-order Gauss-Markov process of standard deviation ``bias_sd_m`` and
      correlation time ``bias_tau_s`` (``b_k+1 = a b_k + sqrt(1 - a^2) bias_sd w``, ``a = exp(-dt/tau)``,
      started from its stationary distribution), the slowly changing satellite geometry and atmosphere;
    * multipath episodes (a reflected signal taken for the direct one, in a street canyon): they start as
      a Poisson process of ``multipath_per_min`` per minute, each shifts the fixes by a constant offset
      of uniform magnitude in ``multipath_jump_m`` and uniform direction for a uniform duration in
      ``multipath_duration_s``; overlapping episodes add;
    * optionally a cold start: the first ``cold_start_fixes`` fixes are off by a further
      ``cold_start_error_m`` in a random direction, shrinking linearly to 0 over those fixes.

    The reported accuracy ``hacc_m`` (Android's 68 % horizontal accuracy radius) is honest for the
    normal errors: ``c sqrt(noise_sd^2 + bias_sd^2) J`` with a log-normal jitter ``J`` (median 1,
    coefficient of variation ``hacc_jitter_cv``) and ``c`` chosen so that 68 % of the normal fixes lie
    within it (``c = 1.51``, the 68 % radius of a circular Gaussian, without jitter).  During multipath
    the receiver under-reports: it gives the same value times ``hacc_multipath_factor``, far below the
    10-40 m it is off (real receivers do this: a consistently reflected signal does not show in the
    solution's residuals, so the accuracy estimate does not grow).  During a cold start it adds the
    cold-start error to the reported accuracy (a large, roughly honest radius).

    Speed and course are Doppler-like: the phone's mean horizontal velocity over the last
    ``velocity_window_s`` plus white noise ``speed_noise_m_s`` per axis (multipath and the position
    bias do not affect them); ``speed_m_s`` is the norm of that noisy velocity and ``course_deg`` its
    compass bearing (clockwise from true north = the simulator's +y), nan below
    ``course_min_speed_m_s``.  ``alt_m`` is the ground's ellipsoidal height plus the phone's height
    plus its own Gauss-Markov bias (``alt_bias_sd_m``, same ``bias_tau_s``) and white noise
    ``alt_noise_sd_m``.

    Fixes come at ``rate_hz`` from ``first_fix_s`` after the start of the recording (time to first
    fix), each time stamp (sensor clock) off its nominal grid by white jitter ``time_jitter_s``
    (clipped at 30 % of the interval).  The position is the one at the time stamp (no latency).

    ``faults`` (:class:`GpsFault`) add what a benchmark of bad-fix handling needs on top: multipath
    jumps, a slow drift, noisy fixes, outages and lying fixes in given windows.  Every normal draw is
    made as without them (a fix an outage removes is drawn and dropped), so the fixes outside the
    faults are exactly the fixes of the same model and seed without faults.
    """

    rate_hz: float = 1.0  #: fixes per second
    noise_sd_m: float = 1.5  #: white position noise per horizontal axis per fix (m)
    bias_sd_m: float = 3.0  #: standard deviation of the wandering bias per horizontal axis (m)
    bias_tau_s: float = 120.0  #: correlation time of the bias (s)
    multipath_per_min: float = 0.2  #: rate of multipath episodes (per minute of fixes)
    multipath_jump_m: tuple[float, float] = (10.0, 40.0)  #: range of the offset of an episode (m, uniform)
    multipath_duration_s: tuple[float, float] = (5.0, 20.0)  #: range of the duration of an episode (s, uniform)
    hacc_jitter_cv: float = 0.2  #: coefficient of variation of the reported accuracy's log-normal jitter
    hacc_multipath_factor: float = 1.5  #: reported accuracy during multipath / the normal one (under-reported)
    speed_noise_m_s: float = 0.1  #: white velocity noise per horizontal axis (m/s)
    course_min_speed_m_s: float = 0.3  #: below this reported speed the course is nan
    velocity_window_s: float = 1.0  #: the velocity is the phone's mean velocity over this window before the fix
    alt_noise_sd_m: float = 3.0  #: white altitude noise per fix (m)
    alt_bias_sd_m: float = 4.0  #: standard deviation of the wandering altitude bias (m)
    first_fix_s: float = 3.0  #: time from the start of the recording to the first fix (s)
    cold_start_fixes: int = 0  #: number of first fixes with the cold-start error (0: a warm start)
    cold_start_error_m: float = 50.0  #: extra error of the first fix of a cold start (m)
    time_jitter_s: float = 0.005  #: white jitter of the fix time stamps around their 1/rate grid (s)
    faults: tuple[GpsFault, ...] = ()  #: injected faults (:class:`GpsFault`), none by default

    def __post_init__(self):
        for name in ("rate_hz", "bias_tau_s", "velocity_window_s"):
            object.__setattr__(self, name, _positive(f"GpsModel.{name}", getattr(self, name)))
        for name in ("noise_sd_m", "bias_sd_m", "multipath_per_min", "hacc_jitter_cv", "speed_noise_m_s",
                     "course_min_speed_m_s", "alt_noise_sd_m", "alt_bias_sd_m", "first_fix_s",
                     "cold_start_error_m", "time_jitter_s"):
            object.__setattr__(self, name, _non_negative(f"GpsModel.{name}", getattr(self, name)))
        object.__setattr__(self, "hacc_multipath_factor",
                           _positive("GpsModel.hacc_multipath_factor", self.hacc_multipath_factor))
        for name in ("multipath_jump_m", "multipath_duration_s"):
            lo, hi = (_non_negative(f"GpsModel.{name}", v) for v in getattr(self, name))
            if hi < lo:
                raise ValueError(f"GpsModel.{name} must be (low, high) with low <= high")
            object.__setattr__(self, name, (lo, hi))
        if self.multipath_per_min > 0 and not self.multipath_duration_s[1] > 0:
            raise ValueError("GpsModel.multipath_duration_s must allow episodes of positive length")
        if isinstance(self.cold_start_fixes, bool) or operator.index(self.cold_start_fixes) < 0:
            raise ValueError(f"GpsModel.cold_start_fixes must be a non-negative integer, got {self.cold_start_fixes!r}")
        if self.noise_sd_m == 0 and self.bias_sd_m == 0:
            raise ValueError("GpsModel needs some position error (noise_sd_m or bias_sd_m) for hacc_m")
        faults = tuple(self.faults)
        if not all(isinstance(f, GpsFault) for f in faults):
            raise ValueError("GpsModel.faults must be GpsFault instances")
        spans = sorted((f.start_s, f.end_s) for f in faults)
        if any(b[0] < a[1] for a, b in zip(spans, spans[1:])):
            raise ValueError("GpsModel.faults must not overlap")
        object.__setattr__(self, "faults", faults)

    @property
    def hacc_scale(self) -> float:
        """``c``: the normal fixes lie within ``c sqrt(noise_sd^2 + bias_sd^2) J`` 68 % of the time.

        The normal horizontal error is circular Gaussian, its radius Rayleigh: ``P(r < x s) = 1 - exp(-x^2/2)``.
        ``c`` solves ``E_J[1 - exp(-(c J)^2 / 2)] = 0.68`` (Gauss-Hermite over the log-normal ``J``, bisection).
        """
        sigma = math.sqrt(math.log1p(self.hacc_jitter_cv ** 2))
        z, w = np.polynomial.hermite_e.hermegauss(40)
        jit = np.exp(sigma * z)
        w = w / w.sum()
        lo, hi = 0.0, 20.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if float(np.dot(w, 1.0 - np.exp(-0.5 * (mid * jit) ** 2))) < HACC_PROBABILITY:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    def as_dict(self) -> dict:
        """The settings as JSON-ready values (for the recording's metadata; ``faults`` only when there are some)."""
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items() if k != "faults"}
        if self.faults:
            d["faults"] = [f.as_dict() for f in self.faults]
        return d


@dataclass(frozen=True, eq=False)
class GpsTruth:
    """What went into each GPS fix (row ``k`` = fix ``k`` of the recording's ``gps`` stream).

    The reported horizontal position is exactly ``pos_enu_m[:, :2] + bias_en_m + multipath_en_m +
    cold_start_en_m + fault_en_m + white noise`` (ENU, converted to latitude/longitude by
    :func:`core.geodesy.enu_to_geodetic` about ``WalkTruth.origin_lat_lon``); the white noise is what is
    left, and ``error_en_m`` is the sum (reported minus true, before the conversion).  The reported
    altitude is ``origin_alt_m + pos_enu_m[:, 2] + alt_bias_m + white noise``.  Fixes inside an
    ``"outage"`` fault are not in the stream and not here.
    """

    model: GpsModel  #: the receiver model
    t_ns: np.ndarray  #: (n,) int64 fix times (= the ``gps`` stream's timestamps)
    pos_enu_m: np.ndarray  #: (n, 3) true phone position at each fix (ENU m, up above the ground)
    vel_en_m_s: np.ndarray  #: (n, 2) true mean horizontal phone velocity over ``velocity_window_s`` before the fix
    bias_en_m: np.ndarray  #: (n, 2) the Gauss-Markov bias (m)
    alt_bias_m: np.ndarray  #: (n,) the altitude's Gauss-Markov bias (m)
    multipath: np.ndarray  #: (n,) bool: the fix is inside a multipath episode
    multipath_en_m: np.ndarray  #: (n, 2) summed offset of the episodes the fix is in (m; 0 outside)
    cold_start_en_m: np.ndarray  #: (n, 2) cold-start offset (m; 0 after the cold start)
    hacc_normal_m: np.ndarray  #: (n,) honest 68 % radius of the normal errors, before the jitter (m)
    multipath_t_ns: np.ndarray  #: (k, 2) int64 start and end of each multipath episode (those touching a fix)
    multipath_offset_en_m: np.ndarray  #: (k, 2) each episode's offset (m)
    error_en_m: np.ndarray  #: (n, 2) the fix's true horizontal error: reported minus true position (m), all included
    fault_index: np.ndarray  #: (n,) int: index in ``model.faults`` of the fault the fix is in (-1: none)
    fault_kind: np.ndarray  #: (n,) str: that fault's kind ("" outside faults and for a lying window's honest fixes)
    fault_en_m: np.ndarray  #: (n, 2) the fault's offset (jump, drift, lying) or noise (noise) on the fix (m; 0 outside)
    fault_t_ns: np.ndarray  #: (f, 2) int64 start and end of each of ``model.faults`` on the sensor clock
    fault_offset_en_m: np.ndarray  #: (f, 2) a jump's offset, a drift's offset at its end (m); 0 for the other kinds

    @property
    def error_model_en_m(self) -> np.ndarray:
        """(n, 2) the injected horizontal error without the white noise: bias + multipath + cold start + fault (m)."""
        return self.bias_en_m + self.multipath_en_m + self.cold_start_en_m + self.fault_en_m

    @property
    def error_m(self) -> np.ndarray:
        """(n,) the fix's true horizontal error (m)."""
        return np.hypot(self.error_en_m[:, 0], self.error_en_m[:, 1])


@dataclass(frozen=True, eq=False)
class WalkTruth:
    """Exact ground truth of a simulated walk (times on the recording's sensor clock).

    Step ``k`` (0-based here) ends with the heel strike at ``step_t_ns[k]``; the
    heel strikes are about ``1 / step_frequency_hz`` apart (``step_time_cv``),
    the last one at ``walk_end_t_ns``.  Positions are the walker's
    (stride-averaged phone) position in ENU metres; ``phone_position_at`` is
    the phone's.  Headings are radians CCW from East.
    """

    n_steps: int  #: number of steps (= heel strikes)
    step_t_ns: np.ndarray  #: (n,) int64 heel-strike times
    step_east_m: np.ndarray  #: (n,) East position after each step (m)
    step_north_m: np.ndarray  #: (n,) North position after each step (m)
    step_length_m: np.ndarray  #: (n,) distance walked along the path during each step (m), exact
    step_heading_rad: np.ndarray  #: (n,) direction of each step's displacement (chord), CCW from East
    start_east_m: float  #: position before the first step (the first waypoint)
    start_north_m: float
    path_length_m: float  #: length of the walked path (polyline with rounded corners) = sum of step_length_m
    polyline_length_m: float  #: length of the waypoint polyline (>= path_length_m: corners are cut)
    walk_start_t_ns: int  #: the walker starts moving
    walk_end_t_ns: int  #: the walker is at rest again (= last heel strike)
    calibration_start_t_ns: int  #: calibration motion interval (start == end if none)
    calibration_end_t_ns: int
    att_t_ns: np.ndarray  #: (m,) int64 uniform grid at ``truth_rate_hz`` over the whole recording
    att_q_wxyz: np.ndarray  #: (m, 4) phone attitude body -> ENU, sign-continuous
    att_walk_heading_rad: np.ndarray  #: (m,) walking heading on the grid (unwrapped)
    att_device_heading_rad: np.ndarray  #: (m,) heading of the device y axis' horizontal projection (unwrapped)
    att_gyro_bias_rad_s: np.ndarray  #: (m, 3) true gyroscope bias on the grid (device frame)
    step_device_heading_rad: np.ndarray  #: (n,) device y heading at each heel strike (wrapped)
    #: mean yaw of the device y axis relative to the walking direction (CCW); nan for the other placements
    #: (there ``forward_in_device_at`` is the walking direction in the device frame)
    phone_yaw_offset_rad: float
    gyro_bias_rad_s: np.ndarray  #: (3,) constant part of the gyroscope bias (device frame)
    acc_bias_m_s2: np.ndarray  #: (3,) accelerometer bias (device frame)
    mag_t_ns: np.ndarray  #: (k,) magnetometer sample times (= recording ``mag`` timestamps)
    mag_field_enu_uT: np.ndarray  #: (k, 3) true field in ENU at the phone at each magnetometer sample (uT)
    mag_hard_iron_uT: np.ndarray  #: (3,) hard-iron offset (device frame, uT)
    mag_soft_iron: np.ndarray  #: (3, 3) soft-iron matrix S (reading = S R^T h_n + hard iron + noise)
    origin_lat_lon: tuple[float, float]  #: WGS-84 latitude, longitude (deg) of the ENU origin
    origin_alt_m: float  #: ellipsoidal height of the ground at the origin (m; the ground is flat)
    gps: GpsTruth | None  #: what went into the GPS fixes (None without a GPS stream)
    _model: "_WalkModel" = field(repr=False)
    #: how the phone is carried: one of ``core.conventions.CARRY_MODES`` (:mod:`desktop.placements`)
    placement: str = CARRY_HANDHELD
    #: pocket, swinging, ear: the leg, arm or ear carrying the phone ("left" / "right"); None otherwise
    side: str | None = None
    #: the placement's drawn or given choices (JSON-ready; e.g. the phone's orientation in the pocket or bag)
    placement_info: dict = field(default_factory=dict)

    @property
    def step_foot(self) -> np.ndarray:
        """(n,) str: the foot of each heel strike, "left" or "right" (they alternate; the first is the right
        foot's: the body sways over the left foot during the first step)."""
        return np.where(np.arange(1, self.n_steps + 1) % 2 == 0, "left", "right")

    def forward_in_device_at(self, t_ns) -> np.ndarray:
        """The walking direction (horizontal unit vector of ``heading_at``) in the device frame: (3,) or (n, 3).

        Whatever the placement, this is what a walking-direction estimator has to find in the phone's own
        frame (with the device y axis horizontal it is about ``(-sin d, cos d, 0)``, ``d`` the offset
        ``device_heading_at - heading_at``)."""
        t = np.atleast_1d(self._t(t_ns))
        h = self._model.walker(t)[2]
        fwd_n = np.stack([np.cos(h), np.sin(h), np.zeros_like(h)], axis=1)
        return self._out(t_ns, _rotate_to_body(quat.to_matrix_array(self._model.quat(t)), fwd_n))

    def _t(self, t_ns) -> np.ndarray:
        return (np.asarray(t_ns, dtype=np.int64) - self._model.clock0_ns) * 1e-9

    def _out(self, t_ns, a):
        return a[0] if np.ndim(t_ns) == 0 else a

    def heading_at(self, t_ns):
        """Walking heading (rad, CCW from East, unwrapped) at ``t_ns`` (scalar or array): the direction of
        motion of the path; while standing, the direction the walker faces."""
        h = self._model.walker(np.atleast_1d(self._t(t_ns)))[2]
        return float(h[0]) if np.ndim(t_ns) == 0 else h

    def device_heading_at(self, t_ns):
        """Heading (rad, CCW from East, wrapped) of the horizontal projection of the device y axis at ``t_ns``
        (ill-defined where the device y axis is near vertical: a phone upright in a pocket or at the ear)."""
        y = quat.to_matrix_array(self._model.quat(np.atleast_1d(self._t(t_ns))))[:, :, 1]
        h = np.arctan2(y[:, 1], y[:, 0])
        return float(h[0]) if np.ndim(t_ns) == 0 else h

    def position_at(self, t_ns) -> np.ndarray:
        """Walker position ``(east_m, north_m)`` at ``t_ns``: shape (2,) for a scalar, (n, 2) for an array."""
        x, y = self._model.walker(np.atleast_1d(self._t(t_ns)))[:2]
        return self._out(t_ns, np.stack([x, y], axis=-1))

    def phone_position_at(self, t_ns) -> np.ndarray:
        """Phone position ``(east, north, up)`` (m, up above the ground): (3,) or (n, 3)."""
        return self._out(t_ns, self._model.position(np.atleast_1d(self._t(t_ns))))

    def attitude_at(self, t_ns) -> np.ndarray:
        """Exact phone attitude quaternion ``(w, x, y, z)`` body -> ENU at ``t_ns``: (4,) or (n, 4)."""
        return self._out(t_ns, self._model.quat(np.atleast_1d(self._t(t_ns))))

    def body_rate_at(self, t_ns) -> np.ndarray:
        """Exact body angular rate (rad/s, device frame) at ``t_ns``, without bias or noise: (3,) or (n, 3)."""
        return self._out(t_ns, self._model.body_rate(np.atleast_1d(self._t(t_ns))))

    def gyro_bias_at(self, t_ns) -> np.ndarray:
        """True gyroscope bias (rad/s, device frame) at ``t_ns``: (3,) or (n, 3)."""
        return self._out(t_ns, self._model.gyro_bias(np.atleast_1d(self._t(t_ns))))

    def mag_field_at(self, t_ns) -> np.ndarray:
        """True magnetic field in ENU (uT) at the phone at ``t_ns``: (3,) or (n, 3)."""
        return self._out(t_ns, self._model.field_n(np.atleast_1d(self._t(t_ns))))

    def phone_velocity_at(self, t_ns) -> np.ndarray:
        """Phone velocity ``(east, north, up)`` (m/s, central difference over +-0.5 ms): (3,) or (n, 3)."""
        return self._out(t_ns, self._model.velocity(np.atleast_1d(self._t(t_ns))))

    def phone_geodetic_at(self, t_ns) -> np.ndarray:
        """Phone position ``(lat_deg, lon_deg, alt_m)`` (WGS-84, ellipsoidal height; via
        :func:`core.geodesy.enu_to_geodetic` about ``origin_lat_lon``): (3,) or (n, 3)."""
        p = self._model.position(np.atleast_1d(self._t(t_ns)))
        lat, lon = enu_to_geodetic(p[:, 0], p[:, 1], self.origin_lat_lon)
        return self._out(t_ns, np.stack([lat, lon, self.origin_alt_m + p[:, 2]], axis=-1))


@dataclass(frozen=True, eq=False)
class SimulatedWalk:
    """Result of :func:`simulate_walk`: the sensor recording and its ground truth."""

    recording: Recording
    truth: WalkTruth


# ---------------------------------------------------------------------------
# small helpers


def _rotate_to_body(mat_nb: np.ndarray, v_n: np.ndarray) -> np.ndarray:
    """``R^T v`` for stacks of matrices (n, 3, 3) and vectors (n, 3)."""
    return np.einsum("nji,nj->ni", mat_nb, v_n)


class _Quintic:
    """C2 piecewise quintic Hermite curve through knots ``(x_k, y_k)`` with slopes ``d_k`` and second
    derivatives ``c_k`` (0 by default); outside the knots it continues linearly with the end slopes (so
    pass ``c = 0`` at the ends for C2 there too)."""

    def __init__(self, x, y, d, c=None):
        self.x = np.asarray(x, float)
        self.y = np.asarray(y, float)
        self.d = np.asarray(d, float)
        self.c = np.zeros_like(self.x) if c is None else np.asarray(c, float)
        if len(self.x) < 2 or np.any(np.diff(self.x) <= 0):
            raise ValueError("knots must be increasing")  # pragma: no cover - internal

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        x, y, d, c = self.x, self.y, self.d, self.c
        j = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
        h = x[j + 1] - x[j]
        s = np.clip((t - x[j]) / h, 0.0, 1.0)
        s2 = s * s
        s3 = s2 * s
        s4 = s3 * s
        s5 = s4 * s
        out = (y[j] * (1 - 10 * s3 + 15 * s4 - 6 * s5) + h * d[j] * (s - 6 * s3 + 8 * s4 - 3 * s5)
               + h * h * c[j] * (0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5)
               + h * h * c[j + 1] * (0.5 * s3 - s4 + 0.5 * s5)
               + h * d[j + 1] * (-4 * s3 + 7 * s4 - 3 * s5) + y[j + 1] * (10 * s3 - 15 * s4 + 6 * s5))
        out = np.where(t < x[0], y[0] + d[0] * (t - x[0]), out)
        return np.where(t > x[-1], y[-1] + d[-1] * (t - x[-1]), out)


#: C2 soft ramp: 0 for s <= -1, s for s >= 1, monotone in between (a soft ``max(s, 0)``)
_SOFT_RAMP = _Quintic([-1.0, 1.0], [0.0, 1.0], [0.0, 1.0])
_PHASE_CLAMP_WIDTH = 0.2  # half-width (step phase) of the soft clamp of the vertical phase at the ends


def _central_slopes(x: np.ndarray, y: np.ndarray, d_first: float, d_last: float) -> np.ndarray:
    d = np.empty_like(y)
    d[1:-1] = (y[2:] - y[:-2]) / (x[2:] - x[:-2])
    d[0], d[-1] = d_first, d_last
    return d


# ---------------------------------------------------------------------------
# gait: the vertical motion of the centre of mass over one step (inverted pendulum with double support)

def _pendulum_excursion(step_length_m, leg_m: float):
    """Vertical excursion (m, peak to peak) of the centre of mass over a step of ``step_length_m``: the inverted
    pendulum of Zijlstra & Hof (2003), ``step = K 2 sqrt(2 L h - h^2)``, solved for ``h``."""
    a = np.asarray(step_length_m, float) / (2.0 * PENDULUM_CORRECTION)
    return leg_m - np.sqrt(np.maximum(leg_m * leg_m - a * a, 0.0))


def _vertical_coefficients(step_frequency_hz: float, gain: float = HAND_VERTICAL_GAIN,
                           lag_s: float = HAND_LAG_S) -> np.ndarray:
    """Complex coefficients (2,) in harmonics 1, 2 of the step frequency of the phone's vertical displacement
    per metre of COM excursion: ``z(u) = Re(sum_m c_m exp(2 pi i m u))``, ``u`` the step phase.

    The COM height is ``-(cos th + b cos 2 th) / 2`` with ``th = 2 pi (u - ds / 2)`` (peak to peak 1, lowest
    in the middle of double support, highest in mid-stance; ``b = COM_SECOND_HARMONIC`` makes the trough
    sharper than the crest); the hand follows with gain ``HAND_VERTICAL_GAIN`` and the lag ``HAND_LAG_S``
    (``gain=1, lag_s=0``: the COM itself, for the placements of :mod:`desktop.placements`).
    """
    u0 = 0.5 * DOUBLE_SUPPORT + lag_s * step_frequency_hz
    c = np.array([-0.5 * np.exp(-2j * np.pi * u0), -0.5 * COM_SECOND_HARMONIC * np.exp(-4j * np.pi * u0)])
    return gain * c


# ---------------------------------------------------------------------------
# the walker's path


class _Path:
    """The walked path as pieces with closed-form position, heading and speed.

    Each piece: start time ``t0``, duration ``dur``, start state ``x0, y0, h0``,
    speed going from ``v0`` to ``v1`` as ``v0 + (v1 - v0) (1 - cos(pi tau / dur)) / 2``
    and a constant heading rate ``om`` (0: straight; else an arc at constant speed,
    or a turn on the spot when the speed is 0).  Before the first piece the
    walker stands at its start, after the last at its end.
    """

    def __init__(self, waypoints_en_m, *, speed_m_s: float, turn_rate_rad_s: float, ramp_s: float,
                 t_start_s: float, step_frequency_hz: float):
        pts = np.asarray(waypoints_en_m, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1 or not np.all(np.isfinite(pts)):
            raise ValueError("waypoints_en_m must be a non-empty sequence of finite (east, north) pairs")
        keep = [0]
        for i in range(1, len(pts)):
            if math.hypot(*(pts[i] - pts[keep[-1]])) > 1e-9:
                keep.append(i)
        pts = pts[keep]
        self.points = pts
        seg = np.diff(pts, axis=0)
        lengths = np.hypot(seg[:, 0], seg[:, 1])
        self.polyline_length_m = float(lengths.sum())
        self.t_start_s = float(t_start_s)
        v, om, ramp_s = float(speed_m_s), float(turn_rate_rad_s), float(ramp_s)
        # Speed changes are cosine ramps lasting ramp_s * |change| / v: the same peak acceleration for any
        # change, and a ramp between x and y covers ramp_s |y^2 - x^2| / (2 v) metres, i.e. the squared speed
        # changes by kappa per metre of ramp.
        kappa = 2.0 * v / ramp_s
        pieces: list[tuple[float, float, float, float]] = []  # (dur, v0, v1, om)
        nseg = len(lengths)
        if nseg:
            th = np.arctan2(seg[:, 1], seg[:, 0])
            turn = np.zeros(nseg + 1)  # turn angle at each vertex (0 at the ends)
            tan_half = np.zeros(nseg + 1)  # tan(|turn| / 2): tangent length of the arc = radius * tan_half
            vc = np.zeros(nseg + 1)  # speed through each vertex; 0 at the ends (start and stop at rest)
            for k in range(1, nseg):
                turn[k] = wrap_angle(th[k] - th[k - 1])
                a = abs(turn[k])
                share = 0.5 * min(lengths[k - 1], lengths[k])  # each corner may use half of each adjacent segment
                if a < 1e-12:
                    vc[k] = v
                elif a < math.pi - 1e-9:
                    tan_half[k] = math.tan(0.5 * a)
                    vc[k] = min(v, om * share / tan_half[k])  # arc radius vc / om must fit into the share
                else:
                    tan_half[k] = math.inf  # U-turn: turn on the spot (vc = 0)

            def tangent(k: int, speed: float) -> float:
                return speed / om * tan_half[k] if speed > 0.0 else 0.0

            def reachable(k: int, rhs: float) -> float:
                """Largest x with x^2 + kappa tangent(k, x) <= rhs."""
                if rhs <= 0.0:
                    return 0.0
                b = kappa * tan_half[k] / om
                return 2.0 * rhs / (b + math.sqrt(b * b + 4.0 * rhs))

            # vertex speeds reachable by ramps on the straight parts: a forward and a backward pass
            for i in range(nseg):
                if vc[i + 1] > 0.0:
                    rhs = vc[i] ** 2 + kappa * (lengths[i] - tangent(i, vc[i]))
                    vc[i + 1] = min(vc[i + 1], reachable(i + 1, rhs))
            for i in reversed(range(nseg)):
                if vc[i] > 0.0:
                    rhs = vc[i + 1] ** 2 + kappa * (lengths[i] - tangent(i + 1, vc[i + 1]))
                    vc[i] = min(vc[i], reachable(i, rhs))
            for i in range(nseg):
                a, b = vc[i], vc[i + 1]
                straight = lengths[i] - tangent(i, a) - tangent(i + 1, b)
                # the highest speed on this segment: ramp up from a, cruise, ramp down to b
                u = max(min(v, math.sqrt(max(v * straight / ramp_s + 0.5 * (a * a + b * b), 0.0))), a, b)
                d_in, d_out = ramp_s * (u - a) / v, ramp_s * (u - b) / v
                cruise = straight - 0.5 * (a + u) * d_in - 0.5 * (u + b) * d_out
                if d_in > 1e-9:
                    pieces.append((d_in, a, u, 0.0))
                if cruise > 1e-9:
                    pieces.append((cruise / u, u, u, 0.0))
                if d_out > 1e-9:
                    pieces.append((d_out, u, b, 0.0))
                if i + 1 < nseg and turn[i + 1] != 0.0:
                    pieces.append((abs(turn[i + 1]) / om, b, b, math.copysign(om, turn[i + 1])))
            h_start = float(th[0])
        else:
            h_start = 0.0  # a single waypoint: standing, facing East
        arr = np.array(pieces, dtype=float).reshape(-1, 4)
        nominal_s = float(arr[:, 0].sum())
        if nseg:
            self.n_steps = max(1, int(round(nominal_s * step_frequency_hz)))
            stretch = self.n_steps / step_frequency_hz / nominal_s
        else:
            self.n_steps, stretch = 0, 1.0
            arr = np.array([[1.0, 0.0, 0.0, 0.0]])  # a standing "piece" so evaluation needs no special case
        self.time_stretch = stretch
        self.dur = arr[:, 0] * stretch
        self.v0 = arr[:, 1] / stretch
        self.v1 = arr[:, 2] / stretch
        self.om = arr[:, 3] / stretch
        self.cruise_speed_m_s = v / stretch
        self.walk_duration_s = self.n_steps / step_frequency_hz if nseg else 0.0
        self.t0 = self.t_start_s + np.concatenate([[0.0], np.cumsum(self.dur)[:-1]])
        # chain the start states
        n = len(self.dur)
        self.x0, self.y0, self.h0, self.s0 = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
        x, y, h, s = float(pts[0, 0]), float(pts[0, 1]), h_start, 0.0
        for j in range(n):
            self.x0[j], self.y0[j], self.h0[j], self.s0[j] = x, y, h, s
            xe, ye, he, _, se = self._piece(j, np.array([self.dur[j]]))
            x, y, h, s = float(xe[0]), float(ye[0]), float(he[0]), s + float(se[0])
        self.path_length_m = s
        self.hint0 = np.concatenate([[0.0], np.cumsum(self.h0 * self.dur + 0.5 * self.om * self.dur ** 2)[:-1]])
        self.end = (x, y, h)

    def _piece(self, j, tau):
        """State within piece ``j`` (index array or int) at local times ``tau``: x, y, h, v, s (distance)."""
        d, v0, v1, om = self.dur[j], self.v0[j], self.v1[j], self.om[j]
        frac = tau / d
        s = v0 * tau + 0.5 * (v1 - v0) * (tau - d / np.pi * np.sin(np.pi * frac))
        v = v0 + 0.5 * (v1 - v0) * (1.0 - np.cos(np.pi * frac))
        h0 = self.h0[j]
        h = h0 + om * tau
        turning = om != 0.0
        radius = np.where(turning, v0 / np.where(turning, om, 1.0), 0.0)  # signed; arcs have v0 == v1
        x = self.x0[j] + np.where(turning, radius * (np.sin(h) - np.sin(h0)), s * np.cos(h0))
        y = self.y0[j] + np.where(turning, radius * (np.cos(h0) - np.cos(h)), s * np.sin(h0))
        return x, y, h, v, s

    def state(self, t: np.ndarray):
        """Walker state at times ``t`` (s on the simulation clock): east, north, heading, speed, distance."""
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(self.t0, t, side="right") - 1, 0, len(self.dur) - 1)
        tau = np.clip(t - self.t0[j], 0.0, self.dur[j])
        x, y, h, v, s = self._piece(j, tau)
        return x, y, h, v, self.s0[j] + s

    def heading_integral(self, t: np.ndarray) -> np.ndarray:
        """Antiderivative of the heading, ``int h dt`` from the start of walking (rad s), closed form."""
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(self.t0, t, side="right") - 1, 0, len(self.dur) - 1)
        tau = t - self.t0[j]
        inside = np.clip(tau, 0.0, self.dur[j])
        h_in = self.h0[j] * inside + 0.5 * self.om[j] * inside * inside
        h_at = self.h0[j] + self.om[j] * inside  # heading where the piece was left (or entered)
        return self.hint0[j] + h_in + h_at * (tau - inside)

    def smooth_heading(self, t: np.ndarray, width_s: float) -> np.ndarray:
        """Moving average of the heading over ``width_s``: equal to the heading on straight parts, but with
        a continuous rate that ramps linearly over ``width_s`` at the ends of each turn."""
        return (self.heading_integral(t + 0.5 * width_s) - self.heading_integral(t - 0.5 * width_s)) / width_s


# ---------------------------------------------------------------------------
# the whole model: position and attitude of the phone as functions of time


class _WalkModel:
    """Phone position (ENU, m), attitude (body -> ENU), gyro bias and magnetic field as functions of
    simulation time (s), built once from the plan and the random draws."""

    def __init__(self, *, path: _Path, clock0_ns: int, step_frequency_hz: float, step_length_m: float,
                 height_m: float, pitch_rad: float, roll_rad: float, yaw_offset_rad: float,
                 sway_rad: Sequence[float], drift: np.ndarray, calibration_s: float, step_length_cv: float,
                 step_time_cv: float, bounce_scale: float, rng_gait: np.random.Generator,
                 gyro_bias: Sequence[float], bias_grid_s: np.ndarray, bias_walk: np.ndarray,
                 earth_field_enu_uT: Sequence[float], zones: Sequence[DisturbanceZone], field_sources=None):
        self.path = path
        self.clock0_ns = int(clock0_ns)
        self.f = f = float(step_frequency_hz)
        self.step_length_m = float(step_length_m)
        self.hand_height_m = _HAND_HEIGHT_RATIO * float(height_m)
        self.leg_m = LEG_LENGTH_RATIO * float(height_m)
        self.pitch, self.roll, self.yaw_offset = float(pitch_rad), float(roll_rad), float(yaw_offset_rad)
        self.sway = np.asarray(sway_rad, float)
        self.drift = drift  # (3 axes, terms, [amplitude rad, frequency Hz, phase rad])
        self.cal_s = float(calibration_s)
        self.bounce_scale = float(bounce_scale)
        self.gyro_bias0 = np.asarray(gyro_bias, float)
        self.bias_grid_s, self.bias_walk = bias_grid_s, bias_walk
        self.h_earth = np.asarray(earth_field_enu_uT, float)
        self.zones = tuple(zones)
        self.field_sources = field_sources  # a desktop.bent_field.SteelField (or None): the building's steel

        n = path.n_steps
        self.n_steps = n
        t_plan = path.t_start_s + np.arange(n + 1) / f  # the plan's heel strikes; k = 0 is the start of walking
        s_plan = path.state(t_plan)[4]
        if n >= 1:
            # heel-strike timing: i.i.d. offsets, the first and the last kept
            d = rng_gait.standard_normal(n + 1) * step_time_cv / (f * math.sqrt(2.0))
            d = np.clip(d, -0.15 / f, 0.15 / f)
            d[0] = d[-1] = 0.0
            t_hs = t_plan + d
            # distance offsets from the plan: stationary AR(1), 0 at the ends, clipped to 30 % of adjacent steps
            l_plan = np.diff(s_plan)
            sd_e = step_length_cv * self.step_length_m / math.sqrt(2.0 * (1.0 - _STEP_AR))
            eps = rng_gait.standard_normal(n + 1)
            e = np.empty(n + 1)
            e[0] = sd_e * eps[0]
            for k in range(1, n + 1):
                e[k] = _STEP_AR * e[k - 1] + math.sqrt(1.0 - _STEP_AR ** 2) * sd_e * eps[k]
            e[0] = e[-1] = 0.0
            if n >= 2:
                lim = 0.3 * np.minimum(l_plan[:-1], l_plan[1:])
                e[1:-1] = np.clip(e[1:-1], -lim, lim)
            target = s_plan + e
            # warped (plan) time of each heel strike: s_plan(w_k) = S_k, by bisection within the adjacent steps
            w = t_plan.copy()
            idx = np.flatnonzero(e != 0.0)
            if len(idx):
                lo, hi = t_plan[idx - 1].copy(), t_plan[idx + 1].copy()
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    below = path.state(mid)[4] < target[idx]
                    lo = np.where(below, mid, lo)
                    hi = np.where(below, hi, mid)
                w[idx] = 0.5 * (lo + hi)
            # where the plan stands still (turning on the spot) a small offset would skip the whole turn: the
            # warped heel strikes stay within 10 % of a period of the plan's (the distance follows from them)
            w = np.clip(w, t_plan - 0.1 / f, t_plan + 0.1 / f)
            self.step_s = path.state(w)[4]  # exact distances along the path at the heel strikes
            self.t_hs = t_hs
            self.warp = _Quintic(t_hs, w, _central_slopes(t_hs, w, 1.0, 1.0))
            self.phase_curve = _Quintic(t_hs, np.arange(n + 1, dtype=float),
                                        _central_slopes(t_hs, np.arange(n + 1, dtype=float), f, f))
            lengths = np.diff(self.step_s)
            # step-length envelope (sway, fore-aft, lateral): knots at the middle of each step, zero at rest
            tk = np.concatenate([[t_hs[0]], 0.5 * (t_hs[1:] + t_hs[:-1]), [t_hs[-1] + 0.5 / f]])
            rel = np.concatenate([[0.0], lengths / self.step_length_m, [0.0]])
            self.env_rel = _Quintic(tk, rel, _central_slopes(tk, rel, 0.0, 0.0))
            # vertical excursion envelope: knots at the middle of each step too.  In gait initiation and
            # termination the feet land about a normal step apart although the body moves less: those two
            # steps vault over END_STEP_FOOT_RATIO of a mean step.  The excursion fades over one step after
            # the last heel strike (the vertical phase is clamped at the crest by then).
            foot = lengths.copy()
            foot[[0, -1]] = np.maximum(foot[[0, -1]], END_STEP_FOOT_RATIO * self.step_length_m)
            te = np.concatenate([[t_hs[0]], 0.5 * (t_hs[1:] + t_hs[:-1]), [t_hs[-1] + 1.0 / f]])
            exc = np.concatenate([[0.0], _pendulum_excursion(foot, self.leg_m), [0.0]])
            self.env_exc = _Quintic(te, exc, _central_slopes(te, exc, 0.0, 0.0))
            self.step_lengths = lengths
        else:
            self.t_hs = t_plan
            self.step_s = s_plan
            self.warp = self.phase_curve = self.env_rel = self.env_exc = None
            self.step_lengths = np.zeros(0)
        self.walk_start_s = float(self.t_hs[0])
        self.walk_end_s = float(self.t_hs[-1])
        # vertical gait: the phone's motion per metre of COM excursion (hand gain and lag included)
        self.vert_coef = _vertical_coefficients(f)
        self.vert_crest_phase = self._crest_phase(self.vert_coef)
        self.vert_crest = float(self._vertical_unit(np.array([self.vert_crest_phase]))[0])
        lag = np.exp(-2j * np.pi * HAND_LAG_S * f)  # the hand's lag, as a phase at the step frequency
        self.fwd_amp = FORE_AFT_SPEED_SWING * self.step_length_m / (2.0 * np.pi) * lag
        self.lat_amp = LATERAL_SWAY_M * np.sqrt(lag)
        # heel-strike transients: one per heel strike k = 1..n, scaled by the step just completed
        self.hs_t = self.t_hs[1:] + HEEL_STRIKE_DELAY_S
        self.hs_amp = HEEL_STRIKE_M_S2 * self.bounce_scale * self.step_lengths / self.step_length_m

    @staticmethod
    def _crest_phase(c: np.ndarray) -> float:
        """Step phase (in [0, 1)) of the crest of the vertical gait motion of coefficients ``c``
        (:func:`_vertical_coefficients`)."""
        u = np.arange(4096) / 4096
        return float(u[np.argmax((c[0] * np.exp(2j * np.pi * u) + c[1] * np.exp(4j * np.pi * u)).real)])

    def _vertical_unit(self, u: np.ndarray) -> np.ndarray:
        base = np.exp(2j * np.pi * np.mod(u, 1.0))
        return (self.vert_coef[0] * base + self.vert_coef[1] * base * base).real

    # -- the walker --------------------------------------------------------------
    def warped(self, t: np.ndarray) -> np.ndarray:
        return np.asarray(t, float) if self.warp is None else self.warp(t)

    def walker(self, t: np.ndarray):
        """Walker state at simulation times ``t``: east, north, heading, plan speed, distance along the path."""
        return self.path.state(self.warped(t))

    def phase(self, t: np.ndarray) -> np.ndarray:
        """Step phase: heel strike ``k`` at phase ``k`` (C2)."""
        if self.phase_curve is None:
            return (np.asarray(t, float) - self.walk_start_s) * self.f
        return self.phase_curve(t)

    def rel_length(self, t: np.ndarray) -> np.ndarray:
        """Step-length envelope / mean step length (0 at rest)."""
        return np.zeros_like(t) if self.env_rel is None else np.maximum(self.env_rel(t), 0.0)

    def _cal_window(self, t: np.ndarray) -> np.ndarray:
        c = self.cal_s
        if c <= 0:
            return np.zeros_like(t)
        taper = min(_CAL_TAPER_S, 0.5 * c)
        up = np.clip(t / taper, 0.0, 1.0)
        down = np.clip((c - t) / taper, 0.0, 1.0)
        return 0.25 * (1.0 - np.cos(np.pi * up)) * (1.0 - np.cos(np.pi * down))

    def _drift(self, t: np.ndarray, axis: int) -> np.ndarray:
        amp, freq, ph = self.drift[axis].T
        return np.sin(2.0 * np.pi * np.outer(t, freq) + ph) @ amp

    def _gait(self, t: np.ndarray) -> np.ndarray:
        """Phone displacement (n, 3) from the gait in the walking frame (forward, left, up), m."""
        n = len(t)
        out = np.zeros((n, 3))
        if self.env_exc is None:
            return out
        u = self.phase(t)
        k = self.rel_length(t)
        exc = np.maximum(self.env_exc(t), 0.0) * self.bounce_scale
        # relative to the crest: standing height is the crest of the walking motion (legs together).  The
        # vertical phase stays at the crest of the first step until the body drops into the first double
        # support, and stops at the crest after the last one: walking starts by dropping into the first
        # trough and ends by rising out of the last one, with no further oscillation.
        lo, hi = self.vert_crest_phase, self.n_steps + self.vert_crest_phase
        v = lo + _PHASE_CLAMP_WIDTH * _SOFT_RAMP((u - lo) / _PHASE_CLAMP_WIDTH)
        v = hi - _PHASE_CLAMP_WIDTH * _SOFT_RAMP((hi - v) / _PHASE_CLAMP_WIDTH)
        out[:, 2] = exc * (self._vertical_unit(v) - self.vert_crest)
        ds2 = 0.5 * DOUBLE_SUPPORT
        out[:, 0] = k * (self.fwd_amp * np.exp(2j * np.pi * (u - ds2))).imag
        out[:, 1] = k * (self.lat_amp * np.exp(1j * np.pi * (u - ds2))).imag
        # heel-strike transients: the heel strikes just before and after t are enough (12 ms wide, ~0.5 s apart)
        if len(self.hs_t):
            j = np.searchsorted(self.hs_t, t)
            sig2 = HEEL_STRIKE_SIGMA_S ** 2
            for off in (-1, 0):
                jj = np.clip(j + off, 0, len(self.hs_t) - 1)
                valid = (j + off >= 0) & (j + off < len(self.hs_t))
                x2 = np.minimum((t - self.hs_t[jj]) ** 2 / sig2, 200.0)
                bump = np.where(valid, self.hs_amp[jj] * sig2 * np.exp(-0.5 * x2), 0.0)
                out[:, 2] -= bump  # a dip in displacement: an upward acceleration peak of hs_amp
                out[:, 0] += HEEL_STRIKE_BRAKE * bump  # and a backward one
        return out

    # -- the model -------------------------------------------------------------
    def offset_w(self, t: np.ndarray) -> np.ndarray:
        """Phone position (n, 3) relative to the walker's ground point in the walking frame (forward, left, up), m."""
        d = self._gait(t)
        d[:, 2] += self.hand_height_m
        return d

    def position(self, t: np.ndarray) -> np.ndarray:
        """Phone position (n, 3) in ENU (m): the walker's ground point plus ``offset_w`` turned by the heading."""
        t = np.asarray(t, float)
        w = self.warped(t)
        x, y = self.path.state(w)[:2]
        h = self.path.smooth_heading(w, _TURN_SMOOTH_S)
        d = self.offset_w(t)
        c, s = np.cos(h), np.sin(h)
        pos = np.stack([x + c * d[:, 0] - s * d[:, 1], y + s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        if self.cal_s > 0:
            wc = self._cal_window(t)
            pos += wc[:, None] * np.stack([0.06 * np.sin(2 * np.pi * 0.30 * t), 0.04 * np.sin(2 * np.pi * 0.60 * t),
                                           0.04 * np.sin(2 * np.pi * 0.45 * t)], axis=1)
        return pos

    def quat(self, t: np.ndarray) -> np.ndarray:
        """Phone attitude quaternions (n, 4), body -> ENU."""
        t = np.asarray(t, float)
        h = self.path.smooth_heading(self.warped(t), _TURN_SMOOTH_S)
        phi = self.phase(t)
        k = self.rel_length(t)  # the sway follows the step length
        yaw = (h - 0.5 * np.pi + self.yaw_offset + k * self.sway[0] * np.sin(np.pi * phi + 0.3)
               + self._drift(t, 0))
        pitch = self.pitch + k * self.sway[1] * np.sin(2.0 * np.pi * phi + 1.0) + self._drift(t, 1)
        roll = self.roll + k * self.sway[2] * np.sin(np.pi * phi - 0.5) + self._drift(t, 2)
        q = quat.multiply_array(quat.multiply_array(quat.about_axis_array(2, yaw), quat.about_axis_array(0, pitch)),
                                quat.about_axis_array(1, roll))
        if self.cal_s > 0:
            wc = self._cal_window(t) * (0.5 * np.pi)
            qa = quat.about_axis_array(2, wc * np.sin(2 * np.pi * 0.11 * t))
            qb = quat.about_axis_array(0, wc * np.sin(2 * np.pi * 0.30 * t + 0.6))
            qc = quat.multiply_array(quat.multiply_array(qa, qb),
                                     quat.about_axis_array(1, wc * np.sin(2 * np.pi * 0.15 * t + 1.3)))
            q = quat.multiply_array(q, qc)
        return q

    def body_rate(self, t: np.ndarray) -> np.ndarray:
        """Exact body angular rate (n, 3) rad/s: ``vee(log(R(t-d)^T R(t+d))) / 2d``."""
        d = _GYRO_DIFF_S
        q_a, q_b = self.quat(t - d), self.quat(t + d)
        q_a[:, 1:] *= -1.0  # conjugate
        return quat.to_rotation_vector_array(quat.multiply_array(q_a, q_b)) / (2.0 * d)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """Phone velocity (n, 3) in ENU (m/s): central difference of :meth:`position`."""
        d = _ACC_DIFF_S
        n = len(t)
        p = self.position(np.concatenate([t - d, t + d]))
        return (p[n:] - p[:n]) / (2.0 * d)

    def linear_acc(self, t: np.ndarray) -> np.ndarray:
        """Phone acceleration (n, 3) in ENU (m/s^2): second central difference of :meth:`position`."""
        d = _ACC_DIFF_S
        n = len(t)
        p = self.position(np.concatenate([t - d, t, t + d]))
        return (p[:n] - 2.0 * p[n:2 * n] + p[2 * n:]) / (d * d)

    def gyro_bias(self, t: np.ndarray) -> np.ndarray:
        """True gyroscope bias (n, 3), rad/s."""
        t = np.asarray(t, float)
        walk = np.stack([np.interp(t, self.bias_grid_s, self.bias_walk[:, i]) for i in range(3)], axis=1)
        return self.gyro_bias0 + walk

    def field_n(self, t: np.ndarray) -> np.ndarray:
        """True magnetic field (n, 3) in ENU at the phone, uT."""
        t = np.asarray(t, float)
        h = np.tile(self.h_earth, (len(t), 1))
        if self.zones or self.field_sources is not None:
            pos = self.position(t)
            if self.field_sources is not None:
                h = h + self.field_sources.field_at(pos)
            for z in self.zones:
                h = z.apply(h, pos[:, 0], pos[:, 1])
        return h


# ---------------------------------------------------------------------------
# sampling


def _sample_times_ns(rng: np.random.Generator, rate_hz: float, jitter: float, duration_s: float,
                     clock0_ns: int) -> np.ndarray:
    """Jittered sample times (int64 ns) covering ``[0, duration_s]`` of simulation time."""
    dt = 1.0 / rate_hz
    n_max = int(math.ceil(duration_s * rate_hz * 1.5)) + 16
    phase = rng.uniform(0.0, dt)
    steps = np.maximum(dt * (1.0 + jitter * rng.standard_normal(n_max)), 0.1 * dt)
    t = phase + np.concatenate([[0.0], np.cumsum(steps)])
    if t[-1] < duration_s:  # pragma: no cover - the mean interval is >= dt, so 1.5x is plenty
        raise RuntimeError("not enough samples drawn")
    t = t[t <= duration_s]
    return clock0_ns + np.round(t * 1e9).astype(np.int64)


def _gauss_markov(rng: np.random.Generator, t_s: np.ndarray, sd: np.ndarray, tau_s: float) -> np.ndarray:
    """First-order Gauss-Markov processes (n, len(sd)) at the times ``t_s``, stationary from the start:
    ``x_k+1 = a x_k + sqrt(1 - a^2) sd w_k`` with ``a = exp(-(t_k+1 - t_k) / tau)``."""
    sd = np.asarray(sd, float)
    w = rng.standard_normal((len(t_s), len(sd))) * sd
    out = np.zeros_like(w)
    if len(t_s):
        a = np.exp(-np.diff(t_s) / tau_s)
        b = np.sqrt(1.0 - a * a)
        out[0] = w[0]
        for k in range(1, len(t_s)):
            out[k] = a[k - 1] * out[k - 1] + b[k - 1] * w[k]
    return out


def _simulate_gps(gps: GpsModel, model: _WalkModel, seeds: np.random.SeedSequence, total_s: float,
                  origin_lat_lon: tuple[float, float], origin_alt_m: float) -> tuple[Stream, GpsTruth]:
    """The ``gps`` stream and its :class:`GpsTruth` (see :class:`GpsModel`); all draws from ``seeds``' children."""
    rng_t, rng_noise, rng_bias, rng_mp, rng_hacc, rng_vel, rng_alt, rng_cold = (
        np.random.default_rng(s) for s in seeds.spawn(8))
    clock0 = model.clock0_ns
    dt = 1.0 / gps.rate_hz
    n = int(math.floor((total_s - gps.first_fix_s) * gps.rate_hz)) + 1 if total_s >= gps.first_fix_s else 0
    jitter = np.clip(gps.time_jitter_s * rng_t.standard_normal(n), -0.3 * dt, 0.3 * dt)
    t_s = gps.first_fix_s + np.arange(n) * dt + jitter
    t_s = t_s[(t_s >= 0.0) & (t_s <= total_s)]
    t_ns = clock0 + np.round(t_s * 1e9).astype(np.int64)
    t = (t_ns - clock0) * 1e-9  # the physics at exactly the time stamps, as for the other sensors
    n = len(t)

    pos = model.position(t)
    vel = (pos[:, :2] - model.position(t - gps.velocity_window_s)[:, :2]) / gps.velocity_window_s
    bias = _gauss_markov(rng_bias, t, (gps.bias_sd_m, gps.bias_sd_m, gps.alt_bias_sd_m), gps.bias_tau_s)

    # multipath: a Poisson process of episodes, started one longest episode before the first fix (stationary)
    lo_s, hi_s = (t[0] - gps.multipath_duration_s[1], t[-1]) if n else (0.0, 0.0)
    k = int(rng_mp.poisson(gps.multipath_per_min / 60.0 * (hi_s - lo_s)))
    starts = np.sort(rng_mp.uniform(lo_s, hi_s, k))
    ends = starts + rng_mp.uniform(*gps.multipath_duration_s, k)
    jump = rng_mp.uniform(*gps.multipath_jump_m, k)
    ang = rng_mp.uniform(0.0, 2.0 * np.pi, k)
    offsets = np.stack([jump * np.cos(ang), jump * np.sin(ang)], axis=1)
    inside = (t[:, None] >= starts) & (t[:, None] < ends)
    touching = inside.any(axis=0)
    multipath = inside.any(axis=1)
    mp_en = inside @ offsets

    # cold start: a random direction, shrinking linearly to 0 over the first cold_start_fixes fixes
    n_cold = int(gps.cold_start_fixes)
    cold_ang = rng_cold.uniform(0.0, 2.0 * np.pi)
    cold_mag = gps.cold_start_error_m * np.clip(1.0 - np.arange(n) / max(n_cold, 1), 0.0, 1.0) * (np.arange(n) < n_cold)
    cold_en = cold_mag[:, None] * np.array([math.cos(cold_ang), math.sin(cold_ang)])

    white = gps.noise_sd_m * rng_noise.standard_normal((n, 2))
    alt = origin_alt_m + pos[:, 2] + bias[:, 2] + gps.alt_noise_sd_m * rng_alt.standard_normal(n)

    hacc_normal = np.full(n, gps.hacc_scale * math.hypot(gps.noise_sd_m, gps.bias_sd_m))
    jit = np.exp(math.sqrt(math.log1p(gps.hacc_jitter_cv ** 2)) * rng_hacc.standard_normal(n))
    hacc = hacc_normal * jit * np.where(multipath, gps.hacc_multipath_factor, 1.0) + cold_mag

    v_meas = vel + gps.speed_noise_m_s * rng_vel.standard_normal((n, 2))
    faults = _gps_faults(gps, seeds, t, hacc_normal * jit)
    if faults is not None:  # only then: the fixes of a model without faults are computed exactly as before
        hacc = np.where(faults["hacc"] == faults["hacc"], faults["hacc"], hacc)
        v_meas = v_meas + faults["vel_en"]
    fault_en = faults["en"] if faults is not None else np.zeros((n, 2))
    err_en = bias[:, :2] + mp_en + cold_en + white + fault_en
    east, north = (pos[:, :2] + bias[:, :2] + mp_en + cold_en + white + fault_en).T  # + 0.0 without faults: exact
    lat, lon = enu_to_geodetic(east, north, origin_lat_lon)
    speed = np.hypot(v_meas[:, 0], v_meas[:, 1])
    bearing = np.array([bearing_deg(h) for h in np.arctan2(v_meas[:, 1], v_meas[:, 0]).tolist()])
    course = np.where(speed >= gps.course_min_speed_m_s, bearing, np.nan)

    keep = np.ones(n, dtype=bool) if faults is None else faults["keep"]
    stream = make_stream(GPS, t_ns[keep], np.stack([lat, lon, alt, hacc, speed, course], axis=1)[keep])
    frozen = _readonly
    nf = len(gps.faults)
    truth = GpsTruth(
        model=gps, t_ns=frozen(t_ns[keep]), pos_enu_m=frozen(pos[keep]), vel_en_m_s=frozen(vel[keep]),
        bias_en_m=frozen(bias[keep, :2]), alt_bias_m=frozen(bias[keep, 2]), multipath=frozen(multipath[keep]),
        multipath_en_m=frozen(mp_en[keep]), cold_start_en_m=frozen(cold_en[keep]),
        hacc_normal_m=frozen(hacc_normal[keep]),
        multipath_t_ns=frozen((clock0 + np.round(np.stack([starts, ends], axis=1) * 1e9).astype(np.int64))[touching]),
        multipath_offset_en_m=frozen(offsets[touching]), error_en_m=frozen(err_en[keep]),
        fault_index=frozen(faults["index"][keep] if faults is not None else np.full(n, -1)),
        fault_kind=frozen(faults["kind"][keep] if faults is not None else np.full(n, "", dtype="<U6")),
        fault_en_m=frozen(fault_en[keep]),
        fault_t_ns=frozen(clock0 + np.round(np.array([(f.start_s, f.end_s) for f in gps.faults],
                                                     dtype=float).reshape(nf, 2) * 1e9).astype(np.int64)),
        fault_offset_en_m=frozen(faults["offset"] if faults is not None else np.zeros((0, 2))))
    return stream, truth


def _gps_faults(gps: GpsModel, seeds: np.random.SeedSequence, t: np.ndarray, hacc_jittered: np.ndarray):
    """The :class:`GpsFault` s of ``gps`` on the fixes at times ``t`` (s): None without faults, else a dict of
    ``en`` (n, 2) position offsets, ``vel_en`` (n, 2) velocity noise, ``hacc`` (n,) reported accuracy (nan:
    unchanged), ``keep`` (n,) bool (False inside an outage), ``index`` (n,) int, ``kind`` (n,) str and
    ``offset`` (f, 2) per fault.  Fault ``i`` draws from child ``i`` of the GPS generator's ninth child.
    ``hacc_jittered``: the normal reported accuracy of each fix (before multipath and cold start)."""
    if not gps.faults:
        return None
    n = len(t)
    out = {"en": np.zeros((n, 2)), "vel_en": np.zeros((n, 2)), "hacc": np.full(n, np.nan),
           "keep": np.ones(n, dtype=bool), "index": np.full(n, -1), "kind": np.full(n, "", dtype="<U6"),
           "offset": np.zeros((len(gps.faults), 2))}
    for i, (f, fs) in enumerate(zip(gps.faults, seeds.spawn(1)[0].spawn(len(gps.faults)))):
        rng = np.random.default_rng(fs)
        idx = np.flatnonzero((t >= f.start_s) & (t < f.end_s))
        m = len(idx)
        if f.kind == "outage":
            out["keep"][idx] = False
            continue
        if f.kind == "jump":
            mag, ang = rng.uniform(*f.offset_m), rng.uniform(0.0, 2.0 * np.pi)
            out["offset"][i] = (mag * math.cos(ang), mag * math.sin(ang))
            en, extra = np.tile(out["offset"][i], (m, 1)), np.full(m, mag)
        elif f.kind == "drift":
            ang = rng.uniform(0.0, 2.0 * np.pi)
            unit = np.array([math.cos(ang), math.sin(ang)])
            out["offset"][i] = f.drift_m_per_min * f.duration_s / 60.0 * unit
            extra = f.drift_m_per_min / 60.0 * (t[idx] - f.start_s)
            en = extra[:, None] * unit
        elif f.kind == "noise":
            en = f.noise_sd_m * rng.standard_normal((m, 2))
            out["vel_en"][idx] = f.velocity_sd_m_s * rng.standard_normal((m, 2))
            extra = np.zeros(m)
        else:  # lying: every draw made for every fix in the window, then the liars kept
            lies = rng.random(m) < f.fraction
            extra, ang = rng.uniform(*f.offset_m, m), rng.uniform(0.0, 2.0 * np.pi, m)
            en = np.stack([extra * np.cos(ang), extra * np.sin(ang)], axis=1)
            idx, en, extra = idx[lies], en[lies], extra[lies]
        u = rng.uniform(0.0, 1.0, m)[:len(idx)]  # for a (low, high) reported accuracy
        out["en"][idx] = en
        out["index"][idx], out["kind"][idx] = i, f.kind
        h = hacc_jittered[idx]
        if f.hacc == "honest" and f.kind == "noise":
            normal_sd = math.hypot(gps.noise_sd_m, gps.bias_sd_m)
            out["hacc"][idx] = h / normal_sd * math.hypot(normal_sd, f.noise_sd_m)
        elif f.hacc == "honest":
            out["hacc"][idx] = h + extra
        elif f.hacc == "normal":
            out["hacc"][idx] = h
        elif f.hacc == "under":
            out["hacc"][idx] = h * gps.hacc_multipath_factor
        else:
            out["hacc"][idx] = f.hacc[0] + (f.hacc[1] - f.hacc[0]) * u
    return out


def _readonly(a) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


def _vec3(name: str, value) -> tuple[float, float, float]:
    try:
        v = tuple(float(x) for x in value)
    except TypeError:
        raise ValueError(f"{name} must be three finite numbers, got {value!r}") from None
    if len(v) != 3 or not all(map(math.isfinite, v)):
        raise ValueError(f"{name} must be three finite numbers, got {value!r}")
    return v


def _positive(name: str, value) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return value


def _non_negative(name: str, value) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a non-negative number, got {value!r}")
    return value


def _finite(name: str, value) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


# ---------------------------------------------------------------------------
# public entry points


def simulate_walk(
    waypoints_en_m,
    *,
    rate_hz: float = 100.0,
    gyro_rate_hz: float | None = None,
    mag_rate_hz: float | None = None,
    timestamp_jitter: float = 0.05,
    step_frequency_hz: float = 1.8,
    step_length_m: float | None = None,
    step_length_cv: float = 0.03,
    step_time_cv: float = 0.02,
    still_start_s: float = 2.0,
    still_end_s: float = 2.0,
    turn_rate_deg_s: float = 90.0,
    height_m: float = 1.75,
    bounce_scale: float = 1.0,
    gyro_noise_rad_s: float = 0.003,
    gyro_bias_rad_s: Sequence[float] = (0.002, -0.0015, 0.001),
    gyro_bias_walk_rad_s_sqrt_s: float = 0.0,
    acc_noise_m_s2: float = 0.02,
    acc_bias_m_s2: Sequence[float] = (0.0, 0.0, 0.0),
    mag_noise_uT: float = 0.4,
    mag_hard_iron_uT: Sequence[float] = (0.0, 0.0, 0.0),
    mag_soft_iron: Sequence[Sequence[float]] | None = None,
    mag_uncalibrated_stream: str | None = None,
    earth_field_enu_uT: Sequence[float] = (0.0, 20.0, -44.0),
    disturbance_zones: Sequence[DisturbanceZone] = (),
    field_sources=None,
    calibration_motion_s: float = 0.0,
    phone_pitch_deg: float = 25.0,
    phone_roll_deg: float = 0.0,
    phone_yaw_offset_deg: float = 3.0,
    hand_sway_deg: Sequence[float] = (3.0, 1.5, 3.0),
    hand_drift_deg_s: Sequence[float] = (0.3, 0.5, 0.5),
    weinberg_c: float | None = None,
    truth_rate_hz: float = 200.0,
    clock_start_ns: int = DEFAULT_CLOCK_START_NS,
    gps: GpsModel | None = None,
    origin_lat_lon: tuple[float, float] = DEFAULT_ORIGIN_LAT_LON,
    origin_alt_m: float = DEFAULT_ORIGIN_ALT_M,
    placement: str = CARRY_HANDHELD,
    placement_options: dict | None = None,
    seed: int = 0,
) -> SimulatedWalk:
    """Simulate a walk along ``waypoints_en_m`` with a phone held in front of the chest (or carried otherwise:
    ``placement``).

    Parameters
    ----------
    waypoints_en_m : sequence of (east, north)
        Polyline in ENU metres, walked in order (repeated points are dropped;
        a single point gives a recording of standing only, facing East).
    rate_hz, gyro_rate_hz, mag_rate_hz : float
        Sensor rates (Hz).  The gyroscope defaults to the accelerometer rate
        (one IMU chip), the magnetometer to ``min(rate_hz, 50)``.
    timestamp_jitter : float
        Relative standard deviation of each sampling interval (0 to 0.5).
    step_frequency_hz : float
        Mean cadence (steps/s).
    step_length_m : float or None
        Mean step length (m); ``None``: from the walk ratio, :func:`default_step_length_m` (0.70 m for
        1.75 m at 1.8 steps/s).  The cruise speed is ``step_frequency_hz * step_length_m``.
    step_length_cv, step_time_cv : float
        Coefficients of variation of the individual step lengths and step durations (0 to 0.1).
    still_start_s, still_end_s : float
        Standing still (phone in the walking pose) before and after walking (s).
    turn_rate_deg_s : float
        Planned heading rate while walking around a corner (deg/s).
    height_m : float
        Walker's body height (m): leg length ``0.53 height``, phone at ``0.75 height``, default step length.
    bounce_scale : float
        Vertical excursion of the centre of mass (and heel-strike transients) relative to the inverted
        pendulum's (1: the model; stiffer or more compliant walkers 0.5-1.5).
    gyro_noise_rad_s, acc_noise_m_s2, mag_noise_uT : float
        Per-sample standard deviation of the white noise of each sensor.
    gyro_bias_rad_s, acc_bias_m_s2 : 3 floats
        Constant sensor biases in the device frame (rad/s, m/s^2).
    gyro_bias_walk_rad_s_sqrt_s : float
        Random walk of the gyroscope bias (rad/s per sqrt(s)), 0 for a constant bias.
    mag_hard_iron_uT : 3 floats
        Constant magnetometer offset in the device frame (uT).
    mag_soft_iron : 3x3 floats or None
        Soft-iron matrix ``S`` (reading = ``S R^T h + hard iron``), identity if None; ``det(S) > 0``.
    mag_uncalibrated_stream : str or None
        If a name (e.g. ``"mag_uncal"``), that stream carries the iron-affected readings and ``mag`` the
        readings without hard and soft iron (as an OS calibration would give them); None: ``mag`` carries
        the iron-affected readings.
    earth_field_enu_uT : 3 floats
        Local geomagnetic field (east, north, up) in uT.
    disturbance_zones : sequence of DisturbanceZone
        Local disturbances (azimuth rotation, dip/strength change, added field), applied in order.
    field_sources : desktop.bent_field.SteelField or None
        The building's magnetised steel (point dipoles, e.g. :func:`desktop.bent_field.corridor_steel`): its
        field at the phone's 3-D position is added to the Earth's before the zones (a bent indoor field fixed in
        space, issue #27).
    calibration_motion_s : float
        Duration of a tumbling figure-8 phone motion (+-90 deg about every
        axis, a few cm of hand motion) at the very start, before
        ``still_start_s``; the phone returns to the walking pose (s).
    phone_pitch_deg, phone_roll_deg : float
        Mean pitch (device y axis up from horizontal) and roll of the held phone (deg).
    phone_yaw_offset_deg : float
        Mean yaw of the device y axis relative to the walking direction (deg, counter-clockwise seen from
        above): the phone is not pointed exactly where the walker goes.
    hand_sway_deg : 3 floats
        Amplitudes (deg) at the mean step length of the yaw (stride frequency), pitch (step frequency) and
        roll (stride frequency) oscillations of the hand while walking.
    hand_drift_deg_s : 3 floats
        RMS angular rate (deg/s) of the slow random drift of the hand's yaw, pitch and roll (0.03-0.3 Hz),
        while standing and walking.  ``(0, 0, 0)`` with ``phone_pitch_deg=0`` holds a phone flat and still.
    weinberg_c : float or None
        Deprecated, kept for old callers: multiplies ``bounce_scale`` by ``(0.47 / weinberg_c) ** 4``, which
        changes the walker's apparent Weinberg constant by about ``weinberg_c / 0.47`` relative to its
        natural one.  The simulator does not make Weinberg's model hold.
    truth_rate_hz : float
        Rate of the dense truth grid ``truth.att_t_ns`` (Hz).
    clock_start_ns : int
        Sensor clock value at the start of the simulation (ns).
    gps : GpsModel or None
        If given, the recording gains a ``gps`` stream (the columns of ``core.recording.STREAM_SPECS["gps"]``)
        from this receiver model and ``truth.gps`` what went into each fix.  Its random numbers come from
        generators of their own: the other streams are the same with and without it.
    origin_lat_lon : 2 floats
        WGS-84 latitude and longitude (deg) of the ENU origin (default: Helsinki's centre); the ENU +y
        axis is true north.
    origin_alt_m : float
        Height of the (flat) ground above the WGS-84 ellipsoid at the origin (m), for the GPS altitude.
    placement : str
        How the phone is carried, one of ``core.conventions.CARRY_MODES``: "handheld" (this module's model,
        the default), "swinging", "pocket", "bag", "ear" (:mod:`desktop.placements`; they ignore
        ``phone_pitch_deg``, ``phone_roll_deg``, ``phone_yaw_offset_deg`` and ``hand_sway_deg``), "still"
        (only with a single waypoint: :func:`desktop.placements.simulate_still`).  The walk itself (heel
        strikes, step lengths, path) is the same for every placement and the same seed; the placement's own
        draws come from a generator of their own.
    placement_options : dict or None
        The placement's choices, drawn per seed where not given (see :mod:`desktop.placements`), e.g.
        ``{"side": "left"}``; ``truth.placement_info`` has them all.
    seed : int
        Seed of all randomness (timestamps, noise, gait variability, hand drift, bias walk, GPS errors).

    Returns
    -------
    SimulatedWalk
        ``recording`` with streams ``acc``, ``gyro``, ``mag`` (and ``mag_uncalibrated_stream``, ``gps``) and
        ``truth``.
    """
    rate_hz = _positive("rate_hz", rate_hz)
    gyro_rate_hz = rate_hz if gyro_rate_hz is None else _positive("gyro_rate_hz", gyro_rate_hz)
    mag_rate_hz = min(rate_hz, 50.0) if mag_rate_hz is None else _positive("mag_rate_hz", mag_rate_hz)
    timestamp_jitter = _non_negative("timestamp_jitter", timestamp_jitter)
    if timestamp_jitter > 0.5:
        raise ValueError(f"timestamp_jitter must be at most 0.5, got {timestamp_jitter}")
    f = _positive("step_frequency_hz", step_frequency_hz)
    height_m = _positive("height_m", height_m)
    step_length_m = (default_step_length_m(height_m, f) if step_length_m is None
                     else _positive("step_length_m", step_length_m))
    step_length_cv = _non_negative("step_length_cv", step_length_cv)
    step_time_cv = _non_negative("step_time_cv", step_time_cv)
    if step_length_cv > 0.1 or step_time_cv > 0.1:
        raise ValueError("step_length_cv and step_time_cv must be at most 0.1")
    still_start_s = _non_negative("still_start_s", still_start_s)
    still_end_s = _non_negative("still_end_s", still_end_s)
    calibration_motion_s = _non_negative("calibration_motion_s", calibration_motion_s)
    turn_rate = math.radians(_positive("turn_rate_deg_s", turn_rate_deg_s))
    bounce_scale = _non_negative("bounce_scale", bounce_scale)
    if weinberg_c is not None:
        bounce_scale *= (0.47 / _positive("weinberg_c", weinberg_c)) ** 4
    for name, val in (("gyro_noise_rad_s", gyro_noise_rad_s), ("acc_noise_m_s2", acc_noise_m_s2),
                      ("mag_noise_uT", mag_noise_uT)):
        _non_negative(name, val)
    bias_walk_sd = _non_negative("gyro_bias_walk_rad_s_sqrt_s", gyro_bias_walk_rad_s_sqrt_s)
    gyro_bias = _vec3("gyro_bias_rad_s", gyro_bias_rad_s)
    acc_bias = _vec3("acc_bias_m_s2", acc_bias_m_s2)
    hard_iron = _vec3("mag_hard_iron_uT", mag_hard_iron_uT)
    soft_iron = np.eye(3) if mag_soft_iron is None else np.array(mag_soft_iron, dtype=float)
    if soft_iron.shape != (3, 3) or not np.all(np.isfinite(soft_iron)) or not np.linalg.det(soft_iron) > 1e-6:
        raise ValueError("mag_soft_iron must be a finite 3x3 matrix with a positive determinant")
    if mag_uncalibrated_stream is not None and (not isinstance(mag_uncalibrated_stream, str)
                                                or mag_uncalibrated_stream in (ACC, GYRO, MAG, "")):
        raise ValueError(f"mag_uncalibrated_stream must be a new stream name, got {mag_uncalibrated_stream!r}")
    h_earth = _vec3("earth_field_enu_uT", earth_field_enu_uT)
    sway = _vec3("hand_sway_deg", hand_sway_deg)
    drift_deg_s = _vec3("hand_drift_deg_s", hand_drift_deg_s)
    if min(drift_deg_s) < 0:
        raise ValueError(f"hand_drift_deg_s must be non-negative, got {hand_drift_deg_s!r}")
    zones = tuple(disturbance_zones)
    if not all(isinstance(z, DisturbanceZone) for z in zones):
        raise ValueError("disturbance_zones must be DisturbanceZone instances")
    if field_sources is not None and not callable(getattr(field_sources, "field_at", None)):
        raise ValueError("field_sources must have field_at(points_enu_m) (a desktop.bent_field.SteelField) or be None")
    truth_rate_hz = _positive("truth_rate_hz", truth_rate_hz)
    phone_pitch_deg = _finite("phone_pitch_deg", phone_pitch_deg)
    phone_roll_deg = _finite("phone_roll_deg", phone_roll_deg)
    phone_yaw_offset_deg = _finite("phone_yaw_offset_deg", phone_yaw_offset_deg)
    clock0 = operator.index(clock_start_ns)
    seed = operator.index(seed)  # an explicit integer: the recording must be reproducible
    if gps is not None and not isinstance(gps, GpsModel):
        raise ValueError(f"gps must be a GpsModel or None, got {type(gps).__name__}")
    origin = tuple(_finite("origin_lat_lon", v) for v in origin_lat_lon)
    if len(origin) != 2 or not (abs(origin[0]) <= 85.0 and abs(origin[1]) <= 180.0):
        raise ValueError(f"origin_lat_lon must be (lat, lon) in degrees, |lat| <= 85, got {origin_lat_lon!r}")
    origin_alt_m = _finite("origin_alt_m", origin_alt_m)
    if placement not in CARRY_MODES:
        raise ValueError(f"placement must be one of {', '.join(CARRY_MODES)}, got {placement!r}")
    if placement != CARRY_HANDHELD and calibration_motion_s > 0:
        raise ValueError("calibration_motion_s is only simulated for the handheld placement")
    if placement == CARRY_HANDHELD and placement_options:
        raise ValueError("the handheld placement takes no placement_options (its pose: phone_pitch_deg etc.)")

    seeds = np.random.SeedSequence(seed)
    rngs = [np.random.default_rng(s) for s in seeds.spawn(9)]
    rng_t_acc, rng_t_gyro, rng_t_mag, rng_n_acc, rng_n_gyro, rng_n_mag, rng_drift, rng_gait, rng_bias = rngs
    gps_seeds = seeds.spawn(1)[0]  # the tenth child: the GPS never moves a draw of the nine above

    speed = f * step_length_m
    walk_start_s = calibration_motion_s + still_start_s
    path = _Path(waypoints_en_m, speed_m_s=speed, turn_rate_rad_s=turn_rate, ramp_s=_RAMP_STEPS / f,
                 t_start_s=walk_start_s, step_frequency_hz=f)
    walk_end_s = walk_start_s + path.walk_duration_s
    total_s = walk_end_s + still_end_s
    if total_s <= 0:
        raise ValueError("nothing to simulate: no walking and no standing time")

    # slow hand drift: per axis _DRIFT_TERMS sinusoids, log-uniform frequencies, RMS rate as asked
    lo, hi = _DRIFT_BAND_HZ
    freq = np.exp(rng_drift.uniform(math.log(lo), math.log(hi), (3, _DRIFT_TERMS)))
    phases = rng_drift.uniform(0.0, 2.0 * np.pi, (3, _DRIFT_TERMS))
    amp = np.radians(drift_deg_s)[:, None] * math.sqrt(2.0 / _DRIFT_TERMS) / (2.0 * np.pi * freq)
    drift = np.stack([amp, freq, phases], axis=-1)

    # gyro bias random walk on a coarse grid
    bias_grid = np.arange(0.0, total_s + 2.0 / _BIAS_GRID_HZ, 1.0 / _BIAS_GRID_HZ)
    incr = rng_bias.standard_normal((len(bias_grid), 3)) * bias_walk_sd * math.sqrt(1.0 / _BIAS_GRID_HZ)
    incr[0] = 0.0
    bias_walk = np.cumsum(incr, axis=0)

    model_kw = dict(path=path, clock0_ns=clock0, step_frequency_hz=f, step_length_m=step_length_m,
                    height_m=height_m, pitch_rad=math.radians(phone_pitch_deg),
                    roll_rad=math.radians(phone_roll_deg), yaw_offset_rad=math.radians(phone_yaw_offset_deg),
                    sway_rad=np.radians(sway), drift=drift, calibration_s=calibration_motion_s,
                    step_length_cv=step_length_cv, step_time_cv=step_time_cv, bounce_scale=bounce_scale,
                    rng_gait=rng_gait, gyro_bias=gyro_bias, bias_grid_s=bias_grid, bias_walk=bias_walk,
                    earth_field_enu_uT=h_earth, zones=zones, field_sources=field_sources)
    if placement == CARRY_HANDHELD:
        model = _WalkModel(**model_kw)
    else:
        from desktop.placements import placement_model  # it builds on this module (a top-level import would cycle)
        model = placement_model(placement, placement_options or {},
                                np.random.default_rng([seed, _PLACEMENT_SEED_TAG]), total_s=total_s, **model_kw)

    def rel(t_ns):
        return (t_ns - clock0) * 1e-9

    # accelerometer
    t_acc = _sample_times_ns(rng_t_acc, rate_hz, timestamp_jitter, total_s, clock0)
    ta = rel(t_acc)
    mat = quat.to_matrix_array(model.quat(ta))
    f_n = model.linear_acc(ta) + np.array([0.0, 0.0, _G])
    acc = _rotate_to_body(mat, f_n) + np.asarray(acc_bias) + acc_noise_m_s2 * rng_n_acc.standard_normal((len(ta), 3))

    # gyroscope
    t_gyro = _sample_times_ns(rng_t_gyro, gyro_rate_hz, timestamp_jitter, total_s, clock0)
    tg = rel(t_gyro)
    gyro = model.body_rate(tg) + model.gyro_bias(tg) + gyro_noise_rad_s * rng_n_gyro.standard_normal((len(tg), 3))

    # magnetometer
    t_mag = _sample_times_ns(rng_t_mag, mag_rate_hz, timestamp_jitter, total_s, clock0)
    tm = rel(t_mag)
    h_n = model.field_n(tm)
    m_b = _rotate_to_body(quat.to_matrix_array(model.quat(tm)), h_n)
    mag_noise = mag_noise_uT * rng_n_mag.standard_normal((len(tm), 3))
    mag_raw = m_b @ soft_iron.T + np.asarray(hard_iron) + mag_noise

    # truth
    def ns(t_s):
        return clock0 + np.round(np.asarray(t_s) * 1e9).astype(np.int64)

    t_steps = model.t_hs[1:]
    xs, ys, hs = model.walker(t_steps)[:3]
    x0, y0 = model.walker(np.array([model.walk_start_s]))[:2]
    x_prev = np.concatenate([x0, xs[:-1]])
    y_prev = np.concatenate([y0, ys[:-1]])
    dx, dy = xs - x_prev, ys - y_prev
    chord = np.hypot(dx, dy)
    step_heading = np.where(chord > 1e-9, np.arctan2(dy, dx), hs)
    # keep the step headings on the same branch as the (unwrapped) path heading
    step_heading = hs + (step_heading - hs + np.pi) % (2.0 * np.pi) - np.pi
    att_t_ns = ns(np.arange(0.0, total_s, 1.0 / truth_rate_hz))
    ta_truth = rel(att_t_ns)
    q_truth = model.quat(ta_truth)
    y_axis = quat.to_matrix_array(q_truth)[:, :, 1]
    dev_heading = np.unwrap(np.arctan2(y_axis[:, 1], y_axis[:, 0]))
    y_steps = quat.to_matrix_array(model.quat(t_steps))[:, :, 1]
    gps_stream, gps_truth = (None, None) if gps is None else _simulate_gps(gps, model, gps_seeds, total_s, origin,
                                                                          origin_alt_m)
    frozen = _readonly
    truth = WalkTruth(
        n_steps=int(path.n_steps),
        step_t_ns=frozen(ns(t_steps)),
        step_east_m=frozen(xs),
        step_north_m=frozen(ys),
        step_length_m=frozen(model.step_lengths),
        step_heading_rad=frozen(step_heading),
        start_east_m=float(path.points[0, 0]),
        start_north_m=float(path.points[0, 1]),
        path_length_m=float(path.path_length_m),
        polyline_length_m=float(path.polyline_length_m),
        walk_start_t_ns=int(ns(walk_start_s)),
        walk_end_t_ns=int(ns(walk_end_s)),
        calibration_start_t_ns=int(clock0),
        calibration_end_t_ns=int(ns(calibration_motion_s)),
        att_t_ns=frozen(att_t_ns),
        att_q_wxyz=frozen(q_truth),
        att_walk_heading_rad=frozen(model.walker(ta_truth)[2]),
        att_device_heading_rad=frozen(dev_heading),
        att_gyro_bias_rad_s=frozen(model.gyro_bias(ta_truth)),
        step_device_heading_rad=frozen(np.arctan2(y_steps[:, 1], y_steps[:, 0])),
        phone_yaw_offset_rad=math.radians(phone_yaw_offset_deg) if placement == CARRY_HANDHELD else math.nan,
        gyro_bias_rad_s=frozen(gyro_bias),
        acc_bias_m_s2=frozen(acc_bias),
        mag_t_ns=frozen(t_mag),
        mag_field_enu_uT=frozen(h_n),
        mag_hard_iron_uT=frozen(hard_iron),
        mag_soft_iron=frozen(soft_iron),
        origin_lat_lon=origin,
        origin_alt_m=origin_alt_m,
        gps=gps_truth,
        _model=model,
        placement=placement,
        side=getattr(model, "side", None),
        placement_info=dict(getattr(model, "info", {})),
    )

    metadata = {
        "simulator": SIMULATOR_VERSION,
        "simulator_module": f"desktop.simulator (pdr {__version__})",
        "waypoints_en_m": [[float(x), float(y)] for x, y in np.asarray(waypoints_en_m, float).reshape(-1, 2)],
        "rate_hz": rate_hz, "gyro_rate_hz": gyro_rate_hz, "mag_rate_hz": mag_rate_hz,
        "timestamp_jitter": timestamp_jitter,
        "step_frequency_hz": f, "step_length_m": step_length_m,
        "step_length_cv": step_length_cv, "step_time_cv": step_time_cv,
        "still_start_s": still_start_s, "still_end_s": still_end_s, "turn_rate_deg_s": float(turn_rate_deg_s),
        "height_m": height_m, "bounce_scale": bounce_scale,
        "gyro_noise_rad_s": float(gyro_noise_rad_s), "gyro_bias_rad_s": list(gyro_bias),
        "gyro_bias_walk_rad_s_sqrt_s": bias_walk_sd,
        "acc_noise_m_s2": float(acc_noise_m_s2), "acc_bias_m_s2": list(acc_bias),
        "mag_noise_uT": float(mag_noise_uT), "mag_hard_iron_uT": list(hard_iron),
        "mag_soft_iron": soft_iron.tolist(), "mag_uncalibrated_stream": mag_uncalibrated_stream,
        "earth_field_enu_uT": list(h_earth),
        "disturbance_zones": [z.as_dict() for z in zones],
        "calibration_motion_s": calibration_motion_s,
        "phone_pitch_deg": phone_pitch_deg, "phone_roll_deg": phone_roll_deg,
        "phone_yaw_offset_deg": phone_yaw_offset_deg,
        "hand_sway_deg": list(sway), "hand_drift_deg_s": list(drift_deg_s),
        "truth_rate_hz": truth_rate_hz, "clock_start_ns": clock0, "seed": seed,
        "truth": {"n_steps": truth.n_steps, "path_length_m": truth.path_length_m,
                  "walk_start_t_ns": truth.walk_start_t_ns, "walk_end_t_ns": truth.walk_end_t_ns,
                  "start_en_m": [truth.start_east_m, truth.start_north_m],
                  "end_en_m": [float(path.end[0]), float(path.end[1])]},
    }
    if weinberg_c is not None:
        metadata["weinberg_c"] = float(weinberg_c)
    if field_sources is not None:  # only then: recordings without it keep their header
        metadata["field_sources"] = field_sources.as_dict()
    if placement != CARRY_HANDHELD:  # only then: hand-held recordings keep their header
        metadata.update(placement=placement, placement_info=dict(model.info))
    if gps is not None:  # only then: recordings without GPS keep their header
        metadata.update(gps=gps.as_dict(), origin_lat_lon=list(origin), origin_alt_m=origin_alt_m)
    streams = {ACC: make_stream(ACC, t_acc, acc), GYRO: make_stream(GYRO, t_gyro, gyro)}
    if mag_uncalibrated_stream is None:
        streams[MAG] = make_stream(MAG, t_mag, mag_raw)
    else:
        streams[MAG] = make_stream(MAG, t_mag, m_b + mag_noise)
        streams[mag_uncalibrated_stream] = Stream(mag_uncalibrated_stream, t_mag, mag_raw, ("x", "y", "z"), "uT",
                                                  "magnetometer, uncalibrated (hard and soft iron included)")
    if gps_stream is not None:
        streams[GPS] = gps_stream
    recording = Recording(streams, device={"model": "simulator"}, metadata=metadata,
                          source=f"simulate_walk(seed={seed})")
    return SimulatedWalk(recording=recording, truth=truth)


#: The demo loop: a 50 m x 30 m rectangle with a dog-leg in its north-east corner (160 m, 6 turns).
DEMO_WAYPOINTS_EN_M = ((0.0, 0.0), (50.0, 0.0), (50.0, 15.0), (35.0, 15.0), (35.0, 30.0), (0.0, 30.0), (0.0, 0.0))

#: The demo's settings besides the waypoints and the seed.
DEMO_WALK_KW = dict(rate_hz=100.0, still_start_s=3.0, still_end_s=3.0, phone_yaw_offset_deg=6.0, phone_pitch_deg=25.0,
                    phone_roll_deg=4.0, hand_drift_deg_s=(0.3, 0.5, 0.5), gyro_bias_rad_s=(0.002, -0.0015, 0.001))


def demo_walk(seed: int = 0) -> SimulatedWalk:
    """The bundled demo: a closed 160 m loop with six turns at 100 Hz, about 2 min 15 s.

    Moderately hard: the phone is held 6 deg to the left of the walking direction, pitched up 25 deg and
    rolled 4 deg, the hand drifts while standing (0.3/0.5/0.5 deg/s RMS), the gyroscope has a true bias of
    (2, -1.5, 1) mrad/s; default sensor noise, step variability and gait; no magnetic disturbance; 3 s
    standing at either end.
    """
    return simulate_walk(DEMO_WAYPOINTS_EN_M, **DEMO_WALK_KW, seed=seed)


# ---------------------------------------------------------------------------
# long outdoor walks


def street_route(length_m: float, *, seed: int, block_m: tuple[float, float] = (40.0, 120.0),
                 straight_prob: float = 0.25, bend_prob: float = 0.2, bend_deg: tuple[float, float] = (10.0, 30.0),
                 start_en_m: tuple[float, float] = (0.0, 0.0), start_heading_deg: float | None = None) -> np.ndarray:
    """Waypoints (n, 2) ENU m of a walk along city streets, ``length_m`` of polyline in all.

    Straight legs along blocks joined by junctions.  A block is uniform in ``block_m``; at the end of a block
    the walker goes straight on with ``straight_prob`` (the leg goes on for another block), else the
    junction is a gentle bend of uniform ``bend_deg`` left or right with ``bend_prob``, else a 90 deg turn
    left or right.  No reversals: no turn is larger than 90 deg, and after two 90 deg turns the same way
    (round a block) the next one goes the other way, so the walk does not circle a block.  The last leg
    ends where ``length_m`` is reached; it absorbs a remainder shorter than half the shortest block, so
    that no leg is a stub.  The first heading is uniform (the street grid's orientation) unless
    ``start_heading_deg`` (CCW from East) is given.  One seed, one route (its own generator, distinct from
    :func:`simulate_walk`'s for the same seed).
    """
    length_m = _positive("length_m", length_m)
    lo, hi = (_positive("block_m", v) for v in block_m)
    b_lo, b_hi = (_non_negative("bend_deg", v) for v in bend_deg)
    if hi < lo or b_hi < b_lo or b_hi >= 90.0:
        raise ValueError("block_m and bend_deg must be (low, high) with low <= high, bends below 90 deg")
    for name, p in (("straight_prob", straight_prob), ("bend_prob", bend_prob)):
        if not 0.0 <= float(p) < 1.0:
            raise ValueError(f"{name} must be in [0, 1), got {p!r}")
    rng = np.random.default_rng([operator.index(seed), _ROUTE_SEED_TAG])
    heading = rng.uniform(0.0, 2.0 * np.pi) if start_heading_deg is None else math.radians(
        _finite("start_heading_deg", start_heading_deg))
    points = [np.array([_finite("start_en_m", v) for v in start_en_m])]
    left, last_turns = length_m, []
    while left > 0.0:
        leg = rng.uniform(lo, hi)
        while rng.random() < straight_prob:
            leg += rng.uniform(lo, hi)
        if left - leg < 0.5 * lo:
            leg = left
        points.append(points[-1] + leg * np.array([math.cos(heading), math.sin(heading)]))
        left -= leg
        if rng.random() < bend_prob:
            heading += math.radians(rng.uniform(b_lo, b_hi)) * rng.choice((-1.0, 1.0))
        else:
            side = float(rng.choice((-1.0, 1.0)))
            if last_turns[-2:] == [side, side]:
                side = -side
            last_turns.append(side)
            heading += side * 0.5 * math.pi
    return np.array(points)


#: outdoor_walk's per-seed walker and phone: uniform ranges
OUTDOOR_HEIGHT_M = (1.55, 1.95)
OUTDOOR_CADENCE_HZ = (1.65, 2.0)
OUTDOOR_YAW_OFFSET_DEG = (-8.0, 8.0)
OUTDOOR_PITCH_DEG = (15.0, 40.0)
#: per-axis standard deviation of the residual hard iron left by the phone's own calibration (uT)
OUTDOOR_HARD_IRON_SD_UT = 1.0
_ROUTE_SEED_TAG = 0x5743  # street_route's generator: [seed, tag], distinct from simulate_walk's SeedSequence(seed)
_OUTDOOR_SEED_TAG = 0x4F57  # outdoor_walk's walker draws
_PLACEMENT_SEED_TAG = 0x504C  # the placements' draws (desktop.placements): [seed, tag]
_RESIDUAL_IRON_SEED_TAG = 0x4849  # residual_hard_iron_uT's draw: [seed, tag]

#: per-axis standard deviation (uT) of the hard iron a phone's own (OS) calibration leaves in its calibrated
#: magnetometer, MEASURED on the tuning split (``python -m benchmarks.residual_iron``, issue #27): sphere fits of
#: Android's calibrated readings over each IPIN 2023 tuning file's waving (routes 01, 02, 21, 22; 16 files, two
#: Samsung phones) give |b| median 0.85 uT (quartiles 0.53-1.26), 0.59 uT per axis with the fits' own noise removed;
#: a cross-check, Android's own estimate on the Microsoft 2020 F3 tuning traces (one phone) is revised by about
#: 1.1 uT per horizontal axis between traces.  Weak evidence: 16 files at two sites of one building, the fit moved
#: by the building's field where the hand moves the phone, and the residual at the end of the waving only.
#: (``OUTDOOR_HARD_IRON_SD_UT`` above, 1.0, was chosen before this measurement and is left as the GPS benchmarks
#: declared it.)
RESIDUAL_HARD_IRON_SD_UT = 0.6


def residual_hard_iron_uT(seed: int, sd_uT: float = RESIDUAL_HARD_IRON_SD_UT) -> tuple[float, float, float]:
    """A residual hard iron (uT, device frame) for ``simulate_walk(mag_hard_iron_uT=...)``: each axis normal with
    standard deviation ``sd_uT`` (default: the measured :data:`RESIDUAL_HARD_IRON_SD_UT`), drawn from a generator of
    its own (``[seed, tag]``), so the walk's other draws do not change with it."""
    if not (math.isfinite(sd_uT) and sd_uT >= 0.0):
        raise ValueError(f"sd_uT must be finite and non-negative, got {sd_uT!r}")
    rng = np.random.default_rng([int(seed), _RESIDUAL_IRON_SEED_TAG])
    return tuple(float(x) for x in sd_uT * rng.standard_normal(3))


def outdoor_walk(seed: int, minutes: float = 15.0, *, year: float = 2025.5, **kw) -> SimulatedWalk:
    """A ``minutes`` long walk along city streets (:func:`street_route`) with GPS, for GPS fusion tests.

    Per seed (a generator of its own) the walker is drawn: height uniform in ``OUTDOOR_HEIGHT_M``, cadence
    in ``OUTDOOR_CADENCE_HZ`` (step length from the walk ratio), the phone's yaw offset in
    ``OUTDOOR_YAW_OFFSET_DEG`` and its pitch in ``OUTDOOR_PITCH_DEG``, and a residual hard iron of
    ``OUTDOOR_HARD_IRON_SD_UT`` per axis (what an OS calibration leaves; the magnetometer is otherwise
    clean: outdoors there are no indoor disturbance zones).  The Earth's field is the World Magnetic
    Model's at the origin (:func:`core.geodesy.magnetic_field`, decimal ``year``), so magnetic north is
    off true north (+y) by the site's declination (about +10 deg in Helsinki in 2025): a compass heading
    needs the declination to meet the GPS course.  The GPS is :class:`GpsModel` () at 1 Hz.  Sensors,
    gait variability and hand drift are :func:`simulate_walk`'s defaults at 100 Hz, 2 s standing at
    either end.  The route is as long as the walker's cruise speed covers in the walking time (corners
    at 90 deg/s cost almost nothing), so the recording lasts ``minutes`` to within a few seconds.

    Any keyword of :func:`simulate_walk` overrides these (e.g. ``gps=GpsModel(cold_start_fixes=10)``,
    ``height_m``, ``origin_lat_lon``); the choices made are in ``metadata["outdoor_walk"]``.
    """
    minutes = _positive("minutes", minutes)
    rng = np.random.default_rng([operator.index(seed), _OUTDOOR_SEED_TAG])
    params = dict(height_m=rng.uniform(*OUTDOOR_HEIGHT_M), step_frequency_hz=rng.uniform(*OUTDOOR_CADENCE_HZ),
                  phone_yaw_offset_deg=rng.uniform(*OUTDOOR_YAW_OFFSET_DEG),
                  phone_pitch_deg=rng.uniform(*OUTDOOR_PITCH_DEG),
                  mag_hard_iron_uT=tuple(OUTDOOR_HARD_IRON_SD_UT * rng.standard_normal(3)),
                  gps=GpsModel(), origin_lat_lon=DEFAULT_ORIGIN_LAT_LON, origin_alt_m=DEFAULT_ORIGIN_ALT_M,
                  rate_hz=100.0, still_start_s=2.0, still_end_s=2.0)
    params.update(kw)
    if "earth_field_enu_uT" not in kw:
        lat, lon = params["origin_lat_lon"]
        dec, inc, total = magnetic_field(lat, lon, params["origin_alt_m"], year)
        params["earth_field_enu_uT"] = (total * math.cos(inc) * math.sin(dec), total * math.cos(inc) * math.cos(dec),
                                        -total * math.sin(inc))
    step_m = params.get("step_length_m") or default_step_length_m(params["height_m"], params["step_frequency_hz"])
    walking_s = max(minutes * 60.0 - params["still_start_s"] - params["still_end_s"], 1.0)
    route = street_route(params["step_frequency_hz"] * step_m * walking_s, seed=seed)
    walk = simulate_walk(route, seed=seed, **params)
    walk.recording.metadata["outdoor_walk"] = {
        "seed": operator.index(seed), "minutes": minutes, "year": float(year),
        "route_length_m": float(np.hypot(*np.diff(route, axis=0).T).sum()),
        "declination_deg": math.degrees(math.atan2(params["earth_field_enu_uT"][0], params["earth_field_enu_uT"][1])),
    }
    return walk


def outdoor_site(recording: Recording) -> tuple[float, float, float, int]:
    """Where and when an :func:`outdoor_walk` was walked: ``(lat_deg, lon_deg, alt_m, unix_ns)``, for
    :meth:`core.pdr.pipeline.Pipeline.set_site` -- what a live app knows from its first GPS fix (a phone has
    a date; the simulated recording has only the model's decimal year, whose WMM field it was given).

    Outdoors the site's field is given and the attitude filter drops the field's heading offset, a state
    for a building's bent field (issue #27): a benchmark that runs an outdoor walk without it runs the
    indoor filter (issue #26: ``gnss_eval``'s simulated 5-minute outages, tuning seeds 0-19, 2.12 % with the
    offset state against 1.90 % before it was turned on).
    """
    meta = recording.metadata
    if "outdoor_walk" not in meta:
        raise ValueError("outdoor_site needs a recording made by outdoor_walk (its metadata has no 'outdoor_walk')")
    year = float(meta["outdoor_walk"]["year"])
    y = int(year)
    a = _dt.datetime(y, 1, 1, tzinfo=_dt.timezone.utc)
    b = _dt.datetime(y + 1, 1, 1, tzinfo=_dt.timezone.utc)
    unix_ns = int((a + (year - y) * (b - a)).timestamp() * 1e9)
    lat, lon = meta["origin_lat_lon"]
    return float(lat), float(lon), float(meta["origin_alt_m"]), unix_ns


# ---------------------------------------------------------------------------------------------------------
# barometer


@dataclass(frozen=True)
class BarometerModel:
    """A phone barometer in a building and in the weather (units in the names).

    Pressure from altitude by the hypsometric equation of an isothermal layer,
    ``p = p0 exp(-g M h / (R T))`` with the air's temperature ``temperature_c`` (not the standard
    atmosphere's polynomial that :mod:`core.floors` inverts: the two differ by about 0.5 % of the height
    at 15 C, as a real phone's would), plus the weather (a linear trend of ``drift_hpa_per_h`` and a slow
    swing), white noise, a Gauss-Markov wander of the sensor, optional door/ventilation transients
    (a pressure step of ``transient_hpa`` lasting ``transient_s``, ``transients_per_h`` times an hour on
    average) and the sensor's resolution ``quantum_hpa``.
    """

    p0_hpa: float = 1013.25
    temperature_c: float = 15.0
    drift_hpa_per_h: float = 3.0
    swing_hpa: float = 0.3
    swing_period_s: float = 1800.0
    noise_hpa: float = 0.02
    wander_hpa: float = 0.02
    wander_tau_s: float = 60.0
    transient_hpa: float = 0.0
    transient_s: float = 3.0
    transients_per_h: float = 0.0
    quantum_hpa: float = 0.0


def floor_profile(t_s, segments) -> np.ndarray:
    """Altitude (m) at times ``t_s`` of a walk made of ``segments`` [(duration_s, climb_m[, shape]), ...]: each
    climbs ``climb_m`` over its duration (0 = level), level after.  ``shape`` "smooth" (default: a lift's
    start and stop, cosine speed) or "linear" (a flight of stairs: constant speed)."""
    t = np.asarray(t_s, dtype=float)
    h = np.zeros_like(t)
    t0, base = 0.0, 0.0
    for seg in segments:
        duration, climb = seg[0], seg[1]
        shape = seg[2] if len(seg) > 2 else "smooth"
        u = np.clip((t - t0) / duration, 0.0, 1.0) if duration > 0 else (t >= t0).astype(float)
        f = u if shape == "linear" else u - np.sin(2 * math.pi * u) / (2 * math.pi)
        h = np.where(t >= t0, base + climb * f, h)
        t0 += duration
        base += climb
    return h


def simulate_pressure(t_ns, altitude_m, model: BarometerModel | None = None, *, seed: int = 0) -> Stream:
    """A ``pressure`` stream (hPa) at times ``t_ns`` for the true altitudes ``altitude_m`` (see :class:`BarometerModel`)."""
    m = model or BarometerModel()
    rng = np.random.default_rng(seed)
    t_ns = np.asarray(t_ns, dtype=np.int64)
    t = (t_ns - t_ns[0]) * 1e-9
    h = np.asarray(altitude_m, dtype=float)
    molar_mass, r_gas = 0.0289644, 8.31446  # kg/mol, J/(mol K)
    p = m.p0_hpa * np.exp(-STANDARD_GRAVITY_M_S2 * molar_mass * h / (r_gas * (m.temperature_c + 273.15)))
    p = p + m.drift_hpa_per_h * t / 3600.0 + m.swing_hpa * np.sin(2 * math.pi * t / m.swing_period_s + rng.uniform(0, 6.3))
    p = p + rng.normal(0.0, m.noise_hpa, len(t)) + _gauss_markov(rng, t, np.array([m.wander_hpa]), m.wander_tau_s)[:, 0]
    if m.transients_per_h > 0 and len(t):
        n = rng.poisson(m.transients_per_h * t[-1] / 3600.0)
        for start in rng.uniform(0.0, t[-1], n):
            p = p + np.where((t >= start) & (t < start + m.transient_s), m.transient_hpa * rng.choice((-1, 1)), 0.0)
    if m.quantum_hpa > 0:
        p = np.round(p / m.quantum_hpa) * m.quantum_hpa
    return make_stream("pressure", t_ns, p.reshape(-1, 1), columns=["p_hpa"], unit="hPa",
                       note="simulated barometer (desktop.simulator.simulate_pressure)")
