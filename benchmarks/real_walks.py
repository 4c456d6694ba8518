"""Real walks decide (issue #25 sections 1 and 3): steps, walking-direction stability and GPS outages.

``python -m benchmarks.real_walks [--data DIR] [--extra DIR] [--only TEXT,...] [--split tuning|report|all]
[--no-write] [--no-outages] [--no-plots] [--jobs N]`` writes ``benchmarks/REAL_WALKS_RESULTS.md`` (and
``benchmarks/real_walks_results.json``) and a plot per walk under ``out/real_walks/`` (not committed).

Every walk runs through **the product's default path**, the code ``pdr replay`` runs
(:func:`desktop.cli.build_gnss`, :func:`desktop.cli.build_pipeline`, :func:`desktop.cli.place_site`,
:func:`desktop.engine.run_pipeline`, with the arguments ``pdr replay WALK --no-profile`` parses: ``--gps auto``,
carry detection on, the World Magnetic Model's declination at the first good fix); ``--no-profile`` so that
no user profile on the machine enters.  Per walk (:mod:`benchmarks.datasets.phone_walks`, each labelled with
its split from :mod:`benchmarks.splits`):

Steps
    Against the stated count (clips), with the carry detector's time per mode and its changes.
Walking-direction stability
    Consecutive 30-s windows (:data:`WINDOW_S`) of good fixes (reported accuracy <= :data:`GOOD_HACC_M`,
    reported speed > :data:`GOOD_SPEED_M_S`, at least :data:`WINDOW_MIN_FIXES` of them) that are straight
    (chord >= :data:`STRAIGHT_MIN` of the path); the GPS course is the chord's direction, the step heading the
    circular mean of the steps' headings inside (the pipeline's step heading, before any GPS fusion: what
    dead reckoning has in an outage).  Per walk: the circular SD of ``course - heading`` over the windows,
    its drift (deg/min, least squares on the differences unwrapped about their mean) and the mean offset.
    Reversed steps: the share of steps (during good fixes) whose heading is more than 90 deg from the GPS course
    (the chord of the good fixes within :data:`REVERSED_HALF_S` of the step, at least :data:`REVERSED_MIN_CHORD_M`
    long) turned by the walk's mean offset -- short groups of steps walked backwards (a flipped
    forward/backward sign) that a 30-s window's mean hides but an outage does not.
    The same for the *device* heading (the smoothed device axis, without the walking-direction offset),
    recorded by :class:`benchmarks.walkdir._Probe` in the same run.  A walk without a magnetometer has no
    absolute heading: its mean offset says nothing about a sign error (reported, not judged).
GPS outages
    Hidden windows of 1, 3 and 5 minutes (``--gps-outage START:LENGTH``, each its own run), starting every
    60 s from :data:`CALIBRATION_S` after walking starts, ending 15 s before the walk does.  The default path:
    its end error (:class:`core.gnss.base.OutageResult`, at the first screened fix after the window) in % of
    the fused distance inside.  "PDR alone": from the same run, dead reckoning from the fused position at the
    last step before the window, each step turned by the heading offset the fusion had learnt (the circular
    mean of fused minus dead-reckoned heading over the last :data:`OFFSET_STEPS` steps before the window),
    its own step lengths, against the same fix.
The reference's floor
    Median reported accuracy of the good fixes over the outage's distance (%): a smaller error than this
    cannot be shown by the GPS.

What can be measured without a counted truth
    The PDR distance against the GPS path (:func:`gps_path`: 5-s chords of the good fixes) and the steps
    against the gait's own periodicity (:func:`periodicity_steps`): proxies, labelled as such.
Groups
    Every number also per corpus (``shared``: ``--data``; ``extra``: ``--extra``) and per carry position as the
    source states it (an inference in brackets, :mod:`benchmarks.datasets.phone_walks`), by split; the results
    say which corpus ran (the folders, the extra folder's MANIFEST.tsv rows and sha256, walks per corpus).

A walk that fails (an exception, no steps, no GPS) is counted and listed, never dropped.
"""

from __future__ import annotations

import argparse
import ast
import math
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.metrics import median_present
from benchmarks.options import git_rev, jsonable, out_dir, write_json, writes_committed
from benchmarks.datasets.phone_walks import STEP_CLIP, RealWalk, real_walks
from benchmarks.splits import REPORT, TUNING
from core.conventions import GPS, wrap_angle
from core.metrics import circular_mean

RESULTS_MD = Path(__file__).with_name("REAL_WALKS_RESULTS.md")
RESULTS_JSON = Path(__file__).with_name("real_walks_results.json")
PLOT_DIR = Path(__file__).resolve().parents[1] / "out" / "real_walks"

WINDOW_S = 30.0
GOOD_HACC_M = 10.0
GOOD_SPEED_M_S = 0.8
WINDOW_MIN_FIXES = 15
STRAIGHT_MIN = 0.9
LENGTHS_S = (60, 180, 300)
CALIBRATION_S = 60.0
EVERY_S = 60.0
OFFSET_STEPS = 20
GPS_PATH_EVERY_S = 5.0
#: steps from the gait's own periodicity (a proxy where nobody counted): windows, step band, "moving" threshold
GAIT_WINDOW_S = 10.0
GAIT_BAND_HZ = (1.2, 2.4)
GAIT_MIN_STD_M_S2 = 0.6
REVERSED_HALF_S = 5.0
REVERSED_MIN_CHORD_M = 6.0

#: issue #25's targets on the report split
TARGET_SD_DEG = 6.0
TARGET_SIGN_DEG = 90.0
TARGET_3MIN_DEFAULT_PCT = 8.0
TARGET_3MIN_PDR_PCT = 12.0


