"""The pedestrian velocity model of Kubrak et al. (2006), eq. 1: speed from the acceleration magnitude's statistics.

::

    v = A * MEAN + B * FREQ + C * STD                                  (eq. 1)

over a trailing window of ``window_s`` = 2 s of the acceleration magnitude
``|a|`` (gravity included, the pipeline's 50 Hz grid of eq. 2 of Tian et al.):
``MEAN`` its mean (m/s^2), ``FREQ`` its characteristic frequency (Hz) and
``STD`` its standard deviation (m/s^2).  ``A`` and ``C`` are in seconds, ``B``
in metres.  ``MEAN`` is gravity plus a little while walking, so ``A * MEAN``
acts as the model's intercept; the three regressors are strongly collinear
(``MEAN`` hardly varies), which is why the coefficients are fitted with a
ridge towards a prior and why, in the Kalman filter of
:mod:`core.gnss.kubrak`, their individual values wander along the direction
the data does not see -- the bad-GPS detector therefore watches the *speed*
they predict, not the coefficients one by one.

The characteristic frequency is the paper's undefined "FREQ"; here it is the
rate of the signal's upward crossings of its window mean, after a 3 Hz
Butterworth low-pass (the step detector's), with a hysteresis of a quarter of
the window's SD (at least ``min_hysteresis_m_s2``) so that noise while
standing gives no crossings: ``(n - 1) / (t_last - t_first)`` for the ``n``
crossings in the window (interpolated between grid samples), 0 with fewer
than two.  For a walker it is the step frequency.

:class:`SpeedFeatureWindow` computes the three features causally, O(1) per
grid sample (the pipeline attaches them to every step's
:class:`core.pdr.stride.StepFeatures`); :class:`VelocityModel` holds A, B, C;
:class:`VelocityStride` makes eq. 1 a per-step distance (speed times the
step's interval) so that it can replace the stride model of the hand-held
chain (``Pipeline(stride_model=VelocityStride())``, ``pdr replay
--stride-model kubrak_velocity``) and be compared with it on the same steps;
:func:`fit_velocity_model` is the offline regression (``tools/train_velocity.py``).
"""

from __future__ import annotations

import json
import math
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.dsp import Biquad, butter2_lowpass
from core.pdr.stride import StepFeatures, StrideModel

#: the shipped coefficients (fitted by tools/train_velocity.py)
DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "models" / "kubrak_velocity.json"


