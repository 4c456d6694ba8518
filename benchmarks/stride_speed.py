"""Does the step length follow a walker's speed changes within a walk? (issue #25, the stride part of an outage)

``python -m benchmarks.stride_speed [--data DIR] [--extra DIR] [--only TEXT,...] [--no-write]`` measures, on the
**tuning** split only (a diagnosis to choose a stride model: it reads no report recording), stretch by stretch:

* the real tuning walks with GPS (:mod:`benchmarks.datasets.phone_walks`, split from :mod:`benchmarks.splits`):
  consecutive :data:`STRETCH_S` stretches of good fixes (reported accuracy <= 10 m,
  :func:`benchmarks.real_walks.good_fixes`) that are straight (chord >= :data:`STRAIGHT_MIN` of the fixes' path,
  chord >= :data:`MIN_CHORD_M`); true speed = chord / time between the first and last fix; and, a second
  reference, every :data:`STRETCH_S` stretch of good fixes (any shape) with the receiver's Doppler speed (its
  mean over the fixes: a path speed, free of the positions' noise, but on iOS 15-25 % low against the chords,
  issue #26: a bias that a within-walk slope does not see unless it changes within the walk);
* IPIN 2023's tuning routes: consecutive landmarks (straight line between them, their times);
* IPOL (waist): each trial's two 10-m legs; a "walk" there is one subject (their trials at their own speeds), and
  again one trial (its two legs).

Per stretch: the true speed, the cadence (our steps / time), Weinberg's step length ``C (A_max - A_min)^(1/4)``
(eq. 4, the features the default path saw), our speed (our step lengths / time) and
``ratio = true distance / Weinberg distance``.  Per walk: the least-squares slope of ``log ratio`` on
``log cadence`` (a cadence exponent: the step length Weinberg misses goes as ``cadence^slope``) and on
``log (A_max - A_min)^(1/4)`` and on ``log`` of the filtered norm's variance over the step, each with its standard
error; pooled: the within-walk slope (each walk's
means removed), with its standard error and the walks' own slopes.

Measured 2026-12-07 (tuning split, ``benchmarks/STRIDE_SPEED_RESULTS.md``): no consistent within-walk cadence slope.
Pooled slopes (+- SE): IPIN tuning routes -0.71 +- 0.22 (48 segments, 16 walks; -0.69 +- 0.11 with the route's
segments as fixed effects too, so not the segments' geometry), IPOL (per subject, across their trials) -0.15 +- 0.07
(within a trial, its two legs: -0.01 +- 0.09), ``thomasdingemanse_lopen`` +3.2 +- 2.0 against the Doppler speed but
-3.1 +- 5.6 against the chords (-5.7 +- 1.8 with 10-s stretches), ``fif911`` -3.3 +- 8.1 (Doppler; no straight 20-s
chord).  On lopen the cadence stays within 1.89-2.00 steps/s over the whole walk while the Doppler speed goes from
1.0-1.3 m/s (40-100 s) to about 1.5 m/s: the speed change the 3-minute outage needs (best scale 1.14, learnt 0.997)
comes at a constant cadence, and Weinberg's amplitude rises only 2-3 % with it, so no cadence term can follow it.  A
within-walk cadence term tried as an experiment (``length * (f_8 / f_120)^b``, EMAs of the step frequency over 8 and
120 steps), b = -0.7 (IPIN's slope): lopen 3-min default / PDR alone 12.5 / 21.3 -> 12.7 / 21.5 %, 1-min 17.2 / 25.1
-> 17.6 / 24.9 %; IPIN tuning landmark median 2.289 -> 2.286 m, pooled 2.517 -> 2.581 m, loop closure 4.011 -> 4.026
%; b = -0.2 (about IPOL's): lopen 12.5 / 21.4 and 17.3 / 25.0 %, IPIN 2.287 m, pooled 2.521 m, loop 4.001 %, walked
distance median abs 3.892 -> 3.696 %: no gain beyond noise even where the slope was measured, so not built.  Nor an
amplitude or variance term: their slopes disagree in sign too (variance: IPIN -0.03 +- 0.05, IPOL 0.02 +- 0.02,
lopen +0.60 +- 0.28 against the Doppler speed, -1.52 +- 0.50 against the chords).

Writes ``benchmarks/STRIDE_SPEED_RESULTS.md`` (a full run with ``--extra``, default stretches), else
``out/benchmarks/stride_speed/``; the stretches as JSON always under ``out/benchmarks/stride_speed/``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from benchmarks.options import HERE, add_common, data_root, only_keys, out_dir, writes_committed
from benchmarks.splits import TUNING, split_of

STRETCH_S = STRETCH_S_DEFAULT = 20.0
STRAIGHT_MIN = STRAIGHT_MIN_DEFAULT = 0.95
RESULTS_MD = HERE / "STRIDE_SPEED_RESULTS.md"
MIN_CHORD_M = 15.0
MIN_FIXES = 8
#: IPIN landmark segments shorter than this are left out (the landmark's own placement error dominates)
IPIN_MIN_SEGMENT_M = 8.0


def _stretch(steps, a_ns: int, b_ns: int, true_m: float, c: float) -> dict | None:
    """One stretch's row from the default path's steps in (a_ns, b_ns]."""
    inside = [s for s in steps if a_ns < s.t_ns <= b_ns]
    dt = (b_ns - a_ns) * 1e-9
    if len(inside) < 6 or dt <= 0 or not true_m > 0:
        return None
    root = np.array([max(s.features.acc_max_m_s2 - s.features.acc_min_m_s2, 0.0) ** 0.25 for s in inside])
    weinberg = c * float(root.sum())  # eq. 4, without the clip
    ours = float(sum(s.length_m for s in inside))
    return {"t_s": a_ns * 1e-9, "dt_s": dt, "true_m": true_m, "true_speed_m_s": true_m / dt,
            "cadence_hz": len(inside) / dt, "weinberg_step_m": weinberg / len(inside),
            "amp_root": float(root.mean()), "acc_var": float(np.mean([s.features.acc_var_m2_s4 for s in inside])),
            "our_speed_m_s": ours / dt, "ratio": true_m / weinberg,
            "ratio_ours": true_m / ours if ours > 0 else float("nan")}


def slope(x, y) -> tuple[float, float]:
    """Least-squares slope of y on x and its standard error (nan where it cannot be had)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 3 or np.ptp(x) <= 0:
        return float("nan"), float("nan")
    xm = x - x.mean()
    b = float(np.dot(xm, y - y.mean()) / np.dot(xm, xm))
    r = y - y.mean() - b * xm
    se = math.sqrt(float(np.dot(r, r)) / (len(x) - 2) / float(np.dot(xm, xm)))
    return b, se


