"""A particle filter on the step-and-heading chain: walls kill particles, fixes reweight them (numpy only).

State of particle ``i``: position ``(x_i, y_i)`` (plan metres), stride
scale ``s_i`` and heading bias ``b_i`` (rad; measured heading = true heading
+ bias).  Weights ``w_i`` sum to 1.

Per step ``(length l, heading h)`` of :class:`core.pdr.pipeline.Step` (the
:meth:`ParticleFilter.update` kernel, which :meth:`ParticleFilter.run` calls too):

1. random walks: ``b_i += N(0, bias_rw_rad)``, ``s_i *= exp(N(0, scale_rw))`` (with
   ``bias_gm=True`` the bias is a first-order Gauss-Markov process instead,
   ``b_i = a b_i + N(0, bias_rw_rad)`` with ``a = sqrt(1 - (bias_rw / bias_sd)^2)``,
   stationary sd ``bias_sd_rad``);
2. move: ``theta_i = h - b_i + N(0, heading_sd_rad)``,
   ``d_i = l s_i (1 + N(0, length_sd))`` (at least 0),
   ``p_i += d_i (cos theta_i, sin theta_i)`` (eq. 1 of Tian et al. 2014 per particle);
3. walls: a particle whose move touches or crosses a wall dies (weight 0;
   :class:`core.indoor.geometry.WallGrid`, bounded cost per particle);
4. all dead -> **recovery**: the step is drawn again from the cloud before it
   with three times the heading and length noise (``retries``); if every
   particle still dies (the map lacks a door, or the cloud is lost), no
   particle moves this step and every bias gets ``N(0, bias_sd_rad)`` more,
   so that later steps find the way the walls allow; ``recoveries`` counts
   it.  Particles never pass a wall, the state never holds NaN and the
   filter never stops;
5. systematic resampling (Kitagawa 1996, "Monte Carlo filter and smoother for
   non-Gaussian nonlinear state space models", J. Comput. Graph. Stat.
   5(1):1-25; Arulampalam et al. 2002, IEEE TSP 50(2), Algorithm 2) when the
   effective sample size ``1 / sum w_i^2`` falls below ``resample_ess * N``,
   followed by roughening (Gordon, Salmond & Smith 1993, "Novel approach to
   nonlinear/non-Gaussian Bayesian state estimation", IEE Proc. F 140(2),
   section 4): every state dimension gets ``N(0, (K E N^(-1/d))^2)`` with ``E``
   the dimension's range over the particles, ``d = 4``, ``K = roughen_k``;
   a roughening that would cross a wall leaves that particle's position as
   it was.

Landmark fix ``(east, north, sd)`` (:meth:`ParticleFilter.fix`): Bayes with a
Gaussian likelihood, ``w_i *= exp(-|p_i - f|^2 / (2 sd^2))``.  When no
particle is within ``fix_reset_sd`` standard deviations, the fix and the
cloud disagree beyond any doubt: the positions are drawn anew around the fix
(biases and scales kept) and ``fix_resets`` counts it.

Estimate (:class:`Estimate`): weighted mean position, weighted 2 x 2
covariance (``spread_m = sqrt(trace)``), the weighted circular mean of the
bias and its spread, the mean stride scale.  When a wall lies between the
weighted mean and the best particle (a cloud split by a wall), the mean is
not a place the walker can be: the estimate is then the living particle
nearest to the mean (``snaps``).

Initialisation: :meth:`ParticleFilter.start` (a point with an sd: a known
start or a landmark) or :meth:`ParticleFilter.start_gps` (a fix in degrees
with its horizontal accuracy, through the plan's georeference).  Samples
that a wall separates from the start point are drawn again (up to 20 times,
then put on the point).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from core.conventions import wrap_angle


@dataclass
class ParticleConfig:
    """Settings of :class:`ParticleFilter` (defaults tuned on the tuning split: ``benchmarks/indoor.py``)."""

    n_particles: int = 500
    #: per-step relative step-length noise
    length_sd: float = 0.12
    #: initial spread of the per-particle stride scale (relative) and its per-step random walk
    scale_sd: float = 0.05
    scale_rw: float = 0.003
    #: per-step heading noise (rad)
    heading_sd_rad: float = math.radians(10.0)
    #: initial spread of the per-particle heading bias (rad) and its per-step random walk (rad)
    bias_sd_rad: float = math.radians(15.0)
    bias_rw_rad: float = math.radians(1.6)
    #: the bias is a first-order Gauss-Markov process (True: it returns towards 0 with the stationary sd
    #: bias_sd_rad) or a random walk (False)
    bias_gm: bool = False
    #: resample when the effective sample size falls below this fraction of N
    resample_ess: float = 0.5
    #: roughening constant K (Gordon et al. 1993)
    roughen_k: float = 0.2
    #: retries of a step that killed every particle (with 3x noise) before the recovery
    retries: int = 1
    #: a fix farther than this many sd from every particle resets the positions around it
    fix_reset_sd: float = 5.0
    #: wall grid cell (m): above the longest step
    cell_m: float = 2.5


@dataclass(frozen=True)
class Estimate:
    t_ns: int
    east_m: float
    north_m: float
    cov: tuple  #: weighted covariance of the position ((xx, xy), (xy, yy)), m^2
    spread_m: float  #: sqrt(trace(cov))
    bias_rad: float  #: estimated heading bias (measured - true), weighted circular mean
    bias_sd_rad: float
    scale: float  #: weighted mean stride scale
    ess: float  #: effective sample size
    snapped: bool  #: the weighted mean was behind a wall: the estimate is the particle nearest to it


@dataclass
class Diagnostics:
    steps: int = 0
    fixes: int = 0
    deaths: int = 0  #: particles killed by walls, in total
    resamples: int = 0
    retries: int = 0  #: steps drawn again after killing every particle
    recoveries: int = 0  #: steps kept through the walls (every particle died twice)
    fix_resets: int = 0
    snaps: int = 0
    min_ess: float = math.inf

    def as_dict(self) -> dict:
        d = asdict(self)
        d["min_ess"] = None if not math.isfinite(self.min_ess) else float(self.min_ess)
        return d


class ParticleFilter:
    """See the module docstring.  ``plan=None``: no walls (fixes only)."""

    def __init__(self, plan=None, config: ParticleConfig | None = None, seed: int = 0, keep_paths: bool = False):
        self.plan = plan
        self.config = config or ParticleConfig()
        self.rng = np.random.default_rng(seed)
        self.grid = plan.grid(self.config.cell_m) if plan is not None and len(plan.walls) else None
        self.diagnostics = Diagnostics()
        self.t_ns = None
        n = int(self.config.n_particles)
        if n < 1:
            raise ValueError("n_particles must be at least 1")
        self.xy = np.zeros((n, 2))
        self.scale = np.ones(n)
        self.bias = np.zeros(n)
        self.w = np.full(n, 1.0 / n)
        self._paths = [] if keep_paths else None
        c = self.config
        # first-order Gauss-Markov bias: stationary sd bias_sd_rad, innovation bias_rw_rad a step
        self._bias_keep = math.sqrt(max(0.0, 1.0 - (c.bias_rw_rad / c.bias_sd_rad) ** 2)) if c.bias_gm else 1.0

    @property
    def started(self) -> bool:
        return self.t_ns is not None

    # -- initialisation -------------------------------------------------------

    def start(self, t_ns: int, east_m: float, north_m: float, sd_m: float = 0.5,
              bias_rad: float = 0.0) -> Estimate:
        """Particles around a known point (a start, a landmark): ``N(point, sd_m^2)`` in each axis."""
        c = self.config
        n = len(self.w)
        p = np.array([float(east_m), float(north_m)])
        if not np.all(np.isfinite(p)) or not sd_m >= 0:
            raise ValueError("a start needs a finite point and a non-negative sd")
        self.xy = self._scatter(p, float(sd_m), n)
        self.scale = np.exp(self.rng.normal(0.0, c.scale_sd, n))
        self.bias = wrap_angle(float(bias_rad) + self.rng.normal(0.0, c.bias_sd_rad, n))
        self.w = np.full(n, 1.0 / n)
        self.t_ns = int(t_ns)
        if self._paths is not None:
            self._paths = []
        return self.estimate()

    def start_gps(self, t_ns: int, lat_deg: float, lon_deg: float, hacc_m: float) -> Estimate:
        """Particles around a GPS fix (degrees, horizontal accuracy m), placed by the plan's georeference."""
        if self.plan is None or self.plan.georef is None:
            raise ValueError("a GPS start needs a plan with a georeference")
        x, y = self.plan.georef.from_geodetic(lat_deg, lon_deg)[0]
        return self.start(t_ns, x, y, max(float(hacc_m), 0.0))

    def _scatter(self, p, sd: float, n: int) -> np.ndarray:
        xy = p + self.rng.normal(0.0, sd, (n, 2))
        if self.grid is None or sd == 0:
            return xy
        src = np.broadcast_to(p, xy.shape)
        bad = self.grid.crosses(src, xy)
        for _ in range(20):
            if not bad.any():
                break
            idx = np.flatnonzero(bad)
            xy[idx] = p + self.rng.normal(0.0, sd, (len(idx), 2))
            bad[idx] = self.grid.crosses(src[idx], xy[idx])
        xy[bad] = p
        return xy

    # -- the step kernel ------------------------------------------------------

    def update(self, step) -> Estimate:
        """One step (anything with ``t_ns``, ``length_m``, ``heading_rad``): move, kill, resample."""
        if not self.started:
            raise RuntimeError("start the filter (start / start_gps) before the first step")
        length, heading = float(step.length_m), float(step.heading_rad)
        if not (math.isfinite(length) and math.isfinite(heading)):  # a step without heading: the walker stands
            self.t_ns = int(step.t_ns)
            self._record(True, None)
            return self.estimate()
        c, d = self.config, self.diagnostics
        n = len(self.w)
        self.bias = wrap_angle(self._bias_keep * self.bias + self.rng.normal(0.0, c.bias_rw_rad, n))
        self.scale = self.scale * np.exp(self.rng.normal(0.0, c.scale_rw, n))
        alive = self.w > 0
        new, hit = self._move(length, heading, 1.0)
        if (hit | ~alive).all():
            for _ in range(c.retries):
                d.retries += 1
                new, hit = self._move(length, heading, 3.0)
                if not (hit | ~alive).all():
                    break
        if (hit | ~alive).all():  # recovery: nobody moves this step and the bias spreads again (module docstring)
            d.recoveries += 1
            new, hit = self.xy.copy(), np.zeros(n, dtype=bool)
            self.bias = wrap_angle(self.bias + self.rng.normal(0.0, c.bias_sd_rad, n))
        d.steps += 1
        d.deaths += int(np.sum(hit & alive))
        dead = hit | ~alive
        self.xy = new
        w = np.where(dead, 0.0, self.w)
        s = w.sum()
        # survivors whose weights all underflowed (after a far fix) share the weight equally
        self.w = w / s if s > 0 and math.isfinite(s) else np.where(dead, 0.0, 1.0) / float(np.sum(~dead))
        parents = self._maybe_resample()
        self.t_ns = int(step.t_ns)
        self._record(True, parents)
        return self.estimate()

    def _move(self, length: float, heading: float, inflate: float):
        c = self.config
        n = len(self.w)
        th = heading - self.bias + self.rng.normal(0.0, c.heading_sd_rad * inflate, n)
        dist = np.maximum(length * self.scale * (1.0 + self.rng.normal(0.0, c.length_sd * inflate, n)), 0.0)
        new = self.xy + dist[:, None] * np.column_stack([np.cos(th), np.sin(th)])
        dead = self.grid.crosses(self.xy, new) if self.grid is not None else np.zeros(n, dtype=bool)
        return new, dead

    def _maybe_resample(self):
        """Resample when the ESS is low; returns the parent index of every particle (None: no resampling)."""
        c, d = self.config, self.diagnostics
        n = len(self.w)
        ess = 1.0 / float(np.sum(self.w ** 2))
        d.min_ess = min(d.min_ess, ess)
        if ess >= c.resample_ess * n:
            return None
        d.resamples += 1
        # systematic resampling (Kitagawa 1996; Arulampalam et al. 2002, Algorithm 2)
        u = (self.rng.random() + np.arange(n)) / n
        cdf = np.cumsum(self.w)
        cdf[-1] = 1.0
        idx = np.searchsorted(cdf, u, side="left")
        self.xy, self.scale, self.bias = self.xy[idx], self.scale[idx], self.bias[idx]
        self.w = np.full(n, 1.0 / n)
        self._roughen()
        return idx

    def _record(self, is_step: bool, parents) -> None:
        """Keep the positions and the resampling's parents for the batch smoother (``keep_paths``)."""
        if self._paths is not None:
            self._paths.append((is_step, self.xy.copy(), parents))

    def smoothed(self) -> np.ndarray:
        """Positions ``(steps, 2)`` after each step, smoothed by the final particles' ancestral paths.

        The filter-smoother of Kitagawa 1996 (section 4.2): each particle keeps
        its past states; the smoothed position at step ``k`` is the final
        weights' mean of the final particles' ancestors at ``k`` (the
        ancestor nearest to it when a wall separates it from the best
        particle's ancestor, as in :meth:`estimate`).  Needs
        ``keep_paths=True``; memory grows with ``steps x N``, so it is for
        batch runs (``pdr replay``), not the live app.
        """
        if self._paths is None:
            raise RuntimeError("construct the filter with keep_paths=True to smooth")
        w = self.w
        a = np.arange(len(w))
        best = int(np.argmax(w))
        out = []
        for is_step, xy, parents in reversed(self._paths):
            if is_step:
                anc = xy[a]
                m = w @ anc
                if self.grid is not None and self.grid.crosses(anc[best][None, :], m[None, :])[0]:
                    m = anc[int(np.argmin(np.where(w > 0, np.hypot(*(anc - m).T), np.inf)))]  # as estimate()
                out.append(m)
            if parents is not None:
                a = parents[a]
        return np.array(out[::-1], dtype=float).reshape(-1, 2)

    def _roughen(self) -> None:
        """Gordon et al. 1993: jitter of K E N^(-1/d) per dimension (positions only where no wall is crossed)."""
        c = self.config
        n = len(self.w)
        f = c.roughen_k * n ** (-1.0 / 4.0)
        span = np.ptp(self.xy, axis=0)
        new = self.xy + self.rng.normal(0.0, 1.0, (n, 2)) * (f * span)
        if self.grid is not None:
            bad = self.grid.crosses(self.xy, new)
            new[bad] = self.xy[bad]
        self.xy = new
        self.scale = self.scale * np.exp(self.rng.normal(0.0, f * float(np.ptp(np.log(self.scale))), n))
        b_span = float(np.ptp(wrap_angle(self.bias - self.bias[0])))
        self.bias = wrap_angle(self.bias + self.rng.normal(0.0, f * b_span, n))

    # -- fixes ----------------------------------------------------------------

    def fix(self, t_ns: int, east_m: float, north_m: float, sd_m: float) -> Estimate:
        """A position fix with its sd (a user's tap, a surveyed landmark): reweight the particles."""
        if not self.started:
            return self.start(t_ns, east_m, north_m, sd_m)
        if not (math.isfinite(east_m) and math.isfinite(north_m) and sd_m > 0):
            raise ValueError("a fix needs a finite point and a positive sd")
        c, d = self.config, self.diagnostics
        d.fixes += 1
        d2 = ((self.xy[:, 0] - east_m) ** 2 + (self.xy[:, 1] - north_m) ** 2) / (sd_m * sd_m)
        if float(d2.min()) > c.fix_reset_sd ** 2:
            d.fix_resets += 1
            self.xy = self._scatter(np.array([east_m, north_m], dtype=float), sd_m, len(self.w))
            self.w = np.full(len(self.w), 1.0 / len(self.w))
        else:
            w = self.w * np.exp(-0.5 * (d2 - d2.min()))
            s = w.sum()
            self.w = w / s if s > 0 and math.isfinite(s) else np.full(len(self.w), 1.0 / len(self.w))
        self._record(False, self._maybe_resample())
        self.t_ns = max(self.t_ns, int(t_ns))
        return self.estimate()

    # -- the estimate ---------------------------------------------------------

    def estimate(self) -> Estimate:
        if not self.started:
            raise RuntimeError("start the filter (start / start_gps) before asking for an estimate")
        w = self.w
        m = w @ self.xy
        dxy = self.xy - m
        cov = (dxy * w[:, None]).T @ dxy
        bm = math.atan2(float(w @ np.sin(self.bias)), float(w @ np.cos(self.bias)))
        bsd = math.sqrt(max(float(w @ wrap_angle(self.bias - bm) ** 2), 0.0))
        snapped = False
        if self.grid is not None:
            best = self.xy[int(np.argmax(w))]
            if self.grid.crosses(best[None, :], m[None, :])[0]:
                m = self.xy[int(np.argmin(np.where(w > 0, np.hypot(*dxy.T), np.inf)))].copy()
                snapped = True
                self.diagnostics.snaps += 1
        return Estimate(t_ns=int(self.t_ns), east_m=float(m[0]), north_m=float(m[1]),
                        cov=((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1]))),
                        spread_m=math.sqrt(max(float(cov[0, 0] + cov[1, 1]), 0.0)), bias_rad=bm, bias_sd_rad=bsd,
                        scale=float(w @ self.scale), ess=1.0 / float(np.sum(w ** 2)), snapped=snapped)

    # -- batch ----------------------------------------------------------------

    def run(self, steps, fixes=()) -> MapMatchResult:
        """Every step (and fix, merged in time order; a fix at a step's time comes after it) through :meth:`update`."""
        t, length, heading = _step_arrays(steps)
        fx = sorted(((int(f[0]), float(f[1]), float(f[2]), float(f[3])) for f in fixes), key=lambda f: f[0])
        out = []
        k = 0
        for i in range(len(t)):
            while k < len(fx) and fx[k][0] < t[i]:
                out.append((False, self.fix(*fx[k])))
                k += 1
            out.append((True, self.update(_Step(int(t[i]), float(length[i]), float(heading[i])))))
        while k < len(fx):
            out.append((False, self.fix(*fx[k])))
            k += 1
        res = MapMatchResult.from_estimates([e for is_step, e in out if is_step], self.diagnostics.as_dict())
        if self._paths is not None:
            sm = self.smoothed()
            res.smoothed_east_m, res.smoothed_north_m = sm[:, 0], sm[:, 1]
        return res