# -- the product's path ----------------------------------------------------------------------------------
def replay_args(folder: Path, outages=()):
    """The arguments ``pdr replay FOLDER --no-profile [--gps-outage A:L ...]`` parses."""
    from desktop.cli import make_parser

    argv = ["replay", str(folder), "--no-profile", "--no-progress"]
    if REPLAY_GPS is not None:
        argv += ["--gps", REPLAY_GPS]
    for a, length in outages:
        argv += ["--gps-outage", f"{a:.3f}:{length:.3f}"]
    return make_parser().parse_args(argv)


#: ``--gps MODE``: the replay's GPS fusion for an experiment (None: the product's default, ``auto``)
REPLAY_GPS: str | None = None

#: ``--set NAME=VALUE``: walking-direction settings for an experiment on the tuning split (None: the defaults)
WALKDIR_OVERRIDES: dict = {}


def run_default(rec, folder: Path, outages=(), probe: bool = False):
    """One run of the default path (what :func:`desktop.cli.replay_recording` runs, without its exports):
    ``(result, pipeline, engine)``.  ``probe``: the walking-direction stage records the device heading too
    (:class:`benchmarks.walkdir._Probe`: the same estimator, the same step headings)."""
    from desktop.cli import build_gnss, build_pipeline, place_site
    from desktop.engine import run_pipeline

    args = replay_args(folder, outages)
    gnss = build_gnss(args, rec, None)
    pipeline = build_pipeline(args, gnss, None)
    place_site(args, rec, pipeline)
    if WALKDIR_OVERRIDES and pipeline.walkdir is not None:
        from core.pdr.walkdir import WalkingDirection

        pipeline.walkdir = WalkingDirection(grid_rate_hz=pipeline.grid_rate_hz, delay_s=pipeline.heading_delay_s,
                                            **WALKDIR_OVERRIDES)
    if probe and pipeline.walkdir is not None:
        from benchmarks.walkdir import _Probe

        pipeline.walkdir.__class__ = _Probe  # same state and settings; reset() (at run) adds the log
        res, engine = run_pipeline(pipeline, rec, "reference")
    else:
        res, engine = run_pipeline(pipeline, rec, args.engine)
    return res, pipeline, engine


# -- GPS: good fixes and straight windows -------------------------------------------------------------------
def good_fixes(gps, origin=None):
    """(t_ns, east, north, hacc) of the fixes with accuracy <= GOOD_HACC_M and speed > GOOD_SPEED_M_S."""
    from core.geodesy import geodetic_to_enu

    cols = list(gps.columns)
    v = gps.values
    hacc, speed = v[:, cols.index("hacc_m")], v[:, cols.index("speed_m_s")]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(v[:, 0]) & np.isfinite(v[:, 1]) & (hacc <= GOOD_HACC_M) & (speed > GOOD_SPEED_M_S)
    if ok.sum() < 2:
        return None
    origin = origin or (float(v[ok, 0][0]), float(v[ok, 1][0]))
    e, n = (np.asarray(x, dtype=float) for x in geodetic_to_enu(v[ok, 0], v[ok, 1], origin))
    return gps.t_ns[ok], e, n, hacc[ok]


def straight_windows(fixes, t0_ns: int, t1_ns: int) -> list[tuple[int, int, float]]:
    """Consecutive WINDOW_S windows that are straight: (start_ns, end_ns, GPS course rad CCW from East)."""
    if fixes is None:
        return []
    t, e, n, _ = fixes
    out = []
    w = int(WINDOW_S * 1e9)
    a = int(t[0])
    while a + w <= t1_ns:
        idx = np.flatnonzero((t >= a) & (t < a + w))
        a += w
        if len(idx) < WINDOW_MIN_FIXES:
            continue
        de, dn = e[idx[-1]] - e[idx[0]], n[idx[-1]] - n[idx[0]]
        chord = math.hypot(de, dn)
        path = float(np.sum(np.hypot(np.diff(e[idx]), np.diff(n[idx]))))
        if chord < 10.0 or chord < STRAIGHT_MIN * path:
            continue
        out.append((int(t[idx[0]]), int(t[idx[-1]]), math.atan2(dn, de)))
    return out


def periodicity_steps(t_s, acc, window_s: float = GAIT_WINDOW_S, band_hz=GAIT_BAND_HZ,
                      min_std: float = GAIT_MIN_STD_M_S2, rate_hz: float = 50.0) -> tuple[float, float]:
    """Steps from the gait's own periodicity, a proxy where nobody counted: per ``window_s`` window whose
    acceleration magnitude varies by more than ``min_std`` (m/s^2, SD), the strongest frequency of the magnitude
    in ``band_hz`` (the step rate of walking, both legs) times the window's length.  ``(steps, moving_s)``.
    A proxy: a phone swung at the stride rate or a harmonic stronger than the step can fool it."""
    t_s = np.asarray(t_s, dtype=float)
    if len(t_s) < 2:
        return 0.0, 0.0
    mag = np.linalg.norm(np.asarray(acc, dtype=float), axis=1)
    grid = np.arange(t_s[0], t_s[-1], 1.0 / rate_hz)
    x = np.interp(grid, t_s, mag)
    n = int(round(window_s * rate_hz))
    nfft = 8 * n
    f = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    win = np.hanning(n)
    steps = moving = 0.0
    for a in range(0, len(x) - n + 1, n):
        w = x[a:a + n] - np.mean(x[a:a + n])
        if np.std(w) < min_std:
            continue
        p = np.abs(np.fft.rfft(w * win, nfft)) ** 2
        steps += float(f[sel][np.argmax(p[sel])]) * window_s
        moving += window_s
    return steps, moving


def gps_path(fixes, every_s: float = GPS_PATH_EVERY_S):
    """The GPS path over the good fixes: chords between fixes at least ``every_s`` apart (shorter chords add the
    fixes' noise to the length), a gap longer than 3 ``every_s`` not bridged.  ``(metres, [(start_ns, end_ns),
    ...])``: the length and the bridged chords' times (the span a PDR distance must be taken over), None without
    two good fixes."""
    if fixes is None or len(fixes[0]) < 2:
        return None
    t, e, n, _ = fixes
    keep = [0]
    for i in range(1, len(t)):
        if (t[i] - t[keep[-1]]) * 1e-9 >= every_s:
            keep.append(i)
    path, spans = 0.0, []
    for a, b in zip(keep[:-1], keep[1:]):
        if (t[b] - t[a]) * 1e-9 <= 3.0 * every_s:
            path += math.hypot(e[b] - e[a], n[b] - n[a])
            spans.append((int(t[a]), int(t[b])))
    return path, spans


