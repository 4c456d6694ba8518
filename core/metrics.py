"""Accuracy of a track against the ground truth a recording carries: the metrics, each with its formula.

Shared by ``pdr replay`` (the error against a recording's landmarks, reference
track or simulator truth) and the benchmark (:mod:`benchmarks.metrics`, which
adds step timing and the table summaries).  Conventions as in :mod:`core`:
times are ``int64`` nanoseconds, positions are local East/North metres,
headings are radians counter-clockwise from East.  Pure numpy on plain arrays.

===============================  ==========================================================
step-count error (%)             ``100 (N_est - N_true) / N_true`` (signed)
walked-distance error (%)        ``100 (D_est - D_true) / D_true``
landmark error (m)               ``e_k = |p(t_k) - L_k|`` after translating the track so
                                 that ``p(t_0) = L_0``; absolute heading (no rotation)
landmark error, best-fit (m)     the same after the 2-D Procrustes rotation about
                                 ``L_0`` that minimises ``sum_k e_k^2`` (no scale)
loop closure (%)                 ``100 |p(t_N) - p(t_0)| / sum_k |L_{k+1} - L_k|``
                                 for walks whose first and last landmark coincide
segment heading error (deg)      ``wrap_angle(circmean(h_i, t_k < t_i <= t_{k+1}) - bearing_k)``
                                 with ``bearing_k = atan2(dN_k, dE_k)``
distance from a reference        ``d_k = |p(t_k) - p(t_0) + G_0 - G_k|`` for every fix ``k >= 1``
track, e.g. GPS (m)              (track placed at the first fix at its time, absolute
                                 heading); the headline is the median over the fixes
the same, best-fit (m)           after the rotation about ``G_0`` minimising ``sum_k d_k^2``
===============================  ==========================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.conventions import wrap_angle
from core.pdr.deadreckoning import DeadReckoner

#: segments shorter than this (m) have no meaningful bearing and are skipped
MIN_SEGMENT_LENGTH_M = 2.0
#: a segment needs at least this many steps for its mean heading
MIN_SEGMENT_STEPS = 2
#: first and last landmark closer than this (m): the walk is a closed loop
LOOP_CLOSED_TOLERANCE_M = 1.0
#: a step takes at most this long (s) when positions are interpolated between steps
MAX_STEP_DURATION_S = 1.0


def circular_mean(angles) -> float:
    """Mean direction ``atan2(mean(sin a), mean(cos a))`` (rad); nan for no angles."""
    a = np.asarray(angles, dtype=float)
    if a.size == 0:
        return math.nan
    return float(math.atan2(np.mean(np.sin(a)), np.mean(np.cos(a))))




def step_count_error_pct(n_est: int, n_true: int) -> float:
    """Signed step-count error in percent: ``100 (n_est - n_true) / n_true``."""
    if not n_true:
        return math.nan
    return 100.0 * (float(n_est) - float(n_true)) / float(n_true)



# ---------------------------------------------------------------------------
# distance


def distance_error_pct(est_m: float, true_m: float) -> float:
    """Signed walked-distance error in percent: ``100 (est - true) / true``."""
    if not true_m:
        return math.nan
    return 100.0 * (float(est_m) - float(true_m)) / float(true_m)


def polyline_length(east_m, north_m) -> float:
    """``sum_k |L_{k+1} - L_k|`` (m)."""
    e = np.asarray(east_m, dtype=float)
    n = np.asarray(north_m, dtype=float)
    return float(np.sum(np.hypot(np.diff(e), np.diff(n))))


# ---------------------------------------------------------------------------
# trajectories against landmarks


def dead_reckon(length_m, heading_rad) -> tuple[np.ndarray, np.ndarray]:
    """Positions after each step from (0, 0): ``p_i = sum_{j<=i} l_j (cos h_j, sin h_j)`` (eq. 1)."""
    pos = np.array(DeadReckoner().run(np.asarray(length_m, dtype=float), np.asarray(heading_rad, dtype=float)),
                   dtype=float).reshape(-1, 2)
    return pos[:, 0], pos[:, 1]


def positions_at(track_t_ns, east_m, north_m, t_ns, start=(0.0, 0.0),
                 max_step_s: float = MAX_STEP_DURATION_S) -> np.ndarray:
    """Track position at times ``t_ns``, shape ``(len(t_ns), 2)``.

    The track is a list of step end points ``p_i`` at times ``t_i``.  Step
    ``i`` moves the walker from ``p_{i-1}`` (``start`` for the first step) to
    ``p_i`` linearly over ``[max(t_{i-1}, t_i - max_step_s), t_i]`` (the first
    step lasts as long as the second); otherwise the walker stands still, so
    a pause between two steps is not smeared over the pause.
    """
    q = np.asarray(t_ns, dtype=np.int64)
    t = np.asarray(track_t_ns, dtype=np.int64)
    if len(t) == 0:
        return np.tile(np.asarray(start, dtype=float), (len(q), 1))
    rel = (t - t[0]).astype(float) * 1e-9  # float-safe times (s) relative to the first step
    first = min(max_step_s, rel[1]) if len(rel) > 1 else max_step_s  # first step: as long as the second
    begin = np.maximum(np.concatenate([[-first], rel[:-1]]), rel - max_step_s)
    xp = np.column_stack([begin, rel]).ravel()
    e = np.asarray(east_m, dtype=float)
    n = np.asarray(north_m, dtype=float)
    e0 = np.concatenate([[start[0]], e[:-1]])
    n0 = np.concatenate([[start[1]], n[:-1]])
    fe = np.column_stack([e0, e]).ravel()
    fn = np.column_stack([n0, n]).ravel()
    x = (q - t[0]).astype(float) * 1e-9
    return np.column_stack([np.interp(x, xp, fe), np.interp(x, xp, fn)])


def best_fit_rotation(est_xy, ref_xy) -> float:
    """Angle ``theta`` (rad, CCW) of the rotation ``R`` about the origin minimising ``sum |R p_k - L_k|^2``.

    2-D Procrustes without scale or translation (both point sets are already
    relative to the common start):
    ``theta = atan2(sum(x_p y_L - y_p x_L), sum(x_p x_L + y_p y_L))``.
    """
    p = np.asarray(est_xy, dtype=float).reshape(-1, 2)
    q = np.asarray(ref_xy, dtype=float).reshape(-1, 2)
    s = float(np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]))
    c = float(np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]))
    if s == 0.0 and c == 0.0:
        return 0.0
    return math.atan2(s, c)


def proper_rotation(h) -> tuple[np.ndarray, np.ndarray]:
    """The rotation ``R = U D V^T`` (``h = U S V^T``, its SVD; ``D = diag(1, .., d)``, ``d = sign det(U V^T)``)
    that maximises ``trace(R^T h)`` among rotations (no reflection): with ``h = B^T A`` for point sets (rows)
    ``A`` and ``B``, ``B R`` fits ``A`` best in least squares (Kabsch 1976; Umeyama 1991 for the sign), in any
    dimension.  Returns ``R`` and the singular values with the last one's sign times ``d`` (their sum is
    ``trace(R^T h)``, what a scale fit needs)."""
    u, sv, vt = np.linalg.svd(np.asarray(h, dtype=float))
    d = 1.0 if np.linalg.det(u @ vt) >= 0 else -1.0  # a reflection is not a motion
    u[:, -1] *= d
    sv = sv.copy()
    sv[-1] *= d
    return u @ vt, sv


def rotate(xy, theta: float) -> np.ndarray:
    """Rotate points ``(n, 2)`` by ``theta`` (rad, CCW) about the origin."""
    c, s = math.cos(theta), math.sin(theta)
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    return np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]])


def _stat(fn, values) -> float:
    """``fn`` of a non-empty array as a float, nan for an empty one."""
    return float(fn(values)) if len(values) else math.nan


@dataclass
class LandmarkErrors:
    """Errors of one track against one walk's landmarks (see :func:`landmark_errors`)."""

    #: per-landmark error with absolute heading, landmark 0 excluded (it is 0 by construction), m
    errors_m: np.ndarray
    #: per-landmark error after the best-fit rotation about the start, m
    errors_fit_m: np.ndarray
    #: the fitted rotation (rad, CCW): how far our absolute heading was off on the whole
    fit_rotation_rad: float
    #: 100 |p(t_N) - p(t_0)| / path length, for closed loops; nan otherwise
    loop_closure_pct: float
    #: per-segment heading error (rad, wrapped), nan for skipped segments
    segment_heading_err_rad: np.ndarray
    #: our positions at the landmark times, after placing the start at landmark 0 (absolute heading)
    est_at_landmarks: np.ndarray
    #: ground-truth polyline length through the landmarks, m
    path_length_m: float

    @property
    def mean_m(self) -> float:
        return _stat(np.mean, self.errors_m)

    @property
    def mean_fit_m(self) -> float:
        return _stat(np.mean, self.errors_fit_m)

    @property
    def median_m(self) -> float:
        return _stat(np.median, self.errors_m)

    @property
    def median_fit_m(self) -> float:
        return _stat(np.median, self.errors_fit_m)

    @property
    def max_m(self) -> float:
        return _stat(np.max, self.errors_m)

    @property
    def final_m(self) -> float:
        return _stat(lambda a: a[-1], self.errors_m)

    @property
    def segment_heading_mae_deg(self) -> float:
        """Mean absolute segment heading error (deg) over the segments that have one."""
        v = self.segment_heading_err_rad[np.isfinite(self.segment_heading_err_rad)]
        return float(np.degrees(np.mean(np.abs(v)))) if len(v) else math.nan