@dataclass(frozen=True)
class _Step:
    t_ns: int
    length_m: float
    heading_rad: float


@dataclass
class StepArrays:
    """Steps as arrays (``t_ns`` int64, ``length_m``, ``heading_rad``): what :meth:`ParticleFilter.run` takes."""

    t_ns: np.ndarray
    length_m: np.ndarray
    heading_rad: np.ndarray


def _step_arrays(steps):
    """``(t_ns, length_m, heading_rad)`` arrays of a list of steps or of a track with those array attributes."""
    if hasattr(steps, "t_ns") and hasattr(steps, "length_m") and np.ndim(steps.t_ns) == 1:
        return (np.asarray(steps.t_ns, dtype=np.int64), np.asarray(steps.length_m, dtype=float),
                np.asarray(steps.heading_rad, dtype=float))
    steps = list(steps)
    return (np.array([s.t_ns for s in steps], dtype=np.int64), np.array([s.length_m for s in steps], dtype=float),
            np.array([s.heading_rad for s in steps], dtype=float))


@dataclass
class MapMatchResult:
    """The map-matched track, one row per step (after the step), with its spread and the bias estimate."""

    t_ns: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    spread_m: np.ndarray
    cov: np.ndarray  #: (n, 2, 2)
    bias_rad: np.ndarray  #: estimated heading bias after each step (measured - true)
    bias_sd_rad: np.ndarray
    scale: np.ndarray
    ess: np.ndarray
    snapped: np.ndarray
    diagnostics: dict = field(default_factory=dict)
    #: the batch smoother's positions (:meth:`ParticleFilter.smoothed`), None unless asked for
    smoothed_east_m: np.ndarray | None = None
    smoothed_north_m: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def final_bias_rad(self) -> float:
        return float(self.bias_rad[-1]) if len(self.bias_rad) else math.nan

    @classmethod
    def from_estimates(cls, est: list, diagnostics: dict) -> MapMatchResult:
        def col(name, dtype=float):
            return np.array([getattr(e, name) for e in est], dtype=dtype)

        return cls(t_ns=col("t_ns", np.int64), east_m=col("east_m"), north_m=col("north_m"),
                   spread_m=col("spread_m"), cov=np.array([e.cov for e in est], dtype=float).reshape(-1, 2, 2),
                   bias_rad=col("bias_rad"), bias_sd_rad=col("bias_sd_rad"), scale=col("scale"), ess=col("ess"),
                   snapped=col("snapped", bool), diagnostics=diagnostics)
