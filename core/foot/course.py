"""The first of the two cascaded Kalman filters (Song & Park 2018, eqs. 11-19): the course-angle error.

State ``x1 = dpsi_c`` (eq. 14), the error of the course measured from the
foot INS's stance positions, a first-order Gauss-Markov process (eq. 15)::

    x1' = -beta_c x1 + n1,          Var(n1) = sigma_1^2 (per second)
    z1  = x1 + v1,                  Var(v1) = sigma_c^2 = gamma sigma_mag^2   (eqs. 16, 19)
    z1  = psi_w - psi_mc,           psi_mc = atan2(s_i - s_{i-1})             (eqs. 17-18)

``psi_w`` is the heading of the waist-mounted magnetometer over the stride,
``s_i`` the foot position at the i-th stance.  All angles are ENU
(counter-clockwise from East); the paper's eq. 17 ``atan2(dN, dE)`` is the
NED bearing, ours is ``atan2(dNorth, dEast)`` as well, measured from East.

Beyond the paper (its conclusion names the waist sensor's misalignment as
future work): the waist sensor's axis is not the walking direction, so the
mean of ``psi_w - psi_mc`` over the first ``boresight_strides`` usable
strides is taken as the waist-to-course offset and subtracted from every later
``z1``; the filter starts after it.  Strides that turn (course or waist
heading changing by more than ``max_turn_rad`` from the previous stride) or
are shorter than ``min_stride_m`` give no measurement, and a measurement whose
NIS exceeds ``gate_nis`` is not used.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

import numpy as np

from core import quaternion as quat
from core.conventions import wrap_angle


@dataclass(frozen=True)
class CourseSettings:
    """Settings of :class:`CourseErrorFilter` (units in the names)."""

    #: 1 / beta_c of eq. 15 (s)
    tau_s: float = 100.0
    #: sigma_1 of eq. 15: random walk of the course error (rad/sqrt(s)), "slightly larger than sigma_g"
    process_noise_rad_sqrt_s: float = 0.003
    #: sigma_mag of eq. 19: noise of the waist magnetometer heading over a stride (rad)
    mag_heading_sd_rad: float = math.radians(10.0)
    #: gamma of eq. 19
    gamma: float = 1.0
    #: prior sd of x1 when the filter starts (rad)
    initial_sd_rad: float = math.radians(5.0)
    #: strides used for the waist-to-course offset before the filter starts
    boresight_strides: int = 4
    #: strides shorter than this give no course (m)
    min_stride_m: float = 0.4
    #: strides turning more than this from the previous one give no measurement (rad)
    max_turn_rad: float = math.radians(15.0)
    #: innovation gate (1 dof)
    gate_nis: float = 16.0
    #: measurements pre-filtered before each hand-over to the second filter (then the filter restarts)
    handover_strides: int = 1


class CourseVerdict(enum.Enum):
    """What one stride's course measurement did (:attr:`CourseUpdate.verdict`); the text is its value."""

    USED = "used"
    NO_WAIST_HEADING = "no waist heading"  #: the waist magnetometer gave no heading over the stride
    SHORT_STRIDE = "short stride"  #: shorter than ``min_stride_m``
    TURNING = "turning"  #: course or waist heading turned more than ``max_turn_rad`` (or no previous stride)
    BORESIGHT = "boresight"  #: one of the strides of the waist-to-course offset, before the filter starts
    GATED = "gated"  #: its NIS beyond ``gate_nis``


#: the verdicts of a stride the gates refused (as against one without a waist heading, or the boresight)
GATED_VERDICTS = frozenset({CourseVerdict.SHORT_STRIDE, CourseVerdict.TURNING, CourseVerdict.GATED})


@dataclass(frozen=True)
class CourseUpdate:
    """One stride's course measurement and what the filter did with it."""

    t_ns: int
    z_rad: float  #: eq. 18 minus the offset (nan when there was none)
    used: bool
    verdict: CourseVerdict
    x_rad: float  #: estimate after the update
    p_rad2: float  #: its variance (eq. 25 hands it to the second filter)
    nis: float = math.nan
    #: this update completes a hand-over: ``x_rad, p_rad2`` go to the second filter, then :meth:`restart`
    handover: bool = False

    @property
    def reason(self) -> str:
        """The verdict in words."""
        return self.verdict.value


