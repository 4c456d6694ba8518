"""Where an outage's end error comes from (issue #25 part 3): heading offset, stride scale, or the heading's wander.

``python -m benchmarks.outage_parts [--extra DIR] [--only TEXT,...] [--lengths 60,180] [--gps MODE]`` runs the
default path of :mod:`benchmarks.real_walks` once per walk of the **tuning** split (the report split is refused:
this is a diagnosis to choose what to fix), then for every outage window of that benchmark
(:func:`benchmarks.real_walks.outage_windows`) the fusion with the window hidden, and writes
``out/benchmarks/real_walks/outage_parts.{md,json}``.

Per outage, over the steps from the last fused step before the window to the first screened fix after it
(``D_k``: the sum of the steps' dead-reckoned vectors ``l_i exp(j h_i)`` up to good fix ``k`` inside the window,
``G_k``: that fix minus the start position, complex East + j North):

* ``z_learnt = s_learnt exp(j theta_learnt)``: what the fusion applied inside the window -- the circular mean
  of fused minus dead-reckoned heading and the ratio of fused to dead-reckoned step length over the window's
  steps (the fusion dead-reckons there with what it learnt before);
* ``z_best``: the constant offset and scale that fit the GPS track inside the window best (least squares
  over the good fixes in it, ``z = sum conj(D_k) G_k / sum |D_k|^2``): ``theta_best = arg z``,
  ``s_best = |z|``;
* the end error of dead reckoning with ``z_learnt`` (``e_learnt``: about the default path's error, without
  what the filter does at the window's edges), with ``theta_best`` and the learnt scale (``e_theta``), with both
  best (``e_best``: what is left, the heading's wander inside the window and the scale's change);
* parts: heading offset ``e_learnt - e_theta``, stride scale ``e_theta - e_best``, wander ``e_best``
  (sequential, in % of the walked distance; not additive in general, vectors);
* ``gps_chord_over_pdr``: the window's start-to-end-fix chord over the dead-reckoned distance (a straight window
  near 1 / the scale; far from it where the street turns or the reference itself is off).

The GPS track is the reference: where its own chords disagree with the cadence (on ``thomasdingemanse_lopen``,
60-120 s, 10-s chord speeds of 0.55-2.9 m/s at 1.97 steps/s while reporting 4.8 m), the "best" offset and scale
fit its errors, and a large wander there is the reference's, not the heading's.
"""

from __future__ import annotations

import argparse
import cmath
import json
import math
import sys
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.datasets.phone_walks import GPS_WALK, real_walks
from benchmarks.options import out_dir
from benchmarks.splits import TUNING
from core.conventions import GPS, wrap_angle
from core.metrics import circular_mean


def decompose(res, rec, outage_start_s: float, length_s: float) -> dict | None:
    """The parts of one outage's end error (module docstring) from a run with that window hidden."""
    from benchmarks import real_walks as rw

    fu = res.fusion
    if fu is None or not fu.outages:
        return None
    o = fu.outages[0]
    fused = {s.index: s for s in fu.steps}
    steps = res.steps
    t = np.array([s.t_ns for s in steps], dtype=np.int64)
    a_ns = rec.t0_ns + int(outage_start_s * 1e9)
    before = [i for i in range(len(steps)) if t[i] < a_ns and i in fused]
    fix = next((f for f in fu.fixes if f.t_ns == o.fix_t_ns), None)
    if not before or fix is None or not math.isfinite(fix.east_m):
        return None
    k0 = before[-1]
    inside = [i for i in range(k0 + 1, len(steps)) if t[i] <= fix.t_ns]
    if len(inside) < 10:
        return None
    p0 = complex(fused[k0].east_m, fused[k0].north_m)
    g_end = complex(fix.east_m, fix.north_m) - p0
    v = np.array([steps[i].length_m * cmath.exp(1j * steps[i].heading_rad) for i in inside])
    cum = np.cumsum(v)
    # what the fusion applied inside the window
    off = circular_mean([wrap_angle(fused[i].heading_rad - steps[i].heading_rad) for i in inside if i in fused])
    ratio = [fused[i].length_m / steps[i].length_m for i in inside if i in fused and steps[i].length_m > 0]
    s_l = float(np.median(ratio)) if ratio else 1.0
    fused_end = complex(fused[inside[-1]].east_m, fused[inside[-1]].north_m) if inside[-1] in fused else None
    # the GPS track inside the window (the good fixes), and the best constant z
    fixes = rw.good_fixes(rec.streams[GPS])
    if fixes is None:
        return None
    ft, fe, fn, _ = fixes
    # good fixes in the window, in the fusion's ENU: shift by the end fix's difference (same origin up to a constant)
    j_end = int(np.argmin(np.abs(ft - fix.t_ns)))
    shift = complex(fix.east_m, fix.north_m) - complex(fe[j_end], fn[j_end]) if abs(int(ft[j_end]) - fix.t_ns) < 1e8 \
        else None
    D, G = [], []
    if shift is not None:
        sel = np.flatnonzero((ft > t[inside[0]]) & (ft <= fix.t_ns))
        for j in sel:
            n = int(np.searchsorted(t[inside], ft[j], side="right"))
            if n == 0:
                continue
            D.append(cum[n - 1])
            G.append(complex(fe[j], fn[j]) + shift - p0)
    D.append(cum[-1])
    G.append(g_end)
    D, G = np.array(D), np.array(G)
    z_best = complex(np.sum(np.conj(D) * G) / np.sum(np.abs(D) ** 2))
    z_learnt = s_l * cmath.exp(1j * off)
    walked = float(np.sum(np.abs(v)) * s_l)
    th_best, s_best = cmath.phase(z_best), abs(z_best)
    e_learnt = abs(z_learnt * cum[-1] - g_end)
    e_theta = abs(s_l * cmath.exp(1j * th_best) * cum[-1] - g_end)
    e_best = abs(z_best * cum[-1] - g_end)
    pct = 100.0 / walked if walked > 0 else math.nan
    # PDR alone of the benchmark (offset of the last OFFSET_STEPS steps, unscaled lengths)
    pa = rw.pdr_alone(res, {"start_ns": a_ns, "fix_t_ns": o.fix_t_ns, "walked_m": o.walked_m})
    return {"start_s": outage_start_s, "length_s": length_s, "walked_m": o.walked_m,
            "default_pct": o.end_error_pct, "pdr_pct": pa["end_error_pct"],
            "pdr_offset_deg": pa["offset_deg"],
            "fused_end_check_m": abs(fused_end - complex(fix.east_m, fix.north_m)) if fused_end is not None else None,
            "theta_learnt_deg": math.degrees(off), "theta_best_deg": math.degrees(th_best),
            "theta_err_deg": math.degrees(wrap_angle(off - th_best)),
            "s_learnt": s_l, "s_best": s_best, "s_err_pct": 100.0 * (s_l / s_best - 1.0),
            "gps_chord_over_pdr": abs(g_end) / float(np.sum(np.abs(v))),
            "e_learnt_pct": e_learnt * pct, "e_theta_pct": e_theta * pct, "e_best_pct": e_best * pct,
            "part_heading_pct": (e_learnt - e_theta) * pct, "part_scale_pct": (e_theta - e_best) * pct,
            "part_wander_pct": e_best * pct, "n_fixes_fit": len(D)}


