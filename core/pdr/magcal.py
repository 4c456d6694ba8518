"""Magnetometer calibration (hard and soft iron) and trust (quasi-static field detection).

Two small streaming estimators for the attitude filter, numpy only (they run on
the phone).  Both follow :mod:`core`'s conventions: ``t_ns`` int64 on the sensor
clock, the Android device frame ``b``, the ENU navigation frame ``n``, the
quaternion ``q = (w, x, y, z)`` rotating ``b`` into ``n``, the field in uT.
Each has its settings as keyword arguments of ``__init__``, a streaming
``update()`` and a batch ``run()`` that loops the very same kernel (so the
batch equals the streaming sample by sample, whatever the chunking), and
reports its diagnostics as data: a frozen dataclass ``status``.

:class:`MagCalibrator` -- online hard- and soft-iron calibration
================================================================
The phone's rotations move the Earth's field over the sensor's sphere of
directions.  A hard-iron offset ``b`` (uT; magnetised parts and the sensor's
own offset) shifts that sphere, soft iron (induced magnetisation, axis
gains) turns it into an ellipsoid::

    m_true = A (m_raw - b),   |m_true| = F   (the local field strength, uT)

with ``A`` symmetric positive definite.  ``A`` is fixed up to a scale factor
only (``c A`` with field ``c F`` fits as well): we normalise ``det A = 1``,
so ``F`` is the geometric mean of the ellipsoid's semi-axes and the
calibration does not change the size of the field on average.  A rotation
part of the distortion (``A`` not symmetric) cannot be seen by a
rotation-only fit at all and is taken as zero (the symmetric polar factor).

Algebraic fit (:func:`fit_ellipsoid`).  Expanding ``|A (m - b)|^2 = F^2``
with ``A^T A = A^2``::

    m^T Q m + g^T m + k = 0,   Q = s A^2,  g = -2 Q b,  k = b^T Q b - s F^2

for any scale ``s != 0``.  We fix the scale by ``trace Q = 3``: for an
ellipsoid ``Q`` is positive definite, so its trace is never zero and the
normalisation excludes no true solution (fixing ``k = -1`` instead fails
when the origin lies near the ellipsoid, i.e. for large offsets), and it
does not depend on how the sensor axes are turned.  Write
``Q = I + Q0`` with the trace-free symmetric
``Q0 = [[p1, p4, p5], [p4, p2, p6], [p5, p6, -p1 - p2]]``; then for a sample
``m = (x, y, z)`` the quadric is linear in ``theta = (p1, p2, p4, p5, p6,
g1, g2, g3, k)``::

    [x^2 - z^2, y^2 - z^2, 2xy, 2xz, 2yz, x, y, z, 1] . theta = -(x^2 + y^2 + z^2)

an ordinary linear least-squares problem in 9 unknowns (``numpy.linalg.lstsq``;
at least 9 samples in general position).  From ``theta``::

    b = -Q^{-1} g / 2,   r^2 = b^T Q b - k  (= s F^2),
    Q = V diag(lam) V^T  (lam > 0 and r^2 > 0, or the quadric is no ellipsoid)
    semi-axes  a_i = sqrt(r^2 / lam_i),   F = (a_1 a_2 a_3)^(1/3),
    A = F V diag(sqrt(lam / r^2)) V^T     (det A = 1)

The samples are centred and scaled to unit RMS radius before the solve (the
raw design matrix mixes uT^2 and 1) and the result is mapped back
(``b = c + s b'``, ``F = s F'``, ``A = A'``).  The algebraic distance is not
the geometric one; the bias it causes is of the order ``sigma^2 / F``
(< 0.01 uT for phone noise of 0.5 uT).  The quality reported is geometric:
the RMS of ``|A (m_i - b)| - F`` over the samples (uT).  References for the
model and for fitting it: Vasconcelos et al. 2011, "Geometric approach to
strapdown magnetometer calibration in sensor frame", IEEE Trans. Aerosp.
Electron. Syst. 47(2); Li and Griffiths 2004, "Least squares ellipsoid
specific fitting", GMAP.

Sample store.  The fit is only as good as the spread of the samples over
directions, and a phone at 50-100 Hz sees the same direction for seconds.
Samples are therefore kept in ``n_bins`` equal-area bins on the sphere of
directions -- ``bin_bands`` bands of equal ``z`` width (equal area by
Archimedes' hat-box theorem), each cut into ``2 bin_bands`` sectors of
azimuth -- of the vector ``A (m_raw - b)`` about the current centre
estimate; each bin keeps its ``samples_per_bin`` newest samples (newest
wins) and samples older than ``sample_max_age_s`` expire, so the store is
bounded (``samples_per_bin n_bins``) and describes the recent past.  The
*coverage* is the fraction of occupied bins.  Until a fit is accepted the
centre is, at every attempt, the best sphere through the store and a
reservoir of the last ``bootstrap_window_s`` (10 readings per second), and
the store is re-binned about it; afterwards it is the fit in force.

Robustness.  Every fit (:meth:`MagCalibrator._trimmed`) starts from all
samples, the newest half and the newest quarter, keeps the start with the
most inliers (``|residual| <= outlier_fraction F``) and is repeated on the
inliers; outliers leave the store with an accepted fit.  This is what
copes with the phone's own calibration jumping while the user waves the
phone (seen in the IPIN 2023 files: 58 -> 24 uT within 5 s).

Acceptance.  A fit is attempted at most every ``refit_interval_s`` and only
when ``refit_min_new_samples`` samples were stored (or a new bin filled)
since the last attempt -- the per-sample cost is a few dozen float
operations.  With coverage below ``min_coverage_soft_iron`` only the hard
iron is fitted (a sphere, 4 unknowns, ``A = I``: :func:`fit_sphere`); the
9 unknowns of the ellipsoid need more directions.  A fit is accepted when,
in order: enough samples; coverage >= ``min_coverage``; the quadric is an
ellipsoid (a sphere); ``F`` lies in ``field_range_uT`` (a geomagnetic
field, not a fridge door); the axis ratio ``a_max / a_min <=
max_axis_ratio`` (a well-conditioned soft iron); the inliers' coverage about
the candidate is >= ``min_coverage``; the directions are not nearly coplanar
(``sqrt`` of the smallest eigenvalue of the covariance of the calibrated
unit directions >= ``min_direction_spread``; 0.577 for the whole sphere,
0.289 for a hemisphere, 0 for one plane of rotation); the RMS residual <=
``max_residual_fraction F``; and, when a fit is in force that came from
more coverage, that fit no longer explains the inliers within the same
residual bound (so a good calibration is not replaced by a worse-covered
one).  The fit in force stays (``apply``) when later attempts are
rejected.  A phone turned about one axis only (flat on a table, or the ETH
walk held flat) never reaches the coverage: its offset along that axis is
not observable from rotations.

Defaults were chosen on the IPIN 2023 tuning routes (01, 02, 21, 22; see
``benchmarks/magcal_check.py``): every file gets a fit during its initial
waving (median 9 s after the start, at most 23 s).

:class:`QuasiStaticField` -- when to trust the magnetometer
===========================================================
Indoors the field is bent by steel: its direction differs from the Earth's
by tens of degrees from one metre to the next, but at any one place it is
constant.  Afzal et al. (2011, "Use of Earth's magnetic field for mitigating
gyroscope errors regardless of magnetic perturbation", Sensors 11(12),
11390-11414) call such periods *quasi-static field* (QSF) periods and detect
them by comparing the field seen over a short window with what the gyroscope
predicts: if the field, rotated by the gyroscope's attitude change into a
common frame, does not move, it can correct the gyroscope even though it is
perturbed.  Here the attitude filter's gyro-propagated quaternion rotates
each calibrated reading into the navigation frame, ``m_n = R(q) m_b``, and
over the trailing ``window_s``:

* direction spread: the largest angle (deg) between a reading's direction
  and the window's mean direction;
* norm spread: the largest deviation (uT) of ``|m_n|`` from its window mean.

Both small means the field is quasi-static (``steady``).  The gyro
attitude drifts slowly (fractions of a degree per second), so only the
change over the window matters, never the absolute heading.  To be
*trusted* as a heading reference the steady field must also look like the
Earth's: its mean norm within ``norm_tol_uT`` of the reference field and its
dip (``atan2(-up, horizontal)``, deg; the tilt comes from gravity, so it is
absolute) within ``dip_tol_deg`` of the reference dip.  The reference is
given (``reference_field_uT``, ``reference_dip_deg``, :meth:`set_reference`,
e.g. the calibrator's ``field_uT``) or learnt as a slow average
(``reference_time_constant_s`` of steady time) over steady windows.

Defaults (window 0.75 s, 2.5 deg, 1.5 uT, 6 uT, 10 deg) were chosen on the
IPIN 2023 tuning routes with the attitude of a gyro + accelerometer filter
(``benchmarks/magcal_check.py``): the direction spread is the best single
predictor of the magnetometer's heading error there, the dip the weakest.
About a quarter of the walking readings are trusted and their per-reading
heading error is smaller than that of all readings, but averaged over a
landmark segment the trusted readings are no better: a bent field that
stands still and keeps its norm and dip cannot be told from the Earth's.

Reasons (``QSF_REASONS``), in the order they are checked: 'invalid input'
(non-finite reading or quaternion), 'warming up' (window not yet full after
the start or a gap, or the reference not yet learnt), 'norm moving',
'direction moving', 'norm off', 'dip off', 'steady' (trusted).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass

import numpy as np

__all__ = [
    "EllipsoidFitError", "fit_ellipsoid", "fit_sphere", "MagCalibrator", "MagCalStatus", "MagCalTrace",
    "QuasiStaticField", "QsfStatus", "QsfTrace", "QSF_REASONS", "MAGCAL_STATES",
]

#: states of :class:`MagCalibrator`
MAGCAL_STATES = ("collecting", "calibrated", "rejected fit")
#: reasons of :class:`QuasiStaticField`, in the order they are checked
QSF_REASONS = ("invalid input", "warming up", "norm moving", "direction moving", "norm off", "dip off", "steady")

_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
#: what :meth:`MagCalibrator.reset` derives from the settings for the per-reading path (not run state)
_DERIVED = frozenset(("_max_nrm2", "_bootstrap_ns", "_r_min", "_sector_scale"))
_RECENT_DT_NS = 100_000_000  # bootstrap reservoir: one reading per 0.1 s


# ---------------------------------------------------------------------------
# ellipsoid fit (pure)


class EllipsoidFitError(ValueError):
    """The samples do not determine an ellipsoid; ``str()`` says why (short, for a status line)."""


def _centred(samples: np.ndarray, n_min: int):
    """``(centre, scale, (samples - centre) / scale)`` with the RMS distance as the scale: a well-conditioned fit.

    The means as ``add.reduce`` over the count, which is what ``ndarray.mean`` computes (the same floats),
    without its wrapping: the fits run on a hundred-odd samples, where numpy's per-call cost is the cost.
    """
    n = len(samples)
    if n < n_min:
        raise EllipsoidFitError(f"too few samples ({n} < {n_min})")
    c = np.add.reduce(samples, axis=0) / n
    d = samples - c
    s = math.sqrt(float(np.add.reduce(np.add.reduce(d * d, axis=1))) / n)
    if not s > 1e-9:
        raise EllipsoidFitError("samples coincide")
    return c, s, d / s


def _norms(d: np.ndarray) -> np.ndarray:
    """Row norms of ``d`` (n, 3): ``numpy.linalg.norm(d, axis=1)``'s own arithmetic, without its wrapping."""
    return np.sqrt(np.add.reduce(d * d, axis=1))