class SpeedFeatureWindow:
    """MEAN, FREQ and STD of the acceleration magnitude over a trailing window (eq. 1's regressors).

    Parameters
    ----------
    window_s : float
        Length of the window (s); the paper's 2 s.
    grid_rate_hz : float
        Rate of the uniform grid the samples come on (Hz).
    cutoff_hz : float
        Low-pass before the crossings are counted (Hz).
    min_hysteresis_m_s2 : float
        Smallest hysteresis band of the crossing detector (m/s^2).
    """

    def __init__(self, *, window_s: float = 2.0, grid_rate_hz: float = 50.0, cutoff_hz: float = 3.0,
                 min_hysteresis_m_s2: float = 0.3):
        if not window_s > 0:
            raise ValueError(f"window_s must be positive, got {window_s}")
        self.window_s = float(window_s)
        self.grid_rate_hz = float(grid_rate_hz)
        self.cutoff_hz = float(cutoff_hz)
        self.min_hysteresis_m_s2 = float(min_hysteresis_m_s2)
        self._ba = butter2_lowpass(cutoff_hz, grid_rate_hz)
        self.reset()

    @property
    def lowpass_ba(self) -> tuple:
        """The low-pass filter's coefficients ``(b, a)`` (:func:`core.dsp.butter2_lowpass` of ``cutoff_hz``)."""
        return self._ba

    def reset(self) -> None:
        self._window_ns = int(self.window_s * 1e9)
        self._buf: deque = deque()
        self._s1 = self._s2 = 0.0
        self._lp = Biquad(*self._ba)
        self._started = False
        self._below = False
        self._prev: tuple | None = None  # (t_ns, lp - level) of the previous sample
        self._crossings: deque = deque()

    def update(self, t_ns: int, norm_m_s2: float) -> None:
        """One grid sample of ``|a|`` (m/s^2)."""
        if not self._started:
            self._lp.reset(norm_m_s2)
            self._started = True
        buf = self._buf
        buf.append((t_ns, norm_m_s2))
        # the sums in locals (every grid sample), the same operations in the same order
        s1 = self._s1 + norm_m_s2
        s2 = self._s2 + norm_m_s2 * norm_m_s2
        limit = t_ns - self._window_ns
        while buf[0][0] <= limit:
            _, old = buf.popleft()
            s1 -= old
            s2 -= old * old
        self._s1, self._s2 = s1, s2
        n = len(buf)
        mean = s1 / n
        sd = math.sqrt(max(s2 / n - mean * mean, 0.0))
        h = max(0.25 * sd, self.min_hysteresis_m_s2)
        y = self._lp.step(norm_m_s2) - mean
        if y < -h:
            self._below = True
        elif self._below and y > h and self._prev is not None:
            t0, y0 = self._prev
            frac = (h - y0) / (y - y0) if y != y0 else 1.0
            self._crossings.append(t0 + int(min(max(frac, 0.0), 1.0) * (t_ns - t0)))
            self._below = False
        self._prev = (t_ns, y)
        cr = self._crossings
        while cr and cr[0] <= limit:
            cr.popleft()

    @property
    def full(self) -> bool:
        """Whether the window spans its whole length."""
        buf = self._buf
        return len(buf) > 1 and buf[-1][0] - buf[0][0] >= self._window_ns - int(2e9 / self.grid_rate_hz)

    def features(self) -> tuple[float, float, float]:
        """(MEAN m/s^2, FREQ Hz, STD m/s^2) of the window; nan until the window is full."""
        if not self.full:
            return math.nan, math.nan, math.nan
        n = len(self._buf)
        mean = self._s1 / n
        sd = math.sqrt(max(self._s2 / n - mean * mean, 0.0))
        cr = self._crossings
        freq = (len(cr) - 1) / ((cr[-1] - cr[0]) * 1e-9) if len(cr) >= 2 and cr[-1] > cr[0] else 0.0
        return mean, freq, sd


def step_regressors(f: StepFeatures) -> tuple[float, float, float]:
    """eq. 1's regressors of a step (the window ending at its peak)."""
    return f.window_mean_m_s2, f.window_freq_hz, f.window_std_m_s2


@dataclass(frozen=True)
class VelocityModel:
    """eq. 1's coefficients: ``v = a_s * MEAN + b_m * FREQ + c_s * STD`` (m/s).

    ``sd`` are the coefficients' prior standard deviations (how much walkers differ), used by
    the Kalman filter of :mod:`core.gnss.kubrak` as its starting uncertainty.
    """

    a_s: float
    b_m: float
    c_s: float
    sd: tuple = (0.005, 0.05, 0.05)
    max_speed_m_s: float = 2.5

    @property
    def coefficients(self) -> np.ndarray:
        return np.array([self.a_s, self.b_m, self.c_s])

    def speed_m_s(self, mean_m_s2: float, freq_hz: float, std_m_s2: float) -> float:
        """eq. 1, clipped to ``[0, max_speed_m_s]``; nan when a regressor is."""
        v = self.a_s * mean_m_s2 + self.b_m * freq_hz + self.c_s * std_m_s2
        return min(max(v, 0.0), self.max_speed_m_s) if v == v else math.nan

    def to_dict(self) -> dict:
        """The model as a ``pdr-stride-model`` file of kind ``kubrak_velocity`` (:mod:`core.pdr.stride_models`)."""
        return {"format": "pdr-stride-model", "format_version": 1, "kind": "kubrak_velocity",
                "coefficients": {"a_s": self.a_s, "b_m": self.b_m, "c_s": self.c_s}, "sd": list(self.sd),
                "max_speed_m_s": self.max_speed_m_s}

    @classmethod
    def from_dict(cls, d: dict) -> VelocityModel:
        """From :meth:`to_dict`'s form (checked: three finite coefficients, three positive SDs)."""
        k = d["coefficients"]
        vals = [float(k[n]) for n in ("a_s", "b_m", "c_s")]
        sd = tuple(float(v) for v in d.get("sd", (0.005, 0.05, 0.05)))
        if not all(math.isfinite(v) for v in vals + list(sd)) or len(sd) != 3 or min(sd) <= 0:
            raise ValueError(f"velocity model coefficients must be finite with 3 positive SDs, got {d!r}")
        return cls(*vals, sd=sd, max_speed_m_s=float(d.get("max_speed_m_s", 2.5)))

    @classmethod
    def load(cls) -> VelocityModel:
        """The shipped coefficients (``core/pdr/models/kubrak_velocity.json``)."""
        with open(DEFAULT_MODEL_PATH, encoding="utf-8") as f:
            return cls.from_dict(json.load(f))