def segment_heading_errors(step_t_ns, step_heading_rad, lm_t_ns, lm_east_m, lm_north_m,
                           min_length_m: float = MIN_SEGMENT_LENGTH_M,
                           min_steps: int = MIN_SEGMENT_STEPS) -> np.ndarray:
    """Heading error on each straight segment between consecutive landmarks (rad).

    For segment ``k`` (landmark ``k`` to ``k+1``) the estimate is the circular
    mean of the per-step headings ``h_i`` of the steps with
    ``t_k < t_i <= t_{k+1}``; the truth is the segment's bearing
    ``atan2(N_{k+1} - N_k, E_{k+1} - E_k)`` (CCW from East).  The error is
    ``wrap_angle(estimate - bearing)`` in ``[-pi, pi)``.  Segments shorter than
    ``min_length_m`` or with fewer than ``min_steps`` steps give nan.
    """
    t = np.asarray(step_t_ns, dtype=np.int64)
    h = np.asarray(step_heading_rad, dtype=float)
    lt = np.asarray(lm_t_ns, dtype=np.int64)
    le = np.asarray(lm_east_m, dtype=float)
    ln = np.asarray(lm_north_m, dtype=float)
    out = np.full(max(len(lt) - 1, 0), np.nan)
    for k in range(len(lt) - 1):
        de, dn = le[k + 1] - le[k], ln[k + 1] - ln[k]
        if math.hypot(de, dn) < min_length_m:
            continue
        m = (t > lt[k]) & (t <= lt[k + 1])
        if int(np.sum(m)) < min_steps:
            continue
        out[k] = float(wrap_angle(circular_mean(h[m]) - math.atan2(dn, de)))
    return out


