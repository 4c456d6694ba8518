"""GPS-assisted PDR (issue #9, Chen et al. 2010): end-of-outage errors on real and simulated walks.

``python -m benchmarks.gnss_eval [--data DIR] [--sim-walks N] [--split report|tuning] [--out FILE]``

For every walk the hand-held pipeline runs once (its steps do not depend on
GPS); then :meth:`core.gnss.fusion.GpsFusion.run` -- the same kernel the
pipeline streams through -- fuses those steps with the walk's fixes, once per
variant and hidden window:

``pdr``          no calibration: dead reckoning from the position at the outage's start
``stride``       the stride scale learnt from GPS, no heading model
``heading``      the heading error model (eq. 12), no stride training
``both``         both, position reset to each fix (the paper's architecture)
``ekf``          both, and the EKF of eq. 13 with GPS position/course updates

Every variant but ``ekf`` puts the position on each good fix, so that all
start the outage from where GPS last was; the ``ekf`` starts from its fused
position.  The error at the end of an outage is measured against the first
screened fix after it (real walks; GPS is itself +-5 m) or against the truth
(simulator: the fused position at the last step inside the window against the
true position then).

Hidden windows: lengths of 1, 3 and 5 minutes, starting every 60 s from 120 s
after walking starts (the calibration period), as long as they end 15 s
before the walk does.  The simulator: one 5-minute outage from minute 6 of a
15-minute street walk, given its site (declination, field) as a live app
knows it from its first fix.

Before running, the site's magnetic declination (WMM, from the first good fix
and the recording's date) is given to the attitude filter where the recording
has a date: what a live app knows from its first fix.  Walks without a
magnetometer run with a heading relative to their start; the heading model's
offset ``A`` then absorbs the unknown initial heading.

Splits (:mod:`benchmarks.splits`): the ETH walk and ``gps_walks_phone`` are
report; simulator seeds 0-19 tuning, 1000-1019 report.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import metrics as M
from benchmarks.options import (add_common, data_root, failed_row, failures_line, failures_markdown, only_keys,
                                out_dir, read_json, result_path, selected, write_json, writes_committed)
from benchmarks.splits import REPORT, SIM_GPS_SEEDS, TUNING
from core.conventions import GPS
from core.gnss.ekf import sigma_max_m
from core.gnss.fusion import GpsFusion

VARIANTS = {
    "pdr": {"filter": "reset", "learn_stride": False, "learn_heading": False},
    "stride": {"filter": "reset", "learn_stride": True, "learn_heading": False},
    "heading": {"filter": "reset", "learn_stride": False, "learn_heading": True},
    "both": {"filter": "reset", "learn_stride": True, "learn_heading": True},
    "ekf": {"filter": "ekf", "learn_stride": True, "learn_heading": True},
}
LENGTHS_S = (60, 180, 300)
#: a walk counts in the real-walk headlines only if its steps cover this share of the GPS (Doppler) distance:
#: where step detection fails (a phone swung in the hand, issue #17) there is no dead reckoning to calibrate
STEPS_DETECTED_MIN = 0.5
CALIBRATION_S = 120.0
RESULTS_JSON = Path(__file__).with_name("gnss_results.json")
RESULTS_MD = Path(__file__).with_name("GNSS_RESULTS.md")

#: the issue's targets: (headline, comparison, value, what)
TARGETS = (
    ("gps_outage_sim_report_5min_pct", "<=", 1.0, "simulator, 5-minute outage, median over 20 walks, % of distance"),
    ("gps_outage_eth_3min_pct", "<=", 3.0, "ETH walk, 3-minute outages, median, % of distance"),
    ("gps_outage_phone_3min_pct", "<=", 3.0, "phone walks with a magnetometer, 3-minute outages, median, %"),
    ("gps_heading_residual_abs_mean_deg_median", "<", 1.0, "heading residual after compensation, mean |bias| (deg)"),
    ("gps_sim_report_rejoin_jump_over_sigma_max", "<=", 3.0, "simulator: jump when GPS returns / fused sigma (max)"),
    ("gps_real_rejoin_jump_over_sigma_max", "<=", 3.0,
     "real walks: jump when GPS returns / fused sigma just before it (max; a rejoin through a relock counts apart)"),
)

#: the real walks: (dataset folder, walk folder glob)
REAL = (("sensorlogger_gps_walk_ethz", "20*"), ("gps_walks_phone", "*"))


def _site_declination(rec, pipe) -> float | None:
    """Give the attitude filter the WMM declination and field at the first good fix (None without a date).

    What ``Pipeline(gnss=GpsFusion())`` does itself when its first fix anchors the walk
    (``site_from_gps``); done here before the run so that one pipeline run serves every variant.
    """
    g = rec.streams[GPS]
    cols = list(g.columns)
    hacc = g.values[:, cols.index("hacc_m")]
    ok = np.isfinite(g.values[:, 0]) & ~(hacc > 20.0)
    off = rec.metadata.get("unix_offset_ns")
    if not ok.any() or not isinstance(off, int):
        return None
    i = int(np.argmax(ok))
    pipe.set_site(g.values[i, 0], g.values[i, 1], g.values[i, cols.index("alt_m")], off + int(g.t_ns[i]))
    return pipe.attitude.declination_rad


def walking_start_s(steps, t0_ns: int) -> float:
    """Time (s from the first event) of the first step of the first 20-step stretch."""
    t = np.array([s.t_ns for s in steps], dtype=np.int64)
    for i in range(len(t) - 20):
        if t[i + 20] - t[i] < 20e9:
            return (t[i] - t0_ns) * 1e-9
    return (t[0] - t0_ns) * 1e-9 if len(t) else 0.0


def windows(start_s: float, end_s: float, lengths=LENGTHS_S, every_s: float = 60.0):
    out = []
    for length in lengths:
        a = start_s + CALIBRATION_S
        while a + length <= end_s - 15.0:
            out.append((a, float(length)))
            a += every_s
    return out


def fuse_outage(steps, gps, t0_ns: int, start_s: float, length_s: float, variant: str):
    hid = [(t0_ns + int(start_s * 1e9), t0_ns + int((start_s + length_s) * 1e9))]
    fu = GpsFusion(hidden_ns=hid, **VARIANTS[variant])
    return fu, fu.run(steps, gps, t0_ns)


PLOTS = Path(__file__).with_name("plots")


def plot_outage(path: Path, title: str, fr, gps, hidden, truth_en=None) -> None:
    """The fused track, the fixes (hidden ones red) and the outage stretch, in the walk's local frame."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from core.geodesy import geodetic_to_enu

    tr = fr.track()
    e, n = geodetic_to_enu(gps.values[:, 0], gps.values[:, 1], fr.origin_lat_lon)
    hid = (gps.t_ns >= hidden[0]) & (gps.t_ns < hidden[1])
    ins = (tr.t_ns >= hidden[0]) & (tr.t_ns < hidden[1])
    fig, ax = plt.subplots(figsize=(7, 7), dpi=100)
    if truth_en is not None:
        ax.plot(truth_en[:, 0], truth_en[:, 1], "-", color="0.6", lw=3, alpha=0.5, label="truth")
    ax.plot(e[~hid], n[~hid], ".", ms=2, color="tab:orange", label="GPS fixes")
    ax.plot(e[hid], n[hid], ".", ms=2, color="tab:red", alpha=0.5, label="GPS hidden (outage)")
    ax.plot(tr.east_m, tr.north_m, "-", lw=1, color="tab:blue", label="fused track")
    ax.plot(tr.east_m[ins], tr.north_m[ins], "-", lw=2, color="tab:purple", label="dead reckoning in the outage")
    if ins.any():
        k = int(np.flatnonzero(ins)[-1])
        ax.add_patch(matplotlib.patches.Circle((tr.east_m[k], tr.north_m[k]), 3 * tr.sigma_m[k], fill=False,
                                               color="tab:purple", ls="--", label="3 sigma at the end"))
    o = fr.outages[0] if fr.outages else None
    sub = f"\nend error {o.end_error_m:.1f} m = {o.end_error_pct:.1f} % of {o.walked_m:.0f} m" if o else ""
    ax.set_title(title + sub, fontsize=10)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def real_folders(root: Path, only: tuple | None = None):
    """``(dataset, folder)`` of every real walk (:data:`REAL`, or ``only``) under ``root``, in order."""
    for ds, pattern in (only or REAL):
        for folder in sorted(p for p in (root / ds).glob(pattern) if p.is_dir()):
            yield ds, folder


