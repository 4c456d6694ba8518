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

import enum
import math
from dataclasses import dataclass

import numpy as np

from core import quaternion as quat


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]x`` (``[v]x w = v x w``)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def inject_rotation(q, dtheta) -> tuple:
    """``normalize(exp(dtheta / 2) (x) q)``: a navigation-frame rotation error folded into ``q`` (w, x, y, z)."""
    return quat.normalize(quat.multiply(quat.from_rotation_vector(tuple(float(v) for v in dtheta)), q))


def reset_jacobian(dtheta, n_states: int, att: slice = slice(0, 3)) -> np.ndarray:
    """``G`` of the reset after injecting ``dtheta``: identity, with ``I + [dtheta / 2]x`` on the rotation block."""
    G = np.eye(n_states)
    G[att, att] += 0.5 * skew(dtheta)
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
        IKH = np.eye(len(P)) - K @ H
        Pn = IKH @ P @ IKH.T + K @ Rm @ K.T
    if not (np.all(np.isfinite(dx)) and np.all(np.isfinite(Pn))):
        return Correction(Verdict.NUMERICAL, nis)
    return Correction(Verdict.USED, nis, dx, Pn, K)