def landmark_errors(track_t_ns, east_m, north_m, step_heading_rad, lm_t_ns, lm_east_m, lm_north_m,
                    start=(0.0, 0.0)) -> LandmarkErrors:
    """All landmark metrics of one track (steps ``track_t_ns`` ending at ``east_m, north_m``).

    1. ``p(t)`` = the track position at time ``t`` (:func:`positions_at`).
    2. Place the start at the first landmark: ``p'(t_k) = p(t_k) - p(t_0) + L_0``
       (translation only; the heading stays absolute, from the magnetometer).
    3. ``e_k = |p'(t_k) - L_k|`` for ``k = 1..N`` (landmark 0 is exact by construction).
    4. Best fit: ``theta`` from :func:`best_fit_rotation` of ``p'(t_k) - L_0`` onto
       ``L_k - L_0``, then ``e_k^fit = |R(theta)(p'(t_k) - L_0) + L_0 - L_k|`` (shape only).
    5. Loop closure, when ``|L_N - L_0| < 1 m``:
       ``100 |p(t_N) - p(t_0)| / sum_k |L_{k+1} - L_k|`` (rotation-invariant).
    6. Segment heading errors: :func:`segment_heading_errors`.
    """
    lt = np.asarray(lm_t_ns, dtype=np.int64)
    L = np.column_stack([np.asarray(lm_east_m, dtype=float), np.asarray(lm_north_m, dtype=float)])
    p = positions_at(track_t_ns, east_m, north_m, lt, start=start)
    rel = p - p[0]
    placed = rel + L[0]
    err = np.hypot(*(placed - L).T)[1:]
    theta = best_fit_rotation(rel[1:], (L - L[0])[1:])
    fitted = rotate(rel, theta) + L[0]
    err_fit = np.hypot(*(fitted - L).T)[1:]
    path = polyline_length(L[:, 0], L[:, 1])
    closed = len(L) > 2 and math.hypot(*(L[-1] - L[0])) < LOOP_CLOSED_TOLERANCE_M
    loop = 100.0 * math.hypot(*(p[-1] - p[0])) / path if closed and path > 0 else math.nan
    seg = segment_heading_errors(track_t_ns, step_heading_rad, lt, L[:, 0], L[:, 1])
    return LandmarkErrors(errors_m=err, errors_fit_m=err_fit, fit_rotation_rad=theta, loop_closure_pct=loop,
                          segment_heading_err_rad=seg, est_at_landmarks=placed, path_length_m=path)


