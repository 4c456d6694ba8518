"""Truth walks (issue #25): the walking direction against a truth track (motion capture or Tango), per carry position.

``python -m benchmarks.truth_walks --extra2 DIR [--split tuning|report|all] [--only TEXT,...] [--no-write]``
writes ``benchmarks/TRUTH_WALKS_RESULTS.md`` and ``benchmarks/truth_walks_results.json``.  ``DIR`` is a folder the
user gives (as ``real_walks --extra``), e.g. ``/work/extra_data2`` (its REBUILD.md says how to rebuild it), holding

* OxIOD ``syn`` pairs ``<owner>__<repo>/<placement>/<dataN>/syn/imuK.csv`` + ``viK.csv`` (iPhone, Vicon truth in a
  room of about 3.5 x 6 m; :mod:`core.importers.oxiod`), and
* RIDI tables ``<owner>__<repo>/**/<name>_data_with_errors.xlsx`` or ``<name>/processed/data.csv`` (Android, Google
  Tango truth, the placement the name's second word: leg = trouser pocket, bag, body, handheld;
  :mod:`core.importers.ridi`), and
* Tyrex attitude-benchmark walks ``<owner>__<repo>/datasets/{android,ios}/<name>/`` + ``qualisys/<name>.mat``
  (Nexus 5, iPhone 4S and 5, Qualisys truth in a room of about 5 x 5 m; FrontPocket / BackPocket = trouser pocket, Swinging = hand
  swinging; :mod:`core.importers.tyrex`; the handler's rotation fitted to the phone as OxIOD's).

Without the folder the benchmark says "not available" and writes nothing (CI has no such folder).

Every walk runs through **the product's default path**, the call :mod:`benchmarks.real_walks` makes for
``pdr replay WALK --no-profile`` (:func:`benchmarks.real_walks.run_default`; the recordings have no GPS, so no
fusion).  Per walk, labelled with its split (:func:`benchmarks.splits.split_of`, datasets
:data:`benchmarks.splits.OXIOD_TRUTH_DATASET` and :data:`~benchmarks.splits.RIDI_TRUTH_DATASET`, declared by sequence
before any number was seen):

Steps and carry
    The number of steps, the carry detector's share of time per mode and the steps per mode.
Walking-direction stability against the truth
    Consecutive :data:`WINDOW_S`-s windows (5 s: the Vicon room's straight stretches are a few metres; the same
    for RIDI) in which
    the truth walks straight (its chord at least :data:`STRAIGHT_MIN` of its path over :data:`PATH_EVERY_S`-s
    samples, and at least :data:`MIN_SPEED_M_S`); the truth's course is the chord's direction, the step heading
    the circular mean of the steps' headings inside (at least :data:`MIN_STEPS` steps).  As
    :func:`benchmarks.real_walks.stability` defines them: the circular SD of ``course - heading`` over the
    windows, its drift (deg/min) and the mean offset (here in the truth's own frame: its absolute value says
    nothing; the SD and the drift do).  Also per carry mode (windows whose steps are over 80 % in one mode) and for
    the device heading (the smoothed device axis, :class:`benchmarks.walkdir._Probe`).  **SD unmixed**: the same
    SD over the windows whose steps are all in the walk's usual state, with the walking-direction offset or
    without it (:func:`unmixed_windows`): a window with steps in the other state (the first strides of a walk,
    or after a reset, before the offset applies) holds the whole offset as a jump, and a 180 deg offset then dominates a walk's SD of eight windows (issue #25: the
    tuning pocket and bag walks); its mean offset is in the truth's unknown frame, so neither SD can tell a
    right constant offset from a wrong one.
Offset against the truth's own attitude (RIDI)
    Where the recording has the truth's attitude of the same device (``truth_attitude``: RIDI's Tango pose), the
    true offset of each step is known in the truth's frame: the truth's course over :data:`TRUE_OFFSET_HALF_S` s
    either side of the step (a chord of at least :data:`TRUE_OFFSET_MIN_CHORD_M`) minus the mean heading, over the
    same samples, of the device axis the step's heading follows (the smoother's ``y`` or ``-z``).  The offset the
    step used (its heading minus the smoothed device heading: 0 where the offset does not apply) against it:
    median and p90 of the absolute error, and the share of steps more than 90 deg off (**wrong**: a sign or axis
    error that the SD cannot see, since it removes the walk's mean).  :func:`truth_offset`.  OxIOD's Vicon
    quaternion is of the marker body, not the phone (its tilt disagrees with Core Motion's gravity by 45-170 deg):
    the constant rotation from the body to the phone is fitted per walk from the gyroscope
    (:func:`device_attitude`: the body's rates from consecutive Vicon rotations against the phone's gyroscope,
    least squares; on the tuning and report copies it puts the phone's vertical within 1.2-4.7 deg of Core
    Motion's gravity, a residual of 0.12-0.21 rad/s, and a hand-held top edge 9-12 deg off the walk).
Reversed steps
    As :func:`benchmarks.real_walks.reversed_steps`, the truth (every :data:`PATH_EVERY_S` s) standing in for the
    GPS fixes: the share of steps more than 90 deg from the truth's chord within 5 s of the step (at least 6 m long),
    turned by the walk's mean offset -- steps walked "backwards" (a flipped sign).
Distance and shape
    The PDR distance (sum of step lengths) against the truth's horizontal path (:data:`PATH_EVERY_S`-s samples,
    from the first step to the last), in %; the 2-D end error after the rotation about the first step that best
    fits the whole PDR track to the truth at the step times (least squares, no scale), in m and in % of the
    truth's path.

Steps against a truth (Tyrex only, issue #25, h15/swingsteps)
    The Qualisys track is of the phone's own marker body, so the truth's step count comes from the phone's motion by
    a fixed rule (:func:`step_truth`), the same for every placement: the **step frequency** is the dominant frequency
    in :data:`STEP_TRUTH_BAND_HZ` (0.8-2.6 Hz: 0.8-2.6 steps/s) of the marker's vertical acceleration (its height
    differentiated twice on a 60-Hz grid, Hann window), over consecutive :data:`STEP_TRUTH_WINDOW_S`-s windows
    (8 s, hop :data:`STEP_TRUTH_HOP_S` = 2 s), counted (``frequency x hop``) where the marker's horizontal speed
    (its velocity's mean over 2 s) has a median above :data:`STEP_TRUTH_MIN_SPEED_M_S` (0.2 m/s: walking) in the
    hop; the count is the sum.  Our steps are counted over the same hops (their centre +-1 s).  Why: in a front pocket the
    body's bounce at each footfall dominates the marker's vertical acceleration (Jakob's tuning front pocket: a peak
    at 1.6-1.8 Hz, the 0.85-Hz stride a quarter of it, the phone's own acceleration norm peaking with it); in a
    swinging hand the
    arm is a pendulum, its height lowest at the middle of each swing, so its vertical acceleration is at twice the
    arm's frequency, which is the step frequency as long as the arm swings once per stride (the natural coupling,
    and what the spectra show: Jakob's six swinging walks have no energy at the 1.7-1.9 Hz of his pocket walks,
    their along-track velocity peaks at 0.55-0.65 Hz and the vertical acceleration at 1.1-1.25 Hz).  Cross-check
    (not the truth): one cycle of the along-track velocity in 0.3-1.3 Hz = one stride gave, on those six walks,
    126-150 steps, 3-10 % above this rule.  The rule cannot see steps taken while the arm stops, nor an arm
    swung at its own rhythm (then it counts the swing): it is a truth of the gait's periodicity, not of footfalls.
    Validation on Jakob's tuning walks (the counter believed right there): front pocket within 0.1-7.7 % of our
    counts (median 2.7 %).  **Not valid in a back pocket** (:data:`STEP_TRUTH_INVALID`): the buttock's vertical
    acceleration peaks at the third stride harmonic (1.5 steps' frequency, 2.4-2.9 Hz) more than at the step
    (Jakob's six: the strongest bins at 2.46-2.81 Hz, the step's at 1.7-1.9 Hz at 0.2-0.7 of it), so the rule reads
    up to 1.5 x the steps where that harmonic falls inside the band (four of six, 28-34 % over our count); shown,
    marked, not a truth.  How it was chosen (h15/swingsteps, TUNING walks only): among three candidates (cycles of
    the along-track velocity x 2; the vertical position's stride frequency x 2; this) by the truth's spectra and
    by the agreement with our counts on the front pockets (the along-track one read 20-50 % under them there);
    its settings were not changed after it was first run, and before any change of the step counter.

A walk that fails (an exception, no steps) is counted and listed, never dropped.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.metrics import median_present
from core.metrics import proper_rotation
from core.conventions import GYRO, wrap_angle
from core.importers._common import TRUTH_ATTITUDE, TRUTH_BODY_ATTITUDE
from core.importers import tyrex as _tyrex
from core.quaternion import to_matrix_array
from benchmarks.options import git_rev, out_dir, write_json
from benchmarks.real_walks import STRAIGHT_MIN, reversed_steps, run_default, stability, step_arrays
from benchmarks.splits import OXIOD_TRUTH_DATASET, REPORT, RIDI_TRUTH_DATASET, TUNING, TYREX_TRUTH_DATASET, split_of

RESULTS_MD = Path(__file__).with_name("TRUTH_WALKS_RESULTS.md")
RESULTS_JSON = Path(__file__).with_name("truth_walks_results.json")

WINDOW_S = 5.0
PATH_EVERY_S = 0.5
MIN_SPEED_M_S = 0.5
MIN_STEPS = 4
PER_MODE_SHARE = 0.8
#: the true offset per step: the truth's course and the device axis's heading over this many seconds either side
TRUE_OFFSET_HALF_S = 1.0
#: ... from a chord of the truth at least this long (m); shorter: the step is not scored
TRUE_OFFSET_MIN_CHORD_M = 1.0
#: a device axis whose horizontal part (mean over the window) is shorter than this has no heading: not scored
TRUE_OFFSET_MIN_HORIZONTAL = 0.2
#: the step truth (Tyrex, :func:`step_truth`): the band of the step frequency (Hz), the window and hop (s), the speed
#: above which a hop is walking (m/s, the 2-s mean of the marker's horizontal velocity) and the grid rate (Hz)
STEP_TRUTH_BAND_HZ = (0.8, 2.6)
STEP_TRUTH_WINDOW_S = 8.0
STEP_TRUTH_HOP_S = 2.0
STEP_TRUTH_MIN_SPEED_M_S = 0.2
STEP_TRUTH_GRID_HZ = 60.0
#: placements where the step truth's rule does not hold (module doc): shown, marked, not a truth
STEP_TRUTH_INVALID = {"backpocket": "not a truth: the buttock's 3rd stride harmonic"}


@dataclass
class TruthWalk:
    name: str
    path: Path  #: OxIOD: the imuK.csv (its viK.csv beside); RIDI: the table (.xlsx or data.csv)
    dataset: str  #: :data:`benchmarks.splits.OXIOD_TRUTH_DATASET` or :data:`~benchmarks.splits.RIDI_TRUTH_DATASET`
    repository: str
    placement: str
    split: str


RIDI_SUFFIX = "_data_with_errors.xlsx"
#: a Tyrex walk's placement by its name's last word (the walking carries only; hand-held and running are not read)
TYREX_PLACEMENTS = {"FrontPocket": "pocket", "BackPocket": "backpocket", "Swinging": "swinging"}


def truth_walks(root: Path | None) -> list[TruthWalk]:
    """The truth walks under ``root``, sorted by name: OxIOD syn pairs
    ``<owner>__<repo>/<placement>/<dataN>/syn/imuK.csv`` (+ ``viK.csv``) and RIDI tables
    ``<owner>__<repo>/**/<name>_data_with_errors.xlsx`` (or RIDI's own ``<name>/processed/data.csv``)."""
    out = []
    if root is None or not Path(root).is_dir():
        return out
    root = Path(root)
    for imu in root.glob("*/*/*/syn/imu*.csv"):
        k = imu.stem[3:]
        if not k.isdigit() or not imu.with_name(f"vi{k}.csv").is_file():
            continue
        data_folder, placement, repo_dir = imu.parent.parent.name, imu.parent.parent.parent.name, imu.parents[3].name
        info = {"placement": placement, "data_folder": data_folder, "sequence": int(k)}
        out.append(TruthWalk(f"oxiod_{placement.replace(' ', '_')}_{data_folder}_seq{k}", imu, OXIOD_TRUTH_DATASET,
                             repo_dir.replace("__", "/", 1), placement, split_of(OXIOD_TRUTH_DATASET, info)))
    tables = [(t, t.name[:-len(RIDI_SUFFIX)]) for t in root.glob(f"*/**/*{RIDI_SUFFIX}")]
    tables += [(t, t.parent.parent.name) for t in root.glob("*/**/processed/data.csv")]
    for table, seq in tables:
        words = seq.split("_")
        if len(words) < 2:
            continue
        placement = words[1].rstrip("0123456789")
        repo_dir = table.relative_to(root).parts[0]
        out.append(TruthWalk(f"ridi_{seq}", table, RIDI_TRUTH_DATASET, repo_dir.replace("__", "/", 1), placement,
                             split_of(RIDI_TRUTH_DATASET, {"sequence": seq})))
    aligns = [*root.glob("*/datasets/android/*/timeAlignment.txt"), *root.glob("*/datasets/ios/*/timeAlignment.txt")]
    for align in aligns:
        folder = align.parent
        # the walk is named by its .mat (``Jakob_iPhone4S_NoDist_Backpocket`` has ``..._BackPocket.mat``)
        mat = Path(_tyrex.truth_path(str(folder)))
        name = mat.stem if mat.is_file() else None
        if name is None or name.split("_")[-1] not in TYREX_PLACEMENTS:
            continue
        repo_dir = folder.relative_to(root).parts[0]
        out.append(TruthWalk(f"tyrex_{name}", folder, TYREX_TRUTH_DATASET, repo_dir.replace("__", "/", 1),
                             TYREX_PLACEMENTS[name.split("_")[-1]], split_of(TYREX_TRUTH_DATASET, {"sequence": name})))
    return sorted(out, key=lambda w: w.name)


def read_walk(walk: TruthWalk):
    """The walk's recording (with its truth as ``posi``)."""
    if walk.dataset == OXIOD_TRUTH_DATASET:
        from core.importers.oxiod import read_oxiod

        return read_oxiod(str(walk.path), warn=False)
    if walk.dataset == TYREX_TRUTH_DATASET:
        from core.importers.tyrex import read_tyrex

        return read_tyrex(str(walk.path), warn=False)
    from core.importers.ridi import read_ridi

    return read_ridi(str(walk.path), warn=False)


# -- the truth: straight windows, path, best-rotation end error ---------------------------------------------
def resample(t_ns: np.ndarray, xy: np.ndarray, every_s: float = PATH_EVERY_S, with_end: bool = True):
    """The truth's horizontal position every ``every_s`` seconds (nearest earlier sample) and at its end."""
    grid = np.arange(t_ns[0], t_ns[-1] + 1, int(round(every_s * 1e9)), dtype=np.int64)
    if with_end and grid[-1] < t_ns[-1]:
        grid = np.append(grid, t_ns[-1])  # the last sample too: the path ends where the truth does
    idx = np.clip(np.searchsorted(t_ns, grid, side="right") - 1, 0, len(t_ns) - 1)
    return grid, xy[idx]


def straight_windows(t_ns: np.ndarray, xy: np.ndarray, window_s: float = WINDOW_S) -> list[tuple[int, int, float]]:
    """``(a_ns, b_ns, course_rad)`` of the consecutive windows in which the truth walks straight (module doc)."""
    grid, p = resample(t_ns, xy, with_end=False)
    per = max(1, int(round(window_s / PATH_EVERY_S)))
    out = []
    for i in range(0, len(grid) - per, per):
        seg = p[i:i + per + 1]
        path = float(np.sum(np.hypot(*np.diff(seg, axis=0).T)))
        d = seg[-1] - seg[0]
        chord = float(math.hypot(d[0], d[1]))
        if chord >= STRAIGHT_MIN * path and chord >= MIN_SPEED_M_S * window_s:
            out.append((int(grid[i]), int(grid[i + per]), math.atan2(d[1], d[0])))
    return out


def path_length_m(t_ns: np.ndarray, xy: np.ndarray, a_ns: int, b_ns: int) -> float:
    """The truth's horizontal path from ``a_ns`` to ``b_ns`` over :data:`PATH_EVERY_S`-s samples."""
    keep = (t_ns >= a_ns) & (t_ns <= b_ns)
    if keep.sum() < 2:
        return 0.0
    _, p = resample(t_ns[keep], xy[keep])
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))


