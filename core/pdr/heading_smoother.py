"""The replay heading smoother: a Rauch-Tung-Striebel backward pass over the attitude filter's run (issue #27).

A live walk can only use the readings it has seen, so the attitude filter
(:class:`core.pdr.attitude.AttitudeEKF`) is causal.  A replay has the whole
walk: indoors the heading taken at the start is off by 18-34 deg on the
IPIN tuning routes 01 and 02 (the field is bent at the start spot,
``benchmarks/discussion.md``), and only later readings, carried back by the
gyroscope, can say so.  This stage keeps what the RTS smoother needs from the
forward run and returns, per epoch, the smoothed heading correction and its
standard deviation; :class:`core.pdr.pipeline.Pipeline` (``heading_smoother=True``)
turns every step's heading by it and dead-reckons the track again (eq. 1 of
Tian et al. 2014).  The live app never runs it (``Pipeline.update`` is
unchanged; only the batch ``Pipeline.run`` applies it), and the fast path
(``desktop/fast``) refuses it: it falls back to the reference with the reason.

The smoother is :class:`core.kalman.RtsSmoother` (the one the foot INS uses),
on the attitude filter's error state ``(dtheta_n, db[, o])`` (navigation-frame
rotation error, gyroscope bias, field heading offset).  Its epochs are the
filter's *used* measurement updates, not its gyroscope events (10-20 a second
instead of 100-400): between two updates the transition is the product of the
gyroscope steps' ``F = [[I, -R dt, 0], [0, I, 0], [0, 0, phi]]``, which is
``[[I, -sum R dt, 0], [0, I, 0], [0, 0, prod phi]]`` (every diagonal block is the
identity or a scalar), and the process noise is what the filter's own covariance
grew by, ``Q = P-_{j+1} - Phi P_j Phi^T``: so the smoother's predicted covariance
is the filter's own, including its growth without a gyroscope and its heading
relock (the heading released by the gate, :meth:`AttitudeEKF._relock`: no heading
information passes back through a relock, as none passed forward).

What is approximate: the magnetometer's heading update is a Schmidt consider
update (tilt rows of the gain zeroed), which the smoother sees only through the
covariances the filter kept (:class:`core.kalman.RtsSmoother`); readings the
forward filter gated stay unused; and a step's heading is turned by the
smoothed heading error about Up only (the tilt part of the correction moves a
horizontal walking axis by second-order amounts).  Between two epochs the
correction is interpolated linearly in time.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, fields, replace

import numpy as np

from core import kalman
from core.conventions import wrap_angle
from core.pdr.deadreckoning import DeadReckoner


#: :class:`core.pdr.pipeline.Pipeline`'s ``heading_smoother``: none (the live app's forward heading), the RTS
#: backward pass applied to every step, or a second forward pass started from the smoothed start heading
HEADING_SMOOTHER_OFF = "off"
HEADING_SMOOTHER_RTS = "rts"
HEADING_SMOOTHER_START = "start"
HEADING_SMOOTHERS = (HEADING_SMOOTHER_OFF, HEADING_SMOOTHER_RTS, HEADING_SMOOTHER_START)


class SmootherVerdict(enum.Enum):
    """Whether the replay's heading smoother turned the track."""

    APPLIED = "applied"
    NO_HISTORY = "no used measurement update"  #: the filter never corrected anything: nothing to smooth
    GPS_FUSION = "not with a GPS fusion stage"  #: the fused track was made from the forward steps: left alone