@dataclass
class TrackErrors:
    """Distances of one track from a dense reference track (see :func:`reference_track_errors`)."""

    #: per reference fix (the first excluded: 0 by construction), absolute heading, m
    errors_m: np.ndarray
    #: the same after the best-fit rotation about the start, m
    errors_fit_m: np.ndarray
    fit_rotation_rad: float
    #: our positions at the fix times, placed at the first fix (absolute heading), (n, 2)
    est_at_fixes: np.ndarray

    @property
    def median_m(self) -> float:
        return float(np.median(self.errors_m)) if len(self.errors_m) else math.nan

    @property
    def median_fit_m(self) -> float:
        return float(np.median(self.errors_fit_m)) if len(self.errors_fit_m) else math.nan

    @property
    def p90_m(self) -> float:
        return float(np.percentile(self.errors_m, 90)) if len(self.errors_m) else math.nan


def reference_track_errors(track_t_ns, east_m, north_m, ref_t_ns, ref_east_m, ref_north_m,
                           start=(0.0, 0.0)) -> TrackErrors:
    """A track against a dense, time-stamped reference track (e.g. GPS fixes), time-aligned.

    1. ``p(t)`` = our position at time ``t`` (:func:`positions_at`; before the
       first step it is ``start``).
    2. Place it at the first fix: ``p'(t_k) = p(t_k) - p(t_0) + G_0``.
    3. ``d_k = |p'(t_k) - G_k|`` for every fix ``k >= 1``.
    4. Shape error: the same after the rotation about ``G_0``
       (:func:`best_fit_rotation`) that minimises ``sum_k d_k^2``.
    """
    rt = np.asarray(ref_t_ns, dtype=np.int64)
    G = np.column_stack([np.asarray(ref_east_m, dtype=float), np.asarray(ref_north_m, dtype=float)])
    if len(rt) < 2:
        empty = np.zeros(0)
        return TrackErrors(empty, empty, 0.0, np.zeros((len(rt), 2)))
    p = positions_at(track_t_ns, east_m, north_m, rt, start=start)
    rel = p - p[0]
    placed = rel + G[0]
    err = np.hypot(*(placed - G).T)[1:]
    theta = best_fit_rotation(rel[1:], (G - G[0])[1:])
    err_fit = np.hypot(*(rotate(rel, theta) + G[0] - G).T)[1:]
    return TrackErrors(errors_m=err, errors_fit_m=err_fit, fit_rotation_rad=theta, est_at_fixes=placed)


# ---------------------------------------------------------------------------
# the ground truth a recording carries, and a track's error against it

#: GPS fixes with a reported accuracy (68 % radius) above this are not used as a reference track (m)
GPS_REFERENCE_MAX_HACC_M = 12.0
#: streams of surveyed points passed at known times: GetSensorData POSI lines, the Microsoft traces' waypoints
LANDMARK_STREAMS = ("posi", "waypoint")
#: cumulative counters that are ground truth: stream -> (column, what it counts); e.g. the Oxford step-counter
#: files' foot-switch step count, a trundle wheel's distance
COUNTER_TRUTHS = {"step_counts": ("ground_truth", "steps"), "wheel": ("distance_m", "distance")}
#: a ``posi`` stream's position columns: (east, north) in metres, or latitude/longitude in degrees
POSI_METRE_COLUMNS = (("east_m", "north_m"), ("x_m", "y_m"), ("x", "y"))
POSI_DEGREE_COLUMNS = ("lat_deg", "lon_deg")