def best_rotation_end_error(pdr_xy: np.ndarray, truth_xy: np.ndarray) -> tuple[float, float]:
    """``(end error m, rotation rad)``: both tracks relative to their first point; the rotation of the PDR track
    about it that fits the truth best (least squares over all points, no scale), then the distance at the end."""
    p = pdr_xy - pdr_xy[0]
    q = truth_xy - truth_xy[0]
    # argmin_theta sum |R(theta) p - q|^2: theta = atan2(sum p x q, sum p . q)
    cross = float(np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]))
    theta = math.atan2(cross, float(np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1])))
    c, s = math.cos(theta), math.sin(theta)
    end = np.array([c * p[-1, 0] - s * p[-1, 1], s * p[-1, 0] + c * p[-1, 1]])
    return float(np.hypot(*(end - q[-1]))), theta


# -- one walk -------------------------------------------------------------------------------------------------
def evaluate_walk(walk: TruthWalk) -> dict:
    row = {"name": walk.name, "dataset": walk.dataset, "split": walk.split, "placement": walk.placement,
           "repository": walk.repository, "file": str(walk.path)}
    try:
        rec = read_walk(walk)
        if walk.dataset == TYREX_TRUTH_DATASET:
            # the step truth needs only the marker track: a walk that fails below still counts its truth, with 0 steps
            truth_hops = step_truth(rec.streams["posi"].t_ns, rec.streams["posi"].values[:, :3])
            row["steps_truth"] = steps_vs_truth(truth_hops, np.zeros(0, dtype=np.int64))
        res, pipe, engine = run_default(rec, walk.path.parent, probe=True)
        t0 = rec.t0_ns
        carry = (res.summary().get("carry") or {})
        time_s = carry.get("time_s") or {}
        total = sum(time_s.values()) or 1.0
        row.update(engine=engine, duration_s=(rec.t1_ns - t0) * 1e-9, n_steps=len(res.steps),
                   carry_share={m: v / total for m, v in sorted(time_s.items())},
                   carry_changes=len(carry.get("changes") or []))
        if not res.steps:
            row["failed"] = "no steps"
            return row
        st_t, heading, device = step_arrays(res, pipe)
        if walk.dataset == TYREX_TRUTH_DATASET:
            row["steps_truth"] = steps_vs_truth(truth_hops, st_t)
        truth_att = device_attitude(rec)
        if truth_att is not None:
            probe_log = getattr(pipe.walkdir, "log", {})
            axes = [probe_log.get(s.heading_rad, {}).get("axis") for s in res.steps]
            pos = rec.streams["posi"]
            row["offset_truth"] = truth_offset(truth_att[0], truth_att[1], pos.t_ns, pos.values[:, :2], st_t, heading,
                                               device, axes)
            row["offset_truth"]["attitude_fit"] = truth_att[2]
        modes = [s.carry_mode for s in res.steps]
        row["steps_per_mode"] = {m: modes.count(m) for m in sorted(set(modes))}
        posi = rec.streams["posi"]
        txy = posi.values[:, :2]
        wins = straight_windows(posi.t_ns, txy)
        row["n_straight_windows"] = len(wins)
        row["stability"] = stability(wins, st_t, heading, t0, MIN_STEPS)
        row["stability_device"] = stability(wins, st_t, device, t0, MIN_STEPS)
        row["stability_unmixed"] = stability(unmixed_windows(wins, st_t, heading, device), st_t, heading, t0,
                                             MIN_STEPS)
        per_mode = {}
        for m in row["steps_per_mode"]:
            mw = [w for w in wins if _mostly(modes, st_t, w, m)]
            s = stability(mw, st_t, heading, t0, MIN_STEPS)
            if s["n_windows"]:
                per_mode[m] = {k: s[k] for k in ("n_windows", "sd_deg", "drift_deg_min", "mean_offset_deg")}
        row["stability_per_mode"] = per_mode
        g, gp = resample(posi.t_ns, txy)
        row["reversed"] = reversed_steps((g, gp[:, 0], gp[:, 1], None), st_t, heading,
                                         row["stability"]["mean_offset_deg"])
        truth_m = path_length_m(posi.t_ns, txy, int(st_t[0]), int(st_t[-1]))
        pdr_m = float(sum(s.length_m for s in res.steps[1:]))  # the steps after the first, as the truth's span
        row.update(truth_path_m=truth_m, pdr_distance_m=pdr_m,
                   distance_error_pct=100.0 * (pdr_m - truth_m) / truth_m if truth_m > 0 else None)
        pdr_xy = np.array([[s.east_m, s.north_m] for s in res.steps])
        idx = np.clip(np.searchsorted(posi.t_ns, st_t), 0, len(posi.t_ns) - 1)
        end_m, rot = best_rotation_end_error(pdr_xy, txy[idx])
        row.update(end_error_m=end_m, best_rotation_deg=math.degrees(rot),
                   end_error_pct=100.0 * end_m / truth_m if truth_m > 0 else None)
    except Exception as e:  # a walk that fails is listed
        row["failed"] = f"{type(e).__name__}: {e}"
        row["traceback"] = traceback.format_exc(limit=3)
    return row


