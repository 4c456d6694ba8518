"""CI regression guard: the quick benchmark subset against thresholds recorded in the repository.

``python -m benchmarks.guard [--data DIR] [--jobs N] [--thresholds FILE] [--update]``

Runs :func:`benchmarks.run.run` on the quick subset (our pipeline only, no
peers: they cannot regress our numbers) and the GPS fusion's quick subset
(:func:`benchmarks.gnss_eval.quick`: three simulated walks, the ETH walk's
3-minute outages) and the foot INS's (:func:`benchmarks.foot.quick`: six PyShoe trials, the x-io
loops), computes the headline numbers per
split (:mod:`benchmarks.headline`; the quick subset holds recordings of both
splits) and compares each with ``benchmarks/thresholds.json``::

    {"metrics": {"handheld_report_step_mae_pct": {"max": 2.1, "baseline": 1.5}, ...}}

``max``: fails when the value is above it; ``min``: fails when below.  The
thresholds are a regression guard, not the issue's targets: the baseline
of the last accepted run plus a margin (:func:`margin`).  A headline with
no value in this run (its dataset absent) is reported and skipped; a
recording that raises fails the guard, and so does a failed data check (:func:`ipin_loader_checks`:
the IPIN loader's own checks on every logfile).

Exit status: 0 passed (or no data folder: skipped), 1 a headline got worse
or a recording failed, 2 bad usage.  ``--update`` rewrites the thresholds
from this run's values (after an accepted improvement, or a deliberate
trade-off the commit message explains).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from benchmarks.datasets.base import default_data_root
from benchmarks.headline import headline
from benchmarks.run import run
from benchmarks.splits import SPLITS

THRESHOLDS = Path(__file__).with_name("thresholds.json")

#: headline metrics guarded when thresholds are (re)written, with ``*`` for the split; "min" for higher-is-better
GUARDED_METRICS = {
    "handheld_*_step_mae_pct": "max",
    "oxford_*_all_step_mae_pct": "max",
    "oxford_*_step_f1_median": "min",
    "brajdic_harle_*_step_mae_pct": "max",
    "ipin2023_*_landmark_median_m": "max",
    "ipin2023_*_landmark_fit_median_m": "max",
    "ipin2023_*_loop_closure_median_pct": "max",
    "ipin2023_*_segment_heading_median_deg": "max",
    "ms_indoor_*_landmark_median_m": "max",
    "ms_indoor_*_landmark_fit_median_m": "max",
    "eth_walk_*_gps_median_m": "max",
    "eth_walk_*_gps_fit_median_m": "max",
    "ipol_*_step_mae_pct": "max",
    "ipol_*_distance_mae_pct": "max",
    "trundlewheel_*_distance_mae_pct": "max",
    # GPS fusion (issue #9): benchmarks.gnss_eval.quick
    "gps_outage_sim_quick_5min_pct": "max",
    "gps_outage_eth_quick_3min_pct": "max",
    # foot-mounted INS (issue #11): benchmarks.foot.quick
    "foot_pyshoe_*_quick_rmse_median_m": "max",
    "foot_xio_*_loop_closure_median_pct": "max",
}
#: every split's name of every guarded metric (a dataset has names only for the splits it has recordings in)
GUARDED = {m.replace("*", sp): kind for m, kind in GUARDED_METRICS.items() for sp in SPLITS}


def margin(name: str, value: float) -> float:
    """Allowed slack around a baseline: 10 % of it, at least 0.5 (%), 0.3 m (foot INS: 0.03 m), 1 deg or
    0.01 (F1)."""
    if name.endswith("_f1_median"):
        return 0.01
    if name.startswith("foot_") and name.endswith("_m"):
        return max(0.1 * abs(value), 0.03)
    floor = 0.3 if name.endswith("_m") else 1.0 if name.endswith("_deg") else 0.5
    return max(0.1 * abs(value), floor)


def compare(values: dict, thresholds: dict) -> tuple[list[list[str]], bool]:
    """Rows ``[metric, value, threshold, status]`` and whether everything passed."""
    rows, ok = [], True
    for name, spec in thresholds.items():
        value = values.get(name)
        if "max" in spec:
            op, limit = "<=", spec["max"]
        else:
            op, limit = ">=", spec["min"]
        if value is None:
            rows.append([name, "-", f"{op} {limit:.3f}", "absent (skipped)"])
            continue
        good = value <= limit if op == "<=" else value >= limit
        ok &= good
        base = spec.get("baseline")
        trend = "" if base is None else f" (baseline {base:.3f})"
        rows.append([name, f"{value:.3f}", f"{op} {limit:.3f}", ("ok" if good else "WORSE") + trend])
    return rows, ok


def print_table(rows: list[list[str]], out=sys.stdout) -> None:
    header = ["headline", "value", "threshold", "status"]
    widths = [max(len(r[k]) for r in rows + [header]) for k in range(4)]
    for r in [header, ["-" * w for w in widths]] + rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)), file=out)


def thresholds_from(values: dict) -> dict:
    out = {}
    for name, kind in GUARDED.items():
        if name not in values:
            continue
        v = values[name]
        limit = v + margin(name, v) if kind == "max" else v - margin(name, v)
        out[name] = {kind: round(limit, 3), "baseline": round(v, 3)}
    return out


def ipin_loader_checks(root: Path) -> list[str]:
    """The IPIN 2023 loader's own checks on every logfile (moved here from tests/test_importers.py, which
    checks two of them, for CI's test time: issue #29): no repairs, the rotation vector agreeing with the
    accelerometer's tilt and the magnetometer's heading, the AHRS angles with its quaternion, the
    Nuremberg field's dip, the 50 Hz rate. A list of failures, one line each (empty: all passed or no data)."""
    from core.importers.getsensordata import read_getsensordata

    failures = []
    for f in sorted((root / "ipin2023_track3" / "logfiles").glob("*.txt.gz")):
        try:
            rec = read_getsensordata(f)
            chk = rec.metadata["rotvec_check"]
            problems = [what for what, bad in (
                (f"repairs {rec.repairs}", rec.repairs != []),
                (f"rotation vector check {chk}", not (chk["tilt_err_deg"] < 10 and chk["heading_diff_deg"] < 15)),
                ("AHRS angles vs quaternion", not rec.metadata["ahrs_angles_vs_quaternion_deg"]["max"] < 0.5),
                (f"dip {rec.metadata['mag_dip_deg']:.1f} deg", not rec.metadata["mag_dip_deg"] > 30),
                (f"acc rate {rec.streams['acc'].rate_hz:.1f} Hz", not 48 < rec.streams["acc"].rate_hz < 51),
            ) if bad]
        except Exception as e:  # noqa: BLE001 - a file that does not load is a failure to report
            problems = [f"{type(e).__name__}: {e}"]
        failures += [f"{f.name}: {p}" for p in problems]
    return failures


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.guard", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--thresholds", type=Path, default=THRESHOLDS)
    ap.add_argument("--update", action="store_true", help="rewrite the thresholds from this run")
    args = ap.parse_args(argv)
    root = args.data or default_data_root()
    if not root.is_dir():
        print(f"benchmark guard: no data folder at {root}: skipped")
        return 0
    t0 = time.perf_counter()
    info = run(root, quick=True, jobs=args.jobs, peer_names=())
    values = headline(info["results"])
    from concurrent.futures import ProcessPoolExecutor

    from benchmarks.foot import quick as foot_quick
    from benchmarks.gnss_eval import quick_real, quick_sim

    # the GPS fusion's two halves and the foot INS's subset are independent: run them side by side
    # (the same numbers as one after the other; CI's time)
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as ex:
        parts = [ex.submit(quick_sim), ex.submit(quick_real, root), ex.submit(foot_quick, root)]
        for f in parts:
            values.update(f.result())
    failed = [r for r in info["results"] if "error" in r]
    loader_failures = ipin_loader_checks(root)
    if args.update:
        doc = {"_about": "CI regression guard (benchmarks/guard.py): quick-subset headline numbers may not get "
                         "worse than these limits (baseline + margin). Not the issue's targets.",
               "metrics": thresholds_from(values)}
        args.thresholds.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"benchmark guard: thresholds written to {args.thresholds}")
    thresholds = json.loads(args.thresholds.read_text())["metrics"]
    rows, ok = compare(values, thresholds)
    print(f"benchmark guard: quick subset, {len(info['results'])} recordings in {time.perf_counter() - t0:.0f} s")
    print_table(rows)
    for r in failed:
        print(f"FAILED recording {r['dataset']}/{r['name']}: {r['error']}")
    for line in loader_failures:
        print(f"FAILED loader check {line}")
    if failed or loader_failures or not ok:
        print("benchmark guard: FAILED (a headline got worse than its threshold, or a recording failed)")
        return 1
    print("benchmark guard: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
