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
    drift is not hidden).  Stance F1: per sample, against ``zv_vicon_opt``.
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
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.foot_splits import REPORT, TUNING
from benchmarks.metrics import best_fit_rotation, rotate
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
        return {"rmse_3d_m": math.nan, "final_3d_m": math.nan, "rmse_2d_m": math.nan, "align_yaw_deg": math.nan}
    e = np.linalg.norm(al[ok] - truth_n[ok], axis=1)
    e2 = np.linalg.norm(al[ok, :2] - truth_n[ok, :2], axis=1)
    return {"rmse_3d_m": float(np.sqrt(np.mean(e ** 2))), "final_3d_m": float(e[-1]),
            "rmse_2d_m": float(np.sqrt(np.mean(e2 ** 2))), "align_yaw_deg": math.degrees(yaw)}


def median(values) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


# ---------------------------------------------------------------------------
# settings of the benchmark (fixed; thresholds chosen on the tuning split, see docs/foot.md)


def foot_settings(detector: str = "shoe", aid: str = "zupt", **stance_overrides) -> FootSettings:
    """One fixed configuration per detector: the tuned defaults; "song" with the paper's 0.15 s window."""
    if detector == "song":
        stance_overrides.setdefault("window_s", 0.15)
    return FootSettings(aid=aid, stance=StanceSettings(detector=detector, **stance_overrides))


# ---------------------------------------------------------------------------
# PyShoe


def run_pyshoe(root: Path, detectors=DETECTORS, split=None, names=None, settings_of=foot_settings) -> list[dict]:
    from benchmarks.datasets import pyshoe

    rows = []
    for tr in pyshoe.trials(root):
        if split is not None and tr.info["split"] != split:
            continue
        if names is not None and tr.name not in names:
            continue
        rec = tr.open()
        acc, gyr = rec.streams["acc"], rec.streams["gyro"]
        row = {"trial": tr.name, "split": tr.info["split"], "walking": tr.info["walking"],
               "pyshoe_errors_m": tr.pyshoe_errors_m, "pyshoe_best": list(tr.pyshoe_best), "cases": {}}
        for det in list(detectors) + ["reference"]:
            fs = settings_of(detector="shoe" if det == "reference" else det)
            nav = FootNavigator(fs)
            t0 = time.perf_counter()
            res = nav.run(rec, stance=tr.zv_reference if det == "reference" else None)
            us = (time.perf_counter() - t0) / max(len(res.t_ns), 1) * 1e6
            case = position_errors(res.position_n, tr.truth_pos_m)
            case["us_per_sample"] = us
            case["zupt_nis_median"] = float(np.median(res.zupt_nis)) if len(res.zupt_nis) else math.nan
            if det != "reference":
                st = StanceDetector(nav.stance_settings).detect(acc.t_ns, acc.values, gyr.values).stance
                case.update({"stance_" + k: v for k, v in stance_scores(st, tr.zv_reference).items()})
            row["cases"][det] = case
        rows.append(row)
    return rows


def summarise_pyshoe(rows, split) -> dict:
    rs = [r for r in rows if r["split"] == split]
    if not rs:
        return {}
    cases = list(rs[0]["cases"])
    out = {"n_trials": len(rs), "cases": {}}
    for c in cases:
        out["cases"][c] = {
            "rmse_3d_median_m": median([r["cases"][c]["rmse_3d_m"] for r in rs]),
            "final_3d_median_m": median([r["cases"][c]["final_3d_m"] for r in rs]),
            "us_per_sample_median": median([r["cases"][c]["us_per_sample"] for r in rs]),
        }
        if c != "reference":
            out["cases"][c]["stance_f1_median_walking"] = median(
                [r["cases"][c]["stance_f1"] for r in rs if r["walking"]])
            out["cases"][c]["stance_f1_median_all"] = median([r["cases"][c]["stance_f1"] for r in rs])
    out["pyshoe_best_per_trial_median_m"] = median([r["pyshoe_best"][1] for r in rs])
    out["pyshoe_per_detector_median_m"] = {d: median([r["pyshoe_errors_m"][d] for r in rs])
                                           for d in rs[0]["pyshoe_errors_m"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data-root", type=Path, default=default_data_root())
    ap.add_argument("--split", choices=[TUNING, REPORT], default=None, help="only this split (default both)")
    args = ap.parse_args(argv)
    rows = run_pyshoe(args.data_root, split=args.split)
    out = {"pyshoe": {"trials": rows, TUNING: summarise_pyshoe(rows, TUNING), REPORT: summarise_pyshoe(rows, REPORT)}}
    print(json.dumps({k: out["pyshoe"][k] for k in (TUNING, REPORT)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