@dataclass
class Reference:
    """Time-stamped true positions in local East/North metres (landmarks, waypoints or GPS fixes)."""

    t_ns: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    #: what they are, for people ("21 landmarks (posi stream)")
    label: str
    #: WGS-84 latitude, longitude of the metres' origin, when the positions came in degrees
    origin_lat_lon: tuple[float, float] | None = None


@dataclass
class RecordingTruth:
    """The ground truth a recording carries (see :func:`truth_of`); every part may be missing."""

    #: surveyed points the walker passed at known times (a ``posi`` or ``waypoint`` stream: IPIN POSI, waypoints)
    landmarks: Reference | None = None
    #: a dense reference track that is not exact: the recording's good GPS fixes
    gps: Reference | None = None
    #: the simulator's truth (``metadata["truth"]``): n_steps, path_length_m, walk_start_t_ns, walk_end_t_ns,
    #: start_en_m, end_en_m
    simulator: dict | None = None
    #: the simulator's waypoints (n, 2) in its metres (for a plot)
    waypoints_en_m: np.ndarray | None = None
    #: a true step count over a time span: ``{"t0_ns", "t1_ns", "n", "what"}`` (a cumulative ground-truth counter)
    steps: dict | None = None
    #: a true distance over a time span: ``{"t0_ns", "t1_ns", "m", "what"}`` (a cumulative odometer: trundle wheel)
    distance: dict | None = None

    def __bool__(self) -> bool:
        return any(x is not None for x in (self.landmarks, self.gps, self.simulator, self.steps, self.distance))


def _posi_reference(stream) -> Reference | None:
    from core.geodesy import geodetic_to_enu

    cols = list(stream.columns)
    v = np.asarray(stream.values, dtype=float)
    t = np.asarray(stream.t_ns, dtype=np.int64)
    origin = None
    for ce, cn in POSI_METRE_COLUMNS:
        if ce in cols and cn in cols:
            e, n = v[:, cols.index(ce)], v[:, cols.index(cn)]
            break
    else:
        if not all(c in cols for c in POSI_DEGREE_COLUMNS):
            return None
        lat, lon = v[:, cols.index("lat_deg")], v[:, cols.index("lon_deg")]
        ok = np.isfinite(lat) & np.isfinite(lon)
        if not ok.any():
            return None
        origin = (float(lat[ok][0]), float(lon[ok][0]))
        e, n = (np.asarray(x, dtype=float).reshape(-1) for x in geodetic_to_enu(lat, lon, origin))
    ok = np.isfinite(e) & np.isfinite(n)
    if int(ok.sum()) < 2:
        return None
    return Reference(t[ok], e[ok], n[ok], f"{int(ok.sum())} landmarks ({stream.name} stream)", origin)


def _gps_reference(stream, max_hacc_m: float) -> Reference | None:
    from core.geodesy import geodetic_to_enu

    cols = list(stream.columns)
    v = np.asarray(stream.values, dtype=float)
    lat, lon = v[:, cols.index("lat_deg")], v[:, cols.index("lon_deg")]
    hacc = v[:, cols.index("hacc_m")] if "hacc_m" in cols else np.full(len(v), np.nan)
    ok = np.isfinite(lat) & np.isfinite(lon) & (hacc <= max_hacc_m)
    if int(ok.sum()) < 2:
        return None
    origin = (float(lat[ok][0]), float(lon[ok][0]))
    e, n = (np.asarray(x, dtype=float).reshape(-1) for x in geodetic_to_enu(lat[ok], lon[ok], origin))
    return Reference(np.asarray(stream.t_ns, dtype=np.int64)[ok], e, n,
                     f"{int(ok.sum())} GPS fixes with accuracy <= {max_hacc_m:g} m", origin)


