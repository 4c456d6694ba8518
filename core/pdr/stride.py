"""Step length models (Tian et al. 2014, section 3, eq. 4).

The pipeline calls a stride model once per detected step with that step's
:class:`StepFeatures` and gets the step length in metres.  Every model
implements :class:`StrideModel`; :class:`WeinbergStride` is Weinberg's
fourth-root model (eq. 4) whose coefficient ``C`` comes from a
:class:`CoefficientModel` -- a constant here, the paper's back-propagation
network (height and step frequency -> C) where one is trained.

Note on words: the paper's "stride length" is the length of *one step*
(heel strike to the next heel strike of the other foot).  We say step length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class StepFeatures:
    """What is known about one step when its length is estimated.

    Accelerations are of the low-pass-filtered acceleration norm (eq. 2),
    gravity included, over the step (from the previous step's peak to this
    one).
    """

    t_ns: int  #: time of the step (the detected peak), sensor clock
    duration_s: float  #: time since the previous step (s); a default cadence for the first step
    acc_max_m_s2: float  #: A_max of eq. 4 (m/s^2)
    acc_min_m_s2: float  #: A_min of eq. 4 (m/s^2)
    acc_var_m2_s4: float  #: variance of the filtered norm over the step ((m/s^2)^2)
    height_m: float | None = None  #: the walker's body height, if the user gave it
    #: Kubrak et al.'s eq.-1 regressors over the 2 s of |a| before the peak (core.pdr.velocity); nan if unknown
    window_mean_m_s2: float = float("nan")
    window_freq_hz: float = float("nan")
    window_std_m_s2: float = float("nan")

    @property
    def frequency_hz(self) -> float:
        """Step frequency, 1 / duration (Hz)."""
        return 1.0 / self.duration_s if self.duration_s > 0 else 0.0


class StrideModel:
    """Interface: ``length_m(features) -> float`` step length in metres."""

    #: short name used in reports
    name = "stride-model"

    def length_m(self, f: StepFeatures) -> float:  # pragma: no cover - interface
        raise NotImplementedError


class CoefficientModel:
    """Interface for Weinberg's coefficient ``C`` of eq. 4 as a function of the step."""

    name = "coefficient-model"

    def coefficient(self, f: StepFeatures) -> float:  # pragma: no cover - interface
        raise NotImplementedError


class ConstantCoefficient(CoefficientModel):
    """``C`` constant for every step.

    Parameters
    ----------
    c : float
        Weinberg coefficient in m / (m/s^2)^(1/4) for the low-pass-filtered
        norm of :mod:`core.pdr.steps`.  The default is the shipped model
        ``core/pdr/models/default.json`` (trained by ``tools/train_stride.py`` on
        the IPOL walkers; the same fit on hand-held IPIN loops gives 0.456; a
        test keeps the two equal).
    """

    name = "constant"

    def __init__(self, *, c: float = 0.455):
        if not c > 0:
            raise ValueError(f"Weinberg coefficient must be positive, got {c}")
        self.c = float(c)

    def coefficient(self, f: StepFeatures) -> float:
        return self.c


class WeinbergStride(StrideModel):
    """Weinberg's model, eq. 4: ``length = C * (A_max - A_min) ** (1/4)``.

    Parameters
    ----------
    coefficient : CoefficientModel or float
        Source of ``C`` for each step; a number means a constant ``C``.
    min_length_m, max_length_m : float
        The result is clipped to this physiological range (m).
    """

    name = "weinberg"

    def __init__(self, *, coefficient: CoefficientModel | float | None = None,
                 min_length_m: float = 0.2, max_length_m: float = 1.4):
        if coefficient is None:
            coefficient = ConstantCoefficient()
        elif isinstance(coefficient, (int, float)):
            coefficient = ConstantCoefficient(c=float(coefficient))
        self.coefficient = coefficient
        self.min_length_m = float(min_length_m)
        self.max_length_m = float(max_length_m)

    def length_m(self, f: StepFeatures) -> float:
        amp = max(f.acc_max_m_s2 - f.acc_min_m_s2, 0.0)
        c = self.coefficient.coefficient(f)
        length = c * math.sqrt(math.sqrt(amp))  # eq. 4
        return min(max(length, self.min_length_m), self.max_length_m)