def walk_summary(name: str, source: str, rows: list[dict]) -> dict:
    lc = np.log([r["cadence_hz"] for r in rows]) if rows else np.array([])
    la = np.log([r["amp_root"] for r in rows]) if rows else np.array([])
    lr = np.log([r["ratio"] for r in rows]) if rows else np.array([])
    b, se = slope(lc, lr)
    ba, sea = slope(la, lr)
    bv, sev = slope(np.log([r["acc_var"] for r in rows]) if rows else np.array([]), lr)
    return {"walk": name, "source": source, "n": len(rows), "stretches": rows,
            "cadence_range_hz": [float(np.min(np.exp(lc))), float(np.max(np.exp(lc)))] if rows else None,
            "speed_range_m_s": [min(r["true_speed_m_s"] for r in rows), max(r["true_speed_m_s"] for r in rows)]
            if rows else None,
            "ratio_median": float(np.median(np.exp(lr))) if rows else None,
            "slope_cadence": b, "slope_cadence_se": se, "slope_amp": ba, "slope_amp_se": sea,
            "slope_var": bv, "slope_var_se": sev}


def pooled(walks: list[dict], key: str = "cadence_hz") -> tuple[float, float, int]:
    """The within-walk slope of log ratio on log ``key`` (each walk's means removed) and its standard error."""
    xs, ys = [], []
    for w in walks:
        if w["n"] < 2:
            continue
        x = np.log([r[key] for r in w["stretches"]])
        y = np.log([r["ratio"] for r in w["stretches"]])
        xs.append(x - x.mean())
        ys.append(y - y.mean())
    if not xs:
        return float("nan"), float("nan"), 0
    x, y = np.concatenate(xs), np.concatenate(ys)
    b = float(np.dot(x, y) / np.dot(x, x))
    r = y - b * x
    dof = max(len(x) - 1 - len(xs), 1)
    return b, math.sqrt(float(np.dot(r, r)) / dof / float(np.dot(x, x))), len(x)