def open_walk(ds: str, folder: Path):
    """One real walk, its pipeline run once (after :func:`_site_declination`) and its facts.

    Returns ``(rec, res, walk)`` with ``walk`` the dict :func:`real_walks` reports (``outages`` empty),
    or None for a recording without GPS.
    """
    from core.importers import load_recording
    from core.pdr.pipeline import Pipeline

    rec = load_recording(str(folder))
    if not rec.has(GPS):
        return None
    pipe = Pipeline()
    decl = _site_declination(rec, pipe)
    res = pipe.run(rec)
    t0 = rec.t0_ns
    g = rec.streams[GPS]
    sp = g.values[:, list(g.columns).index("speed_m_s")]
    ok = np.isfinite(sp)
    gps_d = float(np.sum(0.5 * (sp[ok][1:] + sp[ok][:-1]) * np.diff(g.t_ns[ok] * 1e-9))) if ok.sum() > 1 else 0.0
    step_d = float(sum(s.length_m for s in res.steps))
    walk = {"dataset": ds, "walk": folder.name, "split": REPORT, "magnetometer": rec.has("mag"),
            "gps_distance_m": gps_d, "step_distance_m": step_d,
            "steps_detected": gps_d <= 0 or step_d >= STEPS_DETECTED_MIN * gps_d,
            "declination_deg": math.degrees(decl) if decl is not None else None,
            "walking_from_s": walking_start_s(res.steps, t0), "duration_s": (rec.t1_ns - t0) * 1e-9, "outages": []}
    return rec, res, walk