class CourseErrorFilter:
    """Eqs. 14-19 with the offset and gates of the module docstring."""

    def __init__(self, settings: CourseSettings | None = None, **overrides):
        s = settings or CourseSettings()
        self.settings = replace(s, **overrides) if overrides else s
        self.reset()

    def reset(self) -> None:
        self.x = 0.0
        self.p = self.settings.initial_sd_rad ** 2
        self.fresh = True  #: no information since the start or the last hand-over
        self.n_since_handover = 0
        self.t_ns: int | None = None
        self.offset_rad = math.nan
        self._bore: list[float] = []
        self._prev_course = math.nan
        self._prev_waist = math.nan

    @property
    def started(self) -> bool:
        return not math.isnan(self.offset_rad)

    def predict(self, t_ns: int) -> None:
        """eq. 15 over the time since the last measurement."""
        if self.t_ns is not None and t_ns > self.t_ns:
            dt = (t_ns - self.t_ns) * 1e-9
            e = math.exp(-dt / self.settings.tau_s)
            self.x *= e
            self.p = e * e * self.p + self.settings.process_noise_rad_sqrt_s ** 2 * dt
        self.t_ns = t_ns

    def restart(self) -> None:
        """After a hand-over: no information left (the second filter has it all)."""
        self.x, self.p, self.fresh, self.n_since_handover = 0.0, math.inf, True, 0

    def update(self, t_ns: int, waist_heading_rad: float, stride_east_m: float, stride_north_m: float,
               prior_var_rad2: float = math.nan) -> CourseUpdate:
        """One stride: waist heading and the stride's displacement (eqs. 17-18), then the update of eq. 16.

        ``prior_var_rad2``: the second filter's variance of the heading error, the prediction's variance
        in the gate while this filter has no information (after a restart); nan: no gate then."""
        s = self.settings
        length = math.hypot(stride_east_m, stride_north_m)
        course = math.atan2(stride_north_m, stride_east_m)  # eq. 17 (ENU)
        turn_c = abs(wrap_angle(course - self._prev_course)) if not math.isnan(self._prev_course) else math.inf
        turn_w = abs(wrap_angle(waist_heading_rad - self._prev_waist)) if not math.isnan(self._prev_waist) else math.inf
        self._prev_course, self._prev_waist = course, waist_heading_rad
        if self.started:
            self.predict(t_ns)
        if not math.isfinite(waist_heading_rad):
            return CourseUpdate(t_ns, math.nan, False, CourseVerdict.NO_WAIST_HEADING, self.x, self.p)
        if length < s.min_stride_m:
            return CourseUpdate(t_ns, math.nan, False, CourseVerdict.SHORT_STRIDE, self.x, self.p)
        if max(turn_c, turn_w) > s.max_turn_rad:
            return CourseUpdate(t_ns, math.nan, False, CourseVerdict.TURNING, self.x, self.p)
        z_raw = wrap_angle(waist_heading_rad - course)  # eq. 18
        if not self.started:
            self._bore.append(z_raw)
            if len(self._bore) >= s.boresight_strides:
                a = np.asarray(self._bore)
                self.offset_rad = math.atan2(float(np.mean(np.sin(a))), float(np.mean(np.cos(a))))
                self.t_ns = t_ns
            return CourseUpdate(t_ns, math.nan, False, CourseVerdict.BORESIGHT, self.x, self.p)
        z = wrap_angle(z_raw - self.offset_rad)
        r = s.gamma * s.mag_heading_sd_rad ** 2  # eq. 19
        if self.fresh:  # no information: the gate predicts z = 0 with the second filter's variance
            y = z
            nis = y * y / (prior_var_rad2 + r) if math.isfinite(prior_var_rad2) else math.nan
        else:
            y = wrap_angle(z - self.x)
            nis = y * y / (self.p + r)
        if nis > s.gate_nis:
            return CourseUpdate(t_ns, z, False, CourseVerdict.GATED, self.x, self.p, nis)
        if self.fresh:  # eq. 16 with an uninformative prior
            self.x, self.p, self.fresh = z, r, False
        else:
            k = self.p / (self.p + r)
            self.x += k * y
            self.p *= 1.0 - k
        self.n_since_handover += 1
        return CourseUpdate(t_ns, z, True, CourseVerdict.USED, self.x, self.p, nis,
                            handover=self.n_since_handover >= s.handover_strides)


def body_heading(acc_mean_b, mag_mean_b, axis_b) -> float:
    """Magnetic heading (rad, CCW from East, magnetic north = pi/2) of a body axis, from mean specific
    force and mean field over a window (TRIAD); nan when they do not define one."""
    try:
        q = quat.from_two_vectors_enu(tuple(acc_mean_b), tuple(mag_mean_b))
    except ValueError:
        return math.nan
    a = quat.rotate(q, tuple(axis_b))
    if a[0] * a[0] + a[1] * a[1] < 1e-6:
        return math.nan
    return math.atan2(a[1], a[0])
