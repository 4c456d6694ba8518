"""The carry-mode detector over the whole grid: a second implementation of the features of
:class:`core.pdr.carry.CarryModeDetector` (issue #17), vectorised over all hops at once.

The reference computes its features once per hop (``hop_s``, 0.5 s) over the
last ``window_s`` (4 s) of grid samples, in a ring it fills sample by sample.
Here the hop positions are known in advance -- every ``hop`` samples once the
window is full, counted from the start of each grid segment (the detector
restarts with the grid: its window must refill) -- so every hop's window is a
row of a strided view of the grid and the features of all of them are batched
numpy: one ``rfft`` per signal over all windows, ``np.linalg.eigh`` over all
3x3 covariances (:func:`window_features`).  They agree with
:meth:`core.pdr.carry.CarryModeDetector.compute_features` to about 1e-13
(``tests/test_fast_path.py`` checks random windows and real recordings).

The scoring (:meth:`~core.pdr.carry.CarryModeDetector.mode_scores`) and the
hysteresis are not ported: :func:`run_carry` hands each hop's features to the
reference detector's own per-hop decision (about 7,200 hops an hour of walk),
and records what the pipeline reads after every grid sample (the mode, the
step period, whether the rotation is periodic, whether the walk is gentle, the changes logged so far).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.conventions import CARRY_MODES
from core.pdr.carry import rotation_skew

#: hops whose features are batched together (bounds the memory: 512 windows of 200 x 6 floats and their FFTs)
HOP_CHUNK = 512


def _autocorr(det, x: np.ndarray) -> np.ndarray:
    """Unbiased normalised autocorrelation of each zero-mean row of ``x`` (m, n) at lags 0..n-1 (the detector's
    zero-padded FFT length ``nfft``, :attr:`CarryModeDetector.kernel_settings`); a row without energy gives zeros."""
    m, n = x.shape
    nfft = det.kernel_settings["nfft"]
    f = np.fft.rfft(x, nfft, axis=1)
    r = np.fft.irfft(f * np.conj(f), nfft, axis=1)[:, :n]
    r0 = r[:, :1]
    dead = r0[:, 0] <= 1e-12
    scale = n / (n - np.arange(n))
    out = (r / np.where(dead[:, None], 1.0, r0)) * scale
    out[dead] = 0.0
    return out


def window_features(det, w: np.ndarray, has_gyro: np.ndarray, hi: int | None = None) -> list[dict]:
    """The features of windows ``w`` (m, n, 6: acc xyz, gyro xyz, oldest first) as ``det.compute_features`` gives
    them, one dict per window; ``has_gyro[i]``: the detector had seen a gyroscope reading by window ``i``; ``hi``:
    the longest stride lag of every window (None: each window's, ``det.lag_hi``, the windows grouped by it)."""
    m_w, n, _ = w.shape
    if m_w == 0:
        return []
    if hi is None:
        acc = w[:, :, :3]
        norm = np.sqrt(np.einsum("hij,hij->hi", acc, acc))
        x = norm - norm.mean(axis=1)[:, None]
        his = np.array([det.lag_hi(n, s) for s in np.sqrt(np.mean(x * x, axis=1)).tolist()])
        out = [None] * m_w
        for h in np.unique(his).tolist():
            idx = np.flatnonzero(his == h)
            for i, f in zip(idx.tolist(), window_features(det, w[idx], np.asarray(has_gyro)[idx], h)):
                out[i] = f
        return out
    acc = w[:, :, :3]
    norm = np.sqrt(np.einsum("hij,hij->hi", acc, acc))
    mean = acc.mean(axis=1)
    # |mean| one window at a time with the reference's call (np.linalg.norm of a vector is a BLAS dot): the
    # gravity direction's last bit matters to the tilt of a phone that does not move, whose arc cosine near 1
    # turns it into 1e-8 rad
    m_norm = np.array([float(np.linalg.norm(v)) for v in mean])
    mean_norm = norm.mean(axis=1)
    ok = m_norm > 1e-6
    u = np.where(ok[:, None], mean / np.where(ok, m_norm, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    x = norm - mean_norm[:, None]
    std = np.sqrt(np.mean(x * x, axis=1))
    lengths = det.kernel_settings
    xr = norm[:, n - min(lengths["recent_n"], n):]
    xr = xr - xr.mean(axis=1)[:, None]
    recent_std = np.sqrt(np.mean(xr * xr, axis=1))
    lo = lengths["lag_lo_n"]
    r = _autocorr(det, x)
    rows = np.arange(m_w)
    seg = r[:, lo:hi + 1]
    top = seg.max(axis=1)
    # a slow stride only without a peak near the best at a normal cadence's (CarryModeDetector.slow_stride_s)
    hs = lengths["lag_short_n"]
    short_top = seg[:, :hs - lo + 1].max(axis=1)
    use_short = short_top >= det.slow_stride_margin * top
    lags = np.arange(hi - lo + 1)[None, :]

    def peaks_upto(seg, last):
        """Local maxima within 85 % of the best of ``seg`` up to lag index ``last`` (per row) for the rows that
        use the short range (no peak at ``last``: its edge), of the whole range for the others."""
        sg = np.where(use_short[:, None], np.where(lags <= last[:, None], seg, -np.inf), seg)
        tp = np.where(use_short, sg.max(axis=1), top)
        mid = sg[:, 1:-1]
        pk = (mid >= sg[:, :-2]) & (mid >= sg[:, 2:]) & (mid >= 0.85 * tp[:, None])
        pk &= ~(use_short[:, None] & (lags[:, 1:-1] >= last[:, None]))
        return sg, pk

    seg0 = seg
    seg, peak = peaks_upto(seg0, np.full(m_w, hs - lo))
    if det.slow_stride_edge:  # no peak in the short range: up to the peak that straddles its edge (CarryModeDetector)
        ext = use_short & ~peak.any(axis=1)
        if np.any(ext):
            falls = np.concatenate([seg0[:, 1:] < seg0[:, :-1], np.ones((m_w, 1), dtype=bool)], axis=1)
            falls[:, :hs - lo] = False
            seg_e, peak_e = peaks_upto(seg0, np.argmax(falls, axis=1) + 1)
            seg = np.where(ext[:, None], seg_e, seg)
            peak = np.where(ext[:, None], peak_e, peak)
    has_peak = peak.any(axis=1)
    k2 = lo + np.where(has_peak, np.argmax(peak, axis=1) + 1, np.argmax(seg, axis=1))
    if det.half_stride_ratio > 0.0:  # two strides' lag halved (CarryModeDetector._half_stride)
        half = k2 // 2
        idx = half[:, None] + np.arange(-2, 3)[None, :]
        vals = r[rows[:, None], np.minimum(idx, r.shape[1] - 1)]
        j = np.argmax(vals, axis=1)
        ok = ~use_short & has_peak & (half >= lo) & (j > 0) & (j < 4) & (vals[rows, j] >= det.half_stride_ratio * r[rows, k2])
        k2 = np.where(ok, idx[rows, j], k2)
    # the specific force smoothed over smooth_n samples, its angle from the mean direction
    s = lengths["smooth_n"]
    c = np.cumsum(np.concatenate([np.zeros((m_w, 1, 3)), acc], axis=1), axis=1)
    sm = (c[:, s:] - c[:, :-s]) / s
    smn = np.sqrt(np.einsum("hij,hij->hi", sm, sm))
    smn_c = np.maximum(smn, 1e-9)
    cosang = np.clip(np.matmul(sm, u[:, :, None])[:, :, 0] / smn_c, -1.0, 1.0)
    ang = np.arccos(cosang)
    tilt_rms = np.sqrt(np.mean(ang * ang, axis=1))
    # a slow walk's step found as the stride (core.pdr.carry.CarryModeDetector._stride_lag): the norm in
    # anti-phase at half the lag, and the phone on the trunk (a small tilt, the norm repeating at the lag) or the rotation in anti-phase there too
    anti = det.step_antiphase
    k4 = 2 * k2
    ambiguous = (k4 <= hi) & (r[rows, k2 // 2] < anti)
    double = ambiguous & (tilt_rms < det.trunk_max_tilt_rad) & (r[rows, k2] >= det.trunk_min_periodicity)
    gyro = None
    if np.any(has_gyro):
        gyr = w[:, :, 3:]
        g_rms = np.sqrt(np.mean(np.einsum("hij,hij->hi", gyr, gyr), axis=1))
        gc = gyr - gyr.mean(axis=1)[:, None, :]
        cg = np.matmul(gc.transpose(0, 2, 1), gc)
        ge, gv = np.linalg.eigh(cg)
        share = ge[:, -1] / np.maximum(ge.sum(axis=1), 1e-12)
        main = np.matmul(gc, gv[:, :, -1:])[:, :, 0]
        rg = _autocorr(det, main)
        double |= ambiguous & np.asarray(has_gyro, dtype=bool) & (rg[rows, k2] < anti)
        k2 = np.where(double, k4, k2)
        gyro = (g_rms, share, rg[rows, k2], [rotation_skew(mrow) for mrow in main])
    else:
        k2 = np.where(double, k4, k2)
    ks = k2 // 2
    around = ks[:, None] + np.arange(-2, 3)[None, :]  # lags max(1, ks - 2) .. ks + 2
    r_step = np.where(around >= 1, r[rows[:, None], np.maximum(around, 0)], -np.inf).max(axis=1)
    r_stride = r[rows, k2]
    edge = np.minimum(r_step, r_stride)
    r_step = np.where(has_peak, r_step, edge)
    r_stride = np.where(has_peak, r_stride, edge)
    d = sm / smn_c[:, :, None] - u[:, None, :]
    cov = np.matmul(d.transpose(0, 2, 1), d)
    _, evecs = np.linalg.eigh(cov)
    swing = np.matmul(d, evecs[:, :, -1:])[:, :, 0]
    swing = swing - swing.mean(axis=1)[:, None]
    rt = _autocorr(det, swing)
    tilt_stride = np.where(rt.shape[1] > k2, rt[rows, np.minimum(k2, rt.shape[1] - 1)], 0.0)
    dyn = acc - mean[:, None, :]
    cov_a = np.matmul(dyn.transpose(0, 2, 1), dyn) / n
    vert = np.matmul(np.matmul(u[:, None, :], cov_a), u[:, :, None])[:, 0, 0]
    horiz = np.maximum(np.trace(cov_a, axis1=1, axis2=2) - vert, 0.0)
    rate = det.grid_rate_hz
    out = []
    cols = [u[:, 0], u[:, 1], u[:, 2], tilt_rms, m_norm, mean_norm, std, r_step, r_stride, k2, tilt_stride, vert,
            horiz, recent_std]
    for i, (ux, uy, uz, tr, mn, mnn, sd, rs, rst, k, ts, ve, ho, rsd) in enumerate(zip(*(c.tolist() for c in cols))):
        f = {"gravity_x": ux, "gravity_y": uy, "gravity_z": uz, "tilt_rms_rad": tr,
             "coherence": mn / mnn if mnn > 1e-6 else 1.0, "acc_std_m_s2": sd, "recent_std_m_s2": rsd,
             "periodicity": max(rs, rst),
             "r_step": rs, "r_stride": rst, "stride_share": rst - rs, "stride_period_s": k / rate,
             "tilt_stride_corr": ts, "horizontal_ratio": math.sqrt(ho / ve) if ve > 1e-9 else 0.0}
        if has_gyro[i]:
            f.update(gyro_rms_rad_s=float(gyro[0][i]), gyro_axis_share=float(gyro[1][i]),
                     gyro_periodicity=float(gyro[2][i]), gyro_skew=gyro[3][i])
        out.append(f)
    return out


def hop_samples(det, restart: np.ndarray) -> np.ndarray:
    """The grid samples at which the detector decides (a hop): every ``hop`` samples once its window is full,
    counted from each restart of the grid (``restart[k]``: sample ``k`` starts a segment)."""
    n_grid = len(restart)
    starts = np.flatnonzero(restart)
    if n_grid and (not len(starts) or starts[0] != 0):
        starts = np.concatenate([[0], starts])
    ends = np.append(starts[1:], n_grid)
    lengths = det.kernel_settings
    out = [np.arange(a + lengths["window_n"] - 1, b, lengths["hop_n"]) for a, b in zip(starts.tolist(), ends.tolist())]
    return np.concatenate(out).astype(np.int64) if out else np.zeros(0, np.int64)


@dataclass
class CarryTrack:
    """What the pipeline reads of the carry detector after every grid sample (arrays over the grid)."""

    mode: np.ndarray  #: index into core.conventions.CARRY_MODES of the mode in force
    step_period_s: np.ndarray  #: the detector's step period (nan: unknown)
    rotation_periodic: np.ndarray  #: bool: the rotation is periodic at the stride (core's rotation_periodic)
    gentle: np.ndarray  #: bool: a gentle walk (the detector's ``gentle``)
    uneven: np.ndarray  #: bool: the two half-strides very unlike (the detector's ``uneven``)
    n_changes: np.ndarray  #: how many mode changes were logged so far
    changes: list  #: the detector's change log at the end
    settling: np.ndarray  #: bool: the detector's ``settling`` (a walk's mode not settled yet)
    settling_before: bool  #: its ``settling`` before the first grid sample
    pending: np.ndarray = None  #: index into CARRY_MODES of the detector's ``pending_mode`` (-1: None)
    settling_walk: np.ndarray = None  #: bool: the detector's ``settling_walk`` (settling only by ``settle_walk_s``)
    settling_walk_before: bool = False  #: its ``settling_walk`` before the first grid sample
    gait_std_m_s2: np.ndarray = None  #: the detector's ``gait_std_m_s2`` (nan: the step period unknown)


def run_carry(det, t_ns: np.ndarray, acc: np.ndarray, gyro: np.ndarray, has_gyro: np.ndarray,
              restart: np.ndarray) -> CarryTrack:
    """Run the (freshly reset) reference detector ``det`` over the grid: ``acc`` (n, 3) the accelerometer reading
    behind each grid sample, ``gyro`` (n, 3) the last gyroscope reading before it (zeros where ``has_gyro`` is
    False: none yet), ``restart`` the grid's restarts.  Leaves ``det`` as the pipeline leaves it; returns the
    per-sample :class:`CarryTrack`.

    The features of every hop come from :func:`window_features`; each hop's decision (scores, hysteresis,
    change log) is the detector's own (:meth:`core.pdr.carry.CarryModeDetector.decide`).
    """
    n_grid = len(t_ns)
    hops = hop_samples(det, restart)
    rows = np.ascontiguousarray(np.concatenate([acc, gyro], axis=1), dtype=np.float64)
    seen_gyro = np.logical_or.accumulate(has_gyro) if n_grid else has_gyro
    lengths = det.kernel_settings
    n = lengths["window_n"]
    mode_idx = {m: i for i, m in enumerate(CARRY_MODES)}
    modes = [mode_idx[det.mode]]
    periods = [det.step_period_s]
    amps = [det.gait_std_m_s2]
    periodic = [det.rotation_periodic]
    gentle = [det.gentle]
    uneven = [det.uneven]
    settling = [det.settling]
    n_changes = [len(det.changes)]
    pending = [mode_idx.get(det.pending_mode, -1)]
    settling_walk = [det.settling_walk]
    view = np.lib.stride_tricks.sliding_window_view(rows, n, axis=0) if n_grid >= n else None
    # a very slow walk's hops take the long window (CarryModeDetector.slow_window): full once n_long samples of
    # the hop's grid segment are in
    n_long = lengths["long_window_n"]
    view_long = (np.lib.stride_tricks.sliding_window_view(rows, n_long, axis=0)
                 if n_long > n and n_grid >= n_long else None)
    starts = np.flatnonzero(restart)
    if n_grid and (not len(starts) or starts[0] != 0):
        starts = np.concatenate([[0], starts])
    seg_start = starts[np.searchsorted(starts, hops, side="right") - 1] if len(hops) else hops
    for a in range(0, len(hops), HOP_CHUNK):
        h = hops[a:a + HOP_CHUNK]
        w = view[h - (n - 1)].transpose(0, 2, 1)
        feats = window_features(det, w, seen_gyro[h])
        longs = {}
        if view_long is not None:
            full = (h - seg_start[a:a + HOP_CHUNK]) >= n_long - 1
            slow = [i for i, f in enumerate(feats) if det.slow_window(f, bool(full[i]))]
            if slow:
                hl = h[slow]
                longs = dict(zip(slow, window_features(det, view_long[hl - (n_long - 1)].transpose(0, 2, 1),
                                                       seen_gyro[hl])))
        for i, (k, f) in enumerate(zip(h.tolist(), feats)):
            det.set_gyro_seen(bool(seen_gyro[k]))
            if i in longs:  # core's choice of the long window (it reads the mode in force)
                f = det.take_slow_window(f, longs[i])
            det.decide(int(t_ns[k]), f)  # core's decision, on these features
            modes.append(mode_idx[det.mode])
            periods.append(det.step_period_s)
            amps.append(det.gait_std_m_s2)
            periodic.append(det.rotation_periodic)
            gentle.append(det.gentle)
            uneven.append(det.uneven)
            settling.append(det.settling)
            n_changes.append(len(det.changes))
            pending.append(mode_idx.get(det.pending_mode, -1))
            settling_walk.append(det.settling_walk)
    # the state after sample k: that of the last hop at or before k (the initial state before the first)
    at = np.searchsorted(hops, np.arange(n_grid), side="right")
    track = CarryTrack(np.asarray(modes, dtype=np.int64)[at], np.asarray(periods, dtype=float)[at],
                       np.asarray(periodic, dtype=bool)[at], np.asarray(gentle, dtype=bool)[at],
                       np.asarray(uneven, dtype=bool)[at],
                       np.asarray(n_changes, dtype=np.int64)[at],
                       det.changes, np.asarray(settling, dtype=bool)[at], bool(settling[0]),
                       np.asarray(pending, dtype=np.int64)[at], np.asarray(settling_walk, dtype=bool)[at],
                       bool(settling_walk[0]), np.asarray(amps, dtype=float)[at])
    # time per mode: the mode in force before each sample, added one grid period at a time as the detector does
    before = np.concatenate([[modes[0]], track.mode[:-1]]).astype(np.int64) if n_grid else np.zeros(0, np.int64)
    counts = np.bincount(before, minlength=len(CARRY_MODES))
    dt = lengths["dt_s"]
    for i, m in enumerate(CARRY_MODES):
        s = det.time_s[m]
        for _ in range(int(counts[i])):
            s += dt
        det.time_s[m] = s
    det.set_gyro_seen(bool(seen_gyro[-1]) if n_grid else False)
    return track