def distance_in_spans(st_t, lengths, spans) -> float:
    """The summed step lengths of the steps whose time falls in one of ``spans`` ((start_ns, end_ns], sorted)."""
    if not spans:
        return 0.0
    st_t = np.asarray(st_t, dtype=np.int64)
    inside = np.zeros(len(st_t), dtype=bool)
    for a, b in spans:
        inside |= (st_t > a) & (st_t <= b)
    return float(np.sum(np.asarray(lengths, dtype=float)[inside]))


def stability(windows, st_t, headings, t0_ns: int, min_steps: int = 10) -> dict:
    """Course minus heading per window (of at least ``min_steps`` steps), and the walk's circular SD, drift per
    minute and mean offset."""
    diffs, times = [], []
    for a, b, course in windows:
        idx = np.flatnonzero((st_t >= a) & (st_t <= b))
        h = headings[idx]
        h = h[np.isfinite(h)]
        if len(h) < min_steps:
            continue
        diffs.append(float(wrap_angle(course - circular_mean(h))))
        times.append(0.5 * (a + b - 2 * t0_ns) * 1e-9)
    out = {"n_windows": len(diffs), "t_s": times, "diff_deg": [math.degrees(d) for d in diffs]}
    if len(diffs) < 2:
        out.update(sd_deg=None, drift_deg_min=None, mean_offset_deg=math.degrees(diffs[0]) if diffs else None)
        return out
    d = np.asarray(diffs)
    r = min(math.hypot(float(np.mean(np.cos(d))), float(np.mean(np.sin(d)))), 1.0)
    mu = circular_mean(d)
    u = np.array([wrap_angle(x - mu) for x in d])
    slope = float(np.polyfit(np.asarray(times) / 60.0, np.degrees(u), 1)[0])
    out.update(sd_deg=math.degrees(math.sqrt(-2.0 * math.log(max(r, 1e-12)))), drift_deg_min=slope,
               mean_offset_deg=math.degrees(mu))
    return out


def reversed_steps(fixes, st_t, headings, mean_offset_deg) -> dict:
    """Share of steps more than 90 deg from the local GPS course turned by the mean offset (module docstring)."""
    if fixes is None or mean_offset_deg is None:
        return {"n": 0, "reversed_pct": None}
    t, e, n, _ = fixes
    half = int(REVERSED_HALF_S * 1e9)
    lo = np.searchsorted(t, st_t - half)
    hi = np.searchsorted(t, st_t + half, side="right") - 1
    off = math.radians(mean_offset_deg)
    n_used = n_rev = 0
    for k in range(len(st_t)):
        a, b = lo[k], hi[k]
        if b <= a or not np.isfinite(headings[k]):
            continue
        de, dn = e[b] - e[a], n[b] - n[a]
        if math.hypot(de, dn) < REVERSED_MIN_CHORD_M or t[b] - t[a] > 2 * half:
            continue
        n_used += 1
        if abs(wrap_angle(math.atan2(dn, de) - headings[k] - off)) > 0.5 * math.pi:
            n_rev += 1
    return {"n": n_used, "reversed_pct": 100.0 * n_rev / n_used if n_used else None}


# -- outages ------------------------------------------------------------------------------------------------
def outage_windows(walk_from_s: float, end_s: float) -> list[tuple[float, float]]:
    out = []
    for length in LENGTHS_S:
        a = walk_from_s + CALIBRATION_S
        while a + length <= end_s - 15.0:
            out.append((round(a, 3), float(length)))
            a += EVERY_S
    return out


def pdr_alone(res, outage) -> dict:
    """Dead reckoning over one hidden window from the fused position, turned by the fusion's learnt offset."""
    fu = res.fusion
    steps = res.steps
    t_s = np.array([s.t_ns for s in steps], dtype=np.int64)
    fused = {s.index: s for s in fu.steps}
    start_ns = outage["start_ns"]
    before = [i for i in range(len(steps)) if t_s[i] < start_ns and i in fused]
    fix = next((f for f in fu.fixes if f.t_ns == outage["fix_t_ns"]), None)
    if not before or fix is None or fix.east_m != fix.east_m:
        return {"end_error_m": None, "end_error_pct": None, "offset_deg": None}
    k = before[-1]
    last = before[-OFFSET_STEPS:]
    off = circular_mean([wrap_angle(fused[i].heading_rad - steps[i].heading_rad) for i in last])
    e, n = fused[k].east_m, fused[k].north_m
    for i in range(k + 1, len(steps)):
        if t_s[i] > fix.t_ns:
            break
        h = steps[i].heading_rad + off
        e += steps[i].length_m * math.cos(h)
        n += steps[i].length_m * math.sin(h)
    err = math.hypot(e - fix.east_m, n - fix.north_m)
    walked = outage["walked_m"]
    return {"end_error_m": err, "end_error_pct": 100.0 * err / walked if walked > 0 else None,
            "offset_deg": math.degrees(off)}


class _Fused:
    """A pipeline result with another fusion result (the batch replay of :func:`fuse_outage`)."""

    def __init__(self, steps, fusion):
        self.steps, self.fusion = steps, fusion


