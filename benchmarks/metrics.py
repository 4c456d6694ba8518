"""Accuracy metrics of the benchmark, each with its formula.

Conventions as in :mod:`core`: times are ``int64`` nanoseconds, positions are
local East/North metres, headings are radians counter-clockwise from East.
Every function is pure numpy and works on plain arrays, so the same metric is
applied to our track and to every peer's track.

The metrics of a track against ground truth -- step-count and walked-distance
error, landmark errors (absolute and best-fit), loop closure, segment heading
error, distance from a reference track such as GPS -- are in
:mod:`core.metrics` (``pdr replay`` shows them for recordings that carry
truth) and re-exported here; their formulas are in that module's docstring.
Defined here, for the benchmark only:

===============================  ==========================================================
step timing F1                   one-to-one matching of estimated to true step instants
                                 within ``+-tol`` (0.2 s); ``P = TP/N_est``,
                                 ``R = TP/N_true``, ``F1 = 2PR/(P+R)``
summaries                        nan-skipping mean, median and mean of ``|.|`` over trials
===============================  ==========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.metrics import (  # noqa: F401 - the metrics shared with `pdr replay` live in core; re-exported here
    LOOP_CLOSED_TOLERANCE_M, MAX_STEP_DURATION_S, MIN_SEGMENT_LENGTH_M, MIN_SEGMENT_STEPS, LandmarkErrors,
    TrackErrors, best_fit_rotation, circular_mean, dead_reckon, distance_error_pct, landmark_errors,
    polyline_length, positions_at, reference_track_errors, rotate, segment_heading_errors,
    step_count_error_pct,
)

#: tolerance of the step timing match (s), from the issue
STEP_MATCH_TOLERANCE_S = 0.2

# ---------------------------------------------------------------------------
# steps


@dataclass(frozen=True)
class StepMatch:
    """Result of :func:`match_steps`."""

    tp: int  #: estimated steps matched to a true step
    n_est: int
    n_true: int
    #: median of (estimated - true) time over the matched pairs (s): the detector's lag
    median_lag_s: float

    @property
    def precision(self) -> float:
        return self.tp / self.n_est if self.n_est else math.nan

    @property
    def recall(self) -> float:
        return self.tp / self.n_true if self.n_true else math.nan

    @property
    def f1(self) -> float:
        """``F1 = 2 P R / (P + R) = 2 TP / (N_est + N_true)``."""
        d = self.n_est + self.n_true
        return 2.0 * self.tp / d if d else math.nan


def match_steps(est_t_ns, true_t_ns, tol_s: float = STEP_MATCH_TOLERANCE_S) -> StepMatch:
    """Match estimated step instants to true ones, one to one, within ``+-tol_s``.

    Both lists are sorted and walked together: an estimated step ``e`` and a
    true step ``g`` match when ``|e - g| <= tol``; the earlier of two
    unmatched instants that cannot match any more is dropped.  For matching
    within a fixed window on a line this greedy sweep finds a maximum
    matching (as many true positives as any one-to-one assignment).

    Returns a :class:`StepMatch` with ``TP``; precision ``TP / N_est``,
    recall ``TP / N_true`` and ``F1 = 2 TP / (N_est + N_true)``.
    """
    e = np.sort(np.asarray(est_t_ns, dtype=np.int64))
    g = np.sort(np.asarray(true_t_ns, dtype=np.int64))
    tol = int(round(tol_s * 1e9))
    i = j = 0
    lags = []
    while i < len(e) and j < len(g):
        d = int(e[i]) - int(g[j])
        if d < -tol:
            i += 1  # estimated step too early for any remaining true step: false positive
        elif d > tol:
            j += 1  # true step too early for any remaining estimated step: missed
        else:
            lags.append(d)
            i += 1
            j += 1
    lag = float(np.median(lags)) * 1e-9 if lags else math.nan
    return StepMatch(tp=len(lags), n_est=len(e), n_true=len(g), median_lag_s=lag)


def step_timing_f1(est_t_ns, true_t_ns, tol_s: float = STEP_MATCH_TOLERANCE_S) -> float:
    """F1 score of step instants (see :func:`match_steps`)."""
    return match_steps(est_t_ns, true_t_ns, tol_s).f1


# ---------------------------------------------------------------------------
# summaries


def nanmean(values) -> float:
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if len(v) else math.nan


def nanmedian(values) -> float:
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else math.nan


def median_counting_failures(values, nan_is_failure: bool = True) -> float:
    """Median with a failed recording (None, or an inf error) counted as +inf, never dropped; nan when there are
    no values.

    ``nan_is_failure``: a nan value is a failure too (landmark error, GPS distance); else it is "does not
    apply" and left out (loop closure of a walk that is no loop).
    """
    v = [math.inf if (x is None or (nan_is_failure and x != x)) else float(x) for x in values
         if x is None or nan_is_failure or x == x]
    return float(np.median(v)) if v else math.nan


def median_present(values) -> float | None:
    """Median over the values present (None and nan: not measured here, left out); +inf (a failure) is kept.
    None when nothing is present."""
    v = [x for x in values if x is not None and x == x]
    return float(np.median(v)) if v else None


def median_where_applicable(values) -> float | None:
    """Median over the values that apply (None: does not apply, left out); a non-finite value is a failed run and
    enters as +inf, never dropped.  None when nothing applies."""
    v = [x if math.isfinite(x) else math.inf for x in values if x is not None]
    return float(np.median(v)) if v else None


#: the step-count error of a recording whose run failed: it gave no steps (-100 %)
FAILED_STEP_ERR_PCT = -100.0


def mean_abs(values) -> float:
    """Mean of ``|x|`` (e.g. step-count MAE from signed errors) over the values present: None and nan (not
    measured) are left out, an infinite error (a failure) is kept and makes the mean infinite."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[~np.isnan(v)]
    return float(np.mean(np.abs(v))) if len(v) else math.nan