def real_walks(root: Path, only: tuple | None = None, plots: bool = False, keys=None, failed=None) -> list[dict]:
    """The outage runs on every real walk (``keys``: :func:`benchmarks.options.selected`); a walk that
    fails is appended to ``failed`` (a list) as a named row, or raises when ``failed`` is None."""
    out = []
    for ds, folder in real_folders(root, only):
        if not selected(keys, ds, folder.name):
            continue
        try:
            walk = _real_walk(ds, folder, plots)
        except Exception as e:
            if failed is None:
                raise
            failed.append(failed_row(f"{ds}/{folder.name}", REPORT, e))
            print(f"  {ds}/{folder.name}: FAILED {failed[-1]['failed']}", file=sys.stderr)
            continue
        if walk is not None:
            out.append(walk)
    return out


def _real_walk(ds: str, folder: Path, plots: bool) -> dict | None:
    opened = open_walk(ds, folder)
    if opened is None:
        return None
    rec, res, walk = opened
    t0 = rec.t0_ns
    start, end = walk["walking_from_s"], walk["duration_s"]
    for a, length in windows(start, end):
        for v in VARIANTS:
            fu, fr = fuse_outage(res.steps, rec.streams[GPS], t0, a, length, v)
            if not fr.outages:
                continue
            o = fr.outages[0].as_dict()
            o.update(variant=v)
            walk["outages"].append(o)
    if plots and ds == REAL[0][0] and windows(start, end, lengths=(180,)):
        a, length = windows(start, end, lengths=(180,))[0]
        _, fr = fuse_outage(res.steps, rec.streams[GPS], t0, a, length, "ekf")
        PLOTS.mkdir(parents=True, exist_ok=True)
        plot_outage(PLOTS / "gnss_eth_outage.png", f"ETH walk (report split): 3-minute outage from {a:.0f} s",
                    fr, rec.streams[GPS], (t0 + int(a * 1e9), t0 + int((a + length) * 1e9)))
    fu, fr = fuse_outage(res.steps, rec.streams[GPS], t0, 1e9, 1.0, "ekf")  # no outage: what was learnt
    walk["learnt"] = fr.counters["training"]
    walk["position_nis_mean"] = fr.counters["position_nis_mean"]
    walk["heading_residuals"] = heading_residuals(fu)
    print(f"  {ds}/{folder.name}: {len(walk['outages'])} outage runs", file=sys.stderr)
    return walk


