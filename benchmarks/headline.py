"""Headline numbers of a benchmark run, per split, and the targets they are checked against.

Used by :mod:`benchmarks.run` (the console summary), :mod:`benchmarks.report`,
:mod:`benchmarks.guard` and :mod:`benchmarks.tune`; it imports none of them.

Names: ``<dataset>_<split>_<metric>``, e.g. ``ipin2023_report_landmark_median_m``
or ``ms_indoor_tuning_rotvec_landmark_median_m``, with the splits of
:mod:`benchmarks.splits` (``tuning``, ``report``).  Every number is computed
from the recordings of its split only; a number without data is absent.

Dataset prefixes: ``oxford``, ``brajdic_harle``, ``handheld`` (Oxford
hand-held + Brajdic-Harle), ``ipin2023``, ``ms_indoor``, ``eth_walk``,
``ipol``, ``trundlewheel``.
"""

from __future__ import annotations

from benchmarks import metrics as M
from benchmarks.splits import REPORT, SPLITS

#: the heading peers whose numbers get headlines
PEERS = ("rotvec", "imufusion", "madgwick", "ekf")
#: landmark datasets: folder name -> headline prefix
LANDMARK_DATASETS = (("ipin2023_track3", "ipin2023"), ("ms_indoor_location_2020", "ms_indoor"))
#: datasets scored against a reference track (GPS): folder name -> headline prefix
REFERENCE_DATASETS = (("sensorlogger_gps_walk_ethz", "eth_walk"),)


def _select(results, dataset, split, placement=None):
    """The recordings of a dataset and split, those whose run failed included (they are counted, never dropped:
    :func:`_err`, :func:`benchmarks.metrics.median_counting_failures`)."""
    return [r for r in results if r["dataset"] == dataset and r.get("split") == split
            and (placement is None or r.get("placement") == placement)]


def _err(r: dict, key: str = "step_err_pct"):
    """A recording's signed step-count (or distance) error (%): a failed run gave no steps, -100 %."""
    return M.FAILED_STEP_ERR_PCT if "error" in r else r.get(key)


def headline_split(results: list[dict], split: str) -> dict:
    """The headline numbers of one split (names carry the split)."""
    h = {}

    def put(name, value):
        if value is not None and value == value:
            h[name] = float(value)

    ox = _select(results, "oxford_step_counter", split)
    ox_hand = [r for r in ox if r["placement"] == "hand"]
    bh = _select(results, "brajdic_harle_handheld", split)
    put(f"oxford_{split}_hand_step_mae_pct", M.mean_abs([_err(r) for r in ox_hand]))
    put(f"oxford_{split}_all_step_mae_pct", M.mean_abs([_err(r) for r in ox]))
    f1 = [0.0 if "error" in r else r.get("step_f1") for r in ox]  # a failed run found no step: F1 0
    put(f"oxford_{split}_step_f1_median", M.median_counting_failures([v for v in f1 if v is not None],
                                                                     nan_is_failure=False))
    put(f"brajdic_harle_{split}_step_mae_pct", M.mean_abs([_err(r) for r in bh]))
    put(f"handheld_{split}_step_mae_pct", M.mean_abs([_err(r) for r in ox_hand + bh]))
    failure = M.median_counting_failures
    for ds, short in LANDMARK_DATASETS:
        sel = _select(results, ds, split)
        rs = [r for r in sel if "error" not in r and "sources" in r]
        n_failed = sum(1 for r in sel if "error" in r)  # counted as an infinite error, never dropped
        if not rs and not n_failed:
            continue
        p = f"{short}_{split}"
        ours = [r["sources"]["ours"] for r in rs] + [None] * n_failed
        put(f"{p}_landmark_median_m", failure([s and s["lm_mean_m"] for s in ours]))
        put(f"{p}_landmark_fit_median_m", failure([s and s["lm_fit_mean_m"] for s in ours]))
        put(f"{p}_landmark_pooled_median_m",
            failure([e for s in ours for e in (s.get("lm_errors_m", []) if s else [None])]))
        put(f"{p}_loop_closure_median_pct", failure([s and s["loop_pct"] for s in ours], nan_is_failure=False))
        put(f"{p}_segment_heading_median_deg", failure([s and s["seg_heading_deg"] for s in ours],
                                                       nan_is_failure=False))
        put(f"{p}_distance_median_abs_pct", failure([abs(r["lm_distance_err_pct"]) for r in rs] + [None] * n_failed,
                                                    nan_is_failure=False))
        for peer in PEERS:
            srcs = [r["sources"][peer] for r in rs if peer in r["sources"]]
            if len(srcs) == len(rs):  # a peer's median only over the same recordings as ours (a failed run of
                srcs += [None] * n_failed  # ours leaves the peers without steps: failed for them too)
                put(f"{p}_{peer}_landmark_median_m", failure([s and s["lm_mean_m"] for s in srcs]))
                put(f"{p}_{peer}_loop_closure_median_pct", failure([s and s["loop_pct"] for s in srcs],
                                                                   nan_is_failure=False))
    for ds, short in REFERENCE_DATASETS:
        sel = _select(results, ds, split)
        rs = [r for r in sel if "error" not in r and "ref_sources" in r]
        n_failed = sum(1 for r in sel if "error" in r)
        if not rs and not n_failed:
            continue
        p = f"{short}_{split}"
        ours = [r["ref_sources"]["ours"] for r in rs] + [None] * n_failed
        put(f"{p}_gps_median_m", failure([s and s["median_m"] for s in ours]))
        put(f"{p}_gps_fit_median_m", failure([s and s["fit_median_m"] for s in ours]))
        for peer in PEERS:
            srcs = [r["ref_sources"][peer] for r in rs if peer in r["ref_sources"]]
            if len(srcs) == len(rs):
                srcs += [None] * n_failed
                put(f"{p}_{peer}_gps_median_m", failure([s and s["median_m"] for s in srcs]))
                put(f"{p}_{peer}_gps_fit_median_m", failure([s and s["fit_median_m"] for s in srcs]))
    ip = _select(results, "ipol_healthy_gait_xsens", split)
    put(f"ipol_{split}_step_mae_pct", M.mean_abs([_err(r) for r in ip]))
    put(f"ipol_{split}_distance_mae_pct", M.mean_abs([_err(r, "distance_err_pct") for r in ip]))
    tw = _select(results, "trundlewheel_distance", split)
    put(f"trundlewheel_{split}_distance_mae_pct", M.mean_abs([_err(r, "distance_err_pct") for r in tw]))
    return h