# -- the sources -------------------------------------------------------------------------------------------------
def gps_walks(root: Path, extra: Path | None, only: list[str]) -> list[dict]:
    from benchmarks import real_walks as rw
    from benchmarks.datasets.phone_walks import STEP_CLIP, real_walks
    from core.conventions import GPS
    from core.importers import load_recording

    out = []
    for walk in real_walks(root, extra):
        if walk.split != TUNING or walk.kind == STEP_CLIP or (only and not any(o in walk.name for o in only)):
            continue
        rec = load_recording(str(walk.folder), warn=False)
        if not rec.has(GPS):
            continue
        res, pipe, _ = rw.run_default(rec, walk.folder)
        c = _weinberg_c(pipe)
        fixes = _good(rec.streams[GPS])
        chords, doppler = [], []
        if fixes is not None:
            t, e, n, speed = fixes
            w = int(STRETCH_S * 1e9)
            a = int(t[0])
            while a + w <= int(t[-1]):
                idx = np.flatnonzero((t >= a) & (t < a + w))
                a += w
                if len(idx) < MIN_FIXES:
                    continue
                a_ns, b_ns = int(t[idx[0]]), int(t[idx[-1]])
                sp = speed[idx]
                if np.isfinite(sp).mean() >= 0.8:  # the receiver's Doppler speed over the stretch, any shape
                    row = _stretch(res.steps, a_ns, b_ns, float(np.nanmean(sp)) * (b_ns - a_ns) * 1e-9, c)
                    if row is not None:
                        row["t_s"] -= rec.t0_ns * 1e-9
                        doppler.append(row)
                chord = math.hypot(e[idx[-1]] - e[idx[0]], n[idx[-1]] - n[idx[0]])
                path = float(np.sum(np.hypot(np.diff(e[idx]), np.diff(n[idx]))))
                if chord < MIN_CHORD_M or chord < STRAIGHT_MIN * path:
                    continue
                row = _stretch(res.steps, a_ns, b_ns, chord, c)
                if row is not None:
                    row["t_s"] -= rec.t0_ns * 1e-9
                    chords.append(row)
        out.append(walk_summary(walk.name, "GPS chords", chords))
        out.append(walk_summary(walk.name, "Doppler speed", doppler))
    return out


def _good(gps):
    """(t_ns, east, north, Doppler speed) of the fixes with reported accuracy <= 10 m (no speed gate: a slow
    stretch counts)."""
    from core.geodesy import geodetic_to_enu

    cols = list(gps.columns)
    v = gps.values
    hacc = v[:, cols.index("hacc_m")]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(v[:, 0]) & np.isfinite(v[:, 1]) & (hacc <= 10.0)
    if ok.sum() < MIN_FIXES:
        return None
    origin = (float(v[ok, 0][0]), float(v[ok, 1][0]))
    e, n = (np.asarray(x, dtype=float) for x in geodetic_to_enu(v[ok, 0], v[ok, 1], origin))
    return gps.t_ns[ok], e, n, v[ok, cols.index("speed_m_s")]


def _weinberg_c(pipe) -> float:
    from core.pdr.stride import ConstantCoefficient, WeinbergStride

    m = pipe.stride_model
    inner = getattr(m, "base", m)
    if isinstance(inner, WeinbergStride) and isinstance(inner.coefficient, ConstantCoefficient):
        return inner.coefficient.c
    return ConstantCoefficient().c


def ipin_walks(root: Path, only: list[str]) -> list[dict]:
    from benchmarks.datasets import ipin2023
    from benchmarks.run import make_pipeline
    from desktop.engine import run_pipeline

    out = []
    for trial in ipin2023.trials(root):
        if split_of(ipin2023.NAME, trial.info) != TUNING or (only and not any(o in trial.name for o in only)):
            continue
        rec = trial.load()
        lm = ipin2023.landmarks(rec)
        pipe = make_pipeline(trial)
        res, _ = run_pipeline(pipe, rec, "auto")
        c = _weinberg_c(pipe)
        rows = []
        for k in range(len(lm.t_ns) - 1):
            d = math.hypot(lm.east_m[k + 1] - lm.east_m[k], lm.north_m[k + 1] - lm.north_m[k])
            if d < IPIN_MIN_SEGMENT_M:
                continue
            row = _stretch(res.steps, int(lm.t_ns[k]), int(lm.t_ns[k + 1]), d, c)
            if row is not None:
                row["t_s"] -= rec.t0_ns * 1e-9
                rows.append(row)
        out.append(walk_summary(f"ipin2023/{trial.name}", "landmark segments", rows))
    return out


def ipol_walks(root: Path, only: list[str]) -> list[dict]:
    from benchmarks.datasets import ipol
    from benchmarks.run import make_pipeline
    from desktop.engine import run_pipeline

    by_subject: dict[str, list[dict]] = {}
    for trial in ipol.trials(root):
        sid = trial.subject.get("id", "?")
        if only and not any(o in sid or o in trial.name for o in only):
            continue
        rec = trial.load()
        pipe = make_pipeline(trial)
        res, _ = run_pipeline(pipe, rec, "auto")
        c = _weinberg_c(pipe)
        for a, b, length in trial.legs:
            row = _stretch(res.steps, a, b, length, c)
            if row is not None:
                row["trial"] = trial.name
                by_subject.setdefault(sid, []).append(row)
    return [walk_summary(f"ipol/{sid}", "10-m legs", rows) for sid, rows in sorted(by_subject.items())]