def heading_residuals(fu, skip: int = 5) -> dict:
    """The heading model's residuals, like the paper's Table IV but out of sample.

    Each training window's course deviation against the model's prediction made
    *before* that window (the first ``skip`` windows, while the model starts, are
    left out); the raw deviation (no compensation) beside it.  The final model's
    coefficients in the paper's convention.
    """
    hm = fu.heading_model
    w = [x for x in fu.trainer.windows if x.deviation_rad == x.deviation_rad][skip:]
    w = [x for x in w if x.heading_residual_rad == x.heading_residual_rad]
    if not w:
        return {}
    dev = np.degrees([x.deviation_rad for x in w])
    res = np.degrees([x.heading_residual_rad for x in w])
    return {"n": len(w), "raw_mean_deg": float(np.mean(dev)), "raw_sd_deg": float(np.std(dev)),
            "residual_mean_deg": float(np.mean(res)), "residual_sd_deg": float(np.std(res)),
            "coefficients_paper_deg": hm.paper_coefficients_deg(), "harmonics_trusted": hm.harmonics_trusted}


def sim_walks(seeds, minutes: float = 15.0, start_s: float = 360.0, length_s: float = 300.0,
              plot_seed: int | None = None) -> list[dict]:
    from core.geodesy import enu_to_geodetic, geodetic_to_enu
    from core.pdr.pipeline import Pipeline
    from desktop.simulator import outdoor_site, outdoor_walk

    out = []
    for seed in seeds:
        walk = outdoor_walk(seed, minutes=minutes)
        rec, truth = walk.recording, walk.truth
        pipe = Pipeline()
        # the site, as for the real walks (_site_declination) and gnss_faults' simulated ones: outdoors the attitude
        # filter drops the field's heading-offset state (issue #26: without this the outdoor walk ran the indoor filter)
        pipe.set_site(*outdoor_site(rec))
        res = pipe.run(rec)
        t0 = rec.t0_ns
        row = {"seed": seed, "outages": []}
        for v in VARIANTS:
            _fu, fr = fuse_outage(res.steps, rec.streams[GPS], t0, start_s, length_s, v)
            t_end = t0 + int((start_s + length_s) * 1e9)
            inside = [s for s in fr.steps if t0 + start_s * 1e9 <= s.t_ns < t_end]
            if not inside or fr.origin_lat_lon is None:
                continue
            last = inside[-1]
            e, n = geodetic_to_enu(last.lat_deg, last.lon_deg, truth.origin_lat_lon)
            p = truth.phone_position_at(last.t_ns)
            err = math.hypot(e - p[0], n - p[1])
            walked = sum(s.length_m for s in inside)
            sig = sigma_max_m(last.cov_en_m2)
            if v == "ekf" and seed == plot_seed:
                PLOTS.mkdir(parents=True, exist_ok=True)
                tt = np.linspace(rec.t0_ns, rec.t1_ns, 4000).astype(np.int64)
                pe, pn = truth.phone_position_at(tt)[:, 0], truth.phone_position_at(tt)[:, 1]
                la, lo = enu_to_geodetic(pe, pn, truth.origin_lat_lon)
                te, tn = geodetic_to_enu(la, lo, fr.origin_lat_lon)
                plot_outage(PLOTS / "gnss_sim_outage.png", f"Simulated walk, seed {seed}: 5-minute outage",
                            fr, rec.streams[GPS], (t0 + int(start_s * 1e9), t_end), np.column_stack([te, tn]))
            o = fr.outages[0].as_dict() if fr.outages else {}
            row["outages"].append({"variant": v, "truth_error_m": err, "walked_m": walked,
                                   "truth_error_pct": 100.0 * err / walked, "sigma_m": sig,
                                   "jump_m": o.get("jump_m"), "sigma_at_fix_m": o.get("sigma_m"),
                                   "nees_ratio": err / sig if sig > 0 else None})
        out.append(row)
        print(f"  sim seed {seed}: " + ", ".join(f"{o['variant']} {o['truth_error_pct']:.2f} %"
                                                  for o in row["outages"]), file=sys.stderr)
    return out


