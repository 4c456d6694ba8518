"""The unified heading error model of Chen et al. (2010), eq. 12, learnt online from GPS course.

The paper writes the deviation between the true heading and the raw compass
heading ``xi'`` as five terms (eq. 12)::

    delta = A + B sin(xi') + C cos(xi') + D sin(2 xi') + E cos(2 xi') + omega

and fits ``A..E`` by least squares against GPS course during a one- or
two-minute calibration walk.  Here the fit is recursive and weighted, and runs
whenever GPS is good (:class:`core.gnss.training.OnlineTrainer` feeds it), so
no separate calibration walk is needed: the paper's "future work".

Conventions (:mod:`core`)
    Our heading ``psi`` is counter-clockwise from East; the paper's ``xi`` is
    a compass bearing, clockwise from North: ``xi = pi/2 - psi``.  The model is
    fitted in our convention, ``delta = course_psi - psi`` (true minus ours),
    with the regressors ``(1, sin psi, cos psi, sin 2psi, cos 2psi)``.
    Substituting ``xi = pi/2 - psi`` (``sin xi = cos psi``, ``cos xi = sin psi``,
    ``sin 2xi = sin 2psi``, ``cos 2xi = -cos 2psi``) and ``delta_xi = -delta_psi``
    gives the paper's coefficients from ours::

        A = -a,  B = -c,  C = -b,  D = -d,  E = +e

    (:meth:`HeadingErrorModel.paper_coefficients_deg`, for a table like the
    paper's Table II).

What the terms absorb here
    The paper's compass is a 2-axis one with no tilt compensation; its
    harmonics mostly model tilt and the platform's hard and soft iron.  Our
    heading comes from a tilt-compensated 3-axis filter
    (:mod:`core.pdr.attitude`) with an online hard/soft-iron calibration, so:

    * ``A`` (constant): the phone's yaw offset to the walking direction (the
      paper's misalignment ``beta``, a few degrees for a hand-held phone,
      tens of degrees or 180 deg in a pocket), the magnetic declination when
      it was not applied, and the mean of any steady local field;
    * the first harmonics (``sin psi``, ``cos psi``): residual hard iron the
      online calibration has not removed (a hard-iron offset ``b`` in a field
      of horizontal strength ``H`` gives a heading error ``~ |b|/H sin(psi - phase)``);
    * the second harmonics: residual soft iron;
    * ``omega``: the body's oscillation, step-to-step noise of a few degrees.

    A magnetometer-free heading (gyro only) has no harmonic error; ``A`` then
    absorbs the unknown initial yaw and the fit of the harmonics is refused
    until the headings are spread (see below), which a fixed offset never
    needs.

Spread of headings
    With one walking direction only, the five regressors are collinear (the
    harmonics are constants too) and a least-squares fit is meaningless.  The
    model therefore keeps two estimates side by side: ``A`` alone (a weighted
    mean) and the full five-term fit, and predicts with the full fit only
    once the accepted samples cover at least ``min_quadrants`` of the four
    90-degree quadrants and their mean resultant length is below
    ``max_resultant`` (1: one direction).  The full fit has a ridge prior on
    the harmonics (``harmonic_prior_sd_rad``), so that barely observed terms
    stay near zero and a heading never walked is predicted cautiously.

    Chosen on the simulator's tuning seeds (0-19, 5-minute outages, median
    end error): a hard switch needing three quadrants and a resultant below
    0.6 left the harmonics out on most walks (2.0 %); the ridge fit once two
    directions are walked does better (1.2 % with a 5-degree prior; 8 deg
    extrapolates harmonics too boldly to unseen headings: 1.3 %, mean 2.3 %;
    2 deg fits too little: 1.65 %).

Outliers
    A sample whose residual against the current prediction exceeds
    ``max(outlier_k * sd, outlier_floor_rad)`` is rejected once
    ``min_samples`` have been accepted (``sd`` is the running weighted
    residual SD); rejections are counted and returned as flags.

A new grip (issue #26)
    The gate cannot tell an outlier from a changed offset: a phone turned in
    the hand by more than the gate (45 deg on the simulator's walk of
    tests/test_gnss_relock.py) had every later sample rejected, so the model
    kept the old grip's offset for the rest of the walk and Chen's filter,
    once the fixes stopped agreeing with the steps, ran off at the old offset
    again (seed 1, 7 minutes: 25-86 m off for three minutes after it had taken
    the fixes back).  ``regrip_samples`` consecutive rejected samples whose
    residuals agree with each other (within ``outlier_floor_rad`` of their
    circular mean) are a new grip, not outliers: the model forgets the old
    one (:meth:`HeadingErrorModel.reset`, the starting model kept) and learns
    from those samples (:attr:`HeadingErrorModel.n_regrips` counts it).
    ``regrip_samples=0`` turns the rule off.  On by the tuning split, where it
    changes nothing (``benchmarks.gnss_faults --split tuning``: the simulator's
    fault walks, seeds 0-9, the IPIN tuning routes and the tuning walk
    thomasdingemanse_lopen's leave-out give every headline as before; the CI
    guard's ETH 3-min outage 14.418 % and simulated 5-min 0.971 % as before).

Which predictor (out-of-sample selection)
    Before it learns from a window the model predicts that window's deviation
    with three predictors: the starting model (zero, or the profile's), ``A``
    alone, and the full fit.  Their squared errors, forgotten by
    ``selection_forgetting`` per window, pick the one in use once
    ``min_select_samples`` windows have been seen (the full fit only if the
    spread check passes).  A model that fits noise therefore does not get
    used: on the ETH walk, whose calibrated magnetometer is broken (dip -24
    deg), the deviation wanders with time more than with heading and the
    harmonics fitted there predicted worse out of sample (residual SD 10.6
    deg) than no compensation (7.7 deg).

The attitude filter's lag (issue #26, 2026-12-07; ``LaggedRegressors``, off by default)
    Eq. 12 makes the heading error a function of the heading alone.  Our heading is not a compass's: the
    attitude filter (:mod:`core.pdr.attitude`) carries the heading through a turn on the gyroscope and pulls
    it to the magnetometer's slowly, so after each turn its error still holds the old heading's magnetic
    error (a residual hard iron: a first harmonic of several degrees) and reaches the new heading's with a
    time constant of some 20 s.  On the simulator's street walks (``gnss_eval``, TUNING seeds 0-19, the
    attitude error against the truth in 20-s bins) that is what the heading error left after eq. 12 is made
    of: seed 4 at 180-300 s, a turn from 206 to 136 deg, -2.4, -0.4, +0.4, +0.7, +0.9, +1.1 deg; a street
    block is walked in 30-90 s, so an outage's heading error is mostly such transients.  With
    ``lag_s > 0`` the regressors ``(1, sin psi, cos psi, sin 2psi, cos 2psi)`` go through that first-order
    lag step by step (:class:`LaggedRegressors`; a window's sample uses the mean of its steps' lagged
    regressors, the correction at a step its own): the model stays linear in its five coefficients, the
    constant term is untouched, and a lag of 0 is eq. 12.  Fitted to the truth over minutes 1-6 of the 20
    tuning walks (a ridge of 1 rad on the harmonics, not the model's 5 deg), a lag of 15-20 s leaves the
    least heading error over the 5-minute outage (RMS median 1.9 deg without a lag, 1.3 deg at 15-20 s, 1.7
    at 30 s); :class:`core.gnss.fusion.GpsFusion`'s ``heading_lag_s`` (20 s) is where it is used.

Forgetting
    A hand-held phone is re-gripped now and then, which changes ``A``: every
    accepted sample scales the old information by ``forgetting`` (0.98 keeps
    an effective memory of about 50 samples).

    Faster forgetting does not help (issue #26, 2026-12-06, simulator tuning seeds).
    The simulated heading error left after the five-term fit (the hand's drift) is
    bounded, not a random walk: its change over 30/60/120/300 s has an SD of
    1.4/1.7/1.9/1.9 deg (``gnss_eval`` seeds 0-9 and the fault walks 0-9), a
    Gauss-Markov process of about 1.35 deg and 40 s, so beyond a minute the long
    mean predicts best.  ``forgetting`` 0.95 / 0.9 / 0.995: the 5-minute outage
    (``gnss_eval``, seeds 0-7, ``ekf``) median 1.31 -> 1.33 / 1.50 / 1.39 %; the
    2-minute outage after the noisy minute (``gnss_faults``, seeds 0-9) 10.7 ->
    10.5 m at 0.9 and 10.0 m at 0.8, at the price of the 5-minute one.  The
    model's mean residual over the 5-minute outage is within 0.3 deg of what the
    same fit to the truth before the outage leaves (seeds 0-7), so what remains
    there is the wander itself; after the noisy minute it is mostly the stride
    scale: given the true scale, 10.7 -> 8.3 m (learnt at 180 s from 0-3 chords,
    -7 to +8 % off).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.conventions import wrap_angle

#: Names of the five coefficients in our convention (radians).
TERMS = ("a", "b_sin", "c_cos", "d_sin2", "e_cos2")


def regressors(heading_rad: float) -> np.ndarray:
    """``(1, sin psi, cos psi, sin 2psi, cos 2psi)`` of eq. 12 in our convention."""
    s, c = math.sin(heading_rad), math.cos(heading_rad)
    return np.array([1.0, s, c, 2.0 * s * c, c * c - s * s])


def _x(heading_rad: float, x) -> np.ndarray:
    return regressors(heading_rad) if x is None else np.asarray(x, dtype=float)


class LaggedRegressors:
    """The regressors of eq. 12 at the steps, each through a first-order lag of time constant ``lag_s`` (s):
    ``x_k = x_{k-1} + (1 - exp(-dt / lag_s)) (regressors(psi_k) - x_{k-1})`` (module docstring, "The attitude
    filter's lag").  ``lag_s = 0``: the regressors themselves (the paper's model)."""

    def __init__(self, lag_s: float = 0.0):
        if not (lag_s >= 0.0 and math.isfinite(lag_s)):
            raise ValueError(f"lag_s must be finite and >= 0, got {lag_s!r}")
        self.lag_s = float(lag_s)
        self.reset()

    def reset(self) -> None:
        self.x: np.ndarray | None = None
        self._t_ns: int | None = None

    def update(self, t_ns: int, heading_rad: float) -> np.ndarray:
        """The lagged regressors after a step at ``t_ns`` with our heading ``heading_rad`` (a non-finite heading
        leaves them as they were)."""
        if not math.isfinite(heading_rad):
            return self.x if self.x is not None else regressors(0.0)
        r = regressors(heading_rad)
        if self.lag_s <= 0.0 or self.x is None or self._t_ns is None:
            self.x = r
        else:
            dt = max((int(t_ns) - self._t_ns) * 1e-9, 0.0)
            self.x = self.x + (1.0 - math.exp(-dt / self.lag_s)) * (r - self.x)
        self._t_ns = int(t_ns)
        return self.x


@dataclass(frozen=True)
class SampleFlags:
    """What :meth:`HeadingErrorModel.add` did with one sample."""

    accepted: bool
    residual_rad: float  #: sample minus the prediction before it (rad)
    reason: str = ""  #: why it was rejected ("" when accepted; "new grip": accepted as one, see the class)


class HeadingErrorModel:
    """Recursive weighted least squares of eq. 12 with a spread check and outlier rejection.

    Parameters
    ----------
    offset_prior_sd_rad : float
        Prior SD of ``A`` (rad); large: the offset is unknown at the start.
    harmonic_prior_sd_rad : float
        Prior SD (ridge) of the four harmonic coefficients (rad).
    min_quadrants : int
        The harmonics are used only when the accepted samples' headings fall in at
        least this many of the four 90-degree quadrants ...
    max_resultant : float
        ... and their mean resultant length (1: one direction) is below this.
    outlier_k, outlier_floor_rad : float
        Rejection threshold ``max(outlier_k * sd, outlier_floor_rad)`` on the residual.
    min_samples : int
        Samples accepted before outliers are rejected (the model must know something first).
    forgetting : float
        Factor (0 < f <= 1) on the old information per accepted sample.
    coefficients_rad : sequence of 5 floats or None
        A starting model (a persisted profile); None: zeros.
    min_select_samples, selection_forgetting : float
        The out-of-sample selection of the predictor starts after this many (forgotten-weighted)
        samples, and forgets old errors by this factor per sample.
    regrip_samples : int
        Consecutive rejected samples agreeing with each other that make a new grip (see "A new grip" in the
        module docstring); 0: never.
    """

    def __init__(self, *, offset_prior_sd_rad: float = math.radians(45.0),
                 harmonic_prior_sd_rad: float = math.radians(5.0), min_quadrants: int = 2,
                 max_resultant: float = 0.9, outlier_k: float = 3.0, outlier_floor_rad: float = math.radians(12.0),
                 min_samples: int = 4, forgetting: float = 0.98, coefficients_rad=None,
                 min_select_samples: float = 6.0, selection_forgetting: float = 0.95, regrip_samples: int = 2):
        if not 0.0 < forgetting <= 1.0:
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting}")
        self.offset_prior_sd_rad = float(offset_prior_sd_rad)
        self.harmonic_prior_sd_rad = float(harmonic_prior_sd_rad)
        self.min_quadrants = int(min_quadrants)
        self.max_resultant = float(max_resultant)
        self.outlier_k = float(outlier_k)
        self.outlier_floor_rad = float(outlier_floor_rad)
        self.min_samples = int(min_samples)
        self.forgetting = float(forgetting)
        self.min_select_samples = float(min_select_samples)
        self.selection_forgetting = float(selection_forgetting)
        self.regrip_samples = int(regrip_samples)
        self._start = np.zeros(5) if coefficients_rad is None else np.asarray(coefficients_rad, dtype=float).copy()
        if self._start.shape != (5,) or not np.all(np.isfinite(self._start)):
            raise ValueError("coefficients_rad must be 5 finite numbers (a, b_sin, c_cos, d_sin2, e_cos2)")
        self.reset()

    def reset(self) -> None:
        prior = np.array([self.offset_prior_sd_rad] + [self.harmonic_prior_sd_rad] * 4) ** -2
        #: information matrix and vector of the full fit (ridge prior about the start model)
        self._info = np.diag(prior)
        self._vec = self._info @ self._start
        # A alone: weighted mean (sum of weights, weighted sum), started from the start model's A
        self._w_a = 0.0
        self._sum_a = 0.0
        self._quadrant_w = np.zeros(4)
        self._sum_cos = 0.0
        self._sum_sin = 0.0
        self._sum_w = 0.0
        self._res_w = 0.0
        self._res_sq = 0.0
        self.n_accepted = 0
        self.n_rejected = 0
        self._pq = {"start": 0.0, "offset": 0.0, "full": 0.0}
        self._pq_n = 0.0
        #: the consecutive rejected samples (heading, deviation, weight), for the new-grip rule
        self._rejected_run: list[tuple] = []
        self.n_regrips = 0  #: new grips found (kept across the reset a new grip makes)

    # -- the estimate ---------------------------------------------------------
    @property
    def harmonics_trusted(self) -> bool:
        """Whether the samples' headings are spread enough to use the harmonic terms."""
        if self._sum_w <= 0:
            return False
        quadrants = int(np.sum(self._quadrant_w > 0.05 * self._sum_w))
        resultant = math.hypot(self._sum_cos, self._sum_sin) / self._sum_w
        return quadrants >= self.min_quadrants and resultant < self.max_resultant

    def _offset_only(self) -> np.ndarray:
        a = self._start[0] if self._w_a <= 0 else self._sum_a / self._w_a
        out = self._start.copy() if self._w_a <= 0 else np.zeros(5)
        out[0] = a
        return out

    @property
    def selected(self) -> str:
        """The predictor in use: ``"start"`` (the starting model), ``"offset"`` (``A`` alone) or ``"full"``.

        ``"full"`` needs the spread check; after ``min_select_samples`` samples the
        predictor with the smallest recent out-of-sample error is used (see the module docstring).
        """
        candidates = ["offset"] + (["full"] if self.harmonics_trusted else [])
        if self._pq_n < self.min_select_samples:
            return candidates[-1]
        return min(["start"] + candidates, key=lambda k: self._pq[k])

    def coefficients_rad(self) -> np.ndarray:
        """The five coefficients in use (:attr:`selected`): the start model, ``(A, 0, 0, 0, 0)`` or the full fit."""
        sel = self.selected
        if sel == "full":
            return np.linalg.solve(self._info, self._vec)
        if sel == "start":
            return self._start.copy()
        return self._offset_only()

    def correction_rad(self, heading_rad: float, x=None) -> float:
        """``delta(psi)`` of eq. 12: add it to our heading to get the course.  ``x``: the regressors to use instead
        of ``regressors(heading_rad)`` (the lagged ones of :class:`LaggedRegressors`)."""
        return float(_x(heading_rad, x) @ self.coefficients_rad())

    def _effective_n(self) -> float:
        return min(float(self.n_accepted), 1.0 / (1.0 - self.forgetting) if self.forgetting < 1.0 else math.inf)

    def _scatter(self) -> float:
        """Residual variance relative to what the sample weights claim (>= 1)."""
        if self._res_w <= 0 or self._sum_w <= 0:
            return 1.0
        return max(1.0, self.residual_sd_rad() ** 2 * self._sum_w / max(self._effective_n(), 1.0))

    def full_fit_variance_rad2(self, heading_rad: float, x=None) -> float:
        """Predictive variance of the five-term fit at a heading (rad^2; at the regressors ``x`` if given): large
        where no sample was."""
        x = _x(heading_rad, x)
        return float(x @ np.linalg.solve(self._info, x)) * self._scatter()

    def correction_sd_rad(self, heading_rad: float, x=None) -> float:
        """Standard deviation of :meth:`correction_rad` (rad).

        With the full fit, its predictive SD; with ``A`` alone, the larger of
        the SD of ``A`` and the full fit's predictive SD, so that a heading
        never walked (where the untrusted harmonics could be anything their
        prior allows) is honestly uncertain and the walked one is not.
        """
        full = self.full_fit_variance_rad2(heading_rad, x)
        if self.harmonics_trusted:
            return math.sqrt(full)
        var_a = self._scatter() / self._w_a if self._w_a > 0 else self.offset_prior_sd_rad ** 2
        return math.sqrt(max(var_a, full))

    def residual_sd_rad(self) -> float:
        """Weighted RMS of the accepted samples' residuals (rad); nan before any."""
        return math.sqrt(self._res_sq / self._res_w) if self._res_w > 0 else math.nan

    def paper_coefficients_deg(self) -> dict:
        """The coefficients in the paper's convention (compass bearing, true minus raw), degrees (Table II)."""
        a, b, c, d, e = (math.degrees(v) for v in self.coefficients_rad())
        return {"A": -a, "B": -c, "C": -b, "D": -d, "E": e}

    # -- learning ---------------------------------------------------------------
    def add(self, heading_rad: float, deviation_rad: float, weight: float = 1.0, x=None) -> SampleFlags:
        """One sample: our heading ``psi`` and ``delta = course - psi`` (rad), with a weight (1/rad^2 scale); ``x``:
        the sample's regressors if not ``regressors(psi)`` (the window's mean lagged ones, :class:`LaggedRegressors`;
        the spread check keeps ``psi``)."""
        if not (math.isfinite(heading_rad) and math.isfinite(deviation_rad) and weight > 0 and math.isfinite(weight)):
            self.n_rejected += 1
            return SampleFlags(False, math.nan, "not finite")
        dev = wrap_angle(float(deviation_rad))
        x = _x(heading_rad, x)
        pred = self.correction_rad(heading_rad, x)
        res = wrap_angle(dev - pred)
        if self.n_accepted >= self.min_samples:
            # the gate knows what the model can know: the full fit's predictive variance is large at a
            # heading never walked before (a one-direction A is no prediction for the opposite direction)
            full = float(x @ np.linalg.solve(self._info, self._vec))
            r_full = wrap_angle(dev - full)
            limit = max(self.outlier_k * math.sqrt(1.0 / weight + self.full_fit_variance_rad2(heading_rad, x)),
                        self.outlier_floor_rad)
            if abs(r_full) > limit:
                self.n_rejected += 1
                self._rejected_run.append((float(heading_rad), dev, float(weight), x))
                if self._new_grip():
                    return self._regrip(res)
                return SampleFlags(False, res, f"residual {math.degrees(r_full):.1f} deg > "
                                               f"{math.degrees(limit):.1f} deg")
        self._rejected_run.clear()
        # out-of-sample errors of the three predictors, for the selection (before this sample is learnt)
        g = self.selection_forgetting
        for k, p in (("start", float(x @ self._start)), ("offset", float(x @ self._offset_only())),
                     ("full", float(x @ np.linalg.solve(self._info, self._vec)))):
            self._pq[k] = g * self._pq[k] + wrap_angle(dev - p) ** 2
        self._pq_n = g * self._pq_n + 1.0
        f = self.forgetting
        # unwrap the sample next to the prediction, so that +-180 deg offsets average correctly
        dev = pred + res
        self._info = f * self._info + weight * np.outer(x, x)
        self._vec = f * self._vec + weight * dev * x
        a_now = self._sum_a / self._w_a if self._w_a > 0 else dev
        self._sum_a = f * self._sum_a + weight * (a_now + wrap_angle(dev - a_now))
        self._w_a = f * self._w_a + weight
        q = int((heading_rad % (2.0 * math.pi)) // (math.pi / 2.0)) % 4
        self._quadrant_w *= f
        self._quadrant_w[q] += weight
        self._sum_cos = f * self._sum_cos + weight * math.cos(heading_rad)
        self._sum_sin = f * self._sum_sin + weight * math.sin(heading_rad)
        self._sum_w = f * self._sum_w + weight
        self._res_w = f * self._res_w + weight
        self._res_sq = f * self._res_sq + weight * res * res
        self.n_accepted += 1
        return SampleFlags(True, res)

    def _new_grip(self) -> bool:
        """Whether the last ``regrip_samples`` rejected samples in a row agree on one new offset: their residuals
        against the model (what it predicts at each one's heading) within ``outlier_floor_rad`` of their circular
        mean."""
        n = self.regrip_samples
        run = self._rejected_run[-n:] if n > 0 else []
        if n <= 0 or len(run) < n:
            return False
        r = np.array([wrap_angle(d - self.correction_rad(h, x)) for h, d, _, x in run])
        mean = math.atan2(float(np.mean(np.sin(r))), float(np.mean(np.cos(r))))
        return all(abs(wrap_angle(float(v) - mean)) <= self.outlier_floor_rad for v in r)

    def _regrip(self, residual_rad: float) -> SampleFlags:
        """A new grip: the old one's model forgotten, the run of rejected samples learnt afresh."""
        run = self._rejected_run[-self.regrip_samples:]
        n_rejected, n_regrips = self.n_rejected - len(run), self.n_regrips + 1
        self.reset()
        self.n_rejected, self.n_regrips = n_rejected, n_regrips
        for h, d, w, x in run:
            self.add(h, d, w, x)
        return SampleFlags(True, residual_rad, "new grip")

    # -- persistence ------------------------------------------------------------
    def to_dict(self) -> dict:
        """The learnt model for a profile: coefficients (deg, our convention), whether harmonics were trusted."""
        return {"coefficients_deg": [math.degrees(v) for v in self.coefficients_rad()],
                "terms": list(TERMS), "harmonics_trusted": self.harmonics_trusted, "selected": self.selected,
                "n_samples": self.n_accepted, "residual_sd_deg": math.degrees(self.residual_sd_rad())
                if self._res_w > 0 else None, "new_grips": self.n_regrips}