#: the soft iron of a sphere fit (read-only: shared by every sphere fit)
_EYE = np.eye(3)
_EYE.flags.writeable = False


def _fit(samples: np.ndarray):
    """Kernel of :func:`fit_ellipsoid` on finite samples: ``(offset, A, F, axis ratio)`` (the residual: :func:`_rms`)."""
    c, s, u = _centred(samples, 9)
    n = len(u)
    x, y, z = u.T
    xx, yy, zz = x * x, y * y, z * z
    design = np.empty((9, n))  # transposed: each regressor written whole (lstsq copies into column order anyway)
    np.subtract(xx, zz, out=design[0])
    np.subtract(yy, zz, out=design[1])
    x2 = 2 * x
    np.multiply(x2, y, out=design[2])
    np.multiply(x2, z, out=design[3])
    np.multiply(2 * y, z, out=design[4])
    design[5], design[6], design[7], design[8] = x, y, z, 1.0
    theta, _, rank, _ = np.linalg.lstsq(design.T, -(xx + yy + zz), rcond=None)
    if rank < 9:
        raise EllipsoidFitError(f"degenerate geometry (rank {rank} < 9)")
    p1, p2, p4, p5, p6, g1, g2, g3, k = theta.tolist()
    q = np.array([[1.0 + p1, p4, p5], [p4, 1.0 + p2, p6], [p5, p6, 1.0 - p1 - p2]])
    lam, vec = np.linalg.eigh(q)
    if not lam[0] > 1e-9 * lam[2]:
        raise EllipsoidFitError("not an ellipsoid (quadric not positive definite)")
    b_s = -0.5 * np.linalg.solve(q, np.array([g1, g2, g3]))
    r2 = float(b_s @ q @ b_s - k)
    if not r2 > 0.0:
        raise EllipsoidFitError("not an ellipsoid (imaginary)")
    semi = np.sqrt(r2 / lam)
    field_s = float(np.prod(semi) ** (1.0 / 3.0))
    a = (vec * (field_s * np.sqrt(lam / r2))) @ vec.T
    a = 0.5 * (a + a.T)
    return c + s * b_s, a, s * field_s, float(semi.max() / semi.min())