#: None = does not apply; a non-finite value is a failed run, counted as +inf (never dropped)
_median = M.median_where_applicable


def headlines(real: list[dict], sim: dict) -> dict:
    h = {}
    for length, tag in ((60, "1min"), (180, "3min"), (300, "5min")):
        for v in VARIANTS:
            eth = [o["end_error_pct"] for w in real if w["dataset"] == "sensorlogger_gps_walk_ethz"
                   for o in w["outages"] if o["variant"] == v and abs(o["length_s"] - length) < 1]
            ph = [o["end_error_pct"] for w in real if w["dataset"] == "gps_walks_phone" and w["magnetometer"]
                  and w.get("steps_detected", True)
                  for o in w["outages"] if o["variant"] == v and abs(o["length_s"] - length) < 1]
            nomag = [o["end_error_pct"] for w in real if w["dataset"] == "gps_walks_phone" and not w["magnetometer"]
                     and w.get("steps_detected", True)
                     for o in w["outages"] if o["variant"] == v and abs(o["length_s"] - length) < 1]
            suffix = "" if v == "ekf" else f"_{v}"
            for name, vals in ((f"gps_outage_eth_{tag}{suffix}_pct", eth), (f"gps_outage_phone_{tag}{suffix}_pct", ph),
                               (f"gps_outage_phone_nomag_{tag}{suffix}_pct", nomag)):
                m = _median(vals)
                if m is not None:
                    h[name] = m
    for split, rows in sim.items():
        for v in VARIANTS:
            suffix = "" if v == "ekf" else f"_{v}"
            m = _median([o["truth_error_pct"] for r in rows for o in r["outages"] if o["variant"] == v])
            if m is not None:
                h[f"gps_outage_sim_{split}_5min{suffix}_pct"] = m
        jumps = [o["jump_m"] / o["sigma_at_fix_m"] for r in rows for o in r["outages"]
                 if o["variant"] == "ekf" and o.get("jump_m") is not None and o.get("sigma_at_fix_m")]
        if jumps:
            h[f"gps_sim_{split}_rejoin_jump_over_sigma_max"] = float(np.max(jumps))
        nees = [o["nees_ratio"] for r in rows for o in r["outages"] if o["variant"] == "ekf" and o.get("nees_ratio")]
        if nees:
            h[f"gps_sim_{split}_error_over_sigma_median"] = float(np.median(nees))
    # the jump over the sigma the filter reported just before it (the first accepted fix can come minutes after
    # the window's end); a rejoin through a relock is no consistent update (the filter had refused the stream: its
    # jump says how far off the track was): counted apart, with its own max
    def sigma(o):
        s = o.get("sigma_at_rejoin_m")
        return s if s is not None and s == s else o.get("sigma_m")

    for name, relocked in (("rejoin", False), ("relock", True)):
        jr = [o["jump_m"] / sigma(o) for w in real if w.get("steps_detected", True) for o in w["outages"]
              if o["variant"] == "ekf" and o.get("jump_m") == o.get("jump_m") and sigma(o)
              and bool(o.get("relocked")) == relocked]
        if jr:
            h[f"gps_real_{name}_jump_over_sigma_max"] = float(np.max(jr))
        if relocked:
            h["gps_real_relock_rejoins_n"] = len(jr)
    res = [abs(w["heading_residuals"]["residual_mean_deg"]) for w in real if w.get("heading_residuals")
           and w.get("steps_detected", True)]
    if res:
        h["gps_heading_residual_abs_mean_deg_median"] = float(np.median(res))
    return h


