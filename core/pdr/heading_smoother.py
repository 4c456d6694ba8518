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
from dataclasses import dataclass, replace

import numpy as np

from core import kalman
from core.conventions import wrap_angle
from core.pdr.deadreckoning import DeadReckoner


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

    def correction_at(self, t_ns) -> np.ndarray:
        """The heading correction at times ``t_ns`` (linear in time between epochs, held beyond them; rad)."""
        t = np.asarray(t_ns, dtype=np.float64)
        if not len(self.t_ns):
            return np.zeros(t.shape)
        # unwrap so the interpolation never crosses +-pi the long way round
        c = np.unwrap(self.correction_rad)
        return wrap_angle(np.interp(t, self.t_ns.astype(np.float64), c))


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
        self._done: list[HeadingSmoothing] = []  # smoothed segments
        self._rts: kalman.RtsSmoother | None = None
        self._nominal: list = []  # (t_ns, q) of each closed epoch
        self._cur: tuple | None = None  # (t_ns, q) of the open epoch
        self._P_post: np.ndarray | None = None  # the open epoch's posterior covariance
        self._fwd_sd: list = []  # the forward heading sd of each closed epoch
        self._clear_transition()

    def _clear_transition(self) -> None:
        self._sum_rdt = [0.0] * 9  # sum of R dt over the gyroscope steps since the last epoch (row-major)
        self._phi_o = 1.0  # product of the offset's phi
        self._n_pred = 0

    @property
    def n_epochs(self) -> int:
        return sum(len(s.t_ns) for s in self._done) + (self._rts.n_epochs if self._rts is not None else 0)

    def add_prediction(self, rdt, phi_o: float = 1.0) -> None:
        """One prediction: ``rdt`` the step's ``R dt`` (9-tuple, row-major; None without a gyroscope: F = I there),
        ``phi_o`` the offset's decay."""
        if self._rts is None:
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
        if self._rts is not None and self._rts.n != n:
            self._finish_segment()
        if self._rts is None:
            self._rts = kalman.RtsSmoother(n)
            self._rts.start()
            self._clear_transition()
            return
        if self._n_pred == 0 and np.array_equal(P_prior, self._P_post):
            return  # a second update at the same epoch
        Phi = self._transition(n)
        Q = P_prior - Phi @ self._P_post @ Phi.T
        self._rts.predict(self._P_post, Phi, 0.5 * (Q + Q.T))
        self._nominal.append(self._cur)
        self._fwd_sd.append(math.sqrt(max(float(self._P_post[2, 2]), 0.0)))
        self._clear_transition()

    def after_inject(self, t_ns: int, dx: np.ndarray, G: np.ndarray, P_post: np.ndarray, q) -> None:
        """The update ``dx`` was folded into the nominal state ``q`` with the reset ``G``; ``P_post`` after it."""
        self._rts.inject(np.asarray(dx, dtype=float), G)
        self._P_post = np.array(P_post, dtype=float)
        self._cur = (int(t_ns), tuple(q))

    def _finish_segment(self) -> None:
        if self._rts is None or self._cur is None:
            self._rts = None
            return
        e, Ps = self._rts.smooth(self._P_post)
        nom = self._nominal + [self._cur]
        fwd = self._fwd_sd + [math.sqrt(max(float(self._P_post[2, 2]), 0.0))]
        q = np.array([kalman.inject_rotation(x[1], e[j, 0:3]) for j, x in enumerate(nom)])
        self._done.append(HeadingSmoothing(np.array([x[0] for x in nom], dtype=np.int64), e[:, 2].copy(),
                                           np.sqrt(np.maximum(Ps[:, 2, 2], 0.0)), np.array(fwd), q))
        self._rts, self._nominal, self._cur, self._P_post, self._fwd_sd = None, [], None, None, []

    def smooth(self) -> HeadingSmoothing:
        """The backward pass over everything kept (the history stays usable: a later call smooths again)."""
        done = list(self._done)
        if self._rts is not None and self._cur is not None:
            saved = (self._rts, list(self._nominal), self._cur, self._P_post, list(self._fwd_sd))
            self._finish_segment()
            done.append(self._done.pop())
            self._rts, self._nominal, self._cur, self._P_post, self._fwd_sd = saved
        if not done:
            z = np.zeros(0)
            return HeadingSmoothing(np.zeros(0, dtype=np.int64), z, z, z, np.zeros((0, 4)))
        return HeadingSmoothing(*(np.concatenate([getattr(s, f) for s in done])
                                  for f in ("t_ns", "correction_rad", "sd_rad", "forward_sd_rad", "q_wxyz")))


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