def fuse_outage(rec, walk: RealWalk, res, a: float, length: float):
    """The default path's GPS fusion with one hidden window, over the steps of the run without it:
    :func:`desktop.cli.build_gnss` with ``--gps-outage A:L``, then its batch ``run`` -- the kernel the
    pipeline streams through (``FixFusion.run``: same order of fixes and steps; the steps do not depend on the
    fusion once the site is placed before the run, as ``pdr replay`` places it).  Checked against a full run
    of the product per walk (:func:`evaluate_walk`: ``fusion_replay_max_diff_m``)."""
    from core.conventions import GNSS_STATUS
    from desktop.cli import build_gnss

    gnss = build_gnss(replay_args(walk.folder, [(a, length)]), rec, None)
    fr = gnss.run(res.steps, rec.streams[GPS], rec.t0_ns, rec.streams.get(GNSS_STATUS))
    return _Fused(res.steps, fr)


def run_outage(rec, walk: RealWalk, a: float, length: float, floor_hacc: float | None, base=None) -> dict:
    res = fuse_outage(rec, walk, base, a, length) if base is not None else run_default(rec, walk.folder,
                                                                                        [(a, length)])[0]
    fu = res.fusion
    row = {"start_s": a, "length_s": length}
    if fu is None or not fu.outages:
        row["failed"] = "no outage result (no fix after the window?)"
        return row
    o = fu.outages[0]
    od = o.as_dict()
    od["start_ns"] = rec.t0_ns + int(a * 1e9)
    od["fix_t_ns"] = o.fix_t_ns
    row.update(default_pct=o.end_error_pct, default_m=o.end_error_m, walked_m=o.walked_m,
               sigma_m=o.sigma_m, jump_m=o.jump_m)
    p = pdr_alone(res, od)
    row.update(pdr_pct=p["end_error_pct"], pdr_m=p["end_error_m"], learnt_offset_deg=p["offset_deg"])
    row["floor_pct"] = 100.0 * floor_hacc / o.walked_m if floor_hacc and o.walked_m > 0 else None
    return row


# -- one walk -----------------------------------------------------------------------------------------------
def walking_from_s(steps, t0_ns: int) -> float:
    from benchmarks.gnss_eval import walking_start_s

    return walking_start_s(steps, t0_ns)


def step_arrays(res, pipe):
    """``(t_ns, heading_rad, device_heading_rad)`` of a run's steps; the device heading from the probe's log
    (:class:`benchmarks.walkdir._Probe`), else the step heading."""
    st_t = np.array([s.t_ns for s in res.steps], dtype=np.int64)
    heading = np.array([s.heading_rad for s in res.steps])
    probe_log = getattr(pipe.walkdir, "log", {})
    device = np.array([probe_log.get(s.heading_rad, {}).get("device", s.heading_rad) for s in res.steps])
    return st_t, heading, device


def evaluate_walk(walk: RealWalk, outages: bool = True, plots: bool = True) -> dict:
    from core.importers import load_recording

    row = {"name": walk.name, "dataset": walk.dataset, "walk": walk.walk, "split": walk.split, "kind": walk.kind,
           "repository": walk.repository, "corpus": walk.corpus, "carry": walk.carry}
    try:
        rec = load_recording(str(walk.folder), warn=False)
        res, pipe, engine = run_default(rec, walk.folder, probe=True)
        t0 = rec.t0_ns
        summ = res.summary()
        carry = summ.get("carry") or {}
        row.update(engine=engine, duration_s=(rec.t1_ns - t0) * 1e-9, magnetometer=rec.has("mag"),
                   acc_rate_hz=float(rec.streams["acc"].rate_hz), n_steps=len(res.steps),
                   distance_m=float(sum(s.length_m for s in res.steps)),
                   carry_time_s=carry.get("time_s"),
                   carry_changes=[{"t_s": (c["t_ns"] - t0) * 1e-9, "to": c["to"]} for c in carry.get("changes") or []],
                   walkdir=jsonable(pipe.walkdir.diagnostics()) if pipe.walkdir is not None else None)
        if walk.steps_counted:
            row["steps_counted"] = walk.steps_counted
            row["steps_error_pct"] = 100.0 * (len(res.steps) - walk.steps_counted) / walk.steps_counted
            if walk.path_m:
                row["path_m"] = walk.path_m
                row["distance_error_pct"] = 100.0 * (row["distance_m"] - walk.path_m) / walk.path_m
                if walk.closed_loop and res.steps:
                    row["loop_closure_pct"] = 100.0 * math.hypot(res.steps[-1].east_m,
                                                                 res.steps[-1].north_m) / walk.path_m
        if not res.steps:
            row["failed"] = "no steps"
            return row
        st_t, heading, device = step_arrays(res, pipe)
        acc = rec.streams["acc"]
        gait, moving = periodicity_steps((acc.t_ns - t0) * 1e-9, acc.values)
        row.update(periodicity_steps=gait, periodicity_moving_s=moving,
                   steps_vs_periodicity_pct=100.0 * (len(res.steps) - gait) / gait if gait > 0 else None)
        modes = [s.carry_mode for s in res.steps]
        row["steps_per_mode"] = {m: modes.count(m) for m in sorted(set(modes))}
        fixes = good_fixes(rec.streams[GPS]) if rec.has(GPS) and walk.kind != STEP_CLIP else None
        row["gps"] = walk.kind != STEP_CLIP and fixes is not None
        wins = straight_windows(fixes, t0, rec.t1_ns)
        row["stability"] = stability(wins, st_t, heading, t0)
        row["stability_device"] = stability(wins, st_t, device, t0)
        row["reversed"] = reversed_steps(fixes, st_t, heading, row["stability"]["mean_offset_deg"])
        # per carry mode: windows whose steps are mostly in that mode
        per_mode = {}
        for m in row["steps_per_mode"]:
            mw = []
            for w in wins:
                idx = np.flatnonzero((st_t >= w[0]) & (st_t <= w[1]))
                if len(idx) and sum(modes[i] == m for i in idx) > 0.8 * len(idx):
                    mw.append(w)
            s = stability(mw, st_t, heading, t0)
            if s["n_windows"]:
                per_mode[m] = {k: s[k] for k in ("n_windows", "sd_deg", "drift_deg_min", "mean_offset_deg")}
        row["stability_per_mode"] = per_mode
        row["outages"] = []
        gp = gps_path(fixes) if row["gps"] else None
        if gp is not None and gp[0] > 0:
            pdr_m = distance_in_spans(st_t, [s.length_m for s in res.steps], gp[1])
            row.update(gps_path_m=gp[0], pdr_distance_gps_span_m=pdr_m,
                       distance_vs_gps_pct=100.0 * (pdr_m - gp[0]) / gp[0])
        if row["gps"]:
            row["gps_median_hacc_m"] = float(np.median(fixes[3]))
            if outages:
                row["walking_from_s"] = walking_from_s(res.steps, t0)
                wins_o = outage_windows(row["walking_from_s"], row["duration_s"])
                base = res
                if wins_o:  # the batch replay against one full run of the product (the 3-minute one, else first)
                    a, length = next((w for w in wins_o if w[1] == 180.0), wins_o[0])
                    full = run_default(rec, walk.folder, [(a, length)])[0]
                    rep_ = fuse_outage(rec, walk, res, a, length)
                    fa, fb = full.fusion.track(), rep_.fusion.track()
                    same = len(fa) == len(fb) and len(full.steps) == len(res.steps)
                    row["fusion_replay_max_diff_m"] = (float(max(np.max(np.abs(fa.east_m - fb.east_m)),
                                                                 np.max(np.abs(fa.north_m - fb.north_m))))
                                                       if same and len(fa) else None)
                    if not same or row["fusion_replay_max_diff_m"] is None or row["fusion_replay_max_diff_m"] > 1e-6:
                        base = None  # not the same: every outage as a full run of the product
                for a, length in wins_o:
                    try:
                        row["outages"].append(run_outage(rec, walk, a, length, row["gps_median_hacc_m"], base))
                    except Exception as e:  # an outage that fails is listed
                        row["outages"].append({"start_s": a, "length_s": length, "failed": repr(e)})
        if plots:
            try:
                row["plot"] = plot_walk(walk, rec, res, fixes, row, st_t, modes)
            except Exception as e:
                row["plot_error"] = repr(e)
    except Exception as e:
        row["failed"] = f"{type(e).__name__}: {e}"
        row["traceback"] = traceback.format_exc(limit=3)
    return row