def device_attitude(rec):
    """``(t_ns, R (n, 3, 3) device -> the truth's frame, fit)`` from the recording's truth attitude: RIDI's
    ``truth_attitude`` as it is (fit None); OxIOD's ``truth_body_attitude`` turned by the constant body-to-device
    rotation ``A`` (``v_device = A v_body``) that fits the phone's gyroscope to the body's rates from consecutive
    rotations best (least squares over every pair of rows, the Kabsch solution; fit: the median residual in rad/s).
    None without either."""
    if rec.has(TRUTH_ATTITUDE):
        att = rec.streams[TRUTH_ATTITUDE]
        return att.t_ns, to_matrix_array(att.values), None
    if not (rec.has(TRUTH_BODY_ATTITUDE) and rec.has(GYRO)):
        return None
    att, gyro = rec.streams[TRUTH_BODY_ATTITUDE], rec.streams[GYRO]
    r = to_matrix_array(att.values)  # body -> truth frame
    dt = np.diff(att.t_ns) * 1e-9
    d = np.einsum("nji,njk->nik", r[:-1], r[1:])  # R_k^T R_k+1 = I + [w_body dt]x for a short dt
    w_body = np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], axis=1)
    w_body /= 2.0 * np.maximum(dt, 1e-9)[:, None]
    mid = att.t_ns[:-1] + (att.t_ns[1:] - att.t_ns[:-1]) // 2
    w_dev = np.column_stack([np.interp(mid, gyro.t_ns, gyro.values[:, i]) for i in range(3)])
    ok = (dt > 0) & (dt < 0.1) & np.all(np.isfinite(w_body), axis=1) & (np.linalg.norm(w_body, axis=1) < 20.0)
    if ok.sum() < 100:
        return None
    a, _ = proper_rotation(w_dev[ok].T @ w_body[ok])  # w_body a^T fits w_dev (Kabsch)
    resid = float(np.median(np.linalg.norm(w_dev[ok] - w_body[ok] @ a.T, axis=1)))
    return att.t_ns, np.einsum("nij,kj->nik", r, a), {"residual_rad_s": resid}