def run_walk(walk, lengths) -> dict:
    from benchmarks import real_walks as rw
    from core.importers import load_recording

    rec = load_recording(str(walk.folder), warn=False)
    res, _, _ = rw.run_default(rec, walk.folder)
    w_from = rw.walking_from_s(res.steps, rec.t0_ns)
    rows = []
    for a, length in rw.outage_windows(w_from, (rec.t1_ns - rec.t0_ns) * 1e-9):
        if length not in lengths:
            continue
        r = rw.fuse_outage(rec, walk, res, a, length)
        d = decompose(r, rec, a, length)
        rows.append(d or {"start_s": a, "length_s": length, "failed": True})
        print(f"  {walk.name} {a:.0f}+{length:.0f}: " + (", ".join(
            f"{k} {d[k]:.1f}" for k in ("default_pct", "pdr_pct", "e_learnt_pct", "theta_err_deg", "s_err_pct",
                                        "part_heading_pct", "part_scale_pct", "part_wander_pct")) if d else "failed"),
              file=sys.stderr)
    return {"name": walk.name, "outages": rows}


def main(argv=None) -> int:
    from benchmarks import real_walks as rw

    ap = argparse.ArgumentParser(prog="python -m benchmarks.outage_parts", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--extra", type=Path, default=None)
    ap.add_argument("--only", default=None)
    ap.add_argument("--lengths", default="60,180,300")
    ap.add_argument("--gps", default=None, choices=("auto", "chen", "kubrak"))
    a = ap.parse_args(argv)
    rw.REPLAY_GPS = a.gps
    lengths = {float(x) for x in a.lengths.split(",")}
    walks = [w for w in real_walks(a.data or default_data_root(), a.extra)
             if w.split == TUNING and w.kind == GPS_WALK]
    if a.only:
        walks = [w for w in walks if any(k.strip() in w.name for k in a.only.split(","))]
    out = [run_walk(w, lengths) for w in walks]
    L = ["| walk | outage | default % | PDR alone % | DR learnt % | offset learnt / best deg | scale learnt / best |"
         " heading part % | scale part % | wander % | end chord / PDR distance |", "|" + "---|" * 11]
    for w in out:
        for o in w["outages"]:
            if o.get("failed"):
                L.append(f"| {w['name']} | {o['start_s']:.0f}+{o['length_s']:.0f} | failed |")
                continue
            L.append(f"| {w['name']} | {o['start_s']:.0f}+{o['length_s']:.0f} | {o['default_pct']:.1f} | "
                     f"{o['pdr_pct']:.1f} | {o['e_learnt_pct']:.1f} | {o['theta_learnt_deg']:.1f} / "
                     f"{o['theta_best_deg']:.1f} | {o['s_learnt']:.3f} / {o['s_best']:.3f} | "
                     f"{o['part_heading_pct']:.1f} | {o['part_scale_pct']:.1f} | {o['part_wander_pct']:.1f} | "
                     f"{o['gps_chord_over_pdr']:.3f} |")
    md = "\n".join(L) + "\n"
    d = out_dir("real_walks")
    (d / "outage_parts.md").write_text(md)
    (d / "outage_parts.json").write_text(json.dumps(out, indent=1))
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
