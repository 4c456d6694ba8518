"""The error-state (multiplicative) EKF kernel shared by the attitude filter and the foot INS.

Both :class:`core.pdr.attitude.AttitudeEKF` and :class:`core.foot.ins.ZuptEKF`
estimate a small rotation error expressed in the **navigation frame**
(ENU, see :mod:`core`) beside additive errors (biases, velocity, position)::

    R_true = exp([dtheta]x) R(q),   x_true = x + dx   (every other block)

This module holds what they share, written once:

* SO(3): :func:`skew` (``[v]x w = v x w``) and :func:`inject_rotation`
  (``q <- exp(dtheta / 2) (x) q``, normalised);
* the measurement update, :func:`correct`: gated on the normalised
  innovation squared (NIS), Joseph form (right for any gain, so Schmidt
  consider updates may edit the gain through ``adjust_gain``), or the short
  form for a measurement that selects states (``H = [0 I 0]``, given as a
  slice), one result type (:class:`Correction`) and one non-finite policy;
* the reset after injection, :func:`reset_jacobian` and
  :func:`reset_covariance`: ``G = I + [dtheta / 2]x`` on the rotation block
  for a navigation-frame error.  Derivation (``d`` the injected estimate,
  ``e`` the error left about it): ``exp([e+]x) = exp([d + e]x) exp(-[d]x)``,
  to first order in ``e`` (Baker-Campbell-Hausdorff with
  ``[[a]x, [b]x] = [a x b]x``) ``e+ = e + d x e / 2``.  A body-frame error
  (``R_true = R exp([e]x)``, Sola 2017, arXiv:1711.02508) has the other sign;
  the rest is the ``[d]x^2 / 6`` term of SO(3)'s left Jacobian.

The prediction ``P <- F P F^T + Q`` stays with each filter: the attitude
filter writes it out on 3 x 3 blocks of plain floats (it runs on every
gyroscope event, where numpy's per-call cost outweighs the arithmetic), the
INS builds its 15 x 15 ``Phi``.

Non-finite policy: a singular innovation covariance, a non-finite NIS, or a
correction or covariance that would not be finite rejects the update as
:attr:`Verdict.NUMERICAL`; a NIS beyond the gate as :attr:`Verdict.GATE`.  A
rejected update returns no state: the caller keeps its prior, so nothing
non-finite ever enters it.
"""

from __future__ import annotations

import copy
import enum
import math
from dataclasses import dataclass

import numpy as np

from core import quaternion as quat


class StateSnapshots:
    """``snapshot()`` / ``restore()`` of a filter whose whole state is one dataclass in ``self._state``, of the
    class's ``State`` (made by ``State.initial``): the only way to take it out or put it back whole
    (:class:`core.pdr.attitude.AttitudeEKF`, :class:`core.foot.ins.ZuptEKF`, :class:`core.gnss.ekf.PdrEkf`,
    :class:`core.gnss.kubrak.KubrakKf`)."""

    State: type
    _state: object

    def snapshot(self):
        """A copy of the whole state (the filter keeps its own)."""
        return copy.deepcopy(self._state)

    def restore(self, state) -> None:
        """Continue from ``state`` (a :meth:`snapshot`, possibly changed; the filter takes a copy)."""
        if type(state) is not self.State:
            raise TypeError(f"restore takes {'an' if self.State.__name__[0] in 'AEIOU' else 'a'} "
                            f"{self.State.__name__}, not {type(state).__name__}")
        self._state = copy.deepcopy(state)


def read_only(a):
    """A view of the array ``a`` that cannot be written (``None`` stays ``None``): how a filter hands out its state
    (the values, no copy; a write raises instead of changing the filter behind its back)."""
    if a is None:
        return None
    v = a.view()
    v.flags.writeable = False
    return v


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]x`` (``[v]x w = v x w``)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def inject_rotation(q, dtheta) -> tuple:
    """``normalize(exp(dtheta / 2) (x) q)``: a navigation-frame rotation error folded into ``q`` (w, x, y, z)."""
    return quat.normalize(quat.multiply(quat.from_rotation_vector((float(dtheta[0]), float(dtheta[1]),
                                                                   float(dtheta[2]))), q))


_EYES: dict = {}


def _eye(n: int) -> np.ndarray:
    """The n x n identity, made once (read-only): the updates use it per measurement."""
    e = _EYES.get(n)
    if e is None:
        e = _EYES[n] = np.eye(n)
        e.flags.writeable = False
    return e