def markdown(data: dict) -> str:
    h = data["headlines"]
    f = (lambda v: "-" if v is None else f"{v:.2f}")
    lines = ["## GPS-assisted PDR: end-of-outage errors (issue #9, Chen et al. 2010)", "",
             "Written by `python -m benchmarks.gnss_eval` (see its docstring for the method); "
             f"{data.get('seconds', 0):.0f} s. Splits: the ETH walk and `gps_walks_phone` are **report** "
             "(nothing tuned on them); simulator seeds 0-19 **tuning** (the fusion's defaults were chosen looking at "
             "seeds 0-5), 1000-1019 **report**. Variants: `pdr` no calibration, `stride` GPS-learnt stride scale, "
             "`heading` the eq.-12 heading model, `both`, `ekf` both plus the eq.-13 EKF with GPS updates. "
             "Each cell: the median end-of-outage error in % of the distance walked in the outage.", "",
             "![ETH walk, a 3-minute outage](plots/gnss_eth_outage.png) "
             "![simulated walk, a 5-minute outage](plots/gnss_sim_outage.png)", "",
             "### Targets", "", "| target | headline | measured | target | status |", "|---|---|---|---|---|"]
    for name, op, val, what in TARGETS:
        m = h.get(name)
        ok = None if m is None else (m <= val if op == "<=" else m < val)
        lines.append(f"| {what} | `{name}` | {f(m)} | {op} {val:g} | "
                     f"{'no data' if ok is None else ('met' if ok else '**missed**')} |")
    pdr3, ekf3 = h.get("gps_outage_phone_3min_pdr_pct"), h.get("gps_outage_phone_3min_pct")
    e3p, e3 = h.get("gps_outage_eth_3min_pdr_pct"), h.get("gps_outage_eth_3min_pct")
    lines.append(f"| real walks: EKF better than PDR alone by a factor 2 (3 min) | ETH {f(e3p)} -> {f(e3)}, "
                 f"phones {f(pdr3)} -> {f(ekf3)} | | x2 | "
                 + ("met" if all(v is not None for v in (pdr3, ekf3, e3p, e3)) and ekf3 * 2 <= pdr3 and e3 * 2 <= e3p
                    else "**missed**") + " |")
    lines += ["", "### Median end-of-outage error by variant (% of distance walked in the outage)", "",
              "| set | length | " + " | ".join(VARIANTS) + " |", "|---|---|" + "---|" * len(VARIANTS)]
    for key, label in (("eth", "ETH walk (report)"), ("phone", "phone walks with mag (report)"),
                       ("phone_nomag", "phone walks without mag (report)")):
        for tag in ("1min", "3min", "5min"):
            row = [h.get(f"gps_outage_{key}_{tag}{'' if v == 'ekf' else '_' + v}_pct") for v in VARIANTS]
            if any(r is not None for r in row):
                lines.append(f"| {label} | {tag} | " + " | ".join(f(r) for r in row) + " |")
    for split in ("tuning", "report"):
        row = [h.get(f"gps_outage_sim_{split}_5min{'' if v == 'ekf' else '_' + v}_pct") for v in VARIANTS]
        if any(r is not None for r in row):
            lines.append(f"| simulator ({split}, truth) | 5min | " + " | ".join(f(r) for r in row) + " |")
    lines += ["", "### Per walk (EKF; what was learnt over the whole walk without an outage)", "",
              "| walk | mag | steps / GPS distance (m) | outage runs | EKF 3-min median % | PDR 3-min median % | "
              "stride scale | heading A (deg) | harmonics | residual mean / SD (deg) | raw deviation mean / SD (deg) |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for w in data.get("real", []):
        def med(v, w=w):
            return _median([o["end_error_pct"] for o in w["outages"] if o["variant"] == v
                            and abs(o["length_s"] - 180) < 1])
        lt = w.get("learnt", {})
        hr = w.get("heading_residuals") or {}
        coef = (lt.get("heading_model") or {}).get("coefficients_deg") or [None]
        flag = "" if w.get("steps_detected", True) else " (steps not detected: left out of the headlines)"
        lines.append(f"| {w['walk']}{flag} | {'yes' if w['magnetometer'] else 'no'} | "
                     f"{w.get('step_distance_m', 0):.0f} / {w.get('gps_distance_m', 0):.0f} | "
                     f"{len(w['outages'])} | {f(med('ekf'))} | {f(med('pdr'))} | {f(lt.get('stride_scale'))} | "
                     f"{f(coef[0])} | {hr.get('harmonics_trusted', '-')} | {f(hr.get('residual_mean_deg'))} / "
                     f"{f(hr.get('residual_sd_deg'))} | {f(hr.get('raw_mean_deg'))} / {f(hr.get('raw_sd_deg'))} |")
    lines += ["", "Residuals are out of sample: each window against the model learnt before it (the paper's Table IV "
              "has the mean and SD of the compensated heading against GPS)."]
    others = {k: v for k, v in h.items() if "sigma" in k}
    if others:
        lines += ["", "Uncertainty: " + "; ".join(f"`{k}` {v:.2f}" for k, v in sorted(others.items())) + "."]
    lines += failures_markdown(data.get("failed", []))
    return "\n".join(lines) + "\n"


#: the CI guard's subset: three tuning seeds of the simulator and the ETH walk's 3-minute outages
QUICK_SIM_SEEDS = (0, 1, 2)


def quick(root: Path | None) -> dict:
    """Regression-guard headlines (:mod:`benchmarks.guard`): ``gps_outage_sim_quick_5min_pct``, ``gps_outage_eth_quick_3min_pct``."""
    return {**quick_sim(), **quick_real(root)}


def quick_sim() -> dict:
    """The simulated half of :func:`quick` (the guard runs the halves in two processes)."""
    h = {}
    sim = sim_walks(QUICK_SIM_SEEDS)
    m = _median([o["truth_error_pct"] for r in sim for o in r["outages"] if o["variant"] == "ekf"])
    if m is not None:
        h["gps_outage_sim_quick_5min_pct"] = m
    return h


def quick_real(root: Path | None) -> dict:
    """The real-walk half of :func:`quick`: the ETH walk's 3-minute outages."""
    h = {}
    if root is not None and (Path(root) / REAL[0][0]).is_dir():
        eth = real_walks(Path(root), only=(REAL[0],))
        m = _median([o["end_error_pct"] for w in eth for o in w["outages"]
                     if o["variant"] == "ekf" and abs(o["length_s"] - 180) < 1])
        if m is not None:
            h["gps_outage_eth_quick_3min_pct"] = m
    return h


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.gnss_eval", description=__doc__.split("\n")[0])
    add_common(ap, what="sim or real walk names (2023-03-17_15-50-47, babur_walking)")
    ap.add_argument("--sim-walks", type=int, default=20, help="simulated walks per split (default 20)")
    ap.add_argument("--split", choices=("report", "tuning", "both"), default="both", help="simulator split(s)")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--out", type=Path, default=None, help="the results JSON (default: gnss_results.json, under "
                    "out/benchmarks/gnss_eval/ with --no-write or --only)")
    ap.add_argument("--markdown-only", action="store_true", help="rewrite GNSS_RESULTS.md from the JSON of a run")
    ap.add_argument("--keep-sim", action="store_true", help="reuse the simulator results of the last run (real walks only)")
    args = ap.parse_args(argv)
    global PLOTS
    keys = only_keys(args)
    out_json = args.out or result_path(args, RESULTS_JSON, "gnss_eval")
    out_md = result_path(args, RESULTS_MD, "gnss_eval")
    if not writes_committed(args):
        PLOTS = out_dir("gnss_eval") / "plots"
    if args.markdown_only:
        out_md.write_text(markdown(read_json(out_json)))
        return 0
    root = data_root(args)
    t = time.time()
    failed: list = []
    real = ([] if args.no_real or not Path(root).is_dir() or keys == ["sim"] else
            real_walks(Path(root), plots=True, keys=keys, failed=failed))
    splits = (TUNING, REPORT) if args.split == "both" else (args.split,)
    if args.keep_sim:
        sim = read_json(RESULTS_JSON)["sim"]
    elif selected(keys, "sim"):
        sim = {sp: sim_walks(SIM_GPS_SEEDS[sp][:args.sim_walks], plot_seed=SIM_GPS_SEEDS[REPORT][0])
               for sp in splits}
    else:
        sim = {}
    h = headlines(real, sim)
    write_json(out_json, {"headlines": h, "real": real, "sim": sim, "failed": failed, "seconds": time.time() - t},
               digits=None)
    out_md.write_text(markdown(read_json(out_json)))
    if failed:
        print("gnss_eval: " + failures_line(failed), file=sys.stderr)
    print(f"gnss_eval: wrote {out_md}", file=sys.stderr)
    for k, v in sorted(h.items()):
        print(f"{k:55s} {v:8.3f}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
