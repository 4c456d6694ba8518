"""Per-fix evidence on the IPIN 2023 hand-held loops (issue #26): which fixes help dead reckoning, which hurt.

``python -m tools.ipin_fix_evidence [--split tuning] [--out out/ipin_fix_evidence.json]``

For every fix between the first and the last landmark of each file of the split:

* the truth at the fix's time: the landmarks interpolated linearly in time (the walker goes at a constant speed
  from one landmark to the next: the legs are about straight and every turn has a landmark).  A leg in which the
  walker stands (a gap of more than ``STAND_GAP_S`` between two of the pipeline's steps) breaks that assumption:
  its fixes are dropped;
* the fix's error against that truth, its reported accuracy, satellites in use / in view (the importer's
  ``gnss_status``), and dead reckoning's own error at the same time (the pipeline's track placed at the first
  landmark at its time, absolute heading: the benchmark's ``pdr`` column) -- the error a fix taken there would
  replace;
* whether Chen's filter, as ``benchmarks.gnss_faults`` runs it (known start at the first landmark), took it.

A fix **helps** where its error is below dead reckoning's at its time, **hurts** where above.  Prints the
per-file and per-bin tables (satellites in use, their share of those in view, reported accuracy).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import metrics as M
from benchmarks.gnss_faults import IPIN_START_SD_M, _ipin_trials, fuse, pdr_track
from benchmarks.options import data_root
from benchmarks.splits import split_of
from core.conventions import GNSS_STATUS, GPS
from core.geodesy import geodetic_to_enu

#: a gap between two steps longer than this (s) inside a leg: the walker stood, the constant speed fails
STAND_GAP_S = 2.0


def file_rows(trial) -> list[dict]:
    from benchmarks.run import make_pipeline

    rec = trial.open()
    if not rec.has(GPS):
        return []
    res = make_pipeline(trial).run(rec)
    lm = trial.landmarks
    lt = lm.t_ns
    e, n = pdr_track(res.track)
    gps = rec.streams[GPS]
    st = rec.streams.get(GNSS_STATUS)
    inside = (gps.t_ns >= lt[0]) & (gps.t_ns <= lt[-1])
    t = gps.t_ns
    fe, fn = geodetic_to_enu(gps.values[:, 0], gps.values[:, 1], lm.origin_lat_lon)
    te, tn = np.interp(t, lt, lm.east_m), np.interp(t, lt, lm.north_m)
    p = M.positions_at(res.track.t_ns, e, n, np.concatenate([[lt[0]], t]))
    dr = p[1:] - p[0] + (lm.east_m[0], lm.north_m[0])
    step_t = np.array([s.t_ns for s in res.steps], dtype=np.int64)
    leg = np.searchsorted(lt, t, side="right") - 1
    standing = np.zeros(len(lt), dtype=bool)
    for k in range(len(lt) - 1):
        ts = np.concatenate([[lt[k]], step_t[(step_t > lt[k]) & (step_t < lt[k + 1])], [lt[k + 1]]])
        standing[k] = bool(np.max(np.diff(ts)) * 1e-9 > STAND_GAP_S)
    # Chen's filter as the benchmark runs it: which fixes it took
    after = gps.t_ns >= lt[0]
    fr = fuse("chen", [s for s in res.steps if s.t_ns > lt[0]], replace(gps, t_ns=gps.t_ns[after],
              values=gps.values[after]), rec.t0_ns, st, start=(*lm.origin_lat_lon, IPIN_START_SD_M))
    taken = {x.t_ns for x in fr.fixes if x.accepted}
    rows = []
    for i in np.flatnonzero(inside):
        if standing[min(leg[i], len(lt) - 2)]:
            continue
        j = int(np.searchsorted(st.t_ns, t[i])) if st is not None else -1
        sat = st.values[j] if st is not None and j < len(st) and st.t_ns[j] == t[i] else (math.nan,) * 3
        rows.append({"file": trial.name, "phone": rec.device.get("model"), "t_s": (t[i] - lt[0]) * 1e-9,
                     "fix_err_m": float(math.hypot(fe[i] - te[i], fn[i] - tn[i])),
                     "dr_err_m": float(math.hypot(dr[i, 0] - te[i], dr[i, 1] - tn[i])),
                     "hacc_m": float(gps.values[i, 3]), "n_used": float(sat[0]), "n_view": float(sat[2]),
                     "taken": int(t[i]) in taken})
    return rows


def _table(rows, key, bins, label):
    print(f"\n{label:>14} {'fixes':>6} {'help %':>7} {'fix err med':>11} {'DR err med':>10} {'taken':>6} "
          f"{'taken hurt':>10}")
    for lo, hi in bins:
        sel = [r for r in rows if lo <= key(r) < hi]
        if not sel:
            continue
        helps = [r["fix_err_m"] < r["dr_err_m"] for r in sel]
        tk = [r for r in sel if r["taken"]]
        print(f"{f'{lo:g}-{hi:g}':>14} {len(sel):6d} {100 * np.mean(helps):7.0f} "
              f"{np.median([r['fix_err_m'] for r in sel]):11.1f} {np.median([r['dr_err_m'] for r in sel]):10.1f} "
              f"{len(tk):6d} {sum(r['fix_err_m'] >= r['dr_err_m'] for r in tk):10d}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", default="tuning", choices=("tuning", "report"))
    ap.add_argument("--out", default="out/ipin_fix_evidence.json")
    a = ap.parse_args(argv)
    root = data_root(a)
    rows = []
    for trial in _ipin_trials(Path(root)):
        if split_of(trial.dataset, trial.info) != a.split:
            continue
        r = file_rows(trial)
        rows += r
        if r:
            f = np.array([x["fix_err_m"] for x in r])
            d = np.array([x["dr_err_m"] for x in r])
            print(f"{trial.name} {r[0]['phone']}: {len(r)} fixes, help {100 * np.mean(f < d):.0f} %, fix err median "
                  f"{np.median(f):.1f} m, DR err median {np.median(d):.1f} m, in use median "
                  f"{np.nanmedian([x['n_used'] for x in r]):.0f} of {np.nanmedian([x['n_view'] for x in r]):.0f}, "
                  f"hacc median {np.median([x['hacc_m'] for x in r]):.0f} m, taken {sum(x['taken'] for x in r)}",
                  flush=True)
        else:
            print(f"{trial.name}: no fixes between the landmarks", flush=True)
    inf = math.inf
    _table(rows, lambda r: r["n_used"], [(0, 1), (1, 4), (4, 7), (7, 10), (10, 13), (13, 17), (17, inf)], "in use")
    _table(rows, lambda r: r["n_used"] / r["n_view"] if r["n_view"] > 0 else -1,
           [(-1, 0), (0, 0.5), (0.5, 0.7), (0.7, 0.8), (0.8, 0.9), (0.9, 1.01)], "in use / view")
    _table(rows, lambda r: r["hacc_m"], [(0, 5), (5, 7), (7, 10), (10, 15), (15, 25), (25, inf)], "hacc m")
    for phone in sorted({r["phone"] for r in rows}):
        sub = [r for r in rows if r["phone"] == phone]
        print(f"\n-- {phone}")
        _table(sub, lambda r: r["n_used"], [(0, 1), (1, 4), (4, 7), (7, 10), (10, 13), (13, 17), (17, inf)],
               "in use")
        _table(sub, lambda r: r["hacc_m"], [(0, 5), (5, 7), (7, 10), (10, 15), (15, 25), (25, inf)], "hacc m")
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
