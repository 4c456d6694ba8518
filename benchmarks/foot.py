"""Foot-mounted navigation benchmark (issue #11): ``python -m benchmarks.foot``.

Writes ``benchmarks/foot_results.json`` (every number, per trial and per
split, and the headlines) and ``benchmarks/FOOT_RESULTS.md`` (a section for
RESULTS.md).  Splits: :mod:`benchmarks.foot_splits`; headline numbers are on
the report split.

PyShoe VICON
    3-D position RMSE against VICON over every sample after our alignment,
    and the final error, per trial, for each detector at its fixed threshold
    (one configuration for all trials) and with the reference zero-velocity
    labels (``zv_vicon_opt``) as the best case, beside PyShoe's own errors.
    **Alignment**: our track starts at the origin; it is translated to the
    VICON position of its first sample, and turned about the vertical by the
    2-D least-squares rotation (:func:`benchmarks.metrics.best_fit_rotation`)
    over the samples until the VICON path has reached ``ALIGN_PATH_M``
    (2 m: the first one or two strides; nothing later is used, so heading
    drift is not hidden).  Beside it PyShoe's own metric (:func:`pyshoe_metric`).
    Stance F1: per sample, against a fixed rule on VICON speed
    (:func:`vicon_still`, < 0.05 m/s), not against the per-trial thresholds of
    ``zv_vicon_opt``.  The per-trial optimum of PyShoe's detectors is an
    oracle line, never a competitor.  A recording without a track counts as
    failed (an infinite error in the medians, :func:`median`).

Options: ``--data`` (the data folder), ``--only`` (a subset: datasets and/or
PyShoe trial names; writes nothing), ``--split`` (one split's PyShoe and IPOL trials; writes nothing),
``--no-write``.  Plots:
``benchmarks/plots/foot_pyshoe_{typical,worst}.png``.
x-io foot loops
    Loop closure: distance from the start to the final stance position, in
    per cent of the walked (stride) distance.
IPOL (lower back + both feet)
    The four cases of the paper's Table 2 on each trial and each foot:
    return-position error (horizontal distance from the start to the last
    stance), left-right foot difference (RMS over the left foot's stances of
    the horizontal distance to the right foot's stance track, interpolated in
    time between its stances: the feet are side by side only in that sense),
    and course difference (RMS of the difference between the two feet's
    stride courses, the right foot's interpolated in time).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.foot_splits import REPORT, TUNING
from benchmarks.metrics import best_fit_rotation, rotate
from benchmarks.options import git_rev, read_json, write_json
from core.conventions import wrap_angle
from core.foot.navigator import AIDS, FootNavigator, FootSettings
from core.foot.stance import DETECTORS, StanceDetector, StanceSettings

HERE = Path(__file__).resolve().parent
RESULTS_JSON = HERE / "foot_results.json"
RESULTS_MD = HERE / "FOOT_RESULTS.md"
#: VICON path length (m) over which our track's yaw is fitted (see the module docstring)
ALIGN_PATH_M = 2.0


# ---------------------------------------------------------------------------
# metrics


def stance_scores(pred, ref) -> dict:
    """Per-sample precision, recall and F1 of stance against reference labels."""
    p = np.asarray(pred, dtype=bool)
    r = np.asarray(ref, dtype=bool)
    tp = int(np.sum(p & r))
    prec = tp / max(int(np.sum(p)), 1)
    rec = tp / max(int(np.sum(r)), 1)
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    return {"precision": prec, "recall": rec, "f1": f1}


def align_to_truth(pos_n, truth_n, align_path_m: float = ALIGN_PATH_M):
    """Our positions translated to the truth's at our first valid sample and turned by the yaw fitted over
    the first ``align_path_m`` of truth path; returns ``(aligned (n, 3), valid mask, yaw_rad)``."""
    ok = np.all(np.isfinite(pos_n), axis=1)
    if not np.any(ok):
        return np.full_like(pos_n, np.nan), ok, math.nan
    i0 = int(np.flatnonzero(ok)[0])
    rel_t = truth_n - truth_n[i0]
    rel_p = pos_n - pos_n[i0]
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(truth_n[:, :2], axis=0), axis=1))])
    path = path - path[i0]
    m = ok & (path <= align_path_m) & (np.arange(len(path)) >= i0)
    yaw = best_fit_rotation(rel_p[m, :2], rel_t[m, :2])
    out = np.full_like(pos_n, np.nan)
    out[ok, :2] = rotate(rel_p[ok, :2], yaw) + truth_n[i0, :2]
    out[ok, 2] = rel_p[ok, 2] + truth_n[i0, 2]
    return out, ok, yaw


def position_errors(pos_n, truth_n) -> dict:
    al, ok, yaw = align_to_truth(pos_n, truth_n)
    if not np.any(ok):
        return {"rmse_3d_m": math.nan, "final_3d_m": math.nan, "rmse_2d_m": math.nan, "align_yaw_deg": math.nan,
                "rmse_2d_whole_trial_yaw_m": math.nan, "rmse_z_m": math.nan, "pyshoe_2d_m": math.nan,
                "pyshoe_3d_m": math.nan}
    e = np.linalg.norm(al[ok] - truth_n[ok], axis=1)
    e2 = np.linalg.norm(al[ok, :2] - truth_n[ok, :2], axis=1)
    # diagnostic only (not a result): the yaw fitted over the whole trial, which hides heading drift
    bf, okb, _ = align_to_truth(pos_n, truth_n, align_path_m=math.inf)
    eb = np.linalg.norm(bf[okb, :2] - truth_n[okb, :2], axis=1)
    return {"rmse_3d_m": float(np.sqrt(np.mean(e ** 2))), "final_3d_m": float(e[-1]),
            "rmse_2d_m": float(np.sqrt(np.mean(e2 ** 2))), "align_yaw_deg": math.degrees(yaw),
            "rmse_2d_whole_trial_yaw_m": float(np.sqrt(np.mean(eb ** 2))),
            "rmse_z_m": float(np.sqrt(np.mean((al[ok, 2] - truth_n[ok, 2]) ** 2))),
            **pyshoe_metric(pos_n, truth_n)}


#: PyShoe's alignment point: the first sample at least this far (horizontally) from the estimate's start (m)
PYSHOE_ALIGN_DIST_M = 0.8


def pyshoe_metric(pos_n, truth_n, align_dist_m: float = PYSHOE_ALIGN_DIST_M) -> dict:
    """The error PyShoe publishes (its ``trial_error``), written from the description of its evaluation.

    Both tracks from our first valid sample, each relative to its own start; the estimate turned about
    the vertical so that its position at the first sample ``align_dist_m`` from its start points the
    same way as the truth's at that sample (one point, in a swing: noisy); then the *mean* over samples
    of the per-sample RMS over the axes: ``mean_k |e_xy,k| / sqrt(2)`` ("2d", what the files hold) and
    ``mean_k |e_k| / sqrt(3)`` ("3d").  Not an RMSE in our sense: with the same track it is about
    ``1 / sqrt(2)`` of our 2-D RMSE before the alignment's effect.  Reproduces the files' shoe errors
    with a PyShoe-style filter (:func:`pyshoe_peer`) on the files' shoe labels (docs/foot.md).
    """
    nan = {"pyshoe_2d_m": math.nan, "pyshoe_3d_m": math.nan}
    ok = np.all(np.isfinite(pos_n), axis=1)
    if not np.any(ok):
        return nan
    i0 = int(np.flatnonzero(ok)[0])
    e = pos_n[i0:] - pos_n[i0]
    t = truth_n[i0:] - truth_n[i0]
    okk = ok[i0:]
    far = np.flatnonzero(okk & (np.hypot(e[:, 0], e[:, 1]) >= align_dist_m))
    k = int(far[0]) if len(far) else min(300, len(e) - 1)  # PyShoe: an arbitrary sample if never that far
    yaw = math.atan2(t[k, 1], t[k, 0]) - math.atan2(e[k, 1], e[k, 0])
    d = np.column_stack([rotate(e[okk, :2], yaw), e[okk, 2]]) - t[okk]
    return {"pyshoe_2d_m": float(np.mean(np.hypot(d[:, 0], d[:, 1]) / math.sqrt(2.0))),
            "pyshoe_3d_m": float(np.mean(np.linalg.norm(d, axis=1) / math.sqrt(3.0)))}


def median(values) -> float:
    """Median of errors where a failed recording (None or NaN: no track, no number) counts as an infinite
    error: it is never dropped (a median over trials with one failure in the upper half is unchanged; with
    half of them failed it is inf).  :func:`n_failed` says how many."""
    v = [math.inf if x is None or math.isnan(x) else float(x) for x in values]
    return float(np.median(v)) if v else math.nan


def n_failed(values) -> int:
    """How many of ``values`` are failures (None, NaN or inf: a recording without a usable track)."""
    return sum(1 for x in values if x is None or not math.isfinite(x))


def median_finite(values) -> float:
    """Median of the finite values (for timings and scores that are not errors of a track)."""
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


# ---------------------------------------------------------------------------
# a PyShoe-style peer (benchmark side only): to tell the filter from the labels and the metric


#: PyShoe's settings for this sensor as its VICON evaluation describes them: SHOE noise (m/s^2, rad/s),
#: window (samples), gravity (m/s^2), body-frame process noise per step (m/s^2, rad/s) and ZUPT noise (m/s)
PEER = {"shoe_sigma_a": 0.00098, "shoe_sigma_w": 8.7266463e-5, "window": 5, "g": 9.8029,
        "q_acc": 0.5, "q_gyro": math.radians(0.5), "r_vel": 0.01}


#: the peer's one fixed SHOE threshold: the median of the files' per-trial optima ``G_shoe_opt`` over the
#: tuning split (14 trials, 4.75e5 .. 9.25e7)
PEER_SHOE_FIXED_THRESHOLD = 1.0625e7


def peer_shoe_statistic(acc, gyro, p=PEER) -> np.ndarray:
    """PyShoe's SHOE statistic on non-overlapping windows of ``window`` samples (samples after the last
    whole window keep 0, i.e. "still", as there)."""
    W = p["window"]
    n = len(acc) // W * W
    a = acc[:n].reshape(-1, W, 3)
    w = gyro[:n].reshape(-1, W, 3)
    m = a.mean(axis=1, keepdims=True)
    ra = a - p["g"] * m / np.linalg.norm(m, axis=2, keepdims=True)
    T = (np.sum(ra ** 2, axis=(1, 2)) / p["shoe_sigma_a"] ** 2 + np.sum(w ** 2, axis=(1, 2)) / p["shoe_sigma_w"] ** 2) / W
    out = np.zeros(len(acc))
    out[:n] = np.repeat(T, W)
    return out


def pyshoe_peer(acc, gyro, zv, dt_s: float = 0.005, p=PEER) -> np.ndarray:
    """A 9-state (position, velocity, attitude) ZUPT EKF as PyShoe describes its own, in its z-down frame
    (sensor axes as in the files): attitude from the mean of the first 20 samples (yaw 0), first-order
    mechanisation with the *current* sample and fixed ``dt_s``, gravity ``g``, no bias states, zero
    velocity as the only measurement.  Returns ENU positions (the reader's axis swap)."""
    n = len(acc)
    a0 = acc[:20].mean(axis=0)
    roll, pitch = math.atan2(-a0[1], -a0[2]), math.atan2(a0[0], math.hypot(a0[1], a0[2]))
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    R = np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])  # Ry(pitch) Rx(roll)
    P = np.diag([1e-10] * 6 + [math.radians(0.1) ** 2] * 3)
    Qa, Qg = (p["q_acc"] * dt_s) ** 2, (p["q_gyro"] * dt_s) ** 2
    Rz = np.eye(3) * p["r_vel"] ** 2
    F = np.eye(9)
    F[0:3, 3:6] = np.eye(3) * dt_s
    gvec = np.array([0.0, 0.0, p["g"]])
    pos, vel = np.zeros(3), np.zeros(3)
    out = np.zeros((n, 3))
    for k in range(1, n):
        f, w = acc[k], gyro[k]
        Q = np.zeros((9, 9))
        Q[3:6, 3:6] = Qa * np.eye(3)
        Q[6:9, 6:9] = Qg * np.eye(3)  # R Q R^T = Q for isotropic Q
        fn_old = R @ f
        F[3:6, 6:9] = -dt_s * _skew3(fn_old)
        ang = np.linalg.norm(w) * dt_s
        if ang > 0:
            K = _skew3(w * dt_s / ang)
            R = R @ (np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K))
        an = R @ f + gvec
        vel = vel + dt_s * an
        pos = pos + dt_s * vel + 0.5 * dt_s * dt_s * an
        P = F @ P @ F.T + Q
        if zv[k]:
            S = P[3:6, 3:6] + Rz
            Kg = P[:, 3:6] @ np.linalg.inv(S)
            dx = Kg @ (-vel)
            pos, vel = pos + dx[0:3], vel + dx[3:6]
            R = (np.eye(3) + _skew3(dx[6:9])) @ R
            u, _, vt = np.linalg.svd(R)
            R = u @ vt
            P = P - Kg @ P[3:6, :]
            P = 0.5 * (P + P.T)
        out[k] = pos
    return np.column_stack([out[:, 1], out[:, 0], -out[:, 2]])


