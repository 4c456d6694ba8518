"""Tuning harness: our pipeline only, on the tuning split, the numbers a parameter search looks at.

``python -m benchmarks.tune [--split tuning] [--datasets ipin2023,ms_indoor] [--jobs 2] [--set NAME=VALUE ...]
[--json] [--allow-report]``

From Python::

    from benchmarks.tune import evaluate
    from core.pdr.attitude import AttitudeEKF

    numbers = evaluate(lambda: {"attitude": AttitudeEKF(declination_rad=0.0)})  # tuning split, 2 processes
    numbers["ipin2023_tuning_landmark_median_m"]

:func:`evaluate` runs :func:`benchmarks.run.run` -- the same code as the
full benchmark, our pipeline built by :func:`benchmarks.run.make_pipeline` --
with no peers, on one split, and returns the headlines a tuner needs (IPIN
2023 landmark median, loop-closure median, segment-heading median, Microsoft
landmark median, plus their best-fit and distance companions) under their
headline names (``<dataset>_<split>_<metric>``, :mod:`benchmarks.headline`).

The report split is off limits for tuning (:mod:`benchmarks.splits`):
``split="report"`` raises unless ``allow_report=True`` is passed, which is
for one final check of a finished change, never for a search.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

from benchmarks import splits as S
from benchmarks.datasets.base import default_data_root
from benchmarks.headline import headline_split

#: the metrics :func:`evaluate` returns, per dataset (``*`` = the split)
TUNING_METRICS = (
    "ipin2023_*_landmark_median_m",
    "ipin2023_*_loop_closure_median_pct",
    "ipin2023_*_segment_heading_median_deg",
    "ms_indoor_*_landmark_median_m",
    "ipin2023_*_landmark_fit_median_m",
    "ipin2023_*_distance_median_abs_pct",
    "ms_indoor_*_landmark_fit_median_m",
    "ms_indoor_*_segment_heading_median_deg",
    "eth_walk_*_gps_median_m",
    "eth_walk_*_gps_fit_median_m",
)


class ReportSplitError(ValueError):
    """Asked to tune on the report split."""


def evaluate(pipeline_kwargs_factory=None, split: str = S.TUNING, datasets=("ipin2023", "ms_indoor"), jobs: int = 2,
             *, allow_report: bool = False, data_root=None, log=None, return_results: bool = False):
    """Our pipeline on one split of the chosen datasets; the tuning headlines as ``{name: value}``.

    Parameters
    ----------
    pipeline_kwargs_factory : callable or None
        Called with no arguments once per recording; returns the keyword
        overrides for ``core.pdr.pipeline.Pipeline`` (through
        :func:`benchmarks.run.make_pipeline`), e.g.
        ``lambda: {"attitude": AttitudeEKF(...)}`` -- a factory, so every
        recording gets fresh filter objects.  None: the defaults.  The site's
        magnetic declination is set on the attitude filter by
        ``make_pipeline`` whatever the factory returns.
    split : "tuning" or "report"
    datasets : dataset module names (``benchmarks/datasets/``) or folder names
    jobs : parallel processes (at most 2 on the shared machine)
    allow_report : bool
        Must be True for ``split="report"`` (a final check, not a search).
    data_root : the data folder (default ``../shared/data``)
    log : where the per-recording progress goes (default: nowhere)
    return_results : also return the per-recording rows: ``(numbers, rows)``

    Returns
    -------
    dict
        The :data:`TUNING_METRICS` that have data, plus ``"n_recordings"`` and
        ``"n_failed"`` (recordings that raised: their numbers are missing, so
        a tuner must not read a failure as an improvement).
    """
    from benchmarks.run import run

    S.check_split(split)
    if split == S.REPORT and not allow_report:
        raise ReportSplitError("tuning on the report split is forbidden (benchmarks/splits.py); pass "
                               "allow_report=True only for a final check of a finished change")
    root = Path(data_root) if data_root is not None else default_data_root()
    if not root.is_dir():
        raise FileNotFoundError(f"no data folder at {root}")
    devnull = open("/dev/null", "w") if log is None else None
    try:
        info = run(root, quick=False, only=list(datasets), jobs=jobs, peer_names=(), split=split,
                   pipeline_kwargs_factory=pipeline_kwargs_factory, keep_tracks=False,
                   log=log if log is not None else devnull)
    finally:
        if devnull is not None:
            devnull.close()
    h = headline_split(info["results"], split)
    out = {m.replace("*", split): h[m.replace("*", split)] for m in TUNING_METRICS if m.replace("*", split) in h}
    out["n_recordings"] = len(info["results"])
    out["n_failed"] = sum(1 for r in info["results"] if "error" in r)
    if return_results:
        return out, info["results"]
    return out


def parse_set(items) -> dict:
    """``NAME=VALUE`` pairs (VALUE a Python literal) -> Pipeline keyword overrides."""
    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.isidentifier():
            raise argparse.ArgumentTypeError(f"--set wants NAME=VALUE, got {item!r}")
        try:
            out[name] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[name] = value
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.tune", description=__doc__.split("\n")[0])
    ap.add_argument("--split", choices=S.SPLITS, default=S.TUNING)
    ap.add_argument("--allow-report", action="store_true",
                    help="allow --split report (a final check of a finished change, never a search)")
    ap.add_argument("--datasets", default="ipin2023,ms_indoor", help="comma-separated dataset modules")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a keyword override for core.pdr.pipeline.Pipeline (VALUE a Python literal); repeatable")
    ap.add_argument("--json", action="store_true", help="print the numbers as JSON")
    ap.add_argument("-v", "--verbose", action="store_true", help="per-recording progress on stderr")
    args = ap.parse_args(argv)
    try:
        overrides = parse_set(args.set)
    except argparse.ArgumentTypeError as e:
        ap.error(str(e))
    factory = (lambda: dict(overrides)) if overrides else None
    try:
        numbers = evaluate(factory, split=args.split, datasets=tuple(d for d in args.datasets.split(",") if d),
                           jobs=args.jobs, allow_report=args.allow_report, data_root=args.data,
                           log=sys.stderr if args.verbose else None)
    except (ReportSplitError, FileNotFoundError) as e:
        print(f"benchmarks.tune: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(numbers, indent=1))
    else:
        for k, v in numbers.items():
            print(f"{k:45s} {v:10.3f}" if isinstance(v, float) else f"{k:45s} {v:>10}")
    return 1 if numbers.get("n_failed") else 0


if __name__ == "__main__":
    sys.exit(main())