def _fit_sphere(samples: np.ndarray):
    """Hard iron only: the best sphere ``|m - b| = F`` (linear: ``|m|^2 = 2 b.m + F^2 - |b|^2``), as :func:`_fit`."""
    c, s, x = _centred(samples, 4)
    design = np.empty((len(x), 4))
    np.multiply(x, 2.0, out=design[:, :3])
    design[:, 3] = 1.0
    theta, _, rank, _ = np.linalg.lstsq(design, np.add.reduce(x * x, axis=1), rcond=None)
    if rank < 4:
        raise EllipsoidFitError(f"degenerate geometry (rank {rank} < 4)")
    b_s = theta[:3]
    r2 = float(theta[3] + b_s @ b_s)
    if not r2 > 0.0:
        raise EllipsoidFitError("not a sphere (imaginary)")
    return c + s * b_s, _EYE, s * math.sqrt(r2), 1.0


def _residuals(m: np.ndarray, offset, a, field) -> np.ndarray:
    """``|A (m_i - b)| - F`` per sample (a sphere's ``A`` is the identity: no product needed, the same floats)."""
    d = m - offset
    return _norms(d if a is _EYE else d @ a.T) - field


def _rms(m: np.ndarray, offset, a, field) -> float:
    """RMS of :func:`_residuals` (uT): the quality of a fit, computed for the fit that is kept only."""
    resid = _residuals(m, offset, a, field)
    return math.sqrt(float(np.add.reduce(resid * resid)) / len(resid))


def fit_sphere(samples) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Hard-iron-only fit (soft iron = identity), same interface as :func:`fit_ellipsoid`.

    Linear least squares on ``|m|^2 = 2 b.m + (F^2 - |b|^2)`` (4 unknowns),
    well determined from less coverage than the ellipsoid's 9.
    """
    m = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
    m = m[np.all(np.isfinite(m), axis=1)]
    offset, _, field, _ = _fit_sphere(m)
    return offset, np.eye(3), field, _rms(m, offset, _EYE, field)


def fit_ellipsoid(samples) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Algebraic least-squares ellipsoid fit (derivation in the module docstring).

    ``samples`` (n, 3): raw magnetometer readings (uT); non-finite rows are
    ignored.  Returns ``(offset_uT (3,), soft_iron (3, 3) symmetric with det 1,
    field_uT, residual_uT)`` such that ``soft_iron @ (m - offset)`` has norm
    ``field_uT`` on the fitted ellipsoid, ``residual_uT`` being the RMS of
    ``|soft_iron (m_i - offset)| - field_uT``.  Raises :class:`EllipsoidFitError`
    when the samples determine no ellipsoid (fewer than 9, coplanar, or the
    best quadric is not an ellipsoid).  It does not judge whether the
    directions cover enough of the sphere: :class:`MagCalibrator` does.
    """
    m = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
    m = m[np.all(np.isfinite(m), axis=1)]
    offset, a, field, _ = _fit(m)
    return offset, a, field, _rms(m, offset, a, field)


# ---------------------------------------------------------------------------
# online calibrator


@dataclass(frozen=True)
class MagCalStatus:
    """Diagnostics of :class:`MagCalibrator` (offset, soft iron, field, residual: the calibration in force)."""

    state: str  #: 'collecting' | 'calibrated' | 'rejected fit'
    reason: str  #: outcome of the last attempt ('accepted', or why not), '' before the first
    model: str  #: model of the fit in force: 'hard iron' | 'hard+soft iron' ('' before a fit)
    offset_uT: tuple  #: hard-iron offset b (3 floats, uT); zeros before a fit
    soft_iron: tuple  #: soft-iron matrix A (3 rows of 3), symmetric, det 1; identity before a fit
    field_uT: float  #: field strength F of the accepted fit (nan before)
    residual_uT: float  #: RMS of |A (m - b)| - F over the fitted samples (nan before)
    axis_ratio: float  #: longest / shortest semi-axis of the accepted ellipsoid (nan before)
    fit_coverage: float  #: coverage of the inliers of the fit in force, about it (nan before)
    coverage: float  #: fraction of direction bins holding a sample now (0-1)
    n_samples: int  #: samples in the store now
    n_valid: int  #: finite readings seen
    n_invalid: int  #: readings skipped (non-finite or norm above max_raw_norm_uT)
    n_fits: int  #: fits computed (ellipsoid or sphere)
    n_accepted: int  #: fits accepted
    t_fit_ns: int  #: time of the accepted fit in force (-1 before)
    t_first_fit_ns: int  #: time the first fit was accepted (-1 before)


@dataclass(frozen=True)
class MagCalTrace:
    """Output of :meth:`MagCalibrator.run`."""

    t_ns: np.ndarray  #: (n,) int64
    mag_cal_b: np.ndarray  #: (n, 3) calibrated field (uT; identity before a fit, non-finite input stays so)
    fit_index: np.ndarray  #: (n,) number of accepted fits in force at the sample (0 = uncalibrated)
    fits: tuple  #: MagCalStatus at every accepted fit
    status: MagCalStatus  #: after the last sample