def truth_of(rec, *, gps_max_hacc_m: float = GPS_REFERENCE_MAX_HACC_M) -> RecordingTruth:
    """The ground truth in ``rec`` (a :class:`core.recording.Recording`), read from its streams and header.

    * landmarks: a ``posi`` or ``waypoint`` stream (GetSensorData ``POSI`` lines, surveyor waypoints), positions as
      ``lat_deg, lon_deg`` (to metres about the first) or in metres (:data:`POSI_METRE_COLUMNS`);
    * GPS: the ``gps`` fixes with ``hacc_m <= gps_max_hacc_m``, at least two, as a reference track;
    * the simulator's truth: ``metadata["truth"]`` and ``metadata["waypoints_en_m"]``;
    * cumulative ground-truth counters (:data:`COUNTER_TRUTHS`): the steps or metres between their first and
      last event.
    """
    out = RecordingTruth()
    for name in LANDMARK_STREAMS:
        posi = rec.streams.get(name)
        if posi is not None and len(posi):
            out.landmarks = _posi_reference(posi)
            if out.landmarks is not None:
                break
    gps = rec.streams.get("gps")
    if gps is not None and len(gps) >= 2:
        out.gps = _gps_reference(gps, gps_max_hacc_m)
    for name, (col, kind) in COUNTER_TRUTHS.items():
        c = rec.streams.get(name)
        if c is None or col not in c.columns or len(c) < 2:
            continue
        v = np.asarray(c.values, dtype=float)[:, list(c.columns).index(col)]
        ok = np.isfinite(v)
        if int(ok.sum()) < 2:
            continue
        t = np.asarray(c.t_ns, dtype=np.int64)[ok]
        note = str(getattr(c, "note", "") or "")
        what = note.split(": ", 1)[1] if note.startswith("ground truth beside the recording: ") else \
            f"{name} stream, {col}"
        span = {"t0_ns": int(t[0]), "t1_ns": int(t[-1]), "what": what}
        if kind == "steps":
            out.steps = {**span, "n": int(round(v[ok][-1] - v[ok][0]))}
        else:
            out.distance = {**span, "m": float(v[ok][-1] - v[ok][0])}
    meta = rec.metadata if isinstance(rec.metadata, dict) else {}
    sim = meta.get("truth")
    if meta.get("simulator") and isinstance(sim, dict) and sim.get("path_length_m") is not None:
        out.simulator = dict(sim)
        wp = meta.get("waypoints_en_m")
        if wp is not None:
            out.waypoints_en_m = np.asarray(wp, dtype=float).reshape(-1, 2)
    return out


def track_start(track) -> tuple[float, float]:
    """Where the walker stood before the track's first step: its end point less the step itself."""
    if not len(track):
        return 0.0, 0.0
    l0, h0 = float(track.length_m[0]), float(track.heading_rad[0])
    return float(track.east_m[0]) - l0 * math.cos(h0), float(track.north_m[0]) - l0 * math.sin(h0)


def _pct_or_nan(v) -> float:
    return float(v) if v is not None and math.isfinite(v) else math.nan


