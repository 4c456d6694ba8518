"""What moves the fused track away from dead reckoning on the IPIN 2023 loops (issue #26): per file, each kind of event.

``python -m tools.ipin_gps_moves [--data DIR] [--split tuning] [--only T02r02,...] [--out out/ipin_gps_moves.json]``

Chen's filter as ``benchmarks.gnss_faults`` runs it (the steps after the first landmark, a known start there, the
fixes from its time on, the default settings: ``--gps auto``), scored with the same landmark error, and again with
one kind of event switched off at a time, so that each kind's share of the change from dead reckoning shows:

* ``no_relock``: the relock rules (``relock_s`` made longer than any walk: no "consistent stream", no "gated fixes
  agree");
* ``no_position``: the position part of every gated update (the state's ``E, N`` kept as they were; the update's
  covariance, heading and step length stay: the fix still teaches), :class:`_KeepPosition`;
* ``no_course``: the GPS course (``use_course=False``);
* ``no_heading_model`` / ``no_stride``: training the heading model / the stride scale from the fixes;
* ``no_judge``: the usability judge (every screened fix to the filter: what the judge keeps out).

Beside them, from the default run: the fixes used, how far GPS moved the fused position by kind
(:meth:`core.gnss.base.FixFusion.gps_moves`), and the first move with the filter's position SD before it, dead
reckoning's own error then and the fix's (the truth: the landmarks interpolated in time).  Kubrak's filter's relock
and shadow-adoption counts too (``kubrak_relocks``, ``kubrak_shadow_adoptions``).

A diagnostic, not a benchmark: a file without GNSS is skipped and an exception stops the run, so its medians are not
the headline numbers (``benchmarks.gnss_faults`` counts every file, failures as +inf).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import metrics as M
from benchmarks.gnss_faults import IPIN_START_SD_M, _ipin_trials, fused_en, pdr_track
from benchmarks.options import data_root
from benchmarks.splits import split_of
from core.conventions import GNSS_STATUS, GPS
from core.geodesy import geodetic_to_enu
from core.gnss import make_fusion
from core.gnss.fusion import GpsFusion


class _KeepPosition(GpsFusion):
    """Chen's filter whose gated position updates leave the position where it was (everything else as usual)."""

    def _update_position(self, t_ns, east, north, sigma_m, gate):
        before = self.ekf.x[:2].copy()
        res = super()._update_position(t_ns, east, north, sigma_m, gate)
        if res.accepted:
            self.ekf.set_position(*before)
        return res


#: the runs: name -> (filter factory's settings, class or None for ``make_fusion("chen")``)
VARIANTS = {
    "chen": ({}, None),
    "no_relock": ({"relock_s": 1e6}, None),
    "no_position": ({}, _KeepPosition),
    "no_course": ({"use_course": False}, None),
    "no_heading_model": ({"learn_heading": False}, None),
    "no_stride": ({"learn_stride": False}, None),
    "no_judge": ({"judge": None}, None),
}