class MagCalibrator:
    """Online hard- and soft-iron magnetometer calibration from the phone's own rotations.

    ``m_cal = update(t_ns, mx, my, mz)`` per raw reading (uT) returns the
    calibrated reading (the identity until a fit is accepted); ``status``
    says where it stands.  Method and acceptance tests: module docstring.

    Parameters
    ----------
    bin_bands : int
        Bands of the direction bins; ``2 bin_bands**2`` equal-area bins
        (6 -> 72 bins of about 24 x 24 deg).
    samples_per_bin : int
        Newest samples kept per bin.
    sample_max_age_s : float
        Stored samples older than this expire (s): the fit describes the
        recent past (the field and an OS calibration change over minutes).
    min_samples : int
        Fewest stored samples for a fit (>= 9).
    min_coverage : float
        Fraction of direction bins that must be occupied (0-1) for a fit.
    min_coverage_soft_iron : float
        Coverage from which the full ellipsoid (hard and soft iron, 9
        unknowns) is fitted; below it, down to ``min_coverage``, only the hard
        iron (a sphere, 4 unknowns; soft iron = identity).  Set it to
        ``min_coverage`` for ellipsoids only, above 1 for hard iron only.
    min_direction_spread : float
        Smallest allowed std of the calibrated unit directions along their
        least-spread axis (0.577 = whole sphere, 0 = one plane of rotation).
    outlier_fraction : float
        Samples whose residual exceeds this fraction of the fitted field are
        dropped from the store and the fit is repeated (at most 3 times).
    max_residual_fraction : float
        Largest RMS residual (of the inliers) as a fraction of the fitted field.
    max_axis_ratio : float
        Largest ratio of the ellipsoid's longest to shortest semi-axis.
    field_range_uT : (float, float)
        Plausible geomagnetic field strengths (uT).
    refit_interval_s : float
        Least time between two fit attempts (s).
    refit_min_new_samples : int
        Samples stored since the last attempt needed for another (a newly
        occupied bin also suffices).
    bootstrap_window_s : float
        Before the first plausible fit the bins are centred on a sphere fitted
        (with outlier trimming) to a reservoir of the readings of the last
        ``bootstrap_window_s`` (s), decimated to 10 per second.
    max_raw_norm_uT : float
        Readings with a larger norm are skipped as broken (uT; phone
        magnetometers saturate at 1200-4900 uT).
    """

    def __init__(self, *, bin_bands: int = 6, samples_per_bin: int = 4, sample_max_age_s: float = 30.0,
                 min_samples: int = 30, min_coverage: float = 0.4, min_coverage_soft_iron: float = 0.5,
                 min_direction_spread: float = 0.25, outlier_fraction: float = 0.15,
                 max_residual_fraction: float = 0.06, max_axis_ratio: float = 1.3,
                 field_range_uT: tuple = (20.0, 70.0), refit_interval_s: float = 1.0,
                 refit_min_new_samples: int = 25, bootstrap_window_s: float = 10.0,
                 max_raw_norm_uT: float = 2000.0):
        if int(bin_bands) < 1 or int(samples_per_bin) < 1:
            raise ValueError("bin_bands and samples_per_bin must be >= 1")
        self.bin_bands = int(bin_bands)
        self.samples_per_bin = int(samples_per_bin)
        self.sample_max_age_s = float(sample_max_age_s)
        self.min_samples = max(int(min_samples), 9)
        self.min_coverage = float(min_coverage)
        self.min_coverage_soft_iron = float(min_coverage_soft_iron)
        self.min_direction_spread = float(min_direction_spread)
        self.outlier_fraction = float(outlier_fraction)
        self.max_residual_fraction = float(max_residual_fraction)
        self.max_axis_ratio = float(max_axis_ratio)
        self.field_range_uT = (float(field_range_uT[0]), float(field_range_uT[1]))
        self.refit_interval_s = float(refit_interval_s)
        self.refit_min_new_samples = int(refit_min_new_samples)
        self.bootstrap_window_s = float(bootstrap_window_s)
        self.max_raw_norm_uT = float(max_raw_norm_uT)
        self.n_sectors = 2 * self.bin_bands
        self.n_bins = self.bin_bands * self.n_sectors
        settings = set(vars(self))
        self.reset()
        #: the names of the run state :meth:`reset` makes (what :meth:`state` gives and :meth:`restore_state` may
        #: set); the settings as the per-reading path uses them (:data:`_DERIVED`) are not state
        self._state_names = frozenset(vars(self)) - settings - _DERIVED

    def reset(self) -> None:
        # the settings as the per-reading path uses them (read here: a setting changed later takes effect at reset)
        self._max_nrm2 = self.max_raw_norm_uT * self.max_raw_norm_uT
        self._bootstrap_ns = int(self.bootstrap_window_s * 1e9)
        self._r_min = 0.25 * self.field_range_uT[0]
        self._sector_scale = self.n_sectors / (2.0 * math.pi)
        nslots = self.n_bins * self.samples_per_bin
        # typed arrays: read and written per reading as fast as lists, handed to numpy without a conversion
        self._slot_m = array("d", bytes(24 * nslots))  # raw samples, three floats a slot
        self._slot_t = array("q", [-1]) * nslots  # t_ns, -1 = empty
        self._bin_count = [0] * self.n_bins
        self._n_stored = 0
        self._occupied = 0
        # centre of the direction bins: the bootstrap sphere until a fit is accepted, then the fit
        self._centre = None  # None until the first bootstrap sphere
        self._recent = array("q")  # t_ns of the reservoir for the bootstrap, one per _RECENT_DT_NS
        self._recent_m = array("d")  # its readings, three floats each
        self._centre_a = None  # soft iron of the accepted fit (None: identity)
        self._t_prev = None
        # calibration in force
        self._b = (0.0, 0.0, 0.0)
        self._a = _IDENTITY
        self._field = math.nan
        self._resid = math.nan
        self._ratio = math.nan
        self._model = ""
        self._fit_cov = math.nan
        self._calibrated = False
        self._t_fit = -1
        self._t_first_fit = -1
        # attempts
        self._t_last_attempt = None
        self._new_since = 0
        self._new_bins_since = 0
        self._reason = ""
        self._attempted_fit = False
        self.n_valid = 0
        self.n_invalid = 0
        self.n_fits = 0
        self.n_accepted = 0
        self._fits: list[MagCalStatus] = []

    # -- the desktop fast path's way in and out (desktop/fast/magcal.py: it runs the updates as one kernel) -----------
    @property
    def kernel_settings(self) -> dict:
        """The settings as the per-reading path uses them (made by :meth:`reset`): ``max_nrm2`` (uT^2, the largest
        squared norm of a valid reading), ``bootstrap_ns`` (the reservoir's span), ``r_min_uT`` (the least distance
        from the centre of a binned reading), ``sector_scale`` (azimuth sectors per radian), and the reservoir's
        spacing ``recent_dt_ns`` (a constant)."""
        return {"max_nrm2": self._max_nrm2, "bootstrap_ns": self._bootstrap_ns, "r_min_uT": self._r_min,
                "sector_scale": self._sector_scale, "recent_dt_ns": _RECENT_DT_NS}

    def state(self) -> dict:
        """The run state :meth:`reset` makes, ``{name: value}`` (the objects themselves: read them, do not change
        them; the store's typed arrays, the reservoir, the centre, the calibration in force, the attempt counters)."""
        return {name: getattr(self, name) for name in self._state_names}

    def restore_state(self, values: dict) -> None:
        """Set run state by name (``{name: value}``, names as :meth:`state` gives them, values of the types
        :meth:`update` leaves: the fast path's state before an attempt and after its last reading).  A name
        :meth:`reset` does not make as state (a setting, what it derives from them, an unknown name), or a store
        of another size, raises."""
        unknown = [n for n in values if n not in self._state_names]
        if unknown:
            raise AttributeError(f"restore_state: {unknown} are not MagCalibrator state")
        nslots = self.n_bins * self.samples_per_bin
        for name, size in (("_slot_t", nslots), ("_slot_m", 3 * nslots), ("_bin_count", self.n_bins)):
            if name in values and len(values[name]) != size:
                raise ValueError(f"restore_state: {name} holds {len(values[name])} values, the store {size}")
        for name, value in values.items():
            setattr(self, name, value)

    # -- applying the calibration ---------------------------------------------
    def apply(self, m_raw) -> np.ndarray:
        """Calibrated field ``A (m_raw - b)`` of one reading (3,) or many (n, 3); identity before a fit."""
        m = np.asarray(m_raw, dtype=np.float64)
        if not self._calibrated:
            return m.copy()
        return (m - np.asarray(self._b)) @ np.asarray(self._a).T

    def apply_tuple(self, mx: float, my: float, mz: float) -> tuple:
        """:meth:`apply` of one reading on floats (3 floats; the identity before a fit), as :meth:`update` returns
        it."""
        if not self._calibrated:
            return (mx, my, mz)
        bx, by, bz = self._b
        dx, dy, dz = mx - bx, my - by, mz - bz
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self._a
        return (a00 * dx + a01 * dy + a02 * dz, a10 * dx + a11 * dy + a12 * dz, a20 * dx + a21 * dy + a22 * dz)

    # -- status ---------------------------------------------------------------
    @property
    def calibrated(self) -> bool:
        return self._calibrated

    @property
    def status(self) -> MagCalStatus:
        if self._calibrated:
            state = "calibrated"
        elif self._attempted_fit:
            state = "rejected fit"
        else:
            state = "collecting"
        return MagCalStatus(
            state=state, reason=self._reason, model=self._model, offset_uT=tuple(float(v) for v in self._b),
            soft_iron=tuple(tuple(float(v) for v in row) for row in self._a), field_uT=self._field,
            residual_uT=self._resid, axis_ratio=self._ratio, fit_coverage=self._fit_cov,
            coverage=self._occupied / self.n_bins, n_samples=self._n_stored, n_valid=self.n_valid,
            n_invalid=self.n_invalid, n_fits=self.n_fits,
            n_accepted=self.n_accepted, t_fit_ns=self._t_fit, t_first_fit_ns=self._t_first_fit)

    # -- binning ----------------------------------------------------------------
    def _bins(self, m: np.ndarray) -> np.ndarray:
        """Direction bins of raw readings ``m`` (n, 3) about the current centre, -1 where too close to it.

        The float operations of :meth:`update`'s bin of one reading, element by element (numpy's arithmetic
        is IEEE's, as Python's; the azimuth by ``math.atan2`` as there), so that a re-binned sample lands in
        the bin the streaming path gives it.
        """
        cx, cy, cz = self._centre
        dx, dy, dz = m[:, 0] - cx, m[:, 1] - cy, m[:, 2] - cz
        if self._centre_a is not None:
            (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self._centre_a
            dx, dy, dz = (a00 * dx + a01 * dy + a02 * dz, a10 * dx + a11 * dy + a12 * dz,
                          a20 * dx + a21 * dy + a22 * dz)
        r = np.sqrt(dx * dx + dy * dy + dz * dz)
        k = np.full(len(m), -1, dtype=np.int64)  # direction undefined near the centre (a still phone before any fit)
        ok = np.flatnonzero(r >= self._r_min)
        if len(ok):
            nb, ns = self.bin_bands, self.n_sectors
            band = np.minimum(((dz[ok] / r[ok] + 1.0) * 0.5 * nb).astype(np.int64), nb - 1)
            azimuth = np.array(list(map(math.atan2, dy[ok].tolist(), dx[ok].tolist())))
            sector = np.minimum(((azimuth + math.pi) * self._sector_scale).astype(np.int64), ns - 1)
            k[ok] = band * ns + sector
        return k

    def _stored(self) -> tuple[np.ndarray, np.ndarray]:
        """The store's samples in slot order: ``t_ns`` (n,), ``m`` (n, 3)."""
        t = np.frombuffer(self._slot_t, dtype=np.int64)
        full = t >= 0
        return t[full], np.frombuffer(self._slot_m, dtype=np.float64).reshape(-1, 3)[full]  # copies

    def _refill(self, t: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rebuild the store from samples (newest first wins its bin) about the current centre; returns it.

        Each bin takes its ``samples_per_bin`` newest samples, into its slots newest first; the store is
        returned as :meth:`_stored` gives it (in slot order).
        """
        per, nbins = self.samples_per_bin, self.n_bins
        order = np.argsort(-t, kind="stable")  # newest first
        k = self._bins(m[order])
        by_bin = np.argsort(k, kind="stable")  # grouped by bin, newest first within each
        kb = k[by_bin]
        rank = np.arange(len(kb)) - np.searchsorted(kb, kb, side="left")  # place within its bin
        take = (kb >= 0) & (rank < per)
        slot = kb[take] * per + rank[take]  # ascending: the slot order
        src = order[by_bin[take]]
        t_st, m_st = t[src], m[src]
        slot_t = np.full(nbins * per, -1, dtype=np.int64)
        slot_t[slot] = t_st
        slot_m = np.zeros((nbins * per, 3))
        slot_m[slot] = m_st
        self._slot_t, self._slot_m = array("q", slot_t.tobytes()), array("d", slot_m.tobytes())
        counts = np.bincount(kb[take], minlength=nbins)
        self._bin_count = counts.tolist()
        self._n_stored = len(slot)
        self._occupied = int(np.count_nonzero(counts))
        return t_st, m_st

    # -- streaming ------------------------------------------------------------
    def update(self, t_ns: int, mx: float, my: float, mz: float) -> tuple:
        """Feed one raw reading (uT, device frame); returns the calibrated reading (3 floats).

        Non-finite readings, or a norm above ``max_raw_norm_uT``, are skipped
        (counted in ``n_invalid``) and returned as they came through the
        calibration in force.
        """
        # the per-reading path (the phone runs it at 50-100 Hz): binning and storing written out on locals, the
        # same float operations as _bin_of and _store; the fits happen in attempt, at most every refit_interval_s
        t_ns = int(t_ns)
        mx, my, mz = float(mx), float(my), float(mz)
        nrm2 = mx * mx + my * my + mz * mz
        if not (math.isfinite(nrm2) and nrm2 <= self._max_nrm2):
            self.n_invalid += 1
            return self.apply_tuple(mx, my, mz)
        self.n_valid += 1
        m = (mx, my, mz)
        if not self._calibrated:
            rec = self._recent
            if not rec or t_ns - rec[-1] >= _RECENT_DT_NS:
                rec.append(t_ns)
                self._recent_m.extend(m)
                t_old = t_ns - self._bootstrap_ns
                n_old = 0
                while rec[n_old] < t_old:
                    n_old += 1
                if n_old:
                    del rec[:n_old]
                    del self._recent_m[:3 * n_old]
        self._t_prev = t_ns
        centre = self._centre
        if centre is not None:
            cx, cy, cz = centre
            dx, dy, dz = mx - cx, my - cy, mz - cz
            ca = self._centre_a
            if ca is not None:
                (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = ca
                dx, dy, dz = (a00 * dx + a01 * dy + a02 * dz, a10 * dx + a11 * dy + a12 * dz,
                              a20 * dx + a21 * dy + a22 * dz)
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            if r >= self._r_min:
                nb, ns = self.bin_bands, self.n_sectors
                band = int((dz / r + 1.0) * 0.5 * nb)
                sector = int((math.atan2(dy, dx) + math.pi) * self._sector_scale)
                k = (band if band < nb else nb - 1) * ns + (sector if sector < ns else ns - 1)
                # store: the bin's first empty slot, else its oldest sample (newest wins)
                per = self.samples_per_bin
                ts = self._slot_t
                j = base = k * per
                oldest = ts[base]
                for i in range(base + 1, base + per):
                    if ts[i] < oldest:  # empty slots (-1) come first, then the oldest
                        oldest, j = ts[i], i
                if oldest < 0:
                    self._n_stored += 1
                    counts = self._bin_count
                    if counts[k] == 0:
                        self._occupied += 1
                        self._new_bins_since += 1
                    counts[k] += 1
                ts[j] = t_ns
                sm, j = self._slot_m, 3 * j
                sm[j], sm[j + 1], sm[j + 2] = mx, my, mz
                self._new_since += 1
        if self._t_last_attempt is None:
            self._t_last_attempt = t_ns
        elif ((self._new_since >= self.refit_min_new_samples or self._new_bins_since > 0 or centre is None)
              and (t_ns - self._t_last_attempt) * 1e-9 >= self.refit_interval_s):
            self.attempt(t_ns)
        if not self._calibrated:
            return m
        bx, by, bz = self._b
        dx, dy, dz = mx - bx, my - by, mz - bz
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self._a
        return (a00 * dx + a01 * dy + a02 * dz, a10 * dx + a11 * dy + a12 * dz, a20 * dx + a21 * dy + a22 * dz)

    def _coverage_about(self, m: np.ndarray, offset, a) -> float:
        """Fraction of direction bins hit by the samples ``m`` calibrated with ``offset``, ``a``."""
        d = (m - offset) @ np.asarray(a).T
        r = np.linalg.norm(d, axis=1)
        ok = r >= 0.25 * self.field_range_uT[0]
        d, r = d[ok], r[ok]
        nb, ns = self.bin_bands, self.n_sectors
        band = np.minimum(((d[:, 2] / r + 1.0) * 0.5 * nb).astype(np.int64), nb - 1)
        sector = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) + np.pi) * (ns / (2.0 * np.pi))).astype(np.int64), ns - 1)
        return len(np.unique(band * ns + sector)) / self.n_bins

    def attempt(self, t_ns: int) -> None:
        """One fit attempt on the store at ``t_ns`` (the expensive part): :meth:`update` makes it when one is due (at
        most every refit_interval_s), the desktop fast path where its kernel hands an attempt over."""
        self._t_last_attempt = t_ns
        self._new_since = 0
        self._new_bins_since = 0
        t, m = self._stored()
        keep = (t_ns - t) * 1e-9 <= self.sample_max_age_s
        if not self._calibrated:
            # centre the bins on the best sphere through the store and the recent readings
            if self._recent:
                t = np.concatenate([t[keep], np.frombuffer(self._recent, dtype=np.int64)])
                m = np.concatenate([m[keep], np.frombuffer(self._recent_m, dtype=np.float64).reshape(-1, 3)])
                t, first = np.unique(t, return_index=True)
                m = m[first]
            else:
                t, m = t[keep], m[keep]
            if len(t) >= self.min_samples:
                try:
                    (c_s, _, f_s, _), _, _ = self._trimmed(_fit_sphere, m, t)
                    if f_s >= 0.25 * self.field_range_uT[0]:
                        self._centre = tuple(float(v) for v in c_s)
                except (EllipsoidFitError, np.linalg.LinAlgError):
                    pass
            if self._centre is None:
                self._reason = f"too few samples ({len(t)} < {self.min_samples})"
                return
            t, m = self._refill(t, m)
        elif not np.all(keep):
            t, m = self._refill(t[keep], m[keep])
        n = len(t)
        if n < self.min_samples:
            self._reason = f"too few samples ({n} < {self.min_samples})"
            return
        cov = self._occupied / self.n_bins
        if cov < self.min_coverage:
            self._reason = f"coverage {cov:.2f} < {self.min_coverage:.2f}"
            return
        soft = cov >= self.min_coverage_soft_iron
        self.n_fits += 1
        self._attempted_fit = True
        try:
            (offset, a, field, ratio), inl, fitted = self._trimmed(_fit if soft else _fit_sphere, m, t)
        except EllipsoidFitError as e:
            self._reason = str(e)
            return
        except np.linalg.LinAlgError:
            self._reason = "degenerate geometry (singular)"
            return
        t, m = t[inl], m[inl]
        lo, hi = self.field_range_uT
        if not lo <= field <= hi:
            self._reason = f"field {field:.1f} uT outside {lo:g}-{hi:g}"
            return
        if ratio > self.max_axis_ratio:
            self._reason = f"axis ratio {ratio:.2f} > {self.max_axis_ratio:.2f}"
            return
        cov = self._coverage_about(m, offset, a)
        if cov < self.min_coverage:
            self._reason = f"coverage {cov:.2f} < {self.min_coverage:.2f} (inliers about the fit)"
            return
        u = (m - offset) @ a.T
        u /= np.maximum(_norms(u), 1e-12)[:, None]
        spread = math.sqrt(max(float(np.linalg.eigvalsh(np.cov(u.T))[0]), 0.0))
        if spread < self.min_direction_spread:
            self._reason = f"direction spread {spread:.2f} < {self.min_direction_spread:.2f}"
            return
        rms = _rms(fitted, offset, a, field)
        if rms > self.max_residual_fraction * field:
            self._reason = f"residual {rms:.2f} uT > {self.max_residual_fraction:.1%} of {field:.1f} uT"
            return
        if self._calibrated and cov < self._fit_cov:
            # the fit in force came from more directions: keep it while it still explains the samples
            cur = _rms(m, np.asarray(self._b), np.asarray(self._a), self._field)
            if cur <= self.max_residual_fraction * self._field:
                self._reason = (f"kept the fit in force (coverage {self._fit_cov:.2f} > {cov:.2f}, "
                                f"residual {cur:.2f} uT)")
                return
        # accepted: it calibrates, and the store is re-binned about it without the outliers
        self._b = tuple(float(v) for v in offset)
        self._a = tuple(tuple(float(v) for v in row) for row in a) if soft else _IDENTITY
        self._centre, self._centre_a = self._b, (self._a if soft else None)
        self._recent, self._recent_m = array("q"), array("d")
        self._refill(t, m)
        self._model = "hard+soft iron" if soft else "hard iron"
        self._field, self._resid, self._ratio = float(field), float(rms), float(ratio)
        self._fit_cov = cov
        self._calibrated = True
        self._t_fit = t_ns
        if self._t_first_fit < 0:
            self._t_first_fit = t_ns
        self.n_accepted += 1
        self._reason = "accepted"
        self._fits.append(self.status)

    def _trimmed(self, fit, m: np.ndarray, t: np.ndarray):
        """Robust ``fit``: a start from all samples, the newest half or quarter, then outlier trimming.

        Outliers are mostly samples left from before a change of the offset
        (the phone's own calibration jumping, a magnet moved) or taken next
        to iron.  The start with more inliers (|residual| <= outlier_fraction
        F over all samples) wins, so a jump of the offset leaves the old
        samples as outliers even when they are many; then the fit is
        repeated on the inliers until they no longer change (at most 3
        times).  Returns the fit ``(offset, A, F, axis ratio)``, the inlier mask of ``m`` and the samples the
        fit was made on (its residual is computed by the caller when it needs it).  A start from the newest
        samples is only tried when the fit to all of them left some out: with all of them inliers, no start can
        have more.
        """
        limit = self.outlier_fraction

        def inliers(res):
            return np.abs(_residuals(m, res[0], res[1], res[2])) <= limit * res[2]

        res, fitted = fit(m), m
        mask = inliers(res)
        n_in = int(np.count_nonzero(mask))
        if n_in < len(m):
            order = np.argsort(t, kind="stable")
            for part in (2, 4):
                newest = order[len(t) - len(t) // part:]
                if len(newest) < self.min_samples:
                    break
                m_n = m[newest]
                try:
                    res_n = fit(m_n)
                except (EllipsoidFitError, np.linalg.LinAlgError):
                    continue
                mask_n = inliers(res_n)
                n_n = int(np.count_nonzero(mask_n))
                if n_n > n_in:
                    res, mask, fitted, n_in = res_n, mask_n, m_n, n_n
        for _ in range(3):
            if n_in < self.min_samples or n_in == len(m):
                break
            fitted = m[mask]
            res = fit(fitted)
            new = inliers(res)
            if np.array_equal(new, mask):
                break
            mask = new
            n_in = int(np.count_nonzero(mask))
        return res, mask, fitted

    # -- batch ------------------------------------------------------------------
    def run(self, t_ns, mag_b) -> MagCalTrace:
        """Feed a stream ``t_ns`` (n,), ``mag_b`` (n, 3) raw readings (uT) through :meth:`update`.

        Continues from the current state (call :meth:`reset` to start over),
        so consecutive chunks give the same as one call and as per-sample
        updates.  ``fits`` lists the fits accepted during this call.
        """
        t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        m = np.asarray(mag_b, dtype=np.float64).reshape(len(t), 3)
        n0 = len(self._fits)
        upd = self.update
        rows, idx = [], []
        for ti, (mx, my, mz) in zip(t.tolist(), m.tolist()):
            rows.append(upd(ti, mx, my, mz))
            idx.append(self.n_accepted)
        return MagCalTrace(t_ns=t, mag_cal_b=np.array(rows, dtype=np.float64).reshape(len(t), 3),
                           fit_index=np.array(idx, dtype=np.int64), fits=tuple(self._fits[n0:]), status=self.status)


# ---------------------------------------------------------------------------
# quasi-static field detector


@dataclass(frozen=True)
class QsfStatus:
    """Verdict of :class:`QuasiStaticField` on one magnetometer reading."""

    t_ns: int
    trusted: bool  #: steady and Earth-like: usable as a heading reference
    steady: bool  #: the nav-frame field did not move over the window (usable against gyro drift)
    reason: str  #: one of QSF_REASONS
    dir_spread_deg: float  #: largest angle of a window reading from the window's mean direction (deg)
    norm_spread_uT: float  #: largest deviation of a window reading's norm from the window mean (uT)
    norm_uT: float  #: mean |m| over the window (uT)
    dip_deg: float  #: dip of the window's mean field, positive downwards (deg)
    reference_field_uT: float  #: reference norm in force (nan while unknown)
    reference_dip_deg: float  #: reference dip in force (nan while unknown)
    window_span_s: float  #: time span of the readings in the window (s)
    n_window: int  #: readings in the window
    n_invalid: int  #: non-finite inputs skipped so far


@dataclass(frozen=True)
class QsfTrace:
    """Output of :meth:`QuasiStaticField.run`: one row per reading."""

    t_ns: np.ndarray
    trusted: np.ndarray  #: (n,) bool
    steady: np.ndarray  #: (n,) bool
    reason: np.ndarray  #: (n,) str
    dir_spread_deg: np.ndarray
    norm_spread_uT: np.ndarray
    norm_uT: np.ndarray
    dip_deg: np.ndarray
    status: QsfStatus  #: after the last reading


class QuasiStaticField:
    """Quasi-static field detector (Afzal et al. 2011): is the magnetometer trustworthy now?

    ``st = update(t_ns, mag_b, q_nb)`` per calibrated reading (uT, device
    frame) with the attitude filter's current gyro-propagated quaternion
    (body -> ENU); method in the module docstring.

    Parameters
    ----------
    window_s : float
        Trailing window (s).
    max_dir_spread_deg : float
        Largest direction spread of a quasi-static field (deg).
    max_norm_spread_uT : float
        Largest norm spread of a quasi-static field (uT).
    norm_tol_uT : float
        Largest difference of the window's mean norm from the reference (uT).
    dip_tol_deg : float
        Largest difference of the window's dip from the reference (deg).
    reference_field_uT, reference_dip_deg : float or None
        Fixed reference norm (uT) and dip (deg); None learns it.
    reference_time_constant_s : float
        Time constant (s of steady windows) of the learnt reference.
    reference_warmup_s : float
        Steady time needed before a learnt reference is used (s).
    max_gap_s : float
        A longer gap between readings restarts the window (s).
    """

    def __init__(self, *, window_s: float = 0.75, max_dir_spread_deg: float = 2.5, max_norm_spread_uT: float = 1.5,
                 norm_tol_uT: float = 6.0, dip_tol_deg: float = 10.0, reference_field_uT: float | None = None,
                 reference_dip_deg: float | None = None, reference_time_constant_s: float = 30.0,
                 reference_warmup_s: float = 2.0, max_gap_s: float = 0.5):
        self.window_s = float(window_s)
        self.max_dir_spread_deg = float(max_dir_spread_deg)
        self.max_norm_spread_uT = float(max_norm_spread_uT)
        self.norm_tol_uT = float(norm_tol_uT)
        self.dip_tol_deg = float(dip_tol_deg)
        self.reference_field_uT = None if reference_field_uT is None else float(reference_field_uT)
        self.reference_dip_deg = None if reference_dip_deg is None else float(reference_dip_deg)
        self.reference_time_constant_s = float(reference_time_constant_s)
        self.reference_warmup_s = float(reference_warmup_s)
        self.max_gap_s = float(max_gap_s)
        self.reset()

    def reset(self) -> None:
        self._cap = 256
        self._buf = np.empty((2 * self._cap, 7))  # per reading: m_n (3), its direction (3), its norm
        self._tb = np.empty(2 * self._cap, dtype=np.int64)
        self._lo = 0
        self._hi = 0
        self._t_seg = None
        self._t_prev = None
        self._ref_norm = self.reference_field_uT if self.reference_field_uT is not None else math.nan
        self._ref_dip = self.reference_dip_deg if self.reference_dip_deg is not None else math.nan
        self._learn_norm = self.reference_field_uT is None
        self._learn_dip = self.reference_dip_deg is None
        self._steady_s = 0.0
        self.n_invalid = 0
        self._last = None

    def set_reference(self, field_uT: float | None = None, dip_deg: float | None = None) -> None:
        """Fix the reference norm (uT) and/or dip (deg), e.g. from :class:`MagCalibrator`'s ``field_uT``.

        Runtime state: :meth:`reset` goes back to the ``__init__`` settings.
        """
        if field_uT is not None and math.isfinite(field_uT):
            self._ref_norm = float(field_uT)
            self._learn_norm = False
        if dip_deg is not None and math.isfinite(dip_deg):
            self._ref_dip = float(dip_deg)
            self._learn_dip = False

    @property
    def status(self) -> QsfStatus | None:
        """Verdict on the last reading (None before any)."""
        return self._last

    def _push(self, t_ns: int, v: tuple) -> None:
        if self._hi == len(self._tb):
            live = self._hi - self._lo
            if live >= self._cap:  # window holds more readings than expected: grow
                self._cap *= 2
                buf = np.empty((2 * self._cap, 7))
                tb = np.empty(2 * self._cap, dtype=np.int64)
            else:
                buf, tb = self._buf, self._tb
            buf[:live] = self._buf[self._lo:self._hi]
            tb[:live] = self._tb[self._lo:self._hi]
            self._buf, self._tb = buf, tb
            self._lo, self._hi = 0, live
        self._buf[self._hi] = v
        self._tb[self._hi] = t_ns
        self._hi += 1

    def _verdict(self, t_ns, reason, dir_s=math.nan, norm_s=math.nan, norm=math.nan, dip=math.nan,
                 span=0.0, n=0, steady=False) -> QsfStatus:
        st = QsfStatus(t_ns=t_ns, trusted=reason == "steady", steady=steady, reason=reason, dir_spread_deg=dir_s,
                       norm_spread_uT=norm_s, norm_uT=norm, dip_deg=dip, reference_field_uT=self._ref_norm,
                       reference_dip_deg=self._ref_dip, window_span_s=span, n_window=n, n_invalid=self.n_invalid)
        self._last = st
        return st

    def update(self, t_ns: int, mag_b, q_nb) -> QsfStatus:
        """Judge one calibrated reading ``mag_b`` (3, uT) under the gyro-propagated attitude ``q_nb`` (w, x, y, z)."""
        t_ns = int(t_ns)
        mx, my, mz = (float(v) for v in mag_b)
        w, x, y, z = (float(v) for v in q_nb)
        if not all(math.isfinite(v) for v in (mx, my, mz, w, x, y, z)) or (w * w + x * x + y * y + z * z) < 1e-12:
            self.n_invalid += 1
            return self._verdict(t_ns, "invalid input")
        s = 2.0 / (w * w + x * x + y * y + z * z)  # tolerates a slightly unnormalised q
        r00, r01, r02 = 1 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)
        r10, r11, r12 = s * (x * y + w * z), 1 - s * (x * x + z * z), s * (y * z - w * x)
        r20, r21, r22 = s * (x * z - w * y), s * (y * z + w * x), 1 - s * (x * x + y * y)
        v = (r00 * mx + r01 * my + r02 * mz, r10 * mx + r11 * my + r12 * mz, r20 * mx + r21 * my + r22 * mz)
        if self._t_prev is None or (t_ns - self._t_prev) * 1e-9 > self.max_gap_s or t_ns < self._t_prev:
            self._lo = self._hi = 0
            self._t_seg = t_ns
            dt_s = 0.0
        else:
            dt_s = (t_ns - self._t_prev) * 1e-9
        self._t_prev = t_ns
        nv = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        k = 1.0 / nv if nv > 0.0 else 0.0
        self._push(t_ns, (v[0], v[1], v[2], v[0] * k, v[1] * k, v[2] * k, nv))
        t_old = t_ns - int(round(self.window_s * 1e9))
        tb = self._tb
        while self._lo < self._hi - 1 and tb[self._lo] < t_old:
            self._lo += 1
        win = self._buf[self._lo:self._hi]
        n = len(win)
        span = (t_ns - int(tb[self._lo])) * 1e-9
        sx, sy, sz, ux, uy, uz, sn = win.sum(axis=0).tolist()
        norm = sn / n
        norms = win[:, 6]
        norm_s = max(float(norms.max()) - norm, norm - float(norms.min()))
        dip = math.degrees(math.atan2(-sz, math.hypot(sx, sy)))  # of the mean vector
        c_n = math.sqrt(ux * ux + uy * uy + uz * uz)
        if c_n > 0.0:
            cmin = float((win[:, 3:6] @ np.array([ux, uy, uz])).min()) / c_n
            dir_s = math.degrees(math.acos(max(-1.0, min(1.0, cmin))))
        else:
            dir_s = 180.0
        vals = dict(dir_s=dir_s, norm_s=norm_s, norm=norm, dip=dip, span=span, n=n)
        if (t_ns - self._t_seg) * 1e-9 < self.window_s or n < 3:
            return self._verdict(t_ns, "warming up", **vals)
        if norm_s > self.max_norm_spread_uT:
            return self._verdict(t_ns, "norm moving", **vals)
        if dir_s > self.max_dir_spread_deg:
            return self._verdict(t_ns, "direction moving", **vals)
        # steady: learn the reference from it
        self._steady_s += dt_s
        a = 1.0 - math.exp(-dt_s / self.reference_time_constant_s) if self.reference_time_constant_s > 0 else 1.0
        if self._learn_norm:
            self._ref_norm = norm if math.isnan(self._ref_norm) else self._ref_norm + a * (norm - self._ref_norm)
        if self._learn_dip:
            self._ref_dip = dip if math.isnan(self._ref_dip) else self._ref_dip + a * (dip - self._ref_dip)
        learning = self._learn_norm or self._learn_dip
        if learning and self._steady_s < self.reference_warmup_s:
            return self._verdict(t_ns, "warming up", steady=True, **vals)
        if abs(norm - self._ref_norm) > self.norm_tol_uT:
            return self._verdict(t_ns, "norm off", steady=True, **vals)
        if abs(dip - self._ref_dip) > self.dip_tol_deg:
            return self._verdict(t_ns, "dip off", steady=True, **vals)
        return self._verdict(t_ns, "steady", steady=True, **vals)

    def run(self, t_ns, mag_b, q_nb) -> QsfTrace:
        """Judge a stream: ``t_ns`` (n,), ``mag_b`` (n, 3) calibrated (uT), ``q_nb`` (n, 4) via :meth:`update`.

        Continues from the current state (call :meth:`reset` to start over).
        """
        t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        m = np.asarray(mag_b, dtype=np.float64).reshape(len(t), 3)
        q = np.asarray(q_nb, dtype=np.float64).reshape(len(t), 4)
        n = len(t)
        trusted = np.zeros(n, dtype=bool)
        steady = np.zeros(n, dtype=bool)
        reason = np.empty(n, dtype="<U16")
        cols = np.full((4, n), np.nan)
        for i, (ti, mi, qi) in enumerate(zip(t.tolist(), m.tolist(), q.tolist())):
            st = self.update(ti, mi, qi)
            trusted[i], steady[i], reason[i] = st.trusted, st.steady, st.reason
            cols[:, i] = (st.dir_spread_deg, st.norm_spread_uT, st.norm_uT, st.dip_deg)
        return QsfTrace(t_ns=t, trusted=trusted, steady=steady, reason=reason, dir_spread_deg=cols[0],
                        norm_spread_uT=cols[1], norm_uT=cols[2], dip_deg=cols[3], status=self._last)