def reset_jacobian(dtheta, n_states: int, att: slice = slice(0, 3)) -> np.ndarray:
    """``G`` of the reset after injecting ``dtheta``: identity, with ``I + [dtheta / 2]x`` on the rotation block."""
    G = np.eye(n_states)
    a = att.start or 0
    # [dtheta / 2]x's six entries written into the identity (per update: a skew array and a slice sum cost more)
    x, y, z = 0.5 * float(dtheta[0]), 0.5 * float(dtheta[1]), 0.5 * float(dtheta[2])
    G[a, a + 1], G[a, a + 2] = -z, y
    G[a + 1, a], G[a + 1, a + 2] = z, -x
    G[a + 2, a], G[a + 2, a + 1] = -y, x
    return G


def reset_covariance(P: np.ndarray, dtheta, att: slice = slice(0, 3), G: np.ndarray | None = None) -> np.ndarray:
    """``G P G^T`` (symmetrised) with ``G`` = :func:`reset_jacobian` unless given (a caller may edit rows)."""
    if G is None:
        G = reset_jacobian(dtheta, len(P), att)
    Pn = G @ P @ G.T
    return 0.5 * (Pn + Pn.T)


class Verdict(enum.Enum):
    """What a measurement update did."""

    USED = "used"
    GATE = "gate"  #: NIS beyond the gate
    NUMERICAL = "numerical"  #: singular S, or a result that would not be finite


@dataclass(frozen=True, slots=True)
class Correction:
    """The result of :func:`correct`: the verdict, the NIS, and (when used) the error estimate and covariance."""

    verdict: Verdict
    nis: float  #: normalised innovation squared (nan when S could not be inverted)
    dx: np.ndarray | None = None  #: the error estimate to inject (None when not used)
    P: np.ndarray | None = None  #: the covariance after the update, before the reset (None when not used)
    K: np.ndarray | None = None  #: the gain used (None when not used; a consider term needs it)

    @property
    def used(self) -> bool:
        return self.verdict is Verdict.USED


def correct(P: np.ndarray, y: np.ndarray, H, Rm: np.ndarray, gate: float = math.inf, adjust_gain=None) -> Correction:
    """One gated Kalman update of an error state: ``y = H dx + v``, ``v ~ N(0, Rm)``.

    ``H``: an (m x n) array (Joseph form: ``P <- (I - K H) P (I - K H)^T + K Rm K^T``, right for any gain),
    or a slice of the states the measurement selects (``H = [0 I 0]``: ``P H^T = P[:, H]``, and the short
    form ``P <- P - K (P H^T)^T``, right for the optimal gain only; ``adjust_gain`` is refused then).
    ``adjust_gain(K)``: edits the gain in place before it is used (a Schmidt consider update zeroes rows).
    """
    if isinstance(H, slice):
        if adjust_gain is not None:
            raise ValueError("a consider gain needs the Joseph form: give H as an array")
        PHt = P[:, H]
        S = P[H, H] + Rm
    else:
        PHt = P @ H.T
        S = H @ PHt + Rm
    if len(S) == 1:  # a scalar measurement: 1 / s is LAPACK's inverse bit for bit, without its call's cost
        s = float(S[0, 0])
        if s == 0.0:  # singular (LAPACK's LinAlgError)
            return Correction(Verdict.NUMERICAL, math.nan)
        Sinv = np.array(((1.0 / s,),))
    else:
        try:
            Sinv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            return Correction(Verdict.NUMERICAL, math.nan)
    nis = float(y @ Sinv @ y)
    if not math.isfinite(nis):
        return Correction(Verdict.NUMERICAL, nis)
    if nis > gate:
        return Correction(Verdict.GATE, nis)
    K = PHt @ Sinv
    if adjust_gain is not None:
        adjust_gain(K)
    dx = K @ y
    if isinstance(H, slice):
        Pn = P - K @ PHt.T
    else:
        IKH = _eye(len(P)) - K @ H
        Pn = IKH @ P @ IKH.T + K @ Rm @ K.T
    if not (np.isfinite(dx).all() and np.isfinite(Pn).all()):
        return Correction(Verdict.NUMERICAL, nis)
    return Correction(Verdict.USED, nis, dx, Pn, K)