def truth_offset(att_t_ns, att_r, pos_t_ns, pos_xy, st_t, heading, device, axes) -> dict:
    """The offset each step used against the true offset from the truth's attitude (module doc).  ``att_r``: (n, 3,
    3) rotation matrices device -> the frame of ``pos_xy`` (:func:`device_attitude`); ``axes``: per step the smoothed
    device axis (a 3-tuple in device coordinates, None: ``y``).  Returns the counts, the true offset's circular mean
    and the absolute errors' median / p90 (deg) and the share of steps more than 90 deg off (%)."""
    att_t_ns = np.asarray(att_t_ns, dtype=np.int64)
    mats = np.asarray(att_r, dtype=float)
    half = int(TRUE_OFFSET_HALF_S * 1e9)
    lo_a, hi_a = np.searchsorted(att_t_ns, st_t - half), np.searchsorted(att_t_ns, st_t + half, side="right")
    lo_p = np.searchsorted(pos_t_ns, st_t - half)
    hi_p = np.searchsorted(pos_t_ns, st_t + half, side="right") - 1
    cums: dict = {}
    errs, trues = [], []
    for k in range(len(st_t)):
        a, b, pa, pb = lo_a[k], hi_a[k], lo_p[k], hi_p[k]
        if b <= a or pb <= pa or not (np.isfinite(heading[k]) and np.isfinite(device[k])):
            continue
        d = pos_xy[pb] - pos_xy[pa]
        if math.hypot(d[0], d[1]) < TRUE_OFFSET_MIN_CHORD_M:
            continue
        ax = tuple(axes[k]) if axes[k] is not None else (0.0, 1.0, 0.0)
        if ax not in cums:  # the axis's horizontal components in the truth frame, cumulated over the samples
            v = mats @ np.asarray(ax, dtype=float)
            cums[ax] = np.vstack([np.zeros(2), np.cumsum(v[:, :2], axis=0)])
        c = cums[ax]
        h = (c[b] - c[a]) / (b - a)
        if math.hypot(h[0], h[1]) < TRUE_OFFSET_MIN_HORIZONTAL:
            continue
        true = wrap_angle(math.atan2(d[1], d[0]) - math.atan2(h[1], h[0]))
        trues.append(true)
        errs.append(abs(wrap_angle(wrap_angle(heading[k] - device[k]) - true)))
    if not errs:
        return {"n": 0, "true_offset_deg": None, "abs_err_deg_median": None, "abs_err_deg_p90": None,
                "wrong_pct": None}
    e = np.degrees(np.asarray(errs))
    return {"n": len(e), "true_offset_deg": math.degrees(math.atan2(np.mean(np.sin(trues)), np.mean(np.cos(trues)))),
            "abs_err_deg_median": float(np.median(e)), "abs_err_deg_p90": float(np.percentile(e, 90)),
            "wrong_pct": float(100.0 * np.mean(e > 90.0))}