@dataclass(frozen=True)
class HeadingSmoothing:
    """The smoothed heading of every epoch (a used measurement update) of the forward run."""

    t_ns: np.ndarray  #: (N,) time of each epoch (the filter's clock when it was corrected)
    correction_rad: np.ndarray  #: (N,) smoothed minus forward heading (rad, CCW about Up)
    sd_rad: np.ndarray  #: (N,) the smoothed heading's standard deviation (rad)
    forward_sd_rad: np.ndarray  #: (N,) the forward filter's (rad)
    q_wxyz: np.ndarray  #: (N, 4) the smoothed attitude, body -> ENU
    offset_rad: np.ndarray  #: (N,) the smoothed field heading offset (rad; nan without that state)
    offset_sd_rad: np.ndarray  #: (N,) its standard deviation (rad; nan without it)

    def correction_at(self, t_ns) -> np.ndarray:
        """The heading correction at times ``t_ns`` (linear in time between epochs, held beyond them; rad)."""
        t = np.asarray(t_ns, dtype=np.float64)
        if not len(self.t_ns):
            return np.zeros(t.shape)
        # unwrap so the interpolation never crosses +-pi the long way round
        c = np.unwrap(self.correction_rad)
        return wrap_angle(np.interp(t, self.t_ns.astype(np.float64), c))


@dataclass(frozen=True)
class StartHeading:
    """Where a second forward pass starts (``Pipeline(heading_smoother="start")``): the first pass's smoothed start."""

    correction_rad: float  #: turn the magnetometer's start heading by this (rad, CCW about Up)
    sd_rad: float  #: the heading's prior sd (rad)
    offset_rad: float = math.nan  #: the field heading offset's start value (rad; nan: the filter's own start)
    offset_sd_rad: float = math.nan  #: its prior sd (rad)

    @classmethod
    def of(cls, sm: HeadingSmoothing) -> StartHeading:
        """The first epoch of a smoothing."""
        return cls(float(sm.correction_rad[0]), float(sm.sd_rad[0]), float(sm.offset_rad[0]),
                   float(sm.offset_sd_rad[0]))


@dataclass(slots=True)
class _Segment:
    """The forward run between two changes of the error state's size, fed to its own backward pass as it runs."""

    rts: kalman.RtsSmoother  #: the epochs' covariances, transitions and injections (:class:`core.kalman.RtsSmoother`)
    forward_var: list  #: the forward heading variance of each closed epoch (rad^2)
    nominal: list  #: per epoch: (t_ns, q, field offset) after its injections
    P_last: np.ndarray | None = None  #: the open (last) epoch's posterior covariance

    @property
    def n(self) -> int:
        return self.rts.n


