"""Where the hand-held IPIN error comes from: heading or distance (issue #27), on the TUNING split only.

``python -m benchmarks.ipin_decompose [--engine fast|reference] [--set NAME=VALUE ...]``

Our pipeline (PDR alone, :func:`benchmarks.run.make_pipeline`) on every IPIN 2023 tuning recording; then the
benchmark's metrics (:func:`core.metrics.landmark_errors`: mean landmark error per recording, loop closure) of
our track and of counterfactual tracks that replace one part of it by the truth between landmarks:

``heading true``
    every step between landmark ``k`` and ``k+1`` takes the segment's true bearing, our step lengths kept:
    what is left is the distance error (stride length and step count);
``length true``
    our headings, the step lengths of each segment scaled so the segment has its true length: what is left is
    the heading error;
``global scale``
    our headings, every length scaled by one factor per recording (the walk's true length): a walker's scale;
``heading - mean``
    our headings minus the recording's mean segment heading error (the start heading / a constant offset;
    loop closure is rotation-invariant, so it does not change);
``heading - linear``
    our headings minus a straight line in time fitted to the segment heading errors (an oracle for a gyroscope
    bias drift between relocks);
``first segment``
    only the first segment's heading error removed (the heading the filter took standing at the start).

Then the segment heading errors against the magnetometer's disturbance over the segment: the field norm's
and dip's deviation (in the filter's frame) from the recording's median over the walk, and the share of
rejected magnetometer readings.

Segments shorter than 2 m (the walker stands or turns at a landmark) carry no bearing: their steps keep our
heading in every counterfactual.  The report split is refused (:mod:`benchmarks.splits`): this is a tool for
choosing, and nothing is chosen on the report split.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from benchmarks import splits as S
from benchmarks.datasets import ipin2023
from benchmarks.datasets.base import default_data_root
from benchmarks.tune import parse_set
from core import metrics as M
from core import quaternion as quat
from core.conventions import wrap_angle

#: a segment shorter than this has no bearing (m)
MIN_BEARING_SEGMENT_M = 2.0

#: the counterfactuals, in the table's order
VARIANTS = ("ours", "heading true", "length true", "global scale", "heading - mean", "heading - linear",
            "first segment")


def _segments(t_ns, lm):
    """Per step: its segment index ``k`` (``t_k < t <= t_{k+1}``), -1 or n outside; the segments' bearings and
    lengths."""
    lt = lm.t_ns
    seg = np.searchsorted(lt, t_ns, side="left") - 1
    de, dn = np.diff(lm.east_m), np.diff(lm.north_m)
    return seg, np.arctan2(dn, de), np.hypot(de, dn)


def counterfactuals(t_ns, length_m, heading_rad, lm) -> dict:
    """``{variant: (length_m, heading_rad)}`` of :data:`VARIANTS` for one track and its landmarks."""
    seg, bearing, seglen = _segments(t_ns, lm)
    n = len(bearing)
    has = [(k, seg == k) for k in range(n)]
    herr = np.full(n, np.nan)
    tmid = np.full(n, np.nan)
    for k, m in has:
        if np.any(m) and seglen[k] >= MIN_BEARING_SEGMENT_M:
            herr[k] = wrap_angle(M.circular_mean(heading_rad[m]) - bearing[k])
            tmid[k] = float(np.mean(t_ns[m])) * 1e-9
    h_true = heading_rad.copy()
    L_true = length_m.copy()
    for k, m in has:
        if seglen[k] >= MIN_BEARING_SEGMENT_M:
            h_true[m] = bearing[k]
        if np.sum(length_m[m]) > 0:
            L_true[m] = length_m[m] * seglen[k] / np.sum(length_m[m])
    inwalk = (seg >= 0) & (seg < n)
    L_glob = length_m * (np.sum(seglen) / max(np.sum(length_m[inwalk]), 1e-9))
    ok = np.isfinite(herr)
    out = {"ours": (length_m, heading_rad), "heading true": (length_m, h_true), "length true": (L_true, heading_rad),
           "global scale": (L_glob, heading_rad)}
    if np.any(ok):
        out["heading - mean"] = (length_m, heading_rad - M.circular_mean(herr[ok]))
        tt = tmid[ok] - tmid[ok][0]
        A = np.column_stack([np.ones(len(tt)), tt])
        c0, c1 = np.linalg.lstsq(A, np.unwrap(herr[ok]), rcond=None)[0]
        out["heading - linear"] = (length_m, heading_rad - (c0 + c1 * (t_ns * 1e-9 - tmid[ok][0])))
        h_first = heading_rad.copy()
        if np.isfinite(herr[0]):
            h_first[seg == 0] -= herr[0]
        out["first segment"] = (length_m, h_first)
    return out


def disturbance(t_ns, res, rec, lm) -> list:
    """Per segment with a bearing: ``(heading error deg, norm deviation %, dip deviation deg, rejected %)``."""
    seg, bearing, seglen = _segments(t_ns, lm)
    h = res.track.heading_rad
    at, q = res.attitude.t_ns, res.attitude.q_wxyz
    mag = rec.streams["mag"]
    idx = np.clip(np.searchsorted(at, mag.t_ns), 0, len(at) - 1)
    good = np.isfinite(q[idx]).all(axis=1)
    mw = np.full((len(idx), 3), np.nan)
    for i in np.flatnonzero(good):
        mw[i] = quat.rotate(q[idx[i]], mag.values[i, :3])
    norm = np.linalg.norm(mw, axis=1)
    dip = np.degrees(np.arctan2(-mw[:, 2], np.hypot(mw[:, 0], mw[:, 1])))
    lt = lm.t_ns
    walk = (mag.t_ns > lt[0]) & (mag.t_ns <= lt[-1])
    n0, d0 = np.nanmedian(norm[walk]), np.nanmedian(dip[walk])
    rej = np.asarray(res.attitude.mag_rejected, dtype=bool)
    rows = []
    for k in range(len(bearing)):
        m = seg == k
        if seglen[k] < MIN_BEARING_SEGMENT_M or np.sum(m) < 3:
            continue
        mm = (mag.t_ns > lt[k]) & (mag.t_ns <= lt[k + 1])
        am = (at > lt[k]) & (at <= lt[k + 1])
        rows.append((math.degrees(wrap_angle(M.circular_mean(h[m]) - bearing[k])),
                     100.0 * float(np.nanmean(np.abs(norm[mm] / n0 - 1.0))), float(np.nanmean(np.abs(dip[mm] - d0))),
                     100.0 * float(np.mean(rej[am])) if np.any(am) else math.nan))
    return rows


def decompose(engine: str = "fast", overrides=None, data_root=None, log=sys.stderr) -> dict:
    """Run the tuning recordings; ``{"rows": [(name, {variant: (lm_m, loop_pct)})], "segments": [...]}``."""
    from benchmarks.run import make_pipeline
    from desktop.engine import run_pipeline

    root = data_root if data_root is not None else default_data_root()
    rows, segs = [], []
    for trial in ipin2023.trials(root):
        if S.trial_split(trial) != S.TUNING:
            continue
        rec = trial.open()
        res, _ = run_pipeline(make_pipeline(trial, **(overrides or {})), rec, engine)
        tr, lm = res.track, trial.landmarks
        out = {}
        for name, (L, h) in counterfactuals(tr.t_ns, tr.length_m, tr.heading_rad, lm).items():
            e, n = M.dead_reckon(L, h)
            le = M.landmark_errors(tr.t_ns, e, n, h, lm.t_ns, lm.east_m, lm.north_m)
            out[name] = (le.mean_m, le.loop_closure_pct)
        rows.append((trial.name, out))
        segs += disturbance(tr.t_ns, res, rec, lm)
        print(f"{trial.name}: landmark {out['ours'][0]:.2f} m, loop {out['ours'][1]:.2f} %", file=log, flush=True)
    return {"rows": rows, "segments": segs}


def format_report(d: dict) -> str:
    lines = ["IPIN 2023 TUNING split, PDR alone: mean landmark error (m) / loop closure (%) per recording", "",
             "| recording | " + " | ".join(VARIANTS) + " |", "|---" * (len(VARIANTS) + 1) + "|"]
    for name, out in d["rows"]:
        lines.append(f"| {name} | " + " | ".join(
            f"{out[v][0]:.2f} / {out[v][1]:.2f}" if v in out else "-" for v in VARIANTS) + " |")
    for stat, fn in (("median", np.nanmedian), ("mean", np.nanmean)):
        cells = []
        for v in VARIANTS:
            a = np.array([out[v] for _, out in d["rows"] if v in out], dtype=float)
            cells.append(f"**{fn(a[:, 0]):.2f} / {fn(a[:, 1]):.2f}**" if len(a) else "-")
        lines.append(f"| {stat} | " + " | ".join(cells) + " |")
    X = np.array(d["segments"], dtype=float)
    if len(X):
        lines += ["", f"Segment heading errors ({len(X)} segments of >= {MIN_BEARING_SEGMENT_M:g} m): median |error| "
                  f"{np.median(np.abs(X[:, 0])):.1f} deg; correlation of |error| with the field norm's deviation "
                  f"{np.corrcoef(np.abs(X[:, 0]), X[:, 1])[0, 1]:+.2f}, the dip's deviation "
                  f"{np.corrcoef(np.abs(X[:, 0]), X[:, 2])[0, 1]:+.2f}, the rejected share "
                  f"{np.corrcoef(np.abs(X[:, 0]), X[:, 3])[0, 1]:+.2f}"]
        for j, label, edges in ((2, "dip deviation (deg)", (0, 5, 10, 20, 180)),
                                (1, "norm deviation (%)", (0, 3, 6, 12, 1000))):
            parts = []
            for lo, hi in zip(edges[:-1], edges[1:]):
                m = (X[:, j] >= lo) & (X[:, j] < hi)
                if np.any(m):
                    parts.append(f"{lo}-{hi}: {np.median(np.abs(X[m, 0])):.1f} deg (n={int(np.sum(m))})")
            lines.append(f"- median |error| by {label}: " + ", ".join(parts))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.ipin_decompose", description=__doc__.split("\n")[0])
    ap.add_argument("--engine", choices=("fast", "reference", "auto"), default="auto")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a keyword override for core.pdr.pipeline.Pipeline (VALUE a Python literal); repeatable")
    ap.add_argument("--data", default=None, help="data root (default: ../shared/data beside the repo)")
    args = ap.parse_args(argv)
    root = default_data_root() if args.data is None else args.data
    if not ipin2023.available(root):
        print(f"benchmarks.ipin_decompose: no IPIN 2023 data under {root}", file=sys.stderr)
        return 2
    print(format_report(decompose(args.engine, parse_set(args.set), root)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