def truth_errors(track, truth: RecordingTruth, dr_track=None) -> dict:
    """A track's error against ``truth``, as plain numbers (nan where a metric does not apply).

    ``track`` has ``t_ns, length_m, heading_rad, east_m, north_m`` per step (the track shown); the GPS
    reference is compared with ``dr_track`` (dead reckoning alone, default ``track``), since a track fused
    with the same GPS is not an independent estimate.

    * ``"landmarks"``: :func:`landmark_errors` -- median and max error at the landmarks with the absolute
      heading, median after the best-fit rotation and that rotation, loop closure (%) for a closed walk,
      segment heading error, and the distance error of the steps between the first and last landmark
      against the polyline through them;
    * ``"simulator"``: step-count and distance error over the whole walk, the end point's error (track
      moved from the walk's start to its end, against the true displacement) and, for a walk that ends
      where it started, the loop closure ``100 |p(t_end) - p(t_start)| / path length``;
    * ``"gps"``: :func:`reference_track_errors` -- median, 90th percentile and max distance from the fixes;
    * ``"steps"``, ``"distance"``: the steps (or metres) of the track between a ground-truth counter's first and
      last event against the counter's.
    """
    out: dict = {}
    t = np.asarray(track.t_ns, dtype=np.int64)
    e = np.asarray(track.east_m, dtype=float)
    n = np.asarray(track.north_m, dtype=float)
    lm = truth.landmarks
    if lm is not None and len(t):
        le = landmark_errors(t, e, n, np.asarray(track.heading_rad, dtype=float), lm.t_ns, lm.east_m, lm.north_m,
                             start=track_start(track))
        seg = (t > lm.t_ns[0]) & (t <= lm.t_ns[-1])
        walked = float(np.sum(np.asarray(track.length_m, dtype=float)[seg]))
        out["landmarks"] = {
            "what": lm.label, "n": int(len(lm.t_ns)), "path_m": le.path_length_m,
            "median_m": le.median_m, "max_m": le.max_m, "final_m": le.final_m,
            "median_fit_m": le.median_fit_m, "fit_rotation_deg": math.degrees(le.fit_rotation_rad),
            "loop_closure_pct": _pct_or_nan(le.loop_closure_pct),
            "distance_m": walked, "distance_err_pct": distance_error_pct(walked, le.path_length_m),
            "segment_heading_deg": le.segment_heading_mae_deg,
            "errors_m": [float(x) for x in le.errors_m],
        }
    sim = truth.simulator
    if sim is not None:
        path = float(sim["path_length_m"])
        dist = float(np.sum(np.asarray(track.length_m, dtype=float)))
        d = {"what": "simulator", "n_steps": sim.get("n_steps"), "path_m": path,
             "step_count_err_pct": step_count_error_pct(len(t), sim["n_steps"]) if sim.get("n_steps") else math.nan,
             "distance_m": dist, "distance_err_pct": distance_error_pct(dist, path),
             "end_error_m": math.nan, "loop_closure_pct": math.nan}
        se, ee = sim.get("start_en_m"), sim.get("end_en_m")
        if len(t) and se is not None and ee is not None:
            ts = [int(sim.get("walk_start_t_ns", t[0])), int(sim.get("walk_end_t_ns", t[-1]))]
            p = positions_at(t, e, n, np.asarray(ts, dtype=np.int64), start=track_start(track))
            moved = p[1] - p[0]
            true_moved = np.asarray(ee, dtype=float) - np.asarray(se, dtype=float)
            d["end_error_m"] = float(math.hypot(*(moved - true_moved)))
            if math.hypot(*true_moved) < LOOP_CLOSED_TOLERANCE_M and path > 0:
                d["loop_closure_pct"] = 100.0 * float(math.hypot(*moved)) / path
        out["simulator"] = d
    for key, c in (("steps", truth.steps), ("distance", truth.distance)):
        if c is None:
            continue
        # a counter's first event counts what came before it: the steps after it, up to its last event
        win = (t > c["t0_ns"]) & (t <= c["t1_ns"])
        if key == "steps":
            n_ours = int(np.sum(win))
            out["steps"] = {"what": c["what"], "n_true": c["n"], "n": n_ours,
                            "err_pct": step_count_error_pct(n_ours, c["n"])}
        else:
            d_ours = float(np.sum(np.asarray(track.length_m, dtype=float)[win]))
            out["distance"] = {"what": c["what"], "true_m": c["m"], "m": d_ours,
                               "err_pct": distance_error_pct(d_ours, c["m"])}
    ref = truth.gps
    drt = dr_track if dr_track is not None else track
    if ref is not None and len(drt):
        te = reference_track_errors(drt.t_ns, drt.east_m, drt.north_m, ref.t_ns, ref.east_m, ref.north_m,
                                    start=track_start(drt))
        out["gps"] = {"what": ref.label, "n": int(len(ref.t_ns)), "median_m": te.median_m, "p90_m": te.p90_m,
                      "max_m": float(np.max(te.errors_m)) if len(te.errors_m) else math.nan,
                      "median_fit_m": te.median_fit_m, "fit_rotation_deg": math.degrees(te.fit_rotation_rad)}
    return out


def place_reference(track, ref_t0_ns: int, ref_start_en) -> np.ndarray:
    """The shift (2,) that moves a reference into the track's frame: the reference's first point lands on
    the track's position at that point's time (as every metric here places them)."""
    p = positions_at(track.t_ns, track.east_m, track.north_m, np.array([int(ref_t0_ns)], dtype=np.int64),
                     start=track_start(track))[0]
    return p - np.asarray(ref_start_en, dtype=float)