def file_row(trial) -> dict | None:
    from benchmarks.run import make_pipeline

    rec = trial.open()
    if not rec.has(GPS):
        return None
    res = make_pipeline(trial).run(rec)
    lm = trial.landmarks
    lt, L = lm.t_ns, (lm.east_m, lm.north_m)
    e, n = pdr_track(res.track)
    row = {"file": trial.name, "pdr": M.landmark_errors(res.track.t_ns, e, n, np.asarray(res.track.heading_rad,
                                                                                          dtype=float),
                                                       lt, *L).mean_m}
    gps = rec.streams[GPS]
    after = gps.t_ns >= lt[0]
    gps = replace(gps, t_ns=gps.t_ns[after], values=gps.values[after])
    status = rec.streams.get(GNSS_STATUS)
    steps = [s for s in res.steps if s.t_ns > lt[0]]
    start = (*lm.origin_lat_lon, IPIN_START_SD_M)
    default = None
    for name, (settings, cls) in VARIANTS.items():
        f = cls(start=start, **settings) if cls is not None else make_fusion("chen", start=start, **settings)
        fr = f.run(steps, gps, rec.t0_ns, status)
        en = fused_en(fr, lm.origin_lat_lon)
        st = geodetic_to_enu(*fr.origin_lat_lon, lm.origin_lat_lon)
        t = np.array([s.t_ns for s in fr.steps], dtype=np.int64)
        row[name] = M.landmark_errors(t, en[:, 0], en[:, 1], np.array([s.heading_rad for s in fr.steps]), lt, *L,
                                      start=(float(st[0]), float(st[1]))).mean_m
        if name == "chen":
            default = fr
    c = default.counters
    row["fixes_used"] = sum(x.accepted for x in default.fixes)
    row["moves"] = c["gps_moves"]["by_kind"]
    first = c["gps_moves"]["first"]
    if first is not None:  # the first move against the truth: the filter's sigma, dead reckoning's error, the fix's
        fix = next(x for x in default.fixes if x.t_ns == first["t_ns"])
        ts = (first["t_ns"] - lt[0]) * 1e-9
        lts = (lt - lt[0]) * 1e-9
        truth = np.array([np.interp(ts, lts, L[0]), np.interp(ts, lts, L[1])])
        fe = np.array(geodetic_to_enu(fix.lat_deg, fix.lon_deg, lm.origin_lat_lon), dtype=float)
        # dead reckoning (the pipeline's track placed at the first landmark) at the fix's time: before any fix the
        # filter's track is this one (no stride or heading learnt yet)
        p = M.positions_at(res.track.t_ns, e, n, np.array([lt[0], first["t_ns"]], dtype=np.int64))
        dr = p[1] - p[0] + (L[0][0], L[1][0])
        row["first_move"] = {"t_s": ts, "moved_m": first["moved_m"], "sigma_before_m": first["sigma_before_m"],
                             "dr_err_m": float(np.hypot(*(dr - truth))),
                             "fix_err_m": float(np.hypot(*(fe - truth))), "hacc_m": fix.hacc_m}
    kf = make_fusion("kubrak", start=start)
    kr = kf.run(steps, gps, rec.t0_ns, status)
    row["kubrak_relocks"] = len(kr.counters["relocks"])
    row["kubrak_shadow_adoptions"] = kr.counters["gps_moves"]["by_kind"].get("shadow adopted", {}).get("n", 0)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", default="tuning", choices=("tuning", "report"))
    ap.add_argument("--only", default="", help="comma-separated file names (T02r02, ...)")
    ap.add_argument("--out", default="out/ipin_gps_moves.json")
    a = ap.parse_args(argv)
    only = {x for x in a.only.split(",") if x}
    rows = []
    names = list(VARIANTS)
    print("file  pdr  " + "  ".join(names) + "  used  moves by kind (n: m)  first move (t s, moved, sigma, DR / fix err)")
    for trial in _ipin_trials(Path(data_root(a))):
        if split_of(trial.dataset, trial.info) != a.split or (only and trial.name not in only):
            continue
        r = file_row(trial)
        if r is None:
            continue
        rows.append(r)
        mv = ", ".join(f"{k} {v['n']}: {v['moved_m']:.1f}" for k, v in r["moves"].items()) or "-"
        fm = r.get("first_move")
        fs = (f"{fm['t_s']:.0f} s, {fm['moved_m']:.1f} m, sigma {fm['sigma_before_m']:.1f}, {fm['dr_err_m']:.1f} / "
              f"{fm['fix_err_m']:.1f}") if fm else "-"
        print(f"{r['file']}  {r['pdr']:.2f}  " + "  ".join(f"{r[k]:.2f}" for k in names) +
              f"  {r['fixes_used']}  {mv}  {fs}  kubrak relocks {r['kubrak_relocks']}, adoptions "
              f"{r['kubrak_shadow_adoptions']}", flush=True)
    for k in ["pdr"] + names:
        v = [r[k] for r in rows]
        print(f"{k:>16}: median {np.median(v):.3f}  mean {np.mean(v):.3f}")
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