def step_truth(t_ns: np.ndarray, xyz: np.ndarray) -> tuple[float, list[tuple[int, int]]]:
    """``(steps, hops)``: the truth's step count and the walking hops ``(a_ns, b_ns)`` it counted (module doc,
    *Steps against a truth*): per :data:`STEP_TRUTH_WINDOW_S`-s window, the dominant frequency in
    :data:`STEP_TRUTH_BAND_HZ` of the marker's vertical acceleration, times the hop, where the marker walks."""
    fs = STEP_TRUTH_GRID_HZ
    grid = np.arange(t_ns[0], t_ns[-1], int(round(1e9 / fs)), dtype=np.int64)
    v = np.column_stack([np.interp(grid, t_ns, xyz[:, i]) for i in range(3)])
    vel = np.gradient(v[:, :2], axis=0) * fs
    k = np.ones(int(round(2.0 * fs))) / round(2.0 * fs)
    speed = np.hypot(np.convolve(vel[:, 0], k, "same"), np.convolve(vel[:, 1], k, "same"))
    az = np.gradient(np.gradient(v[:, 2])) * fs * fs
    n, hop = int(round(STEP_TRUTH_WINDOW_S * fs)), int(round(STEP_TRUTH_HOP_S * fs))
    nfft = 8 * n  # zero padding: 1/64 Hz bins
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    band = (f >= STEP_TRUTH_BAND_HZ[0]) & (f <= STEP_TRUTH_BAND_HZ[1])
    win = np.hanning(n)
    total, hops = 0.0, []
    for i in range(0, len(az) - n + 1, hop):
        c = i + n // 2
        if np.median(speed[c - hop // 2:c + hop // 2]) <= STEP_TRUTH_MIN_SPEED_M_S:
            continue
        seg = az[i:i + n]
        p = np.abs(np.fft.rfft((seg - seg.mean()) * win, nfft)) ** 2
        total += float(f[band][np.argmax(p[band])]) * STEP_TRUTH_HOP_S
        hops.append((int(grid[c - hop // 2]), int(grid[c - hop // 2] + int(STEP_TRUTH_HOP_S * 1e9))))
    return total, hops


def steps_vs_truth(truth_hops: tuple[float, list[tuple[int, int]]], st_t: np.ndarray) -> dict | None:
    """Our steps ``st_t`` against :func:`step_truth`'s ``(steps, hops)`` over its walking hops, or None (no walking
    hop).  For the Tyrex walks only, whose truth is the phone's own marker (OxIOD's and RIDI's are not counted so)."""
    truth, hops = truth_hops
    if not hops or truth <= 0:
        return None
    st_t = np.asarray(st_t, dtype=np.int64)
    ours = int(sum(int(np.count_nonzero((st_t >= a) & (st_t < b))) for a, b in hops))
    return {"steps": ours, "truth": truth, "error_pct": 100.0 * (ours - truth) / truth, "hops": len(hops)}


def unmixed_windows(wins, st_t, heading, device) -> list:
    """The windows whose steps are all in the walk's usual state: all with the walking-direction offset where
    most of the walk's steps got it, all without it where most did not (module doc, issue #25).  A window with
    steps in the other state (the first strides of a walk, or after a reset, before the offset applies) holds
    the whole offset as a jump, whatever the estimate does once it applies."""
    applied = np.isfinite(heading) & np.isfinite(device) & (heading != device)  # a nan heading has no offset
    usual = bool(applied.mean() > 0.5) if len(applied) else False
    out = []
    for w in wins:
        idx = np.flatnonzero((st_t >= w[0]) & (st_t <= w[1]))
        if len(idx) and bool(np.all(applied[idx] == usual)):
            out.append(w)
    return out


def _mostly(modes, st_t, w, m) -> bool:
    idx = np.flatnonzero((st_t >= w[0]) & (st_t <= w[1]))
    return bool(len(idx)) and sum(modes[i] == m for i in idx) > PER_MODE_SHARE * len(idx)


# -- summaries and the report --------------------------------------------------------------------------------
def summarize(rows: list[dict]) -> dict:
    """Medians per split and placement; a failed walk (an exception, no steps) is counted in every median as the
    worst value (+inf; its distance error -100 %: no steps), never dropped."""
    out: dict = {}
    for split in (TUNING, REPORT):
        for pl in sorted({(r["dataset"], r["placement"]) for r in rows if r["split"] == split}):
            rs = [r for r in rows if r["split"] == split and (r["dataset"], r["placement"]) == pl]
            ok = [r for r in rs if not r.get("failed")]
            inf = [math.inf] * (len(rs) - len(ok))
            out.setdefault(split, {})[f"{pl[0]}: {pl[1]}"] = {
                "walks": len(rs), "failed": [r["name"] for r in rs if r.get("failed")],
                "sd_deg_median": median_present([r["stability"]["sd_deg"] for r in ok] + inf),
                "abs_drift_deg_min_median": median_present([abs(r["stability"]["drift_deg_min"]) for r in ok
                                                            if r["stability"]["drift_deg_min"] is not None] + inf),
                "device_sd_deg_median": median_present([r["stability_device"]["sd_deg"] for r in ok] + inf),
                "unmixed_sd_deg_median": median_present([(r.get("stability_unmixed") or {}).get("sd_deg")
                                                         for r in ok] + inf),
                "distance_error_pct_median": median_present([r.get("distance_error_pct") for r in ok]
                                                            + [-100.0] * len(inf)),
                "end_error_pct_median": median_present([r.get("end_error_pct") for r in ok] + inf),
                "reversed_pct_median": median_present([(r.get("reversed") or {}).get("reversed_pct") for r in ok]
                                                      + inf),
                "windows": int(sum(r["stability"]["n_windows"] for r in ok)),
                # against the truth's attitude (a walk without one is no walk of this median)
                "offset_truth_err_deg_median": median_present(
                    [r["offset_truth"]["abs_err_deg_median"] for r in ok if r.get("offset_truth")]
                    + (inf if any(r.get("offset_truth") for r in ok) else [])),
                "offset_truth_wrong_pct_median": median_present(
                    [r["offset_truth"]["wrong_pct"] for r in ok if r.get("offset_truth")]
                    + (inf if any(r.get("offset_truth") for r in ok) else [])),
            }
            # steps against the step truth (Tyrex): a failed walk counts with 0 steps against its truth (-100 %), never
            # dropped; a failed walk without a truth (unreadable) counts -100 % in the error medians; a walk whose
            # marker never walks (no hop) has no truth and is listed
            st = [r["steps_truth"] for r in rs if r.get("steps_truth")]
            if st or any(r["dataset"] == TYREX_TRUTH_DATASET for r in rs):
                no_truth_failed = sum(1 for r in rs if r.get("failed") and not r.get("steps_truth"))
                errs = [x["error_pct"] for x in st] + [-100.0] * no_truth_failed
                out[split][f"{pl[0]}: {pl[1]}"]["steps_truth"] = {
                    "walks": len(errs), "invalid": STEP_TRUTH_INVALID.get(pl[1]), "steps": int(sum(x["steps"] for x in st)),
                    "no_hop": [r["name"] for r in ok if r["dataset"] == TYREX_TRUTH_DATASET and not r.get("steps_truth")],
                    "truth": float(sum(x["truth"] for x in st)),
                    "abs_err_pct_median": median_present([abs(e) for e in errs]),
                    "err_pct_mean": float(np.mean(errs)) if errs else None}
    return out


def _f(x, nd=1):
    return "-" if x is None else f"{x:.{nd}f}"


def _truth_cells(o) -> str:
    if not o or not o.get("n"):
        return "- | -"
    fit = o.get("attitude_fit")
    return (f"{_f(o['true_offset_deg'])} | {_f(o['abs_err_deg_median'])} / {_f(o['abs_err_deg_p90'])} "
            f"({_f(o['wrong_pct'])})" + (f"; body fit {fit['residual_rad_s']:.2f} rad/s" if fit else ""))


def _steps_cell(o) -> str:
    return "-" if not o else f"{o['steps']} / {o['truth']:.0f} ({o['error_pct']:+.1f})"


def _steps_summary_cell(o) -> str:
    if not o:
        return "-"
    return (f"{o['steps']} / {o['truth']:.0f}, {_f(o['abs_err_pct_median'])}, "
            f"{'-' if o['err_pct_mean'] is None else format(o['err_pct_mean'], '+.1f')}"
            + (f" ({o['invalid']})" if o.get("invalid") else "")
            + (f"; no walking hop in the truth: {', '.join(o['no_hop'])}" if o.get("no_hop") else ""))


def markdown(rows: list[dict], summ: dict, meta: dict) -> str:
    seen = "; ".join(f"{s}: {'report, seen once' if s == REPORT else 'tuning'}" for s in meta["splits"])
    L = ["# Truth walks: the walking direction against a motion-capture track (issue #25)", "",
         f"Generated by `python -m benchmarks.truth_walks` at {meta['when']} (commit {meta['commit']}, "
         f"{meta['seconds']:.0f} s). Data: `{meta['folder']}` (OxIOD copies, see its REBUILD.md). Splits run: {seen}.",
         "", f"Windows: consecutive {WINDOW_S:g}-s stretches where the truth track (Vicon / Tango) is straight "
         f"(chord >= "
         f"{STRAIGHT_MIN:g} of the path, >= {MIN_SPEED_M_S:g} m/s), at least {MIN_STEPS} steps. SD / drift: circular "
         "SD and drift of (truth course - step heading) over those windows; offset: their mean, in the truth's "
         "frame (not north: its value says nothing). Distance: PDR steps against the truth's path "
         f"({PATH_EVERY_S:g}-s samples). End error: after the best rotation of the whole track about its first step.",
         "", "## Per split and placement (medians)", "",
         "| split | dataset: placement | walks | failed | windows | SD deg | abs drift deg/min | device SD deg | "
         "SD unmixed deg | distance err % | end err % of path | reversed steps % | offset err vs truth attitude deg "
         "| steps > 90 deg off truth % | steps / step truth (Tyrex): sum, median abs err %, mean err % |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for split, by in summ.items():
        label = "report, seen once" if split == REPORT else "tuning"
        for pl, s in by.items():
            L.append(f"| {label} | {pl} | {s['walks']} | {len(s['failed'])} | {s['windows']} | {_f(s['sd_deg_median'])}"
                     f" | {_f(s['abs_drift_deg_min_median'], 2)} | {_f(s['device_sd_deg_median'])} | "
                     f"{_f(s['unmixed_sd_deg_median'])} | "
                     f"{_f(s['distance_error_pct_median'])} | {_f(s['end_error_pct_median'])} | "
                     f"{_f(s['reversed_pct_median'])} | {_f(s.get('offset_truth_err_deg_median'))} | "
                     f"{_f(s.get('offset_truth_wrong_pct_median'))} | {_steps_summary_cell(s.get('steps_truth'))} |")
    L += ["", "## Per walk", "",
          "| split | walk | s | steps | carry share (detector) | windows | SD deg | drift deg/min | offset deg | "
          "device SD deg | SD unmixed deg (windows) | per mode SD deg | PDR m / truth m (err %) | end err m (% of path) | "
          "reversed % (steps) | true offset deg | offset err vs truth deg, median / p90 (> 90 deg %) | "
          "steps / step truth (err %) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("failed"):
            L.append(f"| {r['split']} | {r['name']} | | | | | FAILED: {r['failed']} | | | | | | | | | | | |")
            continue
        st, dv, um = r["stability"], r["stability_device"], r.get("stability_unmixed") or {}
        share = ", ".join(f"{m} {100 * v:.0f}%" for m, v in r["carry_share"].items())
        pm = ", ".join(f"{m} {_f(v['sd_deg'])} ({v['n_windows']})" for m, v in r["stability_per_mode"].items())
        L.append(f"| {r['split']} | {r['name']} | {r['duration_s']:.0f} | {r['n_steps']} | {share} | "
                 f"{st['n_windows']} | {_f(st['sd_deg'])} | {_f(st['drift_deg_min'], 2)} | "
                 f"{_f(st['mean_offset_deg'])} | "
                 f"{_f(dv['sd_deg'])} | {_f(um.get('sd_deg'))} ({um.get('n_windows', 0)}) | {pm} | {r['pdr_distance_m']:.0f} / {r['truth_path_m']:.0f} "
                 f"({_f(r['distance_error_pct'])}) | {r['end_error_m']:.1f} ({_f(r['end_error_pct'])}) | "
                 f"{_f(r['reversed']['reversed_pct'])} ({r['reversed']['n']}) | {_truth_cells(r.get('offset_truth'))} | "
                 f"{_steps_cell(r.get('steps_truth'))} |")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.truth_walks", description=__doc__.split("\n")[0])
    ap.add_argument("--extra2", type=Path, default=None,
                    help="the folder of the truth walks' copies: OxIOD (<owner>__<repo>/<placement>/<dataN>/syn/imuK.csv + "
                         "viK.csv) and RIDI (<owner>__<repo>/.../<name>.xlsx or data.csv); see its REBUILD.md")
    ap.add_argument("--split", choices=(TUNING, REPORT, "all"), default=TUNING)
    ap.add_argument("--only", default=None, help="comma-separated substrings of walk names")
    ap.add_argument("--no-write", action="store_true", help="write under out/benchmarks/truth_walks/ instead")
    a = ap.parse_args(argv)
    walks = truth_walks(a.extra2)
    if not walks:
        print(f"truth walks not available: no OxIOD syn pair, RIDI table or Tyrex walk under {a.extra2} (give --extra2 DIR)")
        return 0
    if a.split != "all":
        walks = [w for w in walks if w.split == a.split]
    if a.only:
        keys = [k.strip() for k in a.only.split(",") if k.strip()]
        walks = [w for w in walks if any(k in w.name for k in keys)]
    t = time.time()
    rows = []
    for w in walks:
        t1 = time.time()
        rows.append(evaluate_walk(w))
        print(f"  {w.name} ({w.split}): {rows[-1].get('failed') or 'ok'} in {time.time() - t1:.1f} s", file=sys.stderr)
    meta = {"when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": git_rev() or "?",
            "seconds": time.time() - t, "folder": str(a.extra2),
            "splits": sorted({w.split for w in walks}, key=(TUNING, REPORT).index),
            "window_s": WINDOW_S, "path_every_s": PATH_EVERY_S, "min_speed_m_s": MIN_SPEED_M_S, "min_steps": MIN_STEPS}
    summ = summarize(rows)
    md = markdown(rows, summ, meta)
    where = out_dir("truth_walks") if a.no_write or a.only else RESULTS_MD.parent
    (where / RESULTS_MD.name).write_text(md)
    write_json(where / RESULTS_JSON.name, {"meta": meta, "summary": summ, "walks": rows})
    print(md)
    print(f"wrote {RESULTS_MD.name} and {RESULTS_JSON.name} in {where}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
