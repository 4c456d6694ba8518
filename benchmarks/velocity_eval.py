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
from benchmarks.datasets.base import default_data_root
from benchmarks.splits import REPORT, TUNING, trial_split
from core.pdr.pipeline import Pipeline
from core.pdr.stride_models import load_stride_model
from core.pdr.velocity import VelocityStride

RESULTS_MD = Path(__file__).with_name("VELOCITY_RESULTS.md")


def _distances(steps, t0: int, t1: int) -> tuple[float, float]:
    stride, vel = load_stride_model("default"), VelocityStride()
    sel = [s for s in steps if t0 < s.t_ns <= t1]
    return sum(stride.length_m(s.features) for s in sel), sum(vel.length_m(s.features) for s in sel)


def run(root: Path, progress=print) -> list[dict]:
    rows = []
    for tr in ipin2023.trials(root):
        rec = tr.open()
        lm = tr.landmarks
        steps = Pipeline().run(rec).steps
        truth = float(np.sum(np.hypot(np.diff(lm.east_m), np.diff(lm.north_m))))
        ds, dv = _distances(steps, int(lm.t_ns[0]), int(lm.t_ns[-1]))
        rows.append({"dataset": "ipin2023_track3", "walk": tr.name, "split": trial_split(tr), "truth_m": truth,
                     "stride_pct": 100 * (ds / truth - 1), "velocity_pct": 100 * (dv / truth - 1)})
        progress(f"{tr.name}: stride {rows[-1]['stride_pct']:+.1f} %, velocity {rows[-1]['velocity_pct']:+.1f} %")
    for tr in ipol.trials(root):
        steps = Pipeline().run(tr.open()).steps
        ds = dv = truth = 0.0
        for t0, t1, length in tr.legs:
            a, b = _distances(steps, t0, t1)
            ds, dv, truth = ds + a, dv + b, truth + length
        rows.append({"dataset": "ipol_healthy_gait_xsens", "walk": tr.name, "split": TUNING, "truth_m": truth,
                     "stride_pct": 100 * (ds / truth - 1), "velocity_pct": 100 * (dv / truth - 1)})
    return rows


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
    ap.add_argument("--data", type=Path, default=default_data_root())
    args = ap.parse_args(argv)
    if not (args.data / ipin2023.NAME).is_dir():
        print(f"no data under {args.data}", file=sys.stderr)
        return 2
    rows = run(args.data, progress=lambda m: print(m, file=sys.stderr))
    md = markdown(rows)
    RESULTS_MD.write_text(md, encoding="utf-8")
    from benchmarks.report import refresh_sections

    refresh_sections()
    print(md)
    return 0 if all(math.isfinite(x["velocity_pct"]) for x in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