def plot_walk(walk: RealWalk, rec, res, fixes, row, st_t, modes) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    PLOT_DIR.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 10), gridspec_kw={"height_ratios": [3, 2]})
    fu = res.fusion
    if fu is not None and fu.steps:
        ft = fu.track()
        ax1.plot(ft.east_m, ft.north_m, "-", lw=1.2, label="fused (default path)")
        from desktop.plot import verdict_group

        fx = [f for f in fu.fixes if f.east_m == f.east_m and f.north_m == f.north_m]
        used = [f for f in fx if f.accepted]
        ax1.plot([f.east_m for f in used], [f.north_m for f in used], ".", ms=2, color="k",
                 label=f"GPS fixes used ({len(used)})")
        groups: dict = {}
        for f in fx:
            if not f.accepted:  # each unused fix under its verdict (the fusion's reason, grouped by rule)
                groups.setdefault(verdict_group(f.reason), []).append(f)
        for g, fs in sorted(groups.items(), key=lambda kv: -len(kv[1])):
            ax1.plot([f.east_m for f in fs], [f.north_m for f in fs], "o", mfc="none", ms=3, alpha=0.6,
                     label=f"GPS not used, {g} ({len(fs)})")
        e0, n0 = ft.east_m[0] - res.steps[0].east_m, ft.north_m[0] - res.steps[0].north_m
    else:
        e0 = n0 = 0.0
    ax1.plot([s.east_m + e0 for s in res.steps], [s.north_m + n0 for s in res.steps], "-", lw=1, alpha=0.7,
             label="PDR alone (from the start)")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.legend(fontsize=7)
    ax1.set_title(f"{walk.name} ({walk.split} split)")
    ax1.set_xlabel("east (m)")
    ax1.set_ylabel("north (m)")
    ax1.set_title(f"{walk.name} ({walk.split} split, {walk.corpus} corpus)\ncarry: {walk.carry}", fontsize=9)
    s = row["stability"]
    if s["n_windows"]:
        ax2.plot(s["t_s"], s["diff_deg"], "o-", label="course - step heading (30-s windows)")
    sd = row["stability_device"]
    if sd["n_windows"]:
        ax2.plot(sd["t_s"], sd["diff_deg"], "x--", alpha=0.6, label="course - device heading")
    names = sorted(set(modes))
    t_rel = (st_t - rec.t0_ns) * 1e-9
    ymin = -200
    for j, m in enumerate(names):
        sel = np.array([x == m for x in modes])
        ax2.plot(t_rel[sel], np.full(sel.sum(), ymin + 8 * j), "|", ms=6, label=f"carry: {m}")
    ax2.set_ylim(ymin - 10, 190)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("deg")
    ax2.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = PLOT_DIR / f"{walk.dataset.replace(':', '_')}__{walk.walk}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return str(path)


# -- summaries ----------------------------------------------------------------------------------------------
def _outage_pct(o: dict, key: str) -> float:
    """An outage's end error (%): one that failed or could not be scored (e.g. no distance walked by the track
    while the fixes moved) is an infinite error in its walk's median, never dropped."""
    v = None if o.get("failed") else o.get(key)
    return math.inf if v is None else v


