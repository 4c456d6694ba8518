"""A very long simulated walk through the streaming pipeline (issue #12): 24 hours by default.

    python -m benchmarks.long_walk                 # 24 h, about 10-15 min on one core
    python -m benchmarks.long_walk --hours 0.5     # a quick look

The walk is simulated one segment at a time (``--segment-min``, an hour by
default: one simulated day at once would need tens of GB) along city streets
(:func:`desktop.simulator.street_route`), each segment starting where and when
the last one ended, with its own gyroscope bias and a short stop between them
(traffic lights).  Everything goes through one :class:`core.pdr.pipeline.Pipeline`
in streaming mode (``keep_steps=False``, as the app runs it).  After every
segment it prints and checks what ``tests/test_pipeline.py`` checks for one
hour: the quaternion's norm, the covariance symmetric and positive definite,
the items the pipeline holds (flat), the process's peak memory, and the
heading error against the simulator's truth (the magnetometer bounds it: it
must not grow with time).  ``--json`` writes the rows.  Exit status 1 when a
check fails.

``--app-steps`` keeps the completed steps as the app's session keeps them (issue #30): ``file`` (now:
:class:`core.export.StepFile`, written to a temporary file, the last few in memory) or ``list`` (before: a
list of :class:`core.pdr.pipeline.Step`); ``app_steps_mb`` is what that store holds in memory (its objects'
bytes, :func:`deep_bytes`), ``app_steps_mb_per_h`` its growth per walked hour.

``--gps kubrak|chen`` walks with GPS (the simulator's outdoor walk: :class:`desktop.simulator.GpsModel` at
1 Hz, the World Magnetic Model's field at the origin, as :func:`desktop.simulator.outdoor_walk`) through that
fusion stage as the app builds it; ``--gps-history file`` (now, the app's: ``keep_history=False``, fused steps
and fix records on disk, the last few in memory) or ``list`` (before issue #30: every one in memory).
``gnss_mb`` is what the fusion and the pipeline's fused steps hold (:func:`deep_bytes`), ``gnss_growth_mb_per_h``
its growth since the first segment per walked hour (the fusion's fixed part, its filters and settings, left out).

``--app-view bounded|unbounded`` runs the events through the app's own :class:`app.session.Session` (the
settings' pipeline: steps in a step file, the fusion's history on disk) instead of a bare pipeline;
``view_mb`` is what the session's view lines hold (the dead-reckoned and fused tracks, the fixes), ``bounded``
as the app does now (thinned past :data:`app.overlay.VIEW_MAX_POINTS`), ``unbounded`` as before issue #30.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time

import numpy as np

from core.pdr.pipeline import Pipeline
from desktop.simulator import simulate_walk, street_route

#: checks per segment: heading error 95th percentile (deg), its growth over the first segment's (deg),
#: held items' growth over the first segment's (fraction)
MAX_P95_DEG = 8.0
MAX_P95_GROWTH_DEG = 2.0
MAX_HELD_GROWTH = 0.05


def _segment(k: int, seed: int, minutes: float, start_en, heading_deg, clock_ns: int, gps: bool = False):
    route = street_route(1.26 * 60.0 * minutes, seed=seed * 1000 + k, start_en_m=start_en,
                         start_heading_deg=heading_deg)
    rng = np.random.default_rng([seed, k])
    kw = {}
    if gps:  # outdoors, as desktop.simulator.outdoor_walk: fixes at 1 Hz, the site's own magnetic field
        from core.geodesy import magnetic_field
        from desktop.simulator import DEFAULT_ORIGIN_ALT_M, DEFAULT_ORIGIN_LAT_LON, GpsModel

        dec, inc, total = magnetic_field(*DEFAULT_ORIGIN_LAT_LON, DEFAULT_ORIGIN_ALT_M, 2025.5)
        kw = dict(gps=GpsModel(), origin_lat_lon=DEFAULT_ORIGIN_LAT_LON, origin_alt_m=DEFAULT_ORIGIN_ALT_M,
                  earth_field_enu_uT=(total * math.cos(inc) * math.sin(dec), total * math.cos(inc) * math.cos(dec),
                                      -total * math.sin(inc)))
    walk = simulate_walk(route, rate_hz=50.0, seed=seed * 1000 + k, clock_start_ns=clock_ns,
                         gyro_bias_rad_s=tuple(rng.normal(0.0, 0.003, 3)), **kw)
    last = route[-1] - route[-2]
    return walk, tuple(route[-1]), math.degrees(math.atan2(last[1], last[0]))


def deep_bytes(obj, seen: set | None = None) -> int:
    """Bytes of ``obj`` and everything it refers to through lists, tuples, deques, dicts, ``__dict__`` and
    ``__slots__`` (``sys.getsizeof`` each object once; a file object counts its buffer)."""
    import collections
    import io

    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    n = sys.getsizeof(obj)
    if isinstance(obj, (list, tuple, collections.deque, set)):
        n += sum(deep_bytes(x, seen) for x in obj)
    elif isinstance(obj, dict):
        n += sum(deep_bytes(k, seen) + deep_bytes(v, seen) for k, v in obj.items())
    elif isinstance(obj, io.IOBase):
        n += 8192
    elif hasattr(obj, "__dict__") and not isinstance(obj, type):
        n += deep_bytes(vars(obj), seen)
    for name in getattr(type(obj), "__slots__", ()):
        if hasattr(obj, name):
            n += deep_bytes(getattr(obj, name), seen)
    return n


def _gnss_row(p, rows, hours: float) -> dict:
    """What the GPS fusion holds: its bytes (with the pipeline's fused steps), fixes and steps seen, growth."""
    g = p.gnss
    mb = (deep_bytes(g) + deep_bytes(p.fused)) / 1e6
    first = rows[0] if rows else None
    growth = (mb - first["gnss_mb"]) / (hours - first["hours"]) if first and hours > first["hours"] else math.nan
    return {"gnss_mb": mb, "gnss_growth_mb_per_h": growth, "gnss_fixes": len(g.fixes),
            "gnss_fused_steps": len(g.steps), "gnss_anchored": g.origin_lat_lon is not None,
            "gnss_fixes_accepted": g.n_fixes_accepted}


class _NoSource:
    """The app session's source when the benchmark feeds it events itself."""

    live, finished, running, unix_offset_ns, device, warning = False, False, False, None, {}, ""


def _app_session(gps: bool, fusion: str, unix_offset_ns, bounded: bool):
    """The app's session with the settings' pipeline (GPS on with ``fusion``, else off); ``bounded`` False:
    the view lines never thinned (as before issue #30)."""
    import app.session as S
    from app.settings import Settings

    if not bounded:
        S.VIEW_MAX_POINTS = S.VIEW_MAX_FIXES = 1 << 62
    make = Settings(use_gps=gps, **({"gps_fusion": fusion} if gps else {})).pipeline_factory()

    def factory():
        p = make()
        p.unix_offset_ns = unix_offset_ns
        return p
    return S.Session(_NoSource(), pipeline_factory=factory)


def _view_lists(ses) -> list:
    return [ses.track_east, ses.track_north, ses.fused_east, ses.fused_north, ses.fused_source, ses.fix_east,
            ses.fix_north, ses.fix_hacc, ses.fix_accepted]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--segment-min", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", help="write the per-segment rows here")
    ap.add_argument("--app-steps", choices=("file", "list"), default="file",
                    help="keep the steps as the app does: in a step file (now) or a list (before issue #30)")
    ap.add_argument("--gps", choices=("off", "kubrak", "chen"), default="off",
                    help="walk outdoors with GPS through this fusion stage (as the app's 'Use GPS')")
    ap.add_argument("--gps-history", choices=("file", "list"), default="file",
                    help="the fusion's fused steps and fix records: on disk (now, the app's) or in lists (before #30)")
    ap.add_argument("--app-view", choices=("off", "bounded", "unbounded"), default="off",
                    help="run the app's session and measure its view lines: thinned (now) or not (before #30)")
    args = ap.parse_args(argv)
    from core.export import StepFile
    from core.gnss import make_fusion

    store = StepFile() if args.app_steps == "file" else []
    n_seg = max(1, math.ceil(args.hours * 60.0 / args.segment_min))
    gps = args.gps != "off"
    # with GPS the anchoring fix gives the site's declination, which needs the date (mid-2025, as the field)
    unix_offset = 1_751_414_400 * 10 ** 9 if gps else None
    ses = None
    if args.app_view != "off":
        ses = _app_session(gps, args.gps, unix_offset, args.app_view == "bounded")
        p, store = ses.pipeline, ses.steps
    else:
        gnss = make_fusion(args.gps, keep_history=args.gps_history == "list") if gps else None
        p = Pipeline(keep_steps=False, gnss=gnss, unix_offset_ns=unix_offset)
    streams = ["gyro", "acc", "mag"] + (["gps"] if gps else [])
    start_en, heading_deg, clock = (0.0, 0.0), None, 10 ** 12
    rows, failures = [], []
    t_wall = time.time()
    for k in range(n_seg):
        walk, start_en, heading_deg = _segment(k, args.seed, args.segment_min, start_en, heading_deg, clock, gps)
        steps = []
        for name, t, v in walk.recording.events(streams):
            if ses is not None:
                steps.extend(ses.ingest([(name, t, v)]))
            else:
                new = p.update(name, t, v)
                if new:
                    steps.extend(new)
                    for s in new:
                        store.append(s)
            clock = t
        clock += 20_000_000
        a = p.attitude
        P = a.P
        ts = np.array([s.t_ns for s in steps], dtype=np.int64)
        if len(ts):
            err = np.degrees(np.angle(np.exp(1j * (np.array([s.heading_rad for s in steps])
                                                   - walk.truth.heading_at(ts)))))
        else:
            err = np.array([math.nan])
        row = {"segment": k, "hours": round((k + 1) * args.segment_min / 60.0, 3), "steps": len(steps),
               "true_steps": int(len(walk.truth.step_t_ns)),
               "heading_err_median_deg": float(np.median(np.abs(err))),
               "heading_err_p95_deg": float(np.percentile(np.abs(err), 95)),
               "heading_sd_deg": math.degrees(math.sqrt(max(float(P[2, 2]), 0.0))),
               "q_norm_error": abs(math.sqrt(sum(c * c for c in a.q)) - 1.0),
               "P_asymmetry": float(np.abs(P - P.T).max() / np.abs(P).max()),
               "P_min_eig": float(np.linalg.eigvalsh(0.5 * (P + P.T)).min()),
               "held_items": p.held_items(), "kept_steps": len(p.steps),
               "app_steps": len(store), "app_steps_mb": deep_bytes(store) / 1e6,
               "app_steps_mb_per_h": deep_bytes(store) / 1e6 / ((k + 1) * args.segment_min / 60.0),
               **(_gnss_row(p, rows, (k + 1) * args.segment_min / 60.0) if gps else {}),
               **({"view_points": len(ses.track_east), "view_fixes": len(ses.fix_east),
                   "view_mb": deep_bytes(_view_lists(ses)) / 1e6, "view_generation": ses.view_generation}
                  if ses is not None else {}),
               "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
               "labels": list(p.labels()), "wall_s": round(time.time() - t_wall, 1)}
        rows.append(row)
        print(" ".join(f"{k_}={v:.4g}" if isinstance(v, float) else f"{k_}={v}" for k_, v in row.items()), flush=True)
        first = rows[0]
        if row["q_norm_error"] > 1e-9:
            failures.append(f"segment {k}: quaternion norm off by {row['q_norm_error']:.2g}")
        if row["P_asymmetry"] > 1e-12 or not row["P_min_eig"] > 0.0:
            failures.append(f"segment {k}: covariance not symmetric positive definite")
        if row["heading_err_p95_deg"] > MAX_P95_DEG:
            failures.append(f"segment {k}: heading error p95 {row['heading_err_p95_deg']:.1f} deg")
        if row["heading_err_p95_deg"] > first["heading_err_p95_deg"] + MAX_P95_GROWTH_DEG:
            failures.append(f"segment {k}: heading error grew to {row['heading_err_p95_deg']:.1f} deg")
        if k and row["held_items"] > (1.0 + MAX_HELD_GROWTH) * rows[0]["held_items"] + 100:
            failures.append(f"segment {k}: the pipeline holds {row['held_items']} items "
                            f"(after the first segment: {rows[0]['held_items']})")
        del walk, steps
    p.finish()
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows, "failures": failures}, f, indent=1)
    for msg in failures:
        print("FAIL", msg, file=sys.stderr)
    print("ok" if not failures else f"{len(failures)} check(s) failed", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