def _skew3(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ---------------------------------------------------------------------------
# settings of the benchmark (fixed; thresholds chosen on the tuning split, see docs/foot.md)


#: the benchmark's detector cases: each at one fixed configuration for every trial ("shoe" the product's
#: default, with the adaptive threshold and the RTS smoother of replays; "shoe_filter" the same, forward filter
#: only (what the live app shows); "shoe_fixed" SHOE at the fixed 1e5 alone; "song" the paper's detector as
#: written, J <= 1 on a trailing 0.15 s window; "learned" the logistic stance model of issue #27,
#: core/foot/models/stance_lr.json, trained on the tuning split: its tuning numbers are in-sample)
CASE_DETECTORS = ("shoe", "shoe_filter", "shoe_fixed", "song", "amv", "are", "learned")


def foot_settings(detector: str = "shoe", aid: str = "zupt", gyro_delay_s: float = 0.0,
                  gyro_range_rad_s: float = math.nan, **stance_overrides) -> FootSettings:
    """One fixed configuration per detector: the defaults (RTS smoother on); "song" with the paper's 0.15 s
    window, "shoe_fixed" SHOE without the adaptive threshold, "shoe_filter" the default without the smoother."""
    if detector == "song":
        stance_overrides.setdefault("window_s", 0.15)
    if detector == "shoe_fixed":
        detector = "shoe"
        stance_overrides.setdefault("threshold", 1.0e5)
        stance_overrides.setdefault("adaptive_floor_factor", 0.0)
        stance_overrides.setdefault("adaptive_ceiling_ratio", 0.0)
    smoother = detector != "shoe_filter"
    if detector == "shoe_filter":
        detector = "shoe"
    return FootSettings(aid=aid, gyro_delay_s=gyro_delay_s, gyro_range_rad_s=gyro_range_rad_s,
                        rts_smoother=smoother,
                        stance=StanceSettings(detector=detector, **stance_overrides))


#: a fixed rule for stance truth from VICON (instead of the files' per-trial zv_vicon_opt thresholds): the
#: foot's VICON speed, differenced over VICON_SPEED_SPAN_S, below VICON_STILL_SPEED_M_S
VICON_STILL_SPEED_M_S = 0.05
VICON_SPEED_SPAN_S = 0.05


def vicon_still(t_ns, truth_pos_m, speed_m_s: float = VICON_STILL_SPEED_M_S,
                span_s: float = VICON_SPEED_SPAN_S) -> np.ndarray:
    """Stance truth by a fixed rule: VICON speed ``|p(t + span/2) - p(t - span/2)| / span`` below ``speed_m_s``
    (central difference at the samples nearest those times; one-sided at the ends)."""
    t = np.asarray(t_ns, dtype=np.int64)
    p = np.asarray(truth_pos_m, dtype=float)
    h = int(round(span_s * 0.5e9))
    a = np.clip(np.searchsorted(t, t - h), 0, len(t) - 1)
    b = np.clip(np.searchsorted(t, t + h), 0, len(t) - 1)
    dt = np.maximum((t[b] - t[a]) * 1e-9, 1e-9)
    v = np.linalg.norm(p[b] - p[a], axis=1) / dt
    return np.isfinite(v) & (v < speed_m_s)


# ---------------------------------------------------------------------------
# PyShoe


def run_pyshoe(root: Path, detectors=CASE_DETECTORS, split=None, names=None, settings_of=foot_settings,
               only=None, progress: bool = False) -> list[dict]:
    """Every case on every PyShoe trial selected; ``progress`` prints a line per trial to stderr."""
    from benchmarks.datasets import pyshoe

    trials = [tr for tr in pyshoe.trials(root)
              if (split is None or tr.info["split"] == split) and (names is None or tr.name in names)
              and (not only or any(o in tr.name for o in only))]
    rows = []
    t_start = time.perf_counter()
    for k, tr in enumerate(trials, 1):
        t_trial = time.perf_counter()
        rec = tr.open()
        acc, gyr = rec.streams["acc"], rec.streams["gyro"]
        still = vicon_still(tr.truth_t_ns, tr.truth_pos_m)
        row = {"trial": tr.name, "split": tr.info["split"], "walking": tr.info["walking"],
               "pyshoe_errors_m": tr.pyshoe_errors_m, "pyshoe_best": list(tr.pyshoe_best), "cases": {},
               "vicon_still_fraction": float(np.mean(still)),
               "pyshoe_labels_f1": {k: stance_scores(v, still)["f1"] for k, v in tr.zv_labels.items()}}
        for det in list(detectors) + ["reference", "vicon_rule"]:
            fs = settings_of(detector="shoe" if det in ("reference", "vicon_rule") else det,
                             gyro_delay_s=tr.info["gyro_delay_s"],
                             gyro_range_rad_s=tr.info["gyro_range_rad_s"])
            nav = FootNavigator(fs)
            labels = {"reference": tr.zv_reference, "vicon_rule": still}.get(det)
            t0 = time.perf_counter()
            res = nav.run(rec, stance=labels)
            us = (time.perf_counter() - t0) / max(len(res.t_ns), 1) * 1e6
            case = position_errors(res.position_n, tr.truth_pos_m)
            case["us_per_sample"] = us
            case["zupt_nis_median"] = float(np.median(res.zupt_nis)) if len(res.zupt_nis) else math.nan
            case["aligned_on_short_stance"] = res.counters.get("aligned_on_short_stance", 0)
            if labels is None:
                st = StanceDetector(nav.stance_settings).detect(acc.t_ns, acc.values, gyr.values).stance
                case.update({"stance_" + k: v for k, v in stance_scores(st, still).items()})
            row["cases"][det] = case
            if det == "shoe":  # for the plots (not written)
                row["_track"] = res.position_n
                row["_stride_idx"] = np.searchsorted(res.t_ns, [x.t_end_ns for x in res.strides])
        # like for like with PyShoe's own numbers: our filter on PyShoe's per-trial-optimal SHOE labels, and
        # the PyShoe-style peer on those labels (reproduces the files' errors), on the VICON labels, and
        # with SHOE at one fixed threshold (the tuning split's median per-trial optimum)
        a, g = acc.values, gyr.values
        res = FootNavigator(settings_of(detector="shoe", gyro_delay_s=tr.info["gyro_delay_s"],
                                        gyro_range_rad_s=tr.info["gyro_range_rad_s"])).run(
            rec, stance=tr.zv_labels["shoe"])
        row["cases"]["ours_pyshoe_shoe_labels"] = position_errors(res.position_n, tr.truth_pos_m)
        for name, zv in (("peer_pyshoe_shoe_labels", tr.zv_labels["shoe"]),
                         ("peer_reference", tr.zv_reference),
                         ("peer_shoe_fixed", peer_shoe_statistic(a, g) < PEER_SHOE_FIXED_THRESHOLD)):
            t0 = time.perf_counter()
            pos = pyshoe_peer(a, g, zv)
            case = position_errors(pos, tr.truth_pos_m)
            case["us_per_sample"] = (time.perf_counter() - t0) / len(a) * 1e6
            if name == "peer_shoe_fixed":
                case.update({"stance_" + k: v for k, v in stance_scores(zv, still).items()})
                row["_peer_track"] = pos
            row["cases"][name] = case
        row["_truth"] = tr.truth_pos_m
        rows.append(row)
        if progress:
            c = row["cases"].get("shoe", {})
            print(f"[{k:2d}/{len(trials)}] pyshoe {tr.name} ({tr.info['split']}): "
                  f"{time.perf_counter() - t_trial:.0f} s, shoe 3-D RMSE {c.get('rmse_3d_m', math.nan):.3f} m "
                  f"({time.perf_counter() - t_start:.0f} s so far)", file=sys.stderr, flush=True)
    return rows


def _of_split(rows, split) -> list:
    return [r for r in rows if r["split"] == split]


def summarise_pyshoe(rows, split) -> dict:
    rs = _of_split(rows, split)
    if not rs:
        return {}
    cases = list(rs[0]["cases"])
    out = {"n_trials": len(rs), "cases": {}}
    for c in cases:
        out["cases"][c] = {
            "rmse_3d_median_m": median([r["cases"][c]["rmse_3d_m"] for r in rs]),
            "rmse_2d_median_m": median([r["cases"][c]["rmse_2d_m"] for r in rs]),
            "rmse_3d_median_walking_m": median([r["cases"][c]["rmse_3d_m"] for r in rs if r["walking"]]),
            "rmse_2d_whole_trial_yaw_median_m": median([r["cases"][c]["rmse_2d_whole_trial_yaw_m"] for r in rs]),
            "final_3d_median_m": median([r["cases"][c]["final_3d_m"] for r in rs]),
            "rmse_z_median_m": median([r["cases"][c].get("rmse_z_m", math.nan) for r in rs]),
            "pyshoe_2d_median_m": median([r["cases"][c].get("pyshoe_2d_m", math.nan) for r in rs]),
            "pyshoe_3d_median_m": median([r["cases"][c].get("pyshoe_3d_m", math.nan) for r in rs]),
            "us_per_sample_median": median_finite([r["cases"][c].get("us_per_sample", math.nan) for r in rs]),
            "n_failed": n_failed([r["cases"][c]["rmse_3d_m"] for r in rs]),
            "rmse_3d_max_m": max((math.inf if not math.isfinite(r["cases"][c]["rmse_3d_m"]) else
                                  r["cases"][c]["rmse_3d_m"] for r in rs), default=math.nan),
            "n_above_0p5_m": sum(1 for r in rs if not r["cases"][c]["rmse_3d_m"] <= 0.5),
        }
        if "stance_f1" in rs[0]["cases"][c]:
            out["cases"][c]["stance_f1_median_walking"] = median_finite(
                [r["cases"][c]["stance_f1"] for r in rs if r["walking"]])
            out["cases"][c]["stance_f1_median_all"] = median_finite([r["cases"][c]["stance_f1"] for r in rs])
    out["pyshoe_best_per_trial_median_m"] = median([r["pyshoe_best"][1] for r in rs])
    out["pyshoe_best_per_trial_median_walking_m"] = median([r["pyshoe_best"][1] for r in rs if r["walking"]])
    out["n_walking"] = sum(1 for r in rs if r["walking"])
    if "pyshoe_labels_f1" in rs[0]:
        out["pyshoe_labels_f1_median_walking"] = {d: median_finite([r["pyshoe_labels_f1"][d] for r in rs if r["walking"]])
                                                  for d in rs[0]["pyshoe_labels_f1"]}
    out["pyshoe_per_detector_median_m"] = {d: median_finite([r["pyshoe_errors_m"][d] for r in rs])
                                           for d in rs[0]["pyshoe_errors_m"]}
    return out


# ---------------------------------------------------------------------------
# IPOL: lower back + both feet, the four cases of Table 2


#: each foot's track is turned so that its course over the first this much path points along +x (m)
LR_ALIGN_PATH_M = 2.0
#: strides shorter than this have no course in the left-right course difference (m)
MIN_COURSE_STRIDE_M = 0.4


def _early_turn(sp) -> float:
    """Angle (rad) by which a stance track must turn so that its first ``LR_ALIGN_PATH_M`` point along +x."""
    d = np.hypot(sp[:, 0], sp[:, 1])
    far = np.flatnonzero(d >= LR_ALIGN_PATH_M)
    if not len(far):
        return 0.0
    return -math.atan2(sp[far[0], 1], sp[far[0], 0])


def _lr_difference(left, right) -> tuple[float, float]:
    """RMS horizontal distance of the left stances to the right stance track (interpolated in time), and
    RMS difference of the stride courses (deg, right interpolated in time).

    The two feet start in frames whose headings differ by their initial-heading errors (the paper set
    the initial heading in advance): each track is first turned about its start so that its course over
    the first ``LR_ALIGN_PATH_M`` of path is +x (the protocol's first leg; nothing later is used).
    """
    tl = np.array([s.t_end_ns for s in left.strides], dtype=float)
    tr_ = np.array([s.t_end_ns for s in right.strides], dtype=float)
    pl, pr = left.stride_positions(), right.stride_positions()
    al, ar = _early_turn(pl), _early_turn(pr)
    pl = np.column_stack([rotate(pl[:, :2], al), pl[:, 2]])
    pr = np.column_stack([rotate(pr[:, :2], ar), pr[:, 2]])
    m = (tl >= tr_[0]) & (tl <= tr_[-1])
    if m.sum() < 2:
        return math.nan, math.nan
    ri = np.column_stack([np.interp(tl[m], tr_, pr[:, k]) for k in range(2)])
    pos = float(np.sqrt(np.mean(np.sum((pl[m, :2] - ri) ** 2, axis=1))))
    # courses of real strides only (a stance split in two leaves a stride of a few cm with any direction)
    keep_l = np.array([s.length_m >= MIN_COURSE_STRIDE_M for s in left.strides])
    keep_r = np.array([s.length_m >= MIN_COURSE_STRIDE_M for s in right.strides])
    cl = np.array([s.course_rad for s in left.strides]) + al
    cr = np.unwrap(np.array([s.course_rad for s in right.strides])[keep_r] + ar)
    okc = m & keep_l
    if keep_r.sum() < 2 or not okc.any():
        return pos, math.nan
    dc = wrap_angle(cl[okc] - np.interp(tl[okc], tr_[keep_r], cr))
    return pos, float(math.degrees(np.sqrt(np.mean(dc ** 2)))) if len(dc) else math.nan


def run_ipol(root: Path, split=None, detector: str = "shoe") -> list[dict]:
    from benchmarks.datasets import ipol_feet

    rows = []
    for tr in ipol_feet.trials(root):
        if split is not None and tr.info["split"] != split:
            continue
        rec = tr.open()
        row = {"trial": tr.name, "split": tr.info["split"], "cases": {}, "stance_f1": {}}
        for f, events in (("left_foot", tr.left_steps_t_ns), ("right_foot", tr.right_steps_t_ns)):
            acc, gyr = rec.streams[f"acc@{f}"], rec.streams[f"gyro@{f}"]
            t = acc.t_ns
            truth = (t >= tr.walk_t_ns[0]) & (t <= tr.walk_t_ns[1])
            for a, b in events:  # the annotated foot-off .. foot-strike: swing
                truth &= ~((t >= a) & (t <= b))
            walk = (t >= tr.walk_t_ns[0]) & (t <= tr.walk_t_ns[1])
            st = StanceDetector(foot_settings(detector).stance).detect(t, acc.values, gyr.values).stance
            row["stance_f1"][f] = stance_scores(st[walk], truth[walk])["f1"]
        for aid in AIDS:
            res = {f: FootNavigator(foot_settings(detector, aid), foot_device=f, waist_device="").run(rec)
                   for f in ("left_foot", "right_foot")}
            case = {}
            for f, r in res.items():
                sp = r.stride_positions()
                case[f"return_{f}_m"] = float(math.hypot(sp[-1, 0], sp[-1, 1])) if len(sp) else math.nan
                case[f"distance_{f}_m"] = r.summary()["distance_m"]
            case["lr_difference_m"], case["course_difference_deg"] = _lr_difference(res["left_foot"],
                                                                                  res["right_foot"])
            row["cases"][aid] = case
        rows.append(row)
    return rows


def summarise_ipol(rows, split) -> dict:
    out = {"n_trials": len(_of_split(rows, split)), "cases": {}}
    if not out["n_trials"]:
        return {}
    out["stance_f1_median"] = median_finite([v for r in _of_split(rows, split) for v in r["stance_f1"].values()])
    for aid in AIDS:
        c = [r["cases"][aid] for r in _of_split(rows, split)]
        out["cases"][aid] = {
            "return_median_m": median([x["return_left_foot_m"] for x in c] + [x["return_right_foot_m"] for x in c]),
            "return_left_median_m": median([x["return_left_foot_m"] for x in c]),
            "return_right_median_m": median([x["return_right_foot_m"] for x in c]),
            "lr_difference_median_m": median([x["lr_difference_m"] for x in c]),
            "course_difference_median_deg": median([x["course_difference_deg"] for x in c]),
        }
    return out


# ---------------------------------------------------------------------------
# x-io foot loops


def run_xio(root: Path) -> dict:
    from benchmarks.datasets import xio_foot

    rows = []
    for tr in xio_foot.trials(root):
        rec = tr.open()
        t0 = time.perf_counter()
        res = FootNavigator(foot_settings("shoe")).run(rec)
        us = (time.perf_counter() - t0) / max(len(res.t_ns), 1) * 1e6
        s = res.summary()
        rows.append({"trial": tr.name, "kind": tr.info["kind"], "split": tr.info["split"], "rate_hz": s["rate_hz"],
                     "n_strides": s["n_strides"], "distance_m": s["distance_m"], "final_up_m": s["final_up_m"],
                     "loop_closure_pct": xio_foot.loop_closure_pct(res.stride_positions(), s["distance_m"])
                     if tr.info["kind"] == "loop" else math.nan, "us_per_sample": us})
    loops = [r["loop_closure_pct"] for r in rows if r["kind"] == "loop"]
    return {"trials": rows, "loop_closure_median_pct": median(loops)}


# ---------------------------------------------------------------------------
# regression guard (benchmarks.guard): a quick subset


#: PyShoe trials of the quick subset per split: the first this many walking trials by name
QUICK_PYSHOE_PER_SPLIT = 3


def quick(root: Path | None) -> dict:
    """Regression-guard headlines (:mod:`benchmarks.guard`), SHOE at its fixed configuration:
    ``foot_pyshoe_<split>_quick_rmse_median_m`` (3-D RMSE median of the first three walking trials of each
    split) and ``foot_xio_report_loop_closure_median_pct`` (the two x-io loops)."""
    from benchmarks.datasets import pyshoe, xio_foot

    h: dict = {}
    if root is None:
        return h
    by_split: dict = {}
    for tr in pyshoe.trials(root):
        if tr.info["walking"] and len(by_split.setdefault(tr.info["split"], [])) < QUICK_PYSHOE_PER_SPLIT:
            by_split[tr.info["split"]].append(tr)
    for split, trs in by_split.items():
        errs = []
        for tr in trs:
            rec = tr.open()
            res = FootNavigator(foot_settings("shoe", gyro_delay_s=tr.info["gyro_delay_s"],
                                              gyro_range_rad_s=tr.info["gyro_range_rad_s"])).run(rec)
            errs.append(position_errors(res.position_n, tr.truth_pos_m)["rmse_3d_m"])
        h[f"foot_pyshoe_{split}_quick_rmse_median_m"] = median(errs)
    loops = []
    for tr in xio_foot.trials(root):
        if tr.info["kind"] == "loop":
            res = FootNavigator(foot_settings("shoe")).run(tr.open())
            loops.append(xio_foot.loop_closure_pct(res.stride_positions(), res.summary()["distance_m"]))
    if loops:
        h["foot_xio_report_loop_closure_median_pct"] = median(loops)
    return h


# ---------------------------------------------------------------------------
# mode detection (core.foot.mounting)


def run_mounting(root: Path) -> dict:
    """Foot or hand-held on recordings of known placement.  The two thresholds of
    :class:`core.foot.mounting.MountingSettings` were chosen on the tuning split (IPOL odd subjects,
    PyShoe odd trials); accuracy is reported on the rest (IPOL even subjects, PyShoe even trials, x-io,
    Brajdic-Harle hand-held walks: a report-split dataset of :mod:`benchmarks.splits`)."""
    from benchmarks.datasets import brajdic_harle, ipin2023, ipol_feet, pyshoe, xio_foot
    from benchmarks.splits import ipin_split
    from core.foot.mounting import detect_mounting

    rows = []

    def add(dataset, name, rec, device, truth, split):
        m = detect_mounting(rec, device)
        rows.append({"dataset": dataset, "recording": name, "device": device or "primary", "truth": truth,
                     "mode": m.mode, "confidence": m.confidence, "peak_rate_rad_s": m.peak_rate_rad_s,
                     "stride_fraction": m.stride_fraction, "split": split})

    for tr in pyshoe.trials(root):
        add("pyshoe_vicon", tr.name, tr.open(), "", "foot", tr.info["split"])
    for tr in xio_foot.trials(root):
        add("xio_foot_imu", tr.name, tr.open(), "", "foot", REPORT)
    for tr in ipol_feet.trials(root):
        rec = tr.open()
        add("ipol", tr.name, rec, "left_foot", "foot", tr.info["split"])
        add("ipol", tr.name, rec, "right_foot", "foot", tr.info["split"])
        add("ipol", tr.name, rec, "", "handheld", tr.info["split"])
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for tr in ipin2023.trials(root):  # hand-held, with compass-calibration waving at the start
            add("ipin2023_track3", tr.name, tr.open(), "", "handheld", ipin_split(tr.info["route"]))
        for tr in brajdic_harle.trials(root):
            rec = tr.open()
            if rec.has("gyro"):
                add("brajdic_harle_handheld", tr.name, rec, "", "handheld", REPORT)
    rep = _of_split(rows, REPORT)
    return {"rows": rows, "accuracy_report": float(np.mean([r["mode"] == r["truth"] for r in rep])) if rep
            else math.nan, "n_report": len(rep),
            "accuracy_tuning": float(np.mean([r["mode"] == r["truth"] for r in _of_split(rows, TUNING)])),
            "errors": [r for r in rows if r["mode"] != r["truth"]]}


def headlines(out, split: str = REPORT) -> dict:
    """The headline numbers of ``split`` (the report split's are the published ones)."""
    ps = out.get("pyshoe", {}).get(split) or {}
    ip = out.get("ipol", {}).get(split) or {}
    h: dict = {"split": split}
    if ps:
        c = ps["cases"]
        h.update({
            "pyshoe_rmse_median_m": c["shoe"]["rmse_3d_median_m"],
            "pyshoe_rmse_median_m_walking": c["shoe"]["rmse_3d_median_walking_m"],
            "pyshoe_rmse_max_m": c["shoe"]["rmse_3d_max_m"],
            "pyshoe_n_trials": ps["n_trials"],
            "pyshoe_n_failed": c["shoe"]["n_failed"],
            "pyshoe_n_above_0p5_m": c["shoe"]["n_above_0p5_m"],
            "pyshoe_metric_median_m": c["shoe"]["pyshoe_2d_median_m"],
            "pyshoe_own_best_per_trial_median_m": ps["pyshoe_best_per_trial_median_m"],
            "target_pyshoe_metric_median_not_worse_than_oracle": bool(
                c["shoe"]["pyshoe_2d_median_m"] <= ps["pyshoe_best_per_trial_median_m"]),
            "target_no_trial_above_0p5_m": c["shoe"]["n_above_0p5_m"] == 0,
            "pyshoe_rmse_median_m_filter_only": c["shoe_filter"]["rmse_3d_median_m"],
            "pyshoe_metric_median_m_filter_only": c["shoe_filter"]["pyshoe_2d_median_m"],
            "pyshoe_rmse_median_m_shoe_fixed": c["shoe_fixed"]["rmse_3d_median_m"],
            "pyshoe_metric_median_m_shoe_fixed": c["shoe_fixed"]["pyshoe_2d_median_m"],
            "pyshoe_rmse_median_m_song_paper": c["song"]["rmse_3d_median_m"],
            "pyshoe_metric_median_m_song_paper": c["song"]["pyshoe_2d_median_m"],
            "pyshoe_rmse_median_m_reference_labels": c["reference"]["rmse_3d_median_m"],
            "pyshoe_metric_median_m_reference_labels": c["reference"]["pyshoe_2d_median_m"],
            "pyshoe_metric_median_m_peer_shoe_fixed": c["peer_shoe_fixed"]["pyshoe_2d_median_m"],
            "pyshoe_rmse_median_m_peer_shoe_fixed": c["peer_shoe_fixed"]["rmse_3d_median_m"],
            "stance_f1_median_walking": c["shoe"]["stance_f1_median_walking"],
            "stance_f1_median_all": c["shoe"]["stance_f1_median_all"],
            "us_per_sample_median": c["shoe"]["us_per_sample_median"]})
    if ip:
        h.update({"ipol_stance_f1_median": ip.get("stance_f1_median"),
                  "ipol_foot_return_median_m": {a: ip["cases"][a]["return_median_m"] for a in AIDS},
                  "ipol_foot_lr_difference_median_m": {a: ip["cases"][a]["lr_difference_median_m"] for a in AIDS}})
    if out.get("xio"):
        h["xio_loop_closure_median_pct"] = out["xio"].get("loop_closure_median_pct", math.nan)
    if out.get("mounting"):
        h["mounting_accuracy"] = out["mounting"].get("accuracy_report")
    return h


CASE_LABELS = {
    "shoe": "**ours, SHOE (default: threshold max(3e4, 2 x floor, 0.01 x swing peak) over 1.2 s; RTS smoother of "
            "replays)**",
    "shoe_filter": "ours, SHOE default, forward filter only (no smoother: the live app)",
    "shoe_fixed": "ours, SHOE at the fixed threshold 1e5 alone",
    "song": "ours, Song & Park eq. 6 as written (g, J <= 1, trailing 0.15 s)",
    "amv": "ours, acceleration moving variance (fixed)",
    "are": "ours, angular-rate energy (fixed)",
    "learned": "ours, learned stance model (logistic, ~1 s of samples, VICON-speed labels of the tuning split; "
               "tuning numbers in-sample)",
    "reference": "ours on PyShoe's VICON labels (per-trial threshold: oracle)",
    "vicon_rule": "ours on VICON speed < 0.05 m/s (truth stance by a fixed rule)",
    "ours_pyshoe_shoe_labels": "ours on PyShoe's per-trial-optimal SHOE labels (oracle)",
    "peer_pyshoe_shoe_labels": "PyShoe-style peer on its per-trial-optimal SHOE labels (oracle)",
    "peer_reference": "PyShoe-style peer on the VICON labels (oracle)",
    "peer_shoe_fixed": "PyShoe-style peer, SHOE at one fixed threshold",
}


def _f(x, fmt=".3f") -> str:
    """A median or a trial's number: inf (a failure in the median's middle) "failed", nan (nothing) "n/a"."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    return "failed" if not math.isfinite(x) else format(x, fmt)


def _ft(x, fmt=".3f") -> str:
    """One trial's error: not finite = the recording failed."""
    return format(x, fmt) if x is not None and math.isfinite(x) else "failed"


def write_markdown(out, path=RESULTS_MD) -> None:
    L = ["## Foot-mounted navigation (issues #11, #27)", "",
         f"Code {out['rev']}. Splits: `benchmarks/foot_splits.py` (declared before tuning). "
         "Headline numbers are on the **report** split; the tuning split (where every setting was chosen) is "
         "shown for comparison. A recording without a track counts as failed: an infinite error in every "
         "median (never dropped), and the `failed` column counts them.", ""]
    h = out["headlines"]
    if "pyshoe_metric_median_m" in h:
        L += ["**Targets (PyShoe report split, one setting for every trial)**: PyShoe's metric, median "
              f"{h['pyshoe_metric_median_m']:.3f} m against PyShoe's best-detector-per-trial oracle "
              f"{h['pyshoe_own_best_per_trial_median_m']:.3f} m: "
              + ("met" if h["target_pyshoe_metric_median_not_worse_than_oracle"] else "**missed**")
              + f"; trials above 0.5 m 3-D RMSE: {h['pyshoe_n_above_0p5_m']} of {h['pyshoe_n_trials']} "
              f"(largest {_f(h['pyshoe_rmse_max_m'])} m): "
              + ("met" if h["target_no_trial_above_0p5_m"] else "**missed**") + ".", ""]
    for split in (REPORT, TUNING):
        ps = out["pyshoe"].get(split)
        if not ps:
            continue
        L += [f"### PyShoe VICON, {split} split ({ps['n_trials']} trials)", "",
              "| case | 3-D RMSE median (m) | largest 3-D RMSE (m) | > 0.5 m | failed | same, walking trials | "
              "vertical RMSE median (m) | **PyShoe's metric** (median, m) | 2-D, yaw fitted over the whole trial "
              "(diagnostic) | final 3-D error median (m) | stance F1 vs VICON speed < 0.05 m/s (walking, all) | "
              "us/sample |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for c, v in ps["cases"].items():
            f1 = (f"{_f(v['stance_f1_median_walking'])}, {_f(v['stance_f1_median_all'])}"
                  if "stance_f1_median_walking" in v else "")
            L.append(f"| {CASE_LABELS.get(c, c)} | {_f(v['rmse_3d_median_m'])} | {_f(v['rmse_3d_max_m'])} | "
                     f"{v['n_above_0p5_m']} | {v['n_failed']} | {_f(v['rmse_3d_median_walking_m'])} | "
                     f"{_f(v['rmse_z_median_m'])} | {_f(v['pyshoe_2d_median_m'])} | "
                     f"{_f(v['rmse_2d_whole_trial_yaw_median_m'])} | {_f(v['final_3d_median_m'])} | {f1} | "
                     f"{v['us_per_sample_median']:.0f} |")
        L.append(f"| *oracle line, not a competitor: PyShoe's own best detector per trial (its metric, threshold "
                 f"chosen per trial after the fact)* | | | | | | | *{ps['pyshoe_best_per_trial_median_m']:.3f}* | | | | |")
        L += ["", "3-D RMSE: ours (LS yaw over the first 2 m of VICON path, RMS over samples, vertical included). "
              "PyShoe's metric: what PyShoe publishes (`pyshoe_metric`: both tracks from their starts, yaw from "
              "one sample 0.8 m out, mean over samples of the per-axis RMS |e_xy|/sqrt(2)). Stance F1 is against "
              "a fixed rule on VICON speed (`vicon_still`), not against the per-trial thresholds of zv_vicon_opt. "
              "Our cases are RTS-smoothed replays (`FootSettings.rts_smoother`, the default of `pdr replay`) except "
              "\"forward filter only\", which is what the live app shows."]
        if "pyshoe_labels_f1_median_walking" in ps:
            L += ["", "Stance F1 of PyShoe's own per-trial-optimal labels against the same VICON-speed rule "
                  "(walking trials, median): "
                  + ", ".join(f"{d} {v:.3f}" for d, v in ps["pyshoe_labels_f1_median_walking"].items())]
        L += ["", f"PyShoe's own errors (its metric, median over the same trials, each at its per-trial optimal "
              f"threshold): best detector per trial {ps['pyshoe_best_per_trial_median_m']:.3f} m (walking trials "
              f"{ps['pyshoe_best_per_trial_median_walking_m']:.3f} m, n = {ps['n_walking']}); per detector "
              + ", ".join(f"{d} {e:.3f}" for d, e in ps["pyshoe_per_detector_median_m"].items()) + " m.", ""]
        L += [f"Per trial ({split} split), m: 3-D RMSE / PyShoe's metric", "",
              "| trial | walking | ours SHOE (default, smoothed) | ours SHOE, filter only | ours SHOE fixed 1e5 | "
              "ours Song (paper) | ours learned | ours on VICON rule | peer SHOE fixed | PyShoe best (oracle, its metric) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
        for r in out["pyshoe"]["trials"]:
            if r["split"] != split:
                continue
            c = r["cases"]
            cell = (lambda k: f"{_ft(c[k]['rmse_3d_m'])} / {_ft(c[k]['pyshoe_2d_m'])}")
            L.append(f"| {r['trial']} | {'yes' if r['walking'] else 'no'} | {cell('shoe')} | {cell('shoe_filter')} | "
                     f"{cell('shoe_fixed')} | "
                     f"{cell('song')} | {cell('learned') if 'learned' in c else ''} | {cell('vicon_rule')} | {cell('peer_shoe_fixed')} | "
                     f"{r['pyshoe_best'][1]:.3f} ({r['pyshoe_best'][0]}) |")
        L.append("")
    for split in (REPORT, TUNING):
        ip = out.get("ipol", {}).get(split)
        if not ip:
            continue
        L += ["", f"### IPOL 10 m out and back, {split} split ({ip['n_trials']} trials, both feet)", "",
              f"Stance F1 against the annotated swing phases (both feet, median): {ip['stance_f1_median']:.3f}", "",
              "| | " + " | ".join(AIDS) + " |", "|---|" + "---|" * len(AIDS)]
        for key, label in (("return_left_median_m", "return error left foot, median (m)"),
                           ("return_right_median_m", "return error right foot, median (m)"),
                           ("lr_difference_median_m", "left-right position difference, median (m)"),
                           ("course_difference_median_deg", "left-right course difference, median (deg)")):
            L.append(f"| {label} | " + " | ".join(f"{ip['cases'][a][key]:.2f}" for a in AIDS) + " |")
    xio = out.get("xio")
    if xio:
        L += ["", "### x-io foot IMU (report only)", "",
              "| recording | rate (Hz) | strides | distance (m) | loop closure (% of path) | final height (m) |",
              "|---|---|---|---|---|---|"]
        for r in xio["trials"]:
            lc = f"{r['loop_closure_pct']:.2f}" if math.isfinite(r["loop_closure_pct"]) else "(not a loop)"
            L.append(f"| {r['trial']} | {r['rate_hz']:.0f} | {r['n_strides']} | {r['distance_m']:.1f} | {lc} | "
                     f"{r['final_up_m']:.2f} |")
    mt = out.get("mounting")
    if mt:
        rows = mt["rows"]
        L += ["", "### Mode detection (foot or hand-held)", "",
              f"Report-split recordings: {mt['n_report']}, correct {100 * mt['accuracy_report']:.1f} % "
              f"(tuning split: {100 * mt['accuracy_tuning']:.1f} %).", "",
              "| dataset | device | truth | n | correct | median confidence |", "|---|---|---|---|---|---|"]
        rows = _of_split(rows, REPORT)
        keys = sorted({(r["dataset"], r["device"], r["truth"]) for r in rows})
        for k in keys:
            rr = [r for r in rows if (r["dataset"], r["device"], r["truth"]) == k]
            L.append(f"| {k[0]} | {k[1]} | {k[2]} | {len(rr)} | {sum(r['mode'] == r['truth'] for r in rr)} | "
                     f"{np.median([r['confidence'] for r in rr]):.2f} |")
        for r in mt["errors"]:
            L.append(f"\nWrong ({r['split']}): {r['dataset']} {r['recording']} {r['device']} -> {r['mode']} "
                     f"(window peak {r['peak_rate_rad_s']:.2f} rad/s, stride fraction "
                     f"{r.get('stride_fraction', float('nan')):.2f})")
    for name in out.get("plots", []):
        L += ["", f"![{name}](plots/{name})"]
    L += ["", "Headlines (foot_results.json): " + json.dumps(out["headlines"]), ""]
    Path(path).write_text("\n".join(L))


PLOTS = HERE / "plots"


def plot_trial(path, row) -> None:
    """Ours (SHOE default) and the PyShoe-style peer against VICON (a line), aligned as the 3-D RMSE aligns;
    the legend counts strides (one stance of the instrumented foot to the next)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth = row["_truth"]
    ours, _, _ = align_to_truth(row["_track"], truth)
    peer, _, _ = align_to_truth(row["_peer_track"], truth)
    idx = np.asarray(row["_stride_idx"], dtype=int)
    idx = idx[(idx >= 0) & (idx < len(ours))]
    idx = idx[np.isfinite(ours[idx, 0])]
    c = row["cases"]
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    ax.plot(truth[:, 0], truth[:, 1], "-", color="0.35", lw=2.5, alpha=0.6, label="VICON (truth)")
    ax.plot(peer[:, 0], peer[:, 1], "-", color="tab:orange", lw=0.8, alpha=0.8,
            label=f"PyShoe-style peer, SHOE fixed (3-D RMSE {_f(c['peer_shoe_fixed']['rmse_3d_m'], '.2f')} m)")
    ax.plot(ours[:, 0], ours[:, 1], "-", color="tab:blue", lw=1.2,
            label=f"ours, SHOE default (3-D RMSE {_f(c['shoe']['rmse_3d_m'], '.2f')} m)")
    ax.plot(ours[idx, 0], ours[idx, 1], ".", color="tab:blue", ms=5, label=f"our stances ({len(idx)} strides)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_title(f"PyShoe VICON {row['trial']} ({row['split']} split)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_plots(rows) -> list[str]:
    """The typical (median 3-D RMSE) and the worst report-split trial of ours."""
    rep = [r for r in rows if r["split"] == REPORT and "_track" in r]
    if not rep:
        return []
    key = (lambda r: r["cases"]["shoe"]["rmse_3d_m"] if math.isfinite(r["cases"]["shoe"]["rmse_3d_m"]) else math.inf)
    rep = sorted(rep, key=key)
    out = []
    PLOTS.mkdir(exist_ok=True)
    for name, r in (("foot_pyshoe_typical.png", rep[len(rep) // 2]), ("foot_pyshoe_worst.png", rep[-1])):
        plot_trial(PLOTS / name, r)
        out.append(name)
    return out


def _public(rows) -> list:
    """Rows without the arrays kept for the plots."""
    return [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", "--data-root", dest="data", type=Path, default=default_data_root(),
                    help="the data folder (default: the shared data root)")
    ap.add_argument("--only", default="", metavar="PARTS",
                    help="comma-separated: datasets (pyshoe, ipol, xio, mounting) and/or parts of PyShoe trial "
                         "names (2017-11-27); runs that subset and writes nothing (implies --no-write)")
    ap.add_argument("--no-write", action="store_true",
                    help="write foot_results.json under out/benchmarks/foot/; do not rewrite foot_results.json, "
                         "FOOT_RESULTS.md or the plots")
    ap.add_argument("--split", choices=(TUNING, REPORT), default=None,
                    help="run only the PyShoe and IPOL trials of this split (x-io is report only: skipped with "
                         "--split tuning); writes nothing (implies --no-write)")
    ap.add_argument("--pyshoe-rows", type=Path, default=None, help="reuse PyShoe rows from a JSON file")
    ap.add_argument("--mounting-only", action="store_true",
                    help="rerun only the mode detection, keeping the other results of foot_results.json")
    args = ap.parse_args(argv)
    write = not args.no_write and not args.only and not args.split
    if args.mounting_only:
        out = read_json(RESULTS_JSON)
        out["mounting"] = run_mounting(args.data)
        out["headlines"] = headlines(out)
        if write:
            write_json(RESULTS_JSON, out, digits=None)
            write_markdown(out)
        m = out["mounting"]
        print(f"mode detection: report {100 * m['accuracy_report']:.1f} % of {m['n_report']}, "
              f"tuning {100 * m['accuracy_tuning']:.1f} %; wrong: "
              + "; ".join(f"{r['dataset']} {r['recording']} {r['device']} ({r['split']})" for r in m["errors"]))
        return 0
    parts = [p.strip() for p in args.only.split(",") if p.strip()]
    sets = {p for p in parts if p in ("pyshoe", "ipol", "xio", "mounting")}
    names = [p for p in parts if p not in sets] or None
    if names and not sets:
        sets = {"pyshoe"}
    if args.split == TUNING and not sets:
        sets = {"pyshoe", "ipol"}  # x-io and the mode detection's report numbers: nothing of a tuning split
    want = (lambda d: not sets or d in sets)
    rows = (read_json(args.pyshoe_rows) if args.pyshoe_rows else
            run_pyshoe(args.data, split=args.split, only=names, progress=True) if want("pyshoe") else [])
    if want("ipol"):
        print("foot: IPOL lower-back walks ...", file=sys.stderr, flush=True)
    irows = run_ipol(args.data, split=args.split) if want("ipol") else []
    out = {"rev": git_rev(),
           "pyshoe": {"trials": _public(rows), TUNING: summarise_pyshoe(rows, TUNING),
                      REPORT: summarise_pyshoe(rows, REPORT)},
           "ipol": {"trials": irows, TUNING: summarise_ipol(irows, TUNING), REPORT: summarise_ipol(irows, REPORT)}}
    if want("xio"):
        print("foot: x-io foot walks ...", file=sys.stderr, flush=True)
        out["xio"] = run_xio(args.data)
    if want("mounting"):
        print("foot: mounting (mode detection) ...", file=sys.stderr, flush=True)
        out["mounting"] = run_mounting(args.data)
    out["headlines"] = headlines(out, args.split or REPORT)
    if write:
        out["plots"] = write_plots(rows)
        write_json(RESULTS_JSON, out, digits=None)
        write_markdown(out)
    else:  # a subset or --no-write: under out/benchmarks/foot/, nothing tracked by git (benchmarks.options)
        from benchmarks.options import out_dir

        write_json(out_dir("foot") / RESULTS_JSON.name, out, digits=None)
        print(f"foot: wrote {out_dir('foot') / RESULTS_JSON.name}", file=sys.stderr)
        for r in out["pyshoe"]["trials"]:
            c = r["cases"]
            print(f"{r['trial']} ({r['split']}): " + ", ".join(
                f"{k} {_f(c[k]['rmse_3d_m'])}/{_f(c[k]['pyshoe_2d_m'])}" for k in
                ("shoe", "shoe_filter", "shoe_fixed", "song", "learned", "vicon_rule", "peer_shoe_fixed")))
    print(json.dumps(out["headlines"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