def headline(results: list[dict], splits=SPLITS) -> dict:
    """The numbers the targets and the CI guard look at, for every split (nan-free: absent without data)."""
    h = {}
    for split in splits:
        h.update(headline_split(results, split))
    return h


def _peers_of(prefix: str, metric: str) -> tuple[str, ...]:
    return tuple(f"{prefix}_{peer}_{metric}" for peer in PEERS)


#: the targets, all on the report split: (headline name, comparison, value / other headline / tuple of headlines
#: whose minimum is the limit, text)
TARGETS = (
    ("handheld_report_step_mae_pct", "<=", 2.0,
     "step count mean absolute error, hand-held traces (Oxford InHand + Brajdic-Harle)"),
    ("oxford_report_all_step_mae_pct", "<=", 4.0, "step count mean absolute error, Oxford, all placements"),
    ("ipin2023_report_loop_closure_median_pct", "<=", 3.0,
     "IPIN 2023 closed loops, median start-to-end error, % of path length"),
    ("ipin2023_report_landmark_median_m", "<=", 2.0, "IPIN 2023 median landmark error (m), absolute heading"),
    ("ms_indoor_report_landmark_median_m", "<", _peers_of("ms_indoor_report", "landmark_median_m"),
     "Microsoft indoor median landmark error better than every peer's"),
    ("eth_walk_report_gps_median_m", "<=", 15.0,
     "ETH walk, median distance from its own GPS track (m), absolute heading, no GPS used"),
    ("ipin2023_report_landmark_median_m", "<", "ipin2023_report_rotvec_landmark_median_m",
     "IPIN 2023: our heading beats the phone's rotation vector on the median landmark error"),
)


def _limit(h: dict, ref):
    """The limit of a target and the headline it came from (None for a number)."""
    if isinstance(ref, tuple):
        present = [(h[name], name) for name in ref if name in h]
        if not present:
            return None, None
        value, name = min(present)
        return value, name
    if isinstance(ref, str):
        return h.get(ref), ref
    return ref, None


def evaluate_targets(h: dict) -> list[dict]:
    out = []
    for name, op, ref, text in TARGETS:
        value = h.get(name)
        limit, ref_name = _limit(h, ref)
        if value is None or limit is None:
            met = None
        else:
            met = value <= limit if op == "<=" else value < limit
        out.append({"metric": name, "op": op, "ref": ref_name, "limit": limit, "value": value, "met": met,
                    "text": text, "split": REPORT})
    return out