class RtsSmoother:
    """Rauch-Tung-Striebel fixed-interval smoother over a forward error-state filter's stored epochs.

    The forward filter calls :meth:`start` after its initialisation, :meth:`predict` at each prediction
    (with the posterior ``P`` it predicts from, ``Phi`` and ``Q``), :meth:`inject` at each error injection
    (``dx`` folded into the nominal state, ``G`` its reset Jacobian), and :meth:`smooth` at the end (with
    the last posterior ``P``).  An *epoch* ``j`` is the state between two predictions: ``xhat_j``, the
    nominal state after all of that epoch's injections, and ``P_j`` its error covariance.

    Derivation (Rauch, Tung & Striebel 1965, written for the error state).  With ``xbar_{j+1}`` the
    predicted nominal state, the error about it is ``e-_{j+1} = Phi_j e_j + w_j`` (covariance
    ``Pp = Phi_j P_j Phi_j^T + Q_j``), so the RTS gain and the smoothed error about ``xhat_j`` are::

        C_j = P_j Phi_j^T Pp^-1
        e_j|N = C_j e-_{j+1}|N ,   P_j|N = P_j + C_j (P-_{j+1}|N - Pp) C_j^T

    (the predicted error's mean is zero: the prediction moved the nominal state, not the error).  The
    smoothed error at ``j+1`` is known about ``xhat_{j+1}``; an injection ``d`` with reset ``G`` changed
    the reference: ``e- = d + G^-1 e`` (the reset is ``e = G (e- - d)``, see :func:`reset_jacobian`), so
    over the epoch's injections ``d_1 .. d_m`` (in order)::

        e-_{j+1}|N = D + M e_{j+1}|N ,  P-_{j+1}|N = M P_{j+1}|N M^T
        D = d_1 + G_1^-1 d_2 + G_1^-1 G_2^-1 d_3 + ... ,  M = G_1^-1 ... G_m^-1

    The smoothed state is ``xhat_j (+) e_j|N`` (the same injection as the filter's).  A measurement that
    is not a function of the current error state alone (a Schmidt consider update) makes the smoother
    approximate: it sees only the covariances the filter kept.
    """

    def __init__(self, n_states: int, att: slice = slice(0, 3)):
        self.n = int(n_states)
        self.att = att
        self.reset()

    def reset(self) -> None:
        self._P: list = []  # posterior covariance of each closed epoch
        self._Phi: list = []  # transition out of each closed epoch
        self._Q: list = []
        self._D: list = []  # injections of each closed epoch (D, M), None for none
        self._cur_D = None
        self._cur_M = None
        self.started = False

    def start(self) -> None:
        """A new forward run (forgets everything stored)."""
        self.reset()
        self.started = True

    @property
    def n_epochs(self) -> int:
        """Epochs so far (the open one included); the current epoch's index is ``n_epochs - 1``."""
        return len(self._P) + 1 if self.started else 0

    def predict(self, P_post: np.ndarray, Phi: np.ndarray, Q: np.ndarray) -> None:
        """Close the current epoch with its posterior ``P_post``; ``Phi``, ``Q`` lead to the next (copied)."""
        self._P.append(np.array(P_post, dtype=float))
        self._D.append(None if self._cur_D is None else (self._cur_D, self._cur_M))
        self._Phi.append(np.array(Phi, dtype=float))
        self._Q.append(Q)
        self._cur_D = self._cur_M = None

    def inject(self, dx: np.ndarray, G: np.ndarray) -> None:
        """The filter folded ``dx`` into the nominal state and reset its covariance with ``G``."""
        Ginv = np.eye(self.n)
        if G[self.att, self.att].size:
            Ginv[self.att, self.att] = np.linalg.inv(G[self.att, self.att])
        if self._cur_D is None:
            self._cur_D, self._cur_M = np.array(dx, dtype=float), Ginv
        else:
            self._cur_D = self._cur_D + self._cur_M @ dx
            self._cur_M = self._cur_M @ Ginv

    def smooth(self, P_last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The backward pass: ``(e (N, n), P (N, n, n))``, each epoch's smoothed error about its nominal
        state and its covariance.  A singular predicted covariance falls back to the pseudo-inverse."""
        P = np.array(self._P + [np.array(P_last, dtype=float)])
        N = len(P)
        e = np.zeros((N, self.n))
        Ps = np.empty_like(P)
        Ps[-1] = P[-1]
        if N == 1:
            return e, Ps
        Phi = np.array(self._Phi)
        Pp = Phi @ P[:-1] @ np.transpose(Phi, (0, 2, 1)) + np.array(self._Q)
        Pp = 0.5 * (Pp + np.transpose(Pp, (0, 2, 1)))
        PhiP = Phi @ P[:-1]  # Phi_j P_j = (P_j Phi_j^T)^T
        try:
            Ct = np.linalg.solve(Pp, PhiP)  # C_j^T = Pp^-1 Phi_j P_j
        except np.linalg.LinAlgError:
            Ct = np.linalg.pinv(Pp, hermitian=True) @ PhiP
        C = np.transpose(Ct, (0, 2, 1))
        D = self._D + [None if self._cur_D is None else (self._cur_D, self._cur_M)]
        for j in range(N - 2, -1, -1):
            inj = D[j + 1]
            if inj is None:
                em, Pm = e[j + 1], Ps[j + 1]
            else:
                d, M = inj
                em = d + M @ e[j + 1]
                Pm = M @ Ps[j + 1] @ M.T
            Cj = C[j]
            e[j] = Cj @ em
            Pj = P[j] + Cj @ (Pm - Pp[j]) @ Cj.T
            Ps[j] = 0.5 * (Pj + Pj.T)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(Ps))):
            raise FloatingPointError("the RTS backward pass did not stay finite")
        return e, Ps