class AttitudeHistory:
    """What the RTS smoother needs, kept by the attitude filter while it runs (``AttitudeEKF(keep_history=True)``).

    The filter calls :meth:`add_prediction` on every gyroscope step (or covariance growth without one),
    :meth:`before_inject` and :meth:`after_inject` around every used update; :meth:`smooth` runs the backward
    pass.  A change of the error state's size (the field offset dropped outdoors, ``set_site_field``) ends a
    segment: each segment is smoothed on its own.
    """

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self._segments: list[_Segment] = []
        self._P_post: np.ndarray | None = None  # the open epoch's posterior covariance
        self._clear_transition()

    def _clear_transition(self) -> None:
        self._sum_rdt = [0.0] * 9  # sum of R dt over the gyroscope steps since the last epoch (row-major)
        self._phi_o = 1.0  # product of the offset's phi
        self._n_pred = 0

    @property
    def n_epochs(self) -> int:
        return sum(len(g.nominal) for g in self._segments)

    def add_prediction(self, rdt, phi_o: float = 1.0) -> None:
        """One prediction: ``rdt`` the step's ``R dt`` (9-tuple, row-major; None without a gyroscope: F = I there),
        ``phi_o`` the offset's decay."""
        if self._P_post is None:
            return
        if rdt is not None:
            s = self._sum_rdt
            for i in range(9):
                s[i] += rdt[i]
        self._phi_o *= phi_o
        self._n_pred += 1

    def _transition(self, n: int) -> np.ndarray:
        Phi = np.eye(n)
        Phi[0:3, 3:6] = -np.array(self._sum_rdt).reshape(3, 3)
        if n == 7:
            Phi[6, 6] = self._phi_o
        return Phi

    def before_inject(self, t_ns: int, P_prior: np.ndarray) -> None:
        """A used update is about to be folded in; ``P_prior`` is the filter's covariance before it."""
        n = len(P_prior)
        seg = self._segments[-1] if self._segments else None
        if seg is None or seg.n != n or self._P_post is None:
            rts = kalman.RtsSmoother(n, slice(0, 3))
            rts.start()
            self._segments.append(_Segment(rts, [], []))
            self._clear_transition()
            return
        if self._n_pred == 0 and np.array_equal(P_prior, self._P_post):
            return  # a second update at the same epoch
        Phi = self._transition(n)
        Q = P_prior - Phi @ self._P_post @ Phi.T
        seg.rts.predict(self._P_post, Phi, 0.5 * (Q + Q.T))  # closes the epoch
        seg.forward_var.append(float(self._P_post[2, 2]))
        self._clear_transition()

    def after_inject(self, t_ns: int, dx: np.ndarray, G: np.ndarray, P_post: np.ndarray, q, offset_rad: float) -> None:
        """The update ``dx`` was folded into the nominal state (``q``, the field offset ``offset_rad``) with the
        reset ``G``; ``P_post`` after it."""
        seg = self._segments[-1]
        seg.rts.inject(np.array(dx, dtype=float), np.array(G, dtype=float))
        self._P_post = seg.P_last = np.array(P_post, dtype=float)
        if len(seg.nominal) < seg.rts.n_epochs:
            seg.nominal.append(None)
        seg.nominal[-1] = (int(t_ns), tuple(q), float(offset_rad))

    @staticmethod
    def _smooth_segment(seg: _Segment) -> HeadingSmoothing:
        e, Ps = seg.rts.smooth(seg.P_last)
        N = len(seg.nominal)
        var = np.diagonal(Ps, axis1=1, axis2=2)
        fwd = np.array(seg.forward_var + [seg.P_last[2, 2]])
        q = np.array([kalman.inject_rotation(x[1], e[j, 0:3]) for j, x in enumerate(seg.nominal)])
        has_o = seg.n == 7
        o = np.array([x[2] for x in seg.nominal]) + e[:, 6] if has_o else np.full(N, np.nan)
        o_sd = np.sqrt(np.maximum(var[:, 6], 0.0)) if has_o else np.full(N, np.nan)
        return HeadingSmoothing(np.array([x[0] for x in seg.nominal], dtype=np.int64), e[:, 2].copy(),
                                np.sqrt(np.maximum(var[:, 2], 0.0)), np.sqrt(np.maximum(fwd, 0.0)), q, o, o_sd)

    def smooth(self) -> HeadingSmoothing:
        """The backward pass over everything kept (the history stays as it is: a later call smooths again)."""
        out = [self._smooth_segment(seg) for seg in self._segments if seg.nominal]
        if not out:
            z = np.zeros(0)
            return HeadingSmoothing(np.zeros(0, dtype=np.int64), z, z, z, np.zeros((0, 4)), z, z)
        return HeadingSmoothing(*(np.concatenate([getattr(s, f.name) for s in out]) for f in fields(HeadingSmoothing)))


def smooth_steps(steps: list, smoothing: HeadingSmoothing, start_en=(0.0, 0.0)) -> list:
    """The steps (:class:`core.pdr.pipeline.Step`) with their headings turned by the smoothed correction at each
    step's time and their positions dead-reckoned again from ``start_en`` (eq. 1)."""
    if not steps:
        return []
    dh = smoothing.correction_at(np.array([s.t_ns for s in steps], dtype=np.int64))
    dr = DeadReckoner(east_m=start_en[0], north_m=start_en[1])
    out = []
    for s, d in zip(steps, dh):
        h = float(wrap_angle(s.heading_rad + float(d))) if math.isfinite(s.heading_rad) else s.heading_rad
        e, n = dr.update(s.length_m, h)
        out.append(replace(s, heading_rad=h, east_m=e, north_m=n))
    return out
