"""Headline numbers of a benchmark run and the issue targets they are checked against.

Used by :mod:`benchmarks.run` (the console summary), :mod:`benchmarks.report` and
:mod:`benchmarks.guard`; it imports neither.
"""

from __future__ import annotations



from benchmarks import metrics as M

# ---------------------------------------------------------------------------
# headline numbers


def _select(results, dataset, placement=None):
    return [r for r in results if r["dataset"] == dataset and "error" not in r
            and (placement is None or r["placement"] == placement)]


def headline(results: list[dict]) -> dict:
    """The numbers the targets and the CI guard look at (nan-free: a number is absent if it has no data)."""
    h = {}

    def put(name, value):
        if value is not None and value == value:
            h[name] = float(value)

    ox = _select(results, "oxford_step_counter")
    ox_hand = [r for r in ox if r["placement"] == "hand"]
    bh = _select(results, "brajdic_harle_handheld")
    put("oxford_hand_step_mae_pct", M.mean_abs([r.get("step_err_pct") for r in ox_hand]))
    put("oxford_all_step_mae_pct", M.mean_abs([r.get("step_err_pct") for r in ox]))
    put("oxford_step_f1_median", M.nanmedian([r.get("step_f1") for r in ox]))
    put("brajdic_harle_step_mae_pct", M.mean_abs([r.get("step_err_pct") for r in bh]))
    put("handheld_step_mae_pct", M.mean_abs([r.get("step_err_pct") for r in ox_hand + bh]))
    for ds, short in (("ipin2023_track3", "ipin"), ("ms_indoor_location_2020", "ms")):
        rs = [r for r in _select(results, ds) if "sources" in r]
        if not rs:
            continue
        ours = [r["sources"]["ours"] for r in rs]
        put(f"{short}_landmark_median_m", M.nanmedian([s["lm_mean_m"] for s in ours]))
        put(f"{short}_landmark_fit_median_m", M.nanmedian([s["lm_fit_mean_m"] for s in ours]))
        put(f"{short}_landmark_pooled_median_m", M.nanmedian([e for s in ours for e in s.get("lm_errors_m", [])]))
        put(f"{short}_loop_closure_median_pct", M.nanmedian([s["loop_pct"] for s in ours]))
        put(f"{short}_segment_heading_median_deg", M.nanmedian([s["seg_heading_deg"] for s in ours]))
        put(f"{short}_distance_median_abs_pct", M.nanmedian([abs(r["lm_distance_err_pct"]) for r in rs]))
        for peer in ("rotvec", "imufusion", "madgwick", "ekf"):
            vals = [r["sources"][peer]["lm_mean_m"] for r in rs if peer in r["sources"]]
            if len(vals) == len(rs):
                put(f"{short}_{peer}_landmark_median_m", M.nanmedian(vals))
    ip = _select(results, "ipol_healthy_gait_xsens")
    put("ipol_step_mae_pct", M.mean_abs([r.get("step_err_pct") for r in ip]))
    put("ipol_distance_mae_pct", M.mean_abs([r.get("distance_err_pct") for r in ip]))
    tw = _select(results, "trundlewheel_distance")
    put("trundlewheel_distance_mae_pct", M.mean_abs([r.get("distance_err_pct") for r in tw]))
    return h


#: the issue's targets: (headline name, comparison, value or other headline name, text)
TARGETS = (
    ("handheld_step_mae_pct", "<=", 2.0, "step count mean absolute error, hand-held traces (Oxford InHand + Brajdic-Harle)"),
    ("oxford_all_step_mae_pct", "<=", 4.0, "step count mean absolute error, Oxford, all placements"),
    ("ipin_loop_closure_median_pct", "<=", 2.0, "IPIN 2023 closed loops: median start-to-end error, % of path length"),
    ("ipin_landmark_median_m", "<=", 3.0, "IPIN 2023: median landmark error (m), absolute heading"),
    ("ipin_landmark_median_m", "<", "ipin_rotvec_landmark_median_m",
     "IPIN 2023: our heading beats the phone's rotation vector on the median landmark error"),
)


def evaluate_targets(h: dict) -> list[dict]:
    out = []
    for name, op, ref, text in TARGETS:
        value = h.get(name)
        limit = h.get(ref) if isinstance(ref, str) else ref
        if value is None or limit is None:
            met = None
        else:
            met = value <= limit if op == "<=" else value < limit
        out.append({"metric": name, "op": op, "ref": ref, "limit": limit, "value": value, "met": met, "text": text})
    return out


# ---------------------------------------------------------------------------
# command line
