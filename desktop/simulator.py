"""A hand-held smartphone walk simulator with exact ground truth (numpy only).

:func:`simulate_walk` turns a polyline of waypoints into a
:class:`~core.recording.Recording` (streams ``acc``, ``gyro``, ``mag``, each on
its own jittered clock) plus a :class:`WalkTruth` (heel strikes, positions,
step lengths, headings, dense attitude).  :func:`demo_walk` is the bundled
demo.  All quantities follow the conventions of :mod:`core` (ENU, Android
device frame, quaternion ``(w, x, y, z)`` body -> ENU, ``t_ns`` int64, SI, uT).

The model
=========
Everything is a closed-form function of time ``t``; each sensor is sampled
by evaluating those functions at its own (integer-nanosecond) sample times,
so every sensor is consistent with the truth by construction.

Timeline
    ``[calibration_motion_s]`` (optional phone waving while standing) ->
    ``[still_start_s]`` standing, phone in the walking pose -> walking ->
    ``[still_end_s]`` standing.

Walker (the truth path)
    The walker follows the polyline at the cruise speed
    ``v = step_frequency_hz * step_length_m``.  Each corner is rounded by a
    circular arc walked at exactly ``turn_rate_deg_s``, so its radius is
    ``r = v / turn_rate`` and it cuts ``r (2 tan(|turn|/2) - |turn|)`` off the
    polyline (0.34 m for a 90 deg corner with the defaults).  A corner may use
    half of each adjacent segment; where the full-speed arc does not fit,
    the walker slows down to the speed whose arc fits, down to turning on
    the spot (U-turn).  Speed changes are cosine ramps that last one step
    period for a change of ``v`` (shorter changes proportionally, so the
    peak acceleration is always ``pi v f / 2``, 3.6 m/s^2 with the
    defaults); a forward and a backward pass make every corner speed
    reachable, and segments too short to reach ``v`` peak lower.  Walking
    starts and ends at rest.  Position and speed are continuous; heading
    rate and path acceleration jump at the ends of arcs.

    The walk lasts an exact whole number ``n_steps`` of step periods: the
    plan is stretched in time by a factor within ``1 +- 0.5 / n_steps`` (speed
    and turn rate scaled by its inverse).  Heel strike ``k = 1..n_steps`` is
    at ``walk_start + k / step_frequency_hz``; the first one ends the first
    (half-length, accelerating) step, the last one coincides with the end of
    the walk, so the position after the last step is the last waypoint.
    ``n_steps = round(path_length / step_length + 1)`` when the walker never
    has to slow down for a corner.

Phone attitude (body -> ENU)
    ``R = Rz(yaw) Rx(pitch) Ry(roll)`` (Android's ZXY order: yaw about ENU up,
    then pitch about the device x axis, then roll about the device y axis)
    with

    * ``yaw = heading_s - 90 deg + sway_yaw w sin(pi phi + 0.3) + wander_yaw(t)``,
    * ``pitch = phone_pitch_deg + sway_pitch w sin(2 pi phi + 1) + wander_pitch(t)``,
    * ``roll = phone_roll_deg + sway_roll w sin(pi phi - 0.5) + wander_roll(t)``,

    where ``phi`` is the step phase (heel strike ``k`` at ``phi = k``), ``w``
    the walking speed averaged over the last step divided by ``v`` and
    ``heading_s`` the walking heading averaged over 0.3 s (equal to it on
    straight parts; it gives the hand a continuous turn rate that ramps in
    and out over 0.3 s at the ends of each arc).  So the device y axis
    points along the walking direction, tilted up by the pitch; its
    horizontal projection is exactly ``heading_s + sway + wander_yaw``, and
    its average over a stride is the walking heading up to the yaw wander
    (bounded by ``hand_wander_deg[0]``, 0.6 deg by default).  The wander is
    a sum of three slow sinusoids (0.03-0.15 Hz) per axis whose peak is
    bounded by ``hand_wander_deg``; it is present while standing too.  The
    calibration motion multiplies the pose on the right by
    ``Rz(a) Rx(b) Ry(c)`` with ``a, b, c`` up to +-90 deg (0.11, 0.30 and
    0.15 Hz: a tumbling figure-8), tapered in and out over 1.5 s.

Phone position and linear acceleration
    phone = path point + (0, 0, 0.75 height) + ``Rz(heading_s) gait(t)`` (+ a
    few cm of hand motion during calibration).  ``gait`` is a periodic hand
    displacement in the walking frame (forward, left, up) given by its
    Fourier series in the step phase (48 harmonics of the stride frequency)
    times an amplitude ``E``: the vertical acceleration is an asymmetric
    step-frequency wave with two harmonics, a 4 % left/right difference and
    a sharp heel-strike bump (~14 ms wide, just after each heel strike);
    fore-aft is a braking/propulsion wave at the step frequency (0.4 x
    vertical); lateral is a stride-frequency sway (0.2 x vertical).  ``E``
    follows the step length ``l = (speed averaged over the last step) / f``
    -- at a heel strike exactly the length of the step just completed -- so
    that Weinberg's model holds: the steady-state ``A_max - A_min`` (per
    step, peak minus the lowest value since the previous peak) of the
    acceleration norm after a Butterworth low-pass (order
    ``weinberg_filter_order``, cut-off ``weinberg_cutoff_hz``) equals
    ``(l / weinberg_c) ** 4``.  With the defaults (0.7 m, 1.8 Hz, C = 0.47,
    2nd order, 3 Hz) that is 4.97 m/s^2 and the raw norm swings between
    about 7.8 and 14 m/s^2.  Consequences: ``E`` is zero at rest, grows over
    the first step and fades out over one step after the walker stops; the
    first and last steps (half steps, ``l / 2``) have 1/16 of the gait
    amplitude, their norm peaks come mostly from the walker's own start and
    stop acceleration (``core.pdr.steps`` still detects every step of the demo,
    with ``A_max - A_min`` of about 0.8 and 2 m/s^2 for those two).  The
    acceleration of the phone in ENU is the exact second derivative of this
    position (central difference over +-0.5 ms, error < 1e-4 m/s^2),
    including the walker's own acceleration along the path and the
    centripetal acceleration in corners.

Sensors
    * accelerometer: ``R^T (a_n + (0, 0, g)) + acc_bias + noise``, g = 9.80665;
    * gyroscope: ``vee(log(R(t - d)^T R(t + d))) / 2d`` with d = 10 us (the
      exact body rate to ~1e-10 rad/s) ``+ gyro_bias + noise``;
    * magnetometer: ``R^T (h_earth + sum of zones) + hard_iron + noise``;
      a :class:`DisturbanceZone` adds its field with the taper
      ``(1 + cos(pi d / radius)) / 2`` inside its radius and nothing outside.

    Noise is white Gaussian with the given per-sample standard deviation.
    Each stream starts at a random phase within its first interval; each
    interval is ``(1 + timestamp_jitter * N(0, 1)) / rate`` (clipped at 10 %
    of the nominal interval); timestamps are integer nanoseconds on a clock
    starting at ``clock_start_ns`` (10**12 by default, like
    ``elapsedRealtimeNanos``) and the physics is evaluated at exactly those
    instants.  All randomness comes from ``numpy.random.SeedSequence(seed)``
    (one child generator per purpose, so the same seed gives the same
    recording and e.g. changing a noise level does not move the timestamps).
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from core import __version__
from core import quaternion as quat
from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2, wrap_angle
from core.recording import Recording, make_stream

__all__ = ["simulate_walk", "demo_walk", "SimulatedWalk", "WalkTruth", "DisturbanceZone", "SIMULATOR_VERSION"]

#: Version of the simulation model (stored in ``metadata["simulator"]``); bumped when the same
#: parameters and seed no longer give the same recording.
SIMULATOR_VERSION = "1"

#: Default start of the simulated sensor clock (ns), large like Android's ``elapsedRealtimeNanos``.
DEFAULT_CLOCK_START_NS = 10**12

_G = STANDARD_GRAVITY_M_S2
_GYRO_DIFF_S = 1e-5  # half-width of the central difference for the body rate
_ACC_DIFF_S = 5e-4  # half-width of the second difference for the linear acceleration
_HAND_HEIGHT_RATIO = 0.75  # phone height above the ground / body height (in front of the chest)
_CAL_TAPER_S = 1.5  # taper of the calibration motion at either end (s)
_TURN_SMOOTH_S = 0.3  # the hand's yaw follows the heading averaged over this window (continuous turn rate)


# ---------------------------------------------------------------------------
# public result types


@dataclass(frozen=True)
class DisturbanceZone:
    """A local magnetic disturbance (e.g. a steel pillar) added to the Earth field.

    Inside ``radius_m`` of ``center_en_m`` (horizontal distance) the field
    ``field_enu_uT`` is added with the weight ``(1 + cos(pi d / radius)) / 2``
    (full at the centre, zero with zero slope at the edge); outside nothing.
    """

    center_en_m: tuple[float, float]
    radius_m: float
    field_enu_uT: tuple[float, float, float]

    def __post_init__(self):
        c = tuple(float(x) for x in self.center_en_m)
        f = tuple(float(x) for x in self.field_enu_uT)
        if len(c) != 2 or len(f) != 3 or not all(map(math.isfinite, c + f)):
            raise ValueError("DisturbanceZone needs center_en_m=(east, north) and field_enu_uT=(e, n, u), finite")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"DisturbanceZone radius_m must be positive, got {self.radius_m}")
        object.__setattr__(self, "center_en_m", c)
        object.__setattr__(self, "field_enu_uT", f)
        object.__setattr__(self, "radius_m", float(self.radius_m))

    def field_at(self, east_m, north_m) -> np.ndarray:
        """The added field (n, 3) in ENU (uT) at horizontal positions ``east_m``, ``north_m`` (n,)."""
        d = np.hypot(np.asarray(east_m, float) - self.center_en_m[0], np.asarray(north_m, float) - self.center_en_m[1])
        w = np.where(d < self.radius_m, 0.5 * (1.0 + np.cos(np.pi * np.minimum(d / self.radius_m, 1.0))), 0.0)
        return w[..., None] * np.asarray(self.field_enu_uT)

    def as_dict(self) -> dict:
        return {"center_en_m": list(self.center_en_m), "radius_m": self.radius_m,
                "field_enu_uT": list(self.field_enu_uT)}


@dataclass(frozen=True, eq=False)
class WalkTruth:
    """Exact ground truth of a simulated walk (times on the recording's sensor clock).

    Step ``k`` (0-based here) ends with the heel strike at ``step_t_ns[k]``;
    heel strikes are exactly ``1 / step_frequency_hz`` apart, the first one
    step period after ``walk_start_t_ns`` and the last one at
    ``walk_end_t_ns``.  Positions are the walker's (stride-averaged phone)
    position in ENU metres.
    """

    n_steps: int  #: number of steps = (walk_end - walk_start) * step_frequency, an exact integer
    step_t_ns: np.ndarray  #: (n,) int64 heel-strike times
    step_east_m: np.ndarray  #: (n,) East position after each step (m)
    step_north_m: np.ndarray  #: (n,) North position after each step (m)
    step_length_m: np.ndarray  #: (n,) distance walked along the path during each step (m)
    step_heading_rad: np.ndarray  #: (n,) direction of each step's displacement (speed-weighted mean heading), CCW from East
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
    _model: "_WalkModel" = field(repr=False)

    def _t(self, t_ns) -> np.ndarray:
        return (np.asarray(t_ns, dtype=np.int64) - self._model.clock0_ns) * 1e-9

    def heading_at(self, t_ns):
        """Walking heading (rad, CCW from East, unwrapped) at ``t_ns`` (scalar or array): the direction of
        motion of the path; while standing, the direction the walker faces."""
        h = self._model.path.state(np.atleast_1d(self._t(t_ns)))[2]
        return float(h[0]) if np.ndim(t_ns) == 0 else h

    def position_at(self, t_ns) -> np.ndarray:
        """Walker position ``(east_m, north_m)`` at ``t_ns``: shape (2,) for a scalar, (n, 2) for an array."""
        x, y = self._model.path.state(np.atleast_1d(self._t(t_ns)))[:2]
        p = np.stack([x, y], axis=-1)
        return p[0] if np.ndim(t_ns) == 0 else p

    def attitude_at(self, t_ns) -> np.ndarray:
        """Exact phone attitude quaternion ``(w, x, y, z)`` body -> ENU at ``t_ns``: (4,) or (n, 4)."""
        q = self._model.quat(np.atleast_1d(self._t(t_ns)))
        return q[0] if np.ndim(t_ns) == 0 else q


@dataclass(frozen=True, eq=False)
class SimulatedWalk:
    """Result of :func:`simulate_walk`: the sensor recording and its ground truth."""

    recording: Recording
    truth: WalkTruth


# ---------------------------------------------------------------------------
# rotation helpers (private; quaternions (w, x, y, z), arrays (..., 4))


def _rotate_to_body(mat_nb: np.ndarray, v_n: np.ndarray) -> np.ndarray:
    """``R^T v`` for stacks of matrices (n, 3, 3) and vectors (n, 3)."""
    return np.einsum("nji,nj->ni", mat_nb, v_n)


# ---------------------------------------------------------------------------
# gait waveform: hand acceleration in the walking frame over one stride (two steps)

_GAIT_HARMONICS = 48  # harmonics of the stride frequency kept (24 of the step frequency)
_GAIT_GRID = 1024  # samples per stride for the Fourier analysis


def _gait_acc_shape(phi: np.ndarray) -> np.ndarray:
    """Hand acceleration (n, 3) = (forward, left, up) per unit vertical amplitude at step phase ``phi``.

    Heel strikes are at integer ``phi`` (left foot at even, right at odd).
    """
    w = 2.0 * np.pi * phi
    sigma, centre = 0.025, 0.04  # heel-strike transient: width and delay, in steps
    bump = sum(np.exp(-0.5 * ((phi - centre - j) / sigma) ** 2) for j in range(-1, 4))
    bump = 0.45 * (bump - sigma * math.sqrt(2.0 * math.pi))  # zero mean over a step
    up = np.cos(w) + 0.30 * np.cos(2 * w - 0.7) + 0.08 * np.cos(3 * w - 1.4) + 0.04 * np.cos(0.5 * w) + bump
    fwd = 0.40 * (-np.sin(w - 0.3) + 0.25 * np.sin(2 * w + 0.5))
    left = 0.20 * (np.sin(0.5 * w) + 0.15 * np.sin(1.5 * w))
    return np.stack([fwd, left, up], axis=-1)


def _gait_coefficients() -> np.ndarray:
    """Complex Fourier coefficients (3, M) of the gait acceleration in harmonics ``m = 1..M`` of the stride
    frequency: ``a(phi) = Re(sum_m c_m exp(i pi m phi))``."""
    phi = 2.0 * np.arange(_GAIT_GRID) / _GAIT_GRID
    spec = np.fft.rfft(_gait_acc_shape(phi), axis=0) / _GAIT_GRID
    return (2.0 * spec[1:_GAIT_HARMONICS + 1]).T


_GAIT_ACC_COEF = _gait_coefficients()
_GAIT_M = np.arange(1, _GAIT_HARMONICS + 1)


def _gait_series(phi: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Evaluate ``Re(sum_m coef[:, m] exp(i pi m phi))`` -> (n, 3)."""
    base = np.exp(1j * np.pi * np.mod(phi, 2.0))  # the series has period 2 in phi
    powers = np.cumprod(np.broadcast_to(base[:, None], (len(base), _GAIT_HARMONICS)), axis=1)  # exp(i pi m phi)
    return (powers @ coef.T).real


def _butterworth_response(freq_hz: np.ndarray, cutoff_hz: float, order: int) -> np.ndarray:
    """Complex response of the analogue Butterworth low-pass of ``order`` at ``freq_hz``."""
    k = np.arange(1, order + 1)
    poles = np.exp(1j * np.pi * (2 * k + order - 1) / (2 * order))
    s = 1j * np.asarray(freq_hz, float)[:, None] / cutoff_hz
    return 1.0 / np.prod(s - poles[None, :], axis=1)


def _weinberg_table(step_frequency_hz: float, cutoff_hz: float, order: int, max_pp: float):
    """Steady-state per-step ``A_max - A_min`` of the low-passed acceleration norm as a function of the gait
    amplitude ``E``: returns increasing arrays ``(pp, E)`` for interpolation."""
    phi = 2.0 * np.arange(_GAIT_GRID) / _GAIT_GRID
    a_unit = _gait_series(phi, _GAIT_ACC_COEF)
    freq = np.arange(_GAIT_GRID // 2 + 1) * step_frequency_hz / 2.0  # stride period = 2 / f
    h = _butterworth_response(freq, cutoff_hz, order)

    def pp_of(e: float) -> float:
        norm = np.linalg.norm(e * a_unit + np.array([0.0, 0.0, _G]), axis=1)
        y = np.fft.irfft(np.fft.rfft(norm) * h, n=_GAIT_GRID)
        y = np.roll(y, -int(np.argmax(y)))  # the higher peak at index 0
        j2 = _GAIT_GRID // 4 + int(np.argmax(y[_GAIT_GRID // 4: 3 * _GAIT_GRID // 4]))  # the other step's peak
        pp1 = y[j2] - y[:j2 + 1].min()
        pp2 = y[0] - y[j2:].min()
        return 0.5 * (pp1 + pp2)

    slope = pp_of(1.0)
    e_max = 2.0 * max_pp / slope + 1.0
    es = np.linspace(0.0, e_max, 121)
    pps = np.array([pp_of(e) for e in es])
    if np.any(np.diff(pps) <= 0):  # pragma: no cover - the shape is fixed; guards edits of it
        raise RuntimeError("gait amplitude table is not monotonic")
    return pps, es


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
    """Closed-form phone position (ENU, m) and attitude (body -> ENU) as functions of simulation time (s)."""

    def __init__(self, *, path: _Path, clock0_ns: int, step_frequency_hz: float, height_m: float,
                 pitch_rad: float, roll_rad: float, sway_rad: Sequence[float], wander: np.ndarray,
                 calibration_s: float, weinberg_c: float, weinberg_cutoff_hz: float, weinberg_order: int):
        self.path = path
        self.clock0_ns = int(clock0_ns)
        self.f = float(step_frequency_hz)
        self.hand_height_m = _HAND_HEIGHT_RATIO * float(height_m)
        self.pitch, self.roll = float(pitch_rad), float(roll_rad)
        self.sway = np.asarray(sway_rad, float)
        self.wander = wander  # (3 axes, 3 terms, [amplitude rad, frequency Hz, phase rad])
        self.cal_s = float(calibration_s)
        self.weinberg_c = float(weinberg_c)
        # gait displacement coefficients: a / (i pi m f)^2 -> -a / (pi m f)^2
        self.disp_coef = -_GAIT_ACC_COEF / (np.pi * _GAIT_M * self.f) ** 2
        max_len = path.cruise_speed_m_s / self.f * 1.05
        self.pp_table, self.e_table = _weinberg_table(self.f, weinberg_cutoff_hz, weinberg_order,
                                                      (max_len / self.weinberg_c) ** 4)

    # -- helpers -------------------------------------------------------------
    def gait_amplitude(self, speed: np.ndarray) -> np.ndarray:
        """Gait amplitude ``E`` (m/s^2 per unit of :func:`_gait_acc_shape`) for a walking speed: the one whose
        low-passed acceleration norm gives ``A_max - A_min = (speed / f / C) ** 4`` (Weinberg)."""
        target = (speed / self.f / self.weinberg_c) ** 4
        slope = (self.e_table[-1] - self.e_table[-2]) / (self.pp_table[-1] - self.pp_table[-2])
        return np.where(target <= self.pp_table[-1], np.interp(target, self.pp_table, self.e_table),
                        self.e_table[-1] + slope * (target - self.pp_table[-1]))

    def smooth_speed(self, t: np.ndarray) -> np.ndarray:
        """Walking speed averaged over the last step period (m/s).

        The gait amplitude and the hand sway follow it, so they change smoothly even where the speed changes
        quickly; at a heel strike it is exactly the length of the step just completed times the cadence, and
        it is zero until walking starts and fades out over one step after the walker stops.
        """
        w = 1.0 / self.f
        return (self.path.state(t)[4] - self.path.state(t - w)[4]) / w

    def phase(self, t: np.ndarray) -> np.ndarray:
        """Step phase: heel strike ``k`` at phase ``k``."""
        return (t - self.path.t_start_s) * self.f

    def _cal_window(self, t: np.ndarray) -> np.ndarray:
        c = self.cal_s
        if c <= 0:
            return np.zeros_like(t)
        taper = min(_CAL_TAPER_S, 0.5 * c)
        up = np.clip(t / taper, 0.0, 1.0)
        down = np.clip((c - t) / taper, 0.0, 1.0)
        return 0.25 * (1.0 - np.cos(np.pi * up)) * (1.0 - np.cos(np.pi * down))

    def _wander(self, t: np.ndarray, axis: int) -> np.ndarray:
        amp, freq, ph = self.wander[axis].T
        return np.sin(2.0 * np.pi * np.outer(t, freq) + ph) @ amp

    # -- the model -------------------------------------------------------------
    def position(self, t: np.ndarray) -> np.ndarray:
        """Phone position (n, 3) in ENU (m)."""
        x, y = self.path.state(t)[:2]
        h = self.path.smooth_heading(t, _TURN_SMOOTH_S)
        e = self.gait_amplitude(self.smooth_speed(t))
        d = _gait_series(self.phase(t), self.disp_coef) * e[:, None]  # (fwd, left, up)
        c, s = np.cos(h), np.sin(h)
        pos = np.stack([x + c * d[:, 0] - s * d[:, 1], y + s * d[:, 0] + c * d[:, 1],
                        self.hand_height_m + d[:, 2]], axis=1)
        if self.cal_s > 0:
            w = self._cal_window(t)
            pos += w[:, None] * np.stack([0.06 * np.sin(2 * np.pi * 0.30 * t), 0.04 * np.sin(2 * np.pi * 0.60 * t),
                                          0.04 * np.sin(2 * np.pi * 0.45 * t)], axis=1)
        return pos

    def quat(self, t: np.ndarray) -> np.ndarray:
        """Phone attitude quaternions (n, 4), body -> ENU."""
        h = self.path.smooth_heading(t, _TURN_SMOOTH_S)
        phi = self.phase(t)
        k = self.smooth_speed(t) / self.path.cruise_speed_m_s  # sway follows the walking speed
        yaw = h - 0.5 * np.pi + k * self.sway[0] * np.sin(np.pi * phi + 0.3) + self._wander(t, 0)
        pitch = self.pitch + k * self.sway[1] * np.sin(2.0 * np.pi * phi + 1.0) + self._wander(t, 1)
        roll = self.roll + k * self.sway[2] * np.sin(np.pi * phi - 0.5) + self._wander(t, 2)
        q = quat.multiply_array(quat.multiply_array(quat.about_axis_array(2, yaw), quat.about_axis_array(0, pitch)), quat.about_axis_array(1, roll))
        if self.cal_s > 0:
            w = self._cal_window(t) * (0.5 * np.pi)
            qc = quat.multiply_array(quat.multiply_array(quat.about_axis_array(2, w * np.sin(2 * np.pi * 0.11 * t)),
                             quat.about_axis_array(0, w * np.sin(2 * np.pi * 0.30 * t + 0.6))),
                       quat.about_axis_array(1, w * np.sin(2 * np.pi * 0.15 * t + 1.3)))
            q = quat.multiply_array(q, qc)
        return q

    def body_rate(self, t: np.ndarray) -> np.ndarray:
        """Exact body angular rate (n, 3) rad/s: ``vee(log(R(t-d)^T R(t+d))) / 2d``."""
        d = _GYRO_DIFF_S
        q_a, q_b = self.quat(t - d), self.quat(t + d)
        q_a[:, 1:] *= -1.0  # conjugate
        return quat.to_rotation_vector_array(quat.multiply_array(q_a, q_b)) / (2.0 * d)

    def linear_acc(self, t: np.ndarray) -> np.ndarray:
        """Phone acceleration (n, 3) in ENU (m/s^2): second central difference of :meth:`position`."""
        d = _ACC_DIFF_S
        n = len(t)
        p = self.position(np.concatenate([t - d, t, t + d]))
        return (p[:n] - 2.0 * p[n:2 * n] + p[2 * n:]) / (d * d)


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


def _readonly(a) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


def _vec3(name: str, value) -> tuple[float, float, float]:
    v = tuple(float(x) for x in value)
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
    step_length_m: float = 0.70,
    still_start_s: float = 2.0,
    still_end_s: float = 2.0,
    turn_rate_deg_s: float = 90.0,
    height_m: float = 1.75,
    gyro_noise_rad_s: float = 0.003,
    gyro_bias_rad_s: Sequence[float] = (0.002, -0.0015, 0.001),
    acc_noise_m_s2: float = 0.02,
    acc_bias_m_s2: Sequence[float] = (0.0, 0.0, 0.0),
    mag_noise_uT: float = 0.4,
    mag_hard_iron_uT: Sequence[float] = (0.0, 0.0, 0.0),
    earth_field_enu_uT: Sequence[float] = (0.0, 20.0, -44.0),
    disturbance_zones: Sequence[DisturbanceZone] = (),
    calibration_motion_s: float = 0.0,
    phone_pitch_deg: float = 25.0,
    phone_roll_deg: float = 0.0,
    hand_sway_deg: Sequence[float] = (3.0, 1.5, 3.0),
    hand_wander_deg: Sequence[float] = (0.6, 3.0, 3.0),
    weinberg_c: float = 0.47,
    weinberg_cutoff_hz: float = 3.0,
    weinberg_filter_order: int = 2,
    truth_rate_hz: float = 200.0,
    clock_start_ns: int = DEFAULT_CLOCK_START_NS,
    seed: int = 0,
) -> SimulatedWalk:
    """Simulate a walk along ``waypoints_en_m`` with a phone held in front of the chest.

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
    step_frequency_hz, step_length_m : float
        Cadence and step length; the cruise speed is their product.
    still_start_s, still_end_s : float
        Standing still (phone in the walking pose) before and after walking (s).
    turn_rate_deg_s : float
        Heading rate while walking around a corner (deg/s).
    height_m : float
        Walker's body height (m); the phone is held at 0.75 of it (metadata for stride models).
    gyro_noise_rad_s, acc_noise_m_s2, mag_noise_uT : float
        Per-sample standard deviation of the white noise of each sensor.
    gyro_bias_rad_s, acc_bias_m_s2 : 3 floats
        Constant sensor biases in the device frame.
    mag_hard_iron_uT : 3 floats
        Constant magnetometer offset in the device frame (uT).
    earth_field_enu_uT : 3 floats
        Local geomagnetic field (east, north, up) in uT.
    disturbance_zones : sequence of DisturbanceZone
        Local fields added to the Earth field near given positions.
    calibration_motion_s : float
        Duration of a tumbling figure-8 phone motion (+-90 deg about every
        axis, a few cm of hand motion) at the very start, before
        ``still_start_s``; the phone returns to the walking pose (s).
    phone_pitch_deg, phone_roll_deg : float
        Mean pitch (device y axis up from horizontal) and roll of the held phone (deg).
        ``phone_pitch_deg=0`` with ``hand_wander_deg=(0, 0, 0)`` holds the phone flat, screen up.
    hand_sway_deg : 3 floats
        Amplitudes (deg) at full walking speed of the yaw (stride frequency), pitch (step
        frequency) and roll (stride frequency) oscillations of the hand.
    hand_wander_deg : 3 floats
        Peak (deg) of the slow random wander of yaw, pitch and roll (present also when standing).
    weinberg_c, weinberg_cutoff_hz, weinberg_filter_order : float, float, int
        The gait amplitude is set so that ``weinberg_c * (A_max - A_min) ** 0.25`` of the acceleration
        norm after a Butterworth low-pass of this cut-off and order reproduces the step length.
    truth_rate_hz : float
        Rate of the dense attitude truth grid ``truth.att_t_ns`` (Hz).
    clock_start_ns : int
        Sensor clock value at the start of the simulation (ns).
    seed : int
        Seed of all randomness (timestamps, noise, hand wander).

    Returns
    -------
    SimulatedWalk
        ``recording`` with streams ``acc``, ``gyro``, ``mag`` and ``truth``.
    """
    rate_hz = _positive("rate_hz", rate_hz)
    gyro_rate_hz = rate_hz if gyro_rate_hz is None else _positive("gyro_rate_hz", gyro_rate_hz)
    mag_rate_hz = min(rate_hz, 50.0) if mag_rate_hz is None else _positive("mag_rate_hz", mag_rate_hz)
    timestamp_jitter = _non_negative("timestamp_jitter", timestamp_jitter)
    if timestamp_jitter > 0.5:
        raise ValueError(f"timestamp_jitter must be at most 0.5, got {timestamp_jitter}")
    f = _positive("step_frequency_hz", step_frequency_hz)
    step_length_m = _positive("step_length_m", step_length_m)
    still_start_s = _non_negative("still_start_s", still_start_s)
    still_end_s = _non_negative("still_end_s", still_end_s)
    calibration_motion_s = _non_negative("calibration_motion_s", calibration_motion_s)
    turn_rate = math.radians(_positive("turn_rate_deg_s", turn_rate_deg_s))
    height_m = _positive("height_m", height_m)
    for name, val in (("gyro_noise_rad_s", gyro_noise_rad_s), ("acc_noise_m_s2", acc_noise_m_s2),
                      ("mag_noise_uT", mag_noise_uT)):
        _non_negative(name, val)
    gyro_bias = _vec3("gyro_bias_rad_s", gyro_bias_rad_s)
    acc_bias = _vec3("acc_bias_m_s2", acc_bias_m_s2)
    hard_iron = _vec3("mag_hard_iron_uT", mag_hard_iron_uT)
    h_earth = _vec3("earth_field_enu_uT", earth_field_enu_uT)
    sway = _vec3("hand_sway_deg", hand_sway_deg)
    wander_deg = _vec3("hand_wander_deg", hand_wander_deg)
    zones = tuple(disturbance_zones)
    if not all(isinstance(z, DisturbanceZone) for z in zones):
        raise ValueError("disturbance_zones must be DisturbanceZone instances")
    weinberg_c = _positive("weinberg_c", weinberg_c)
    weinberg_cutoff_hz = _positive("weinberg_cutoff_hz", weinberg_cutoff_hz)
    if int(weinberg_filter_order) != weinberg_filter_order or not 1 <= weinberg_filter_order <= 8:
        raise ValueError(f"weinberg_filter_order must be an integer from 1 to 8, got {weinberg_filter_order!r}")
    truth_rate_hz = _positive("truth_rate_hz", truth_rate_hz)
    phone_pitch_deg, phone_roll_deg = float(phone_pitch_deg), float(phone_roll_deg)
    if not (math.isfinite(phone_pitch_deg) and math.isfinite(phone_roll_deg)):
        raise ValueError("phone_pitch_deg and phone_roll_deg must be finite")
    clock0 = operator.index(clock_start_ns)
    seed = operator.index(seed)  # an explicit integer: the recording must be reproducible

    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(7)]
    rng_t_acc, rng_t_gyro, rng_t_mag, rng_n_acc, rng_n_gyro, rng_n_mag, rng_wander = rngs

    speed = f * step_length_m
    walk_start_s = calibration_motion_s + still_start_s
    path = _Path(waypoints_en_m, speed_m_s=speed, turn_rate_rad_s=turn_rate, ramp_s=1.0 / f,
                 t_start_s=walk_start_s, step_frequency_hz=f)
    walk_end_s = walk_start_s + path.walk_duration_s
    total_s = walk_end_s + still_end_s
    if total_s <= 0:
        raise ValueError("nothing to simulate: no walking and no standing time")

    # slow hand wander: per axis three sinusoids, amplitudes summing to the peak bound
    weights = rng_wander.uniform(0.5, 1.0, (3, 3))
    weights /= weights.sum(axis=1, keepdims=True)
    wander = np.stack([weights * np.radians(wander_deg)[:, None], rng_wander.uniform(0.03, 0.15, (3, 3)),
                       rng_wander.uniform(0.0, 2.0 * np.pi, (3, 3))], axis=-1)

    model = _WalkModel(path=path, clock0_ns=clock0, step_frequency_hz=f, height_m=height_m,
                       pitch_rad=math.radians(phone_pitch_deg), roll_rad=math.radians(phone_roll_deg),
                       sway_rad=np.radians(sway), wander=wander, calibration_s=calibration_motion_s,
                       weinberg_c=weinberg_c, weinberg_cutoff_hz=weinberg_cutoff_hz,
                       weinberg_order=int(weinberg_filter_order))

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
    gyro = (model.body_rate(rel(t_gyro)) + np.asarray(gyro_bias)
            + gyro_noise_rad_s * rng_n_gyro.standard_normal((len(t_gyro), 3)))

    # magnetometer
    t_mag = _sample_times_ns(rng_t_mag, mag_rate_hz, timestamp_jitter, total_s, clock0)
    tm = rel(t_mag)
    h_n = np.tile(np.asarray(h_earth), (len(tm), 1))
    if zones:
        pos = model.position(tm)
        for z in zones:
            h_n = h_n + z.field_at(pos[:, 0], pos[:, 1])
    mag = (_rotate_to_body(quat.to_matrix_array(model.quat(tm)), h_n) + np.asarray(hard_iron)
           + mag_noise_uT * rng_n_mag.standard_normal((len(tm), 3)))

    # truth
    def ns(t_s):
        return clock0 + np.round(np.asarray(t_s) * 1e9).astype(np.int64)

    k = np.arange(1, path.n_steps + 1)
    t_steps = walk_start_s + k / f
    xs, ys, hs, _, ss = path.state(t_steps)
    x_prev = np.concatenate([[path.x0[0]], xs[:-1]])
    y_prev = np.concatenate([[path.y0[0]], ys[:-1]])
    s_prev = np.concatenate([[0.0], ss[:-1]])
    dx, dy = xs - x_prev, ys - y_prev
    chord = np.hypot(dx, dy)
    step_heading = np.where(chord > 1e-9, np.arctan2(dy, dx), hs)
    # keep the step headings on the same branch as the (unwrapped) path heading
    step_heading = hs + (step_heading - hs + np.pi) % (2.0 * np.pi) - np.pi
    att_t_ns = ns(np.arange(0.0, total_s, 1.0 / truth_rate_hz))
    frozen = _readonly
    truth = WalkTruth(
        n_steps=int(path.n_steps),
        step_t_ns=frozen(ns(t_steps)),
        step_east_m=frozen(xs),
        step_north_m=frozen(ys),
        step_length_m=frozen(ss - s_prev),
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
        att_q_wxyz=frozen(model.quat(rel(att_t_ns))),
        _model=model,
    )

    metadata = {
        "simulator": SIMULATOR_VERSION,
        "simulator_module": f"desktop.simulator (pdr {__version__})",
        "waypoints_en_m": [[float(x), float(y)] for x, y in np.asarray(waypoints_en_m, float).reshape(-1, 2)],
        "rate_hz": rate_hz, "gyro_rate_hz": gyro_rate_hz, "mag_rate_hz": mag_rate_hz,
        "timestamp_jitter": timestamp_jitter,
        "step_frequency_hz": f, "step_length_m": step_length_m,
        "still_start_s": still_start_s, "still_end_s": still_end_s, "turn_rate_deg_s": float(turn_rate_deg_s),
        "height_m": height_m,
        "gyro_noise_rad_s": float(gyro_noise_rad_s), "gyro_bias_rad_s": list(gyro_bias),
        "acc_noise_m_s2": float(acc_noise_m_s2), "acc_bias_m_s2": list(acc_bias),
        "mag_noise_uT": float(mag_noise_uT), "mag_hard_iron_uT": list(hard_iron),
        "earth_field_enu_uT": list(h_earth),
        "disturbance_zones": [z.as_dict() for z in zones],
        "calibration_motion_s": calibration_motion_s,
        "phone_pitch_deg": phone_pitch_deg, "phone_roll_deg": phone_roll_deg,
        "hand_sway_deg": list(sway), "hand_wander_deg": list(wander_deg),
        "weinberg_c": weinberg_c, "weinberg_cutoff_hz": weinberg_cutoff_hz,
        "weinberg_filter_order": int(weinberg_filter_order),
        "truth_rate_hz": truth_rate_hz, "clock_start_ns": clock0, "seed": seed,
        "truth": {"n_steps": truth.n_steps, "path_length_m": truth.path_length_m,
                  "walk_start_t_ns": truth.walk_start_t_ns, "walk_end_t_ns": truth.walk_end_t_ns,
                  "start_en_m": [truth.start_east_m, truth.start_north_m],
                  "end_en_m": [float(path.end[0]), float(path.end[1])]},
    }
    recording = Recording(
        {ACC: make_stream(ACC, t_acc, acc), GYRO: make_stream(GYRO, t_gyro, gyro), MAG: make_stream(MAG, t_mag, mag)},
        device={"model": "simulator"},
        metadata=metadata,
        source=f"simulate_walk(seed={seed})",
    )
    return SimulatedWalk(recording=recording, truth=truth)


#: The demo loop: a 50 m x 30 m rectangle with a dog-leg in its north-east corner (160 m, 6 turns).
DEMO_WAYPOINTS_EN_M = ((0.0, 0.0), (50.0, 0.0), (50.0, 15.0), (35.0, 15.0), (35.0, 30.0), (0.0, 30.0), (0.0, 0.0))


def demo_walk(seed: int = 0) -> SimulatedWalk:
    """The bundled demo: a closed 160 m loop with six turns at 100 Hz, about 2 min 15 s.

    Default noise, a small gyro bias (about 0.1 deg/s per axis), no magnetic
    disturbance, 3 s standing at either end.
    """
    return simulate_walk(DEMO_WAYPOINTS_EN_M, rate_hz=100.0, still_start_s=3.0, still_end_s=3.0, seed=seed)