def summarize(rows: list[dict]) -> dict:
    out = {}
    for split in (TUNING, REPORT):
        rs = [r for r in rows if r["split"] == split]
        if not rs:
            continue
        gps = [r for r in rs if r.get("gps") and not r.get("failed")]
        failed = [r["name"] for r in rs if r.get("failed")]
        # a GPS walk whose run failed counts as an infinite error in the medians, never dropped
        failed_gps = [math.inf for r in rs if r.get("failed") and r.get("kind") == "gps_walk"]
        sds = [r["stability"]["sd_deg"] for r in gps] + failed_gps
        sign = [r["name"] for r in gps if r.get("magnetometer") and r["stability"]["mean_offset_deg"] is not None
                and abs(r["stability"]["mean_offset_deg"]) > TARGET_SIGN_DEG]
        d = {"walks": len(rs), "failed": failed, "gps_walks": len(gps),
             "sd_median_deg": median_present(sds),
             "sd_device_median_deg": median_present([r["stability_device"]["sd_deg"] for r in gps] + failed_gps),
             "abs_drift_median_deg_min": median_present([abs(r["stability"]["drift_deg_min"]) for r in gps
                                                         if r["stability"]["drift_deg_min"] is not None]
                                                        + failed_gps),
             "sign_errors": sign,
             "distance_vs_gps_median_pct": median_present([r.get("distance_vs_gps_pct") for r in gps]
                                                           + [-100.0] * len(failed_gps)),  # a failed run: no distance
             "steps_vs_periodicity_median_pct": median_present([r.get("steps_vs_periodicity_pct")
                                                                if not r.get("failed") else -100.0
                                                                for r in rs]),  # a failed run: no steps
             "reversed_median_pct": median_present([(r.get("reversed") or {}).get("reversed_pct") for r in gps]
                                                   + failed_gps),
             "walks_without_windows": [r["name"] for r in gps if r["stability"]["sd_deg"] is None]}
        for length in LENGTHS_S:
            per_walk_def, per_walk_pdr, per_walk_floor, n_fail = [], [], [], 0
            for r in gps:
                os_ = [o for o in r.get("outages", []) if o["length_s"] == length]
                n_fail += sum(1 for o in os_ if o.get("failed") or o.get("pdr_pct") is None)
                if os_:
                    per_walk_def.append(median_present([_outage_pct(o, "default_pct") for o in os_]))
                    per_walk_pdr.append(median_present([_outage_pct(o, "pdr_pct") for o in os_]))
                    per_walk_floor.append(median_present([o["floor_pct"] for o in os_ if not o.get("failed")]))
            # a GPS walk whose run failed has no outage scored: an infinite error in the medians, never dropped
            per_walk_def += failed_gps
            per_walk_pdr += failed_gps
            d[f"outage_{length}s"] = {"walks": len(per_walk_def), "default_median_pct": median_present(per_walk_def),
                                      "pdr_median_pct": median_present(per_walk_pdr),
                                      "floor_median_pct": median_present(per_walk_floor),
                                      "failed_or_unmeasured": n_fail}
        clips = [r for r in rs if r.get("steps_counted")]
        d["clips"] = len(clips)
        # a counted clip whose run failed gave no steps: -100 %, counted
        d["clip_abs_step_error_mean_pct"] = (float(np.mean([abs(r["steps_error_pct"]) if not r.get("failed")
                                                            else 100.0 for r in clips
                                                            if "steps_error_pct" in r or r.get("failed")]))
                                             if clips else None)
        out[split] = d
    return out


def summarize_by(rows: list[dict], key: str) -> dict:
    """:func:`summarize` of the rows grouped by ``row[key]`` (the corpus, the stated carry position)."""
    out = {}
    for value in sorted({str(r.get(key, "")) for r in rows}):
        out[value] = summarize([r for r in rows if str(r.get(key, "")) == value])
    return out


def corpus_meta(root: Path, extra: Path | None, walks) -> dict:
    """Which corpus a run read: the folders, the extra folder's manifest (rows, sha256) and walks per corpus."""
    import hashlib

    meta = {"data_root": str(root) + ("" if Path(root).is_dir() else " (missing)"),
            "extra": str(extra) if extra else None,
            "walks_per_corpus": {c: sum(1 for w in walks if w.corpus == c) for c in sorted({w.corpus for w in walks})},
            "repositories_extra": sorted({w.repository for w in walks if w.corpus == "extra"})}
    man = Path(extra) / "MANIFEST.tsv" if extra else None
    if man is not None and man.exists():
        data = man.read_bytes()
        meta["extra_manifest"] = {"path": str(man), "rows": max(data.count(b"\n") - 1, 0),
                                  "sha256": hashlib.sha256(data).hexdigest()[:16]}
    return meta


def _f(x, nd=1):
    return "–" if x is None else f"{x:.{nd}f}"


