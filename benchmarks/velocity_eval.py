"""Kubrak et al.'s velocity model (eq. 1) against the stride model, on the same steps (issue #10).

``python -m benchmarks.velocity_eval [--data DIR]``

One pipeline run per walk gives the steps; each step's length is then taken from the
shipped stride model (Weinberg, eq. 4 of Tian et al.) and from eq. 1 of Kubrak et al.
(:class:`core.pdr.velocity.VelocityStride`: the 2-s window's speed times the step's
interval), so that only the distance model differs.  Distance error = model distance over
the stretch between the first and the last surveyed landmark (IPIN 2023) or over the two
10 m legs (IPOL) against the truth, in per cent.  The velocity model was fitted on the
IPIN tuning routes and the IPOL legs (``tools/train_velocity.py``), the stride model on
IPOL: IPOL numbers are training numbers for both; the IPIN report routes were seen by neither.
Writes ``benchmarks/VELOCITY_RESULTS.md`` (folded into RESULTS.md).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from benchmarks.datasets import ipin2023, ipol
from benchmarks.options import (add_common, data_root, failed_row, failures_markdown, only_keys, result_path,
                                selected, writes_committed)
from benchmarks.splits import REPORT, TUNING, trial_split
from core.pdr.pipeline import Pipeline
from core.pdr.stride_models import load_stride_model
from core.pdr.velocity import VelocityStride

RESULTS_MD = Path(__file__).with_name("VELOCITY_RESULTS.md")


def _distances(steps, t0: int, t1: int) -> tuple[float, float]:
    stride, vel = load_stride_model("default"), VelocityStride()
    sel = [s for s in steps if t0 < s.t_ns <= t1]
    return sum(stride.length_m(s.features) for s in sel), sum(vel.length_m(s.features) for s in sel)


def _failed(ds: str, tr, split: str, e: Exception, progress) -> dict:
    """A recording that failed: counted as +inf in both columns and listed (benchmarks.options)."""
    row = {"dataset": ds, "walk": tr.name, "split": split, "truth_m": math.nan, "stride_pct": math.inf,
           "velocity_pct": math.inf, "failed": failed_row(tr.name, split, e)["failed"]}
    progress(f"{tr.name}: FAILED {row['failed']}")
    return row


def run(root: Path, progress=print, keys=None) -> list[dict]:
    """Every IPIN route and IPOL trial (``keys``: :func:`benchmarks.options.selected`)."""
    rows = []
    for tr in ipin2023.trials(root) if ipin2023.available(root) else ():
        if not selected(keys, tr.name, ipin2023.NAME):
            continue
        try:
            rows.append(_ipin_row(tr, progress))
        except Exception as e:
            rows.append(_failed(ipin2023.NAME, tr, trial_split(tr), e, progress))
    for tr in ipol.trials(root):
        if not selected(keys, tr.name, ipol.NAME):
            continue
        try:
            rows.append(_ipol_row(tr))
        except Exception as e:
            rows.append(_failed(ipol.NAME, tr, TUNING, e, progress))
    return rows


def _ipin_row(tr, progress) -> dict:
    rec = tr.open()
    lm = tr.landmarks
    steps = Pipeline().run(rec).steps
    truth = float(np.sum(np.hypot(np.diff(lm.east_m), np.diff(lm.north_m))))
    ds, dv = _distances(steps, int(lm.t_ns[0]), int(lm.t_ns[-1]))
    row = {"dataset": "ipin2023_track3", "walk": tr.name, "split": trial_split(tr), "truth_m": truth,
           "stride_pct": 100 * (ds / truth - 1), "velocity_pct": 100 * (dv / truth - 1)}
    progress(f"{tr.name}: stride {row['stride_pct']:+.1f} %, velocity {row['velocity_pct']:+.1f} %")
    return row


def _ipol_row(tr) -> dict:
    steps = Pipeline().run(tr.open()).steps
    ds = dv = truth = 0.0
    for t0, t1, length in tr.legs:
        a, b = _distances(steps, t0, t1)
        ds, dv, truth = ds + a, dv + b, truth + length
    return {"dataset": "ipol_healthy_gait_xsens", "walk": tr.name, "split": TUNING, "truth_m": truth,
            "stride_pct": 100 * (ds / truth - 1), "velocity_pct": 100 * (dv / truth - 1)}


def markdown(rows: list[dict]) -> str:
    out = ["## Distance: Kubrak et al.'s velocity model against the stride model (issue #10)", "",
           "Same steps, two distance models (`python -m benchmarks.velocity_eval`). Median absolute distance "
           "error (%) and median signed error; the velocity model was fitted on the IPIN tuning routes and the "
           "IPOL legs, the stride model on IPOL: only the IPIN report row is out of sample for both.", "",
           "| dataset | split | walks | stride: median abs % | velocity: median abs % | stride: median % | "
           "velocity: median % |", "|---|---|---|---|---|---|---|"]
    for ds in ("ipin2023_track3", "ipol_healthy_gait_xsens"):
        for split in (REPORT, TUNING):
            r = [x for x in rows if x["dataset"] == ds and x["split"] == split]
            if not r:
                continue
            s = np.array([x["stride_pct"] for x in r])
            v = np.array([x["velocity_pct"] for x in r])
            out.append(f"| {ds} | {split} | {len(r)} | {np.median(np.abs(s)):.1f} | {np.median(np.abs(v)):.1f} | "
                       f"{np.median(s):+.1f} | {np.median(v):+.1f} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_common(ap, what="recording names (T05r01, 1-1) or datasets")
    args = ap.parse_args(argv)
    root = data_root(args)
    if not (root / ipin2023.NAME).is_dir() and not (root / ipol.NAME).is_dir():
        print(f"no data under {root}", file=sys.stderr)
        return 2
    rows = run(root, progress=lambda m: print(m, file=sys.stderr), keys=only_keys(args))
    md = markdown(rows)
    bad = [r for r in rows if r.get("failed")]
    md += "\n".join(failures_markdown([{"name": r["walk"], "split": r["split"], "failed": r["failed"]} for r in bad]))
    out = result_path(args, RESULTS_MD, "velocity_eval")
    out.write_text(md, encoding="utf-8")
    if writes_committed(args):
        from benchmarks.report import refresh_sections

        refresh_sections()
    print(md)
    print(f"velocity_eval: wrote {out}", file=sys.stderr)
    return 0 if all(math.isfinite(x["velocity_pct"]) for x in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