def fit_velocity_model(x, speeds_m_s, *, weights=None, prior: VelocityModel | None = None,
                       ridge: float = 1.0) -> tuple[VelocityModel, np.ndarray]:
    """Weighted least squares of eq. 1 with a ridge towards ``prior``; returns the model and the coefficients' covariance.

    ``x`` is ``(n, 3)`` of (MEAN, FREQ, STD), ``speeds_m_s`` the true mean speeds (GPS,
    a known distance over a known time).  The ridge pulls each coefficient towards the
    prior's with weight ``ridge / sd_i^2`` (no prior: a flat one).  Rows with a non-finite
    value are left out.  The covariance is the residual variance times the normal matrix's inverse.
    """
    x = np.asarray(x, dtype=float).reshape(-1, 3)
    y = np.asarray(speeds_m_s, dtype=float).reshape(-1)
    w = np.ones(len(y)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    ok = np.all(np.isfinite(x), axis=1) & np.isfinite(y) & np.isfinite(w) & (w > 0)
    x, y, w = x[ok], y[ok], w[ok]
    if len(y) < 3:
        raise ValueError(f"fit_velocity_model needs at least 3 finite samples, got {len(y)}")
    a = (x * w[:, None]).T @ x
    b = (x * w[:, None]).T @ y
    if prior is not None:
        lam = np.diag(ridge / np.square(np.asarray(prior.sd, dtype=float)))
        a = a + lam
        b = b + lam @ prior.coefficients
    coef = np.linalg.solve(a, b)
    res = y - x @ coef
    dof = max(len(y) - 3, 1)
    s2 = float(np.sum(w * res * res) / max(np.sum(w), 1e-12) * len(y) / dof)
    cov = np.linalg.inv(a) * s2 * float(np.sum(w)) / len(y)
    sd = tuple(float(v) for v in np.sqrt(np.maximum(np.diag(cov), 1e-12)))
    base = prior.sd if prior is not None else sd
    return VelocityModel(float(coef[0]), float(coef[1]), float(coef[2]), sd=tuple(base)), cov


class VelocityStride(StrideModel):
    """eq. 1 as a step length: the model's speed over the window ending at the peak, times the step's interval.

    A step without the window features (a window not yet full) gets the speed of the
    last step that had them, or ``fallback_speed_m_s``.
    """

    name = "kubrak_velocity"

    def __init__(self, model: VelocityModel | None = None, *, fallback_speed_m_s: float = 1.2):
        self.model = model or VelocityModel.load()
        self.fallback_speed_m_s = float(fallback_speed_m_s)
        self._last = self.fallback_speed_m_s

    def length_m(self, f: StepFeatures) -> float:
        v = self.model.speed_m_s(*step_regressors(f))
        if v == v:
            self._last = v
        else:
            v = self._last
        return v * f.duration_s