def markdown(rows: list[dict], summ: dict, meta: dict) -> str:
    L = ["## Real walks (issue #25): steps, walking-direction stability, GPS outages", "",
         f"Built by `python -m benchmarks.real_walks` ({meta['when']}, code at {meta['commit']}, {meta['seconds']:.0f} s)."
         " Every walk through the product's default path (`pdr replay WALK --no-profile`: `--gps auto`, carry "
         "detection on, WMM declination at the first good fix); see the module docstring for every definition. "
         "Stability: 30-s straight windows of fixes with accuracy <= 10 m and speed > 0.8 m/s; `course - heading` "
         "per window; SD = circular SD over the windows. Outages: 1/3/5 min, every 60 s from 60 s after walking "
         "starts; end error in % of the fused distance inside; PDR alone = dead reckoning from the fused position "
         "at the window's start, turned by the fusion's learnt heading offset. Floor = median reported accuracy / "
         "outage distance.", ""]
    cm = meta.get("corpus") or {}
    if cm:
        man = cm.get("extra_manifest")
        L += [f"Corpus: data root `{cm['data_root']}`"
              + (f", extra folder `{cm['extra']}`" if cm.get("extra") else ", no extra folder")
              + (f" (manifest `{man['path']}`, {man['rows']} files, sha256 {man['sha256']})" if man else "")
              + "; walks per corpus: " + ", ".join(f"{k} {v}" for k, v in cm["walks_per_corpus"].items())
              + (f"; extra repositories: {', '.join(cm['repositories_extra'])}" if cm.get("repositories_extra") else "")
              + ".", ""]
    L += ["### Per split against the targets", "",
          "| split | walks (GPS) | failed | 30-s SD median (deg) | device-axis SD median | abs drift median (deg/min) | "
          "sign errors (|mean offset| > 90, walks with a magnetometer) | reversed steps median % | "
          "3-min default median % | 3-min PDR alone % | "
          "3-min floor % | 1-min default / PDR % | 5-min default / PDR % | clips: mean abs step error % |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for split, d in summ.items():
        o1, o3, o5 = d["outage_60s"], d["outage_180s"], d["outage_300s"]
        L.append(f"| {split} | {d['walks']} ({d['gps_walks']}) | {len(d['failed'])} {', '.join(d['failed'])} | "
                 f"{_f(d['sd_median_deg'])} | {_f(d['sd_device_median_deg'])} | {_f(d['abs_drift_median_deg_min'])} | "
                 f"{len(d['sign_errors'])} {', '.join(d['sign_errors'])} | {_f(d.get('reversed_median_pct'))} | "
                 f"{_f(o3['default_median_pct'])} "
                 f"({o3['walks']} walks) | {_f(o3['pdr_median_pct'])} | {_f(o3['floor_median_pct'])} | "
                 f"{_f(o1['default_median_pct'])} / {_f(o1['pdr_median_pct'])} | "
                 f"{_f(o5['default_median_pct'])} / {_f(o5['pdr_median_pct'])} | "
                 f"{_f(d['clip_abs_step_error_mean_pct'])} ({d['clips']}) |")
    if REPORT in summ:
        d = summ[REPORT]
        o3 = d["outage_180s"]

        def verdict(x, t):
            return "–" if x is None else ("met" if x <= t else "missed")
        L += ["", f"Targets (report split): 30-s SD median <= {TARGET_SD_DEG:g} deg: "
              f"{verdict(d['sd_median_deg'], TARGET_SD_DEG)} ({_f(d['sd_median_deg'])}); no sign error: "
              f"{'met' if not d['sign_errors'] else 'missed'} ({len(d['sign_errors'])}); 3-min default path "
              f"<= {TARGET_3MIN_DEFAULT_PCT:g} %: {verdict(o3['default_median_pct'], TARGET_3MIN_DEFAULT_PCT)} "
              f"({_f(o3['default_median_pct'])}); 3-min PDR alone <= {TARGET_3MIN_PDR_PCT:g} %: "
              f"{verdict(o3['pdr_median_pct'], TARGET_3MIN_PDR_PCT)} ({_f(o3['pdr_median_pct'])})."]
    for title, groups in (("corpus", meta.get("by_corpus") or {}),
                          ("carry position (as the source states it; an inference in brackets)",
                           meta.get("by_carry") or {})):
        if not groups:
            continue
        L += ["", f"### Per {title} and split", "",
              "| group | split | walks (GPS) | failed | 30-s SD median (deg) | device-axis SD median | "
              "abs drift median (deg/min) | sign errors | PDR distance vs GPS path, median % | steps vs gait "
              "periodicity, median % | 1-min default / PDR % | 3-min default / PDR % (walks) | "
              "clips: mean abs step error % |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for g, per_split in groups.items():
            for split, d in per_split.items():
                o1, o3 = d["outage_60s"], d["outage_180s"]
                L.append(f"| {g} | {split} | {d['walks']} ({d['gps_walks']}) | {len(d['failed'])} | "
                         f"{_f(d['sd_median_deg'])} | {_f(d['sd_device_median_deg'])} | "
                         f"{_f(d['abs_drift_median_deg_min'])} | {len(d['sign_errors'])} | "
                         f"{_f(d.get('distance_vs_gps_median_pct'), 0)} | "
                         f"{_f(d.get('steps_vs_periodicity_median_pct'), 0)} | "
                         f"{_f(o1['default_median_pct'])} / {_f(o1['pdr_median_pct'])} | "
                         f"{_f(o3['default_median_pct'])} / {_f(o3['pdr_median_pct'])} ({o3['walks']}) | "
                         f"{_f(d['clip_abs_step_error_mean_pct'])} ({d['clips']}) |")
    L += ["", "### Per walk", "",
          "| split | walk | kind | stated carry | mag | acc Hz | steps (count, error %) | distance m | "
          "detected carry (share of steps) | "
          "windows | SD deg | drift deg/min | mean offset deg | device-axis SD / mean | reversed steps % | "
          "1-min def / PDR % | 3-min def / PDR % | 5-min def / PDR % | floor 3-min % | learnt offset median deg |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("failed"):
            L.append(f"| {r['split']} | {r['name']} | {r['kind']} | {r.get('carry', '')} | | | FAILED: {r['failed']} |"
                     + " |" * 13)
            continue
        n = r["n_steps"]
        steps = f"{n}" + (f" ({r['steps_counted']}, {r['steps_error_pct']:+.1f})" if r.get("steps_counted") else "")
        if r.get("periodicity_steps"):
            steps += f" (gait ~{r['periodicity_steps']:.0f}: {r['steps_vs_periodicity_pct']:+.0f} %)"
        dist = f"{r['distance_m']:.0f}" + (f" (path {r['path_m']:.0f}, {r['distance_error_pct']:+.1f} %; loop "
                                           f"closure {r['loop_closure_pct']:.1f} %)" if r.get("path_m") else "")
        if r.get("gps_path_m"):
            dist += f" (GPS path {r['gps_path_m']:.0f}: {r['distance_vs_gps_pct']:+.0f} %)"
        carry = ", ".join(f"{m} {100 * c / max(n, 1):.0f}" for m, c in
                          sorted(r["steps_per_mode"].items(), key=lambda kv: -kv[1]))
        s, sd = r["stability"], r["stability_device"]
        outs = {}
        for length in LENGTHS_S:
            good = [o for o in r.get("outages", []) if o["length_s"] == length and not o.get("failed")]
            bad = [o for o in r.get("outages", []) if o["length_s"] == length and o.get("failed")]
            outs[length] = (f"{_f(median_present([o['default_pct'] for o in good]))} / "
                            f"{_f(median_present([o['pdr_pct'] for o in good]))}"
                            f" (n {len(good)}{', failed ' + str(len(bad)) if bad else ''})") if good or bad else "–"
        g3 = [o for o in r.get("outages", []) if o["length_s"] == 180 and not o.get("failed")]
        learnt = median_present([o.get("learnt_offset_deg") for o in r.get("outages", []) if not o.get("failed")])
        L.append(f"| {r['split']} | {r['name']} | {r['kind']} | {r.get('carry', '')} | "
                 f"{'yes' if r.get('magnetometer') else 'no'} | "
                 f"{r['acc_rate_hz']:.0f} | {steps} | {dist} | {carry} | {s['n_windows']} | {_f(s['sd_deg'])} | "
                 f"{_f(s['drift_deg_min'])} | {_f(s['mean_offset_deg'])} | {_f(sd['sd_deg'])} / "
                 f"{_f(sd['mean_offset_deg'])} | {_f((r.get('reversed') or {}).get('reversed_pct'))} | "
                 f"{outs[60]} | {outs[180]} | {outs[300]} | "
                 f"{_f(median_present([o['floor_pct'] for o in g3]))} | {_f(learnt)} |")
    L += ["", "### Per carry mode (windows with > 80 % of their steps in the mode)", "",
          "| split | walk | mode | windows | SD deg | drift deg/min | mean offset deg |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        for m, s in (r.get("stability_per_mode") or {}).items():
            L.append(f"| {r['split']} | {r['name']} | {m} | {s['n_windows']} | {_f(s['sd_deg'])} | "
                     f"{_f(s['drift_deg_min'])} | {_f(s['mean_offset_deg'])} |")
    L += ["", "### Carry-mode timelines (the detector's changes: time s, new mode)", ""]
    for r in rows:
        ch = r.get("carry_changes") or []
        ts = r.get("carry_time_s") or {}
        L.append(f"- {r['name']} ({r['split']}): time per mode "
                 + ", ".join(f"{m} {v:.0f} s" for m, v in sorted(ts.items(), key=lambda kv: -kv[1]))
                 + (f"; {len(ch)} changes: " + ", ".join(_change(c) for c in ch[:12]) + (" ..." if len(ch) > 12 else "")
                    if ch else ""))
    return "\n".join(L) + "\n"


def _change(c) -> str:
    return f"{c['t_s']:.0f} s {c['to']}" if isinstance(c, dict) and "t_s" in c else str(c)


def _task(args):
    global REPLAY_GPS
    walk, outages, plots, overrides, gps = args
    REPLAY_GPS = gps
    WALKDIR_OVERRIDES.clear()
    WALKDIR_OVERRIDES.update(overrides)
    t = time.time()
    r = evaluate_walk(walk, outages, plots)
    r["seconds"] = round(time.time() - t, 1)
    print(f"  {walk.name} ({walk.split}): {r.get('failed') or 'ok'} in {r['seconds']} s", file=sys.stderr)
    return r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.real_walks", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default ../shared/data)")
    ap.add_argument("--extra", type=Path, default=None, help="a folder of fetched recordings (<owner>__<repo>/<walk>)")
    ap.add_argument("--only", default=None, help="comma-separated substrings of walk names")
    ap.add_argument("--split", choices=(TUNING, REPORT, "all"), default="all")
    ap.add_argument("--no-write", action="store_true",
                    help="write the results under out/benchmarks/real_walks/, touch nothing tracked by git")
    ap.add_argument("--no-outages", action="store_true")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a core.pdr.walkdir.WalkingDirection setting for an experiment (tuning split only)")
    ap.add_argument("--gps", default=None, choices=("auto", "off", "chen", "kubrak"),
                    help="the replay's --gps for an experiment (default: the product's, auto); writes under out/")
    a = ap.parse_args(argv)
    root = a.data or default_data_root()
    walks = real_walks(root, a.extra)
    if a.only:
        keys = [k.strip() for k in a.only.split(",") if k.strip()]
        walks = [w for w in walks if any(k in w.name for k in keys)]
    if a.split != "all":
        walks = [w for w in walks if w.split == a.split]
    t = time.time()
    overrides = {}
    for item in a.set:
        k, v = item.split("=", 1)
        try:
            overrides[k] = ast.literal_eval(v)
        except (ValueError, SyntaxError):
            overrides[k] = v
    if overrides and any(w.split != TUNING for w in walks):
        ap.error("--set is for experiments on the tuning split: add --split tuning")
    tasks = [(w, not a.no_outages, not a.no_plots, overrides, a.gps) for w in walks]
    if a.jobs > 1:
        with ProcessPoolExecutor(a.jobs) as ex:
            rows = list(ex.map(_task, tasks))
    else:
        rows = [_task(x) for x in tasks]
    summ = summarize(rows)
    commit = git_rev() or "?"
    meta = {"when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": commit, "seconds": time.time() - t}
    meta.update(corpus=corpus_meta(root, a.extra, walks), by_corpus=summarize_by(rows, "corpus"),
                by_carry=summarize_by(rows, "carry"))
    md = markdown(rows, summ, meta)
    # a subset (--only, --split, --extra, --set) or --no-write: under out/benchmarks/real_walks/ (benchmarks.options)
    subset = a.split != "all" or a.extra is not None or bool(overrides) or a.gps is not None
    res_md = RESULTS_MD if writes_committed(a) and not subset else out_dir("real_walks") / RESULTS_MD.name
    res_json = RESULTS_JSON if writes_committed(a) and not subset else out_dir("real_walks") / RESULTS_JSON.name
    res_md.write_text(md)
    write_json(res_json, {"meta": meta, "summary": summ, "walks": rows})
    print(md)
    print(f"wrote {res_md} and {res_json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