def by_trial(subjects: list[dict]) -> list[dict]:
    """IPOL's legs regrouped by trial (the two legs of one 10-m out-and-back walk): the strict within-walk view."""
    trials: dict[str, list[dict]] = {}
    for w in subjects:
        for r in w["stretches"]:
            trials.setdefault(r["trial"], []).append(r)
    return [walk_summary(f"ipol/{name}", "10-m legs", rows) for name, rows in trials.items()]


# -- report ------------------------------------------------------------------------------------------------------
def _f(x, nd=3):
    return "--" if x is None or not (isinstance(x, (int, float)) and math.isfinite(x)) else f"{x:.{nd}f}"


def markdown(groups: dict, args=None) -> str:
    cmd = "python -m benchmarks.stride_speed" + (f" --extra {args.extra}" if args is not None and args.extra else "")
    lines = ["# Stride and speed within a walk (tuning split only)", "",
             f"Built by `{cmd}` ({datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC); definitions in the module "
             f"docstring. GPS stretches {STRETCH_S:.0f} s, chord stretches straight to {STRAIGHT_MIN:.2f} of their "
             "path.",
             "",
             "ratio = true distance / Weinberg distance (eq. 4, constant C) per stretch; slopes of log ratio on "
             "log cadence (a cadence exponent), on log (A_max - A_min)^(1/4) and on log of the step's variance, "
             "+- standard error.", ""]
    for gname, walks in groups.items():
        b, se, n = pooled(walks)
        ba, sea, _ = pooled(walks, "amp_root")
        bv, sev, _ = pooled(walks, "acc_var")
        lines += [f"## {gname}: pooled within-walk slope, cadence {_f(b, 2)} +- {_f(se, 2)}, "
                  f"amplitude {_f(ba, 2)} +- {_f(sea, 2)}, variance {_f(bv, 2)} +- {_f(sev, 2)} ({n} stretches)", "",
                  "| walk | reference | stretches | cadence (Hz) | true speed (m/s) | median ratio | slope cadence | "
                  "slope amplitude | slope variance |", "|---|---|---:|---|---|---:|---|---|---|"]
        for w in walks:
            cr, sr = w["cadence_range_hz"], w["speed_range_m_s"]
            cad = _f(cr[0], 2) + "-" + _f(cr[1], 2) if cr else "--"
            lines.append(f"| {w['walk']} | {w['source']} | {w['n']} | {cad} | "
                         f"{_f(sr[0], 2) + '-' + _f(sr[1], 2) if sr else '--'} | {_f(w['ratio_median'])} | "
                         f"{_f(w['slope_cadence'], 2)} +- {_f(w['slope_cadence_se'], 2)} | "
                         f"{_f(w['slope_amp'], 2)} +- {_f(w['slope_amp_se'], 2)} | "
                         f"{_f(w['slope_var'], 2)} +- {_f(w['slope_var_se'], 2)} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    global STRETCH_S, STRAIGHT_MIN  # noqa: PLW0603 - the stretch settings of this run
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_common(ap, what="walk names (the tuning split only)")
    ap.add_argument("--extra", type=Path, default=None, help="a folder of fetched recordings (<owner>__<repo>/<walk>)")
    ap.add_argument("--sources", default="gps,ipin,ipol", help="comma-separated: gps, ipin, ipol")
    ap.add_argument("--stretch-s", type=float, default=20.0, help="GPS stretch length (s)")
    ap.add_argument("--straight", type=float, default=0.95, help="GPS chord stretch: least chord / path")
    args = ap.parse_args(argv)
    STRETCH_S, STRAIGHT_MIN = args.stretch_s, args.straight
    root = data_root(args)
    only = only_keys(args) or []
    src = set(args.sources.split(","))
    groups = {}
    if "gps" in src:
        walks = gps_walks(root, args.extra, only)
        for ref in ("GPS chords", "Doppler speed"):
            groups[f"GPS walks (tuning), {ref}"] = [w for w in walks if w["source"] == ref]
    if "ipin" in src:
        groups["IPIN 2023 tuning routes"] = ipin_walks(root, only)
    if "ipol" in src:
        groups["IPOL (waist, per subject)"] = subjects = ipol_walks(root, only)
        groups["IPOL (waist, per trial: its two legs)"] = by_trial(subjects)
    md = markdown(groups, args)
    print(md)
    full = writes_committed(args) and src == {"gps", "ipin", "ipol"} and args.extra is not None \
        and (args.stretch_s, args.straight) == (STRETCH_S_DEFAULT, STRAIGHT_MIN_DEFAULT)
    d = HERE if full else out_dir("stride_speed")
    (d / RESULTS_MD.name).write_text(md + "\n")
    (out_dir("stride_speed") / "stride_speed.json").write_text(json.dumps(groups, indent=1))
    print(f"wrote {d / RESULTS_MD.name}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
