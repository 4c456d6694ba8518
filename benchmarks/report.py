"""The benchmark's Markdown report and trajectory plots (from :func:`benchmarks.run.run`'s output)."""

from __future__ import annotations

import datetime as _dt
import math
import os
import platform
import subprocess
from pathlib import Path

import numpy as np


from benchmarks import metrics as M
from benchmarks.headline import PEERS, evaluate_targets, headline
from benchmarks.options import read_json
from benchmarks.splits import SPLITS

#: the "before" column of issue #8 (headlines of the code before it, per split)
BASELINE = Path(__file__).with_name("baseline_before.json")

SOURCE_NAMES = {
    "ours": "ours",
    "rotvec": "phone rotation vector",
    "imufusion": "x-io Fusion (imufusion)",
    "madgwick": "ahrs Madgwick",
    "ekf": "ahrs EKF",
}
PEER_ORDER = ("ours", "rotvec", "imufusion", "madgwick", "ekf")
COLOURS = {"ours": "tab:blue", "rotvec": "tab:orange", "imufusion": "tab:green", "madgwick": "tab:purple",
           "ekf": "tab:brown"}


def _fmt(v, nd=1, signed=False) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if not math.isfinite(v):
        return ""
    return f"{v:+.{nd}f}" if signed else f"{v:.{nd}f}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def _summary_rows(rows_num: list[list], n_label_cols: int, fmts: list) -> list[list[str]]:
    """Mean and median rows over the numeric columns (label columns left blank)."""
    out = []
    for label, fn in (("**mean**", M.nanmean), ("**median**", M.nanmedian)):
        row = [label] + [""] * (n_label_cols - 1)
        for k, f in enumerate(fmts):
            col = [r[n_label_cols + k] for r in rows_num]
            if f is None:
                row.append("")
                continue
            vals = [v for v in col if isinstance(v, (int, float, np.integer, np.floating))]
            row.append(f(fn(vals)) if vals else "")
        out.append(row)
    return out


def _render(header, rows_num, n_label_cols, fmts) -> str:
    body = []
    for r in rows_num:
        body.append([str(x) for x in r[:n_label_cols]] +
                    [("" if f is None and x is None else (f(x) if f is not None else str(x)))
                     for f, x in zip(fmts, r[n_label_cols:])])
    return _table(header, body + _summary_rows(rows_num, n_label_cols, fmts))


def _f(nd=1, signed=False):
    return lambda v: _fmt(v, nd, signed)


# ---------------------------------------------------------------------------
# per-dataset tables


def step_table(results: list[dict]) -> str:
    peers = sorted({p for r in results for p in r.get("peer_counts", {})})
    has_f1 = any("step_f1" in r for r in results)
    has_dist = any("distance_err_pct" in r for r in results)
    header = ["recording", "placement", "true steps", "our steps", "error %"]
    fmts = [_f(0), _f(0), _f(1, True)]
    if has_f1:
        header += ["F1 (+-0.2 s)", "precision", "recall", "lag s"]
        fmts += [_f(3), _f(3), _f(3), _f(2, True)]
    for p in peers:
        header += [f"{p} count", f"{p} error %"]
        fmts += [_f(0), _f(1, True)]
    if has_dist:
        header += ["true distance m", "our distance m", "distance error %"]
        fmts += [_f(1), _f(1), _f(1, True)]
    rows = []
    for r in results:
        if "error" in r:
            continue
        row = [r["name"], r["placement"], r.get("steps_true"), r.get("steps_ours"), r.get("step_err_pct")]
        if has_f1:
            row += [r.get("step_f1"), r.get("step_precision"), r.get("step_recall"), r.get("step_lag_s")]
        for p in peers:
            pc = r.get("peer_counts", {}).get(p)
            row += [pc["count"] if pc else None, pc["err_pct"] if pc else None]
        if has_dist:
            row += [r.get("distance_true_m"), r.get("distance_ours_m"), r.get("distance_err_pct")]
        rows.append(row)
    text = _render(header, rows, 2, fmts)
    mae = M.mean_abs([r.get("step_err_pct") for r in results])
    n_err = sum(1 for r in results if r.get("step_err_pct") is not None and r.get("step_err_pct") == r.get("step_err_pct"))
    lines = [text]
    if n_err:
        lines += ["", f"Step-count mean absolute error: **{_fmt(mae, 2)} %** over the {n_err} recordings "
                      "with a true count."]
    by_place = {}
    for r in results:
        if r.get("step_err_pct") is not None and "error" not in r:
            by_place.setdefault(r["placement"], []).append(r["step_err_pct"])
    if len(by_place) > 1:
        lines.append("")
        lines.append(_table(["placement", "recordings", "step MAE %", "mean signed error %"],
                            [[p, str(len(v)), _fmt(M.mean_abs(v), 2), _fmt(M.nanmean(v), 2, True)]
                             for p, v in sorted(by_place.items())]))
    for p in peers:
        pe = [r["peer_counts"][p]["err_pct"] for r in results if p in r.get("peer_counts", {})]
        oe = [r["step_err_pct"] for r in results if p in r.get("peer_counts", {})]
        if pe and any(x == x for x in pe):
            lines.append("")
            lines.append(f"Where `{p}` has a count ({len(pe)} recordings): its MAE {_fmt(M.mean_abs(pe), 2)} %, "
                         f"ours {_fmt(M.mean_abs(oe), 2)} % on the same recordings.")
    return "\n".join(lines)


def landmark_tables(results: list[dict]) -> str:
    rs = [r for r in results if "sources" in r]
    if not rs:
        return "_No landmark results._"
    header = ["recording", "phone", "landmarks", "path m", "steps", "steps before first landmark", "distance error %",
              "landmark error m", "best-fit landmark error m", "fit rotation deg", "final error m",
              "loop closure %", "segment heading error deg", "mag rejected %"]
    fmts = [_f(0), _f(1), _f(0), _f(0), _f(1, True), _f(2), _f(2), _f(1, True), _f(2), _f(2), _f(1), _f(0)]
    rows = []
    for r in rs:
        s = r["sources"]["ours"]
        rows.append([r["name"], r["info"].get("phone", ""), r["n_landmarks"], r["path_m"],
                     r["steps_between_landmarks"], r.get("steps_before_first_landmark"), r["lm_distance_err_pct"],
                     s["lm_mean_m"], s["lm_fit_mean_m"],
                     s["fit_rotation_deg"], s["lm_final_m"], s["loop_pct"], s["seg_heading_deg"],
                     r.get("mag_rejected_pct")])
    out = ["**Ours** (landmark error = mean over the recording's landmarks after the first; "
           "absolute heading unless 'best-fit'):", "", _render(header, rows, 2, fmts)]

    sources = [p for p in PEER_ORDER if any(p in r["sources"] for r in rs)]
    if len(sources) > 1:
        header = ["recording"] + [f"landmark m: {p}" for p in sources] + \
                 [f"heading deg: {p}" for p in sources] + [f"loop %: {p}" for p in sources] + ["best (landmark)"]
        fmts = [_f(2)] * len(sources) + [_f(1)] * len(sources) + [_f(2)] * len(sources) + [None]
        rows = []
        for r in rs:
            src = r["sources"]
            lm = [src[p]["lm_mean_m"] if p in src else None for p in sources]
            best = min((v, p) for v, p in zip(lm, sources) if v is not None and v == v)[1] if any(
                v is not None and v == v for v in lm) else ""
            rows.append([r["name"]] + lm + [src[p]["seg_heading_deg"] if p in src else None for p in sources] +
                        [src[p]["loop_pct"] if p in src else None for p in sources] + [best])
        out += ["", "**Heading side by side** (same steps and step lengths; only the attitude differs):", "",
                _render(header, rows, 1, fmts)]
        wins = []
        for p in sources[1:]:
            pairs = [(r["sources"]["ours"]["lm_mean_m"], r["sources"][p]["lm_mean_m"]) for r in rs if p in r["sources"]]
            w = sum(1 for a, b in pairs if a < b)
            wins.append(f"{SOURCE_NAMES[p]}: ours better on {w} of {len(pairs)}")
        out += ["", "Per recording, our landmark error against each peer's: " + "; ".join(wins) + "."]
        rot = [f"{p} {_fmt(M.nanmedian([r['sources'][p]['fit_rotation_deg'] for r in rs if p in r['sources']]), 1, True)}"
               for p in sources]
        out += ["", "Median best-fit rotation (deg; the heading offset a source had on the whole, "
                "after the declination correction): " + ", ".join(rot) + "."]
    return "\n".join(out)


def reference_tables(results: list[dict]) -> str:
    """Tables of the recordings scored against a reference track (GPS)."""
    rs = [r for r in results if "ref_sources" in r]
    if not rs:
        return "_No reference-track results._"
    out = []
    for r in rs:
        out += [f"**{r['name']}** ({r['info'].get('phone', '')}): {r['n_fixes']} reference fixes over "
                f"{r['ref_time_s'] / 60:.1f} min ({r.get('ref_source', '')}; median reported accuracy "
                f"{_fmt(r.get('ref_hacc_median_m'), 1)} m, {r['info'].get('gps_fixes_dropped', 0)} fixes dropped), "
                f"GPS path {r['ref_path_m']:.0f} m, our steps {r['steps_between_fixes']} covering "
                f"{r['ref_distance_ours_m']:.0f} m; declination {r['declination_deg']:+.2f} deg (WMM). "
                "Track placed at the first reference fix at its time, absolute heading; distances at every fix:", ""]
        header = ["heading source", "median m", "best-rotation median m", "90th percentile m", "at the last fix m",
                  "best rotation deg"]
        rows = []
        for name in PEER_ORDER:
            s = r["ref_sources"].get(name)
            if s is None:
                continue
            rows.append([SOURCE_NAMES[name], _fmt(s["median_m"], 1), _fmt(s["fit_median_m"], 1), _fmt(s["p90_m"], 1),
                         _fmt(s["final_m"], 1), _fmt(s["fit_rotation_deg"], 1, True)])
        out += [_table(header, rows), ""]
    return "\n".join(out).rstrip()


# ---------------------------------------------------------------------------
# plots


def _tracks_figure(title: str, path: Path, draw_reference, tracks: dict, anchor, label_of, fit_label: str) -> None:
    """One track plot: the reference (``draw_reference(ax)``), every source's track, ours also after its
    best rotation about ``anchor``; ``label_of(name)`` is a source's legend text."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 6), dpi=90)
    draw_reference(ax)
    for name in PEER_ORDER:
        tr = tracks.get(name)
        if tr is None:
            continue
        xy = tr["xy"]
        lw, alpha = (2.0, 1.0) if name == "ours" else (1.0, 0.8)
        ax.plot(xy[:, 0], xy[:, 1], color=COLOURS[name], lw=lw, alpha=alpha, label=label_of(name))
        if name == "ours":
            fit = M.rotate(xy - anchor, tr["fit_rotation_rad"]) + anchor
            ax.plot(fit[:, 0], fit[:, 1], "--", color=COLOURS[name], lw=1, label=fit_label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.grid(alpha=0.3)
    import textwrap  # noqa: PLC0415

    ax.set_title(textwrap.fill(title, 64), fontsize=10)  # wrapped, never cut at the figure's edge
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def plot_trajectory(r: dict, path: Path, title: str) -> None:
    lm = r["plot"]["landmarks"]

    def landmarks(ax):
        ax.plot(lm[:, 0], lm[:, 1], "-", color="0.6", lw=1, zorder=1)
        ax.scatter(lm[:, 0], lm[:, 1], c="k", s=18, zorder=3, label="landmarks (truth)")
        from desktop.plot import label_groups  # noqa: PLC0415 - matplotlib only when plotting

        for x, y, text in label_groups(lm):
            ax.annotate(text, (x, y), textcoords="offset points", xytext=(3, 3), fontsize=7)

    _tracks_figure(title, path, landmarks, r["plot"]["tracks"], lm[0],
                   lambda name: f"{SOURCE_NAMES[name]}: {r['sources'][name]['lm_mean_m']:.1f} m",
                   f"ours, best-fit rotation: {r['sources']['ours']['lm_fit_mean_m']:.1f} m")


def plot_reference(r: dict, path: Path, title: str) -> None:
    ref = r["ref_plot"]["reference"]

    def fixes(ax):
        ax.plot(ref[:, 0], ref[:, 1], ".", color="k", ms=2, zorder=3, label="GPS fixes (reference, not used)")
        ax.plot(ref[:1, 0], ref[:1, 1], "o", color="k", ms=6, zorder=4)

    _tracks_figure(title, path, fixes, r["ref_plot"]["tracks"], ref[0],
                   lambda name: f"{SOURCE_NAMES[name]}: median {r['ref_sources'][name]['median_m']:.1f} m",
                   f"ours, best rotation: median {r['ref_sources']['ours']['fit_median_m']:.1f} m")


def make_plots(results: list[dict], plots_dir: Path) -> dict:
    """A typical (the median recording by our landmark error, on the report split when it has recordings) and
    the worst trajectory of every landmark dataset, and every reference-track recording:
    ``{dataset: [(kind, name, path)]}``."""
    out = {}
    for r in results:
        if "ref_plot" in r and "ref_sources" in r:
            p = plots_dir / f"{r['dataset']}.png"
            try:
                plot_reference(r, p, f"{r['dataset']} ({r.get('split', '')} split): "
                                     f"median {r['ref_sources']['ours']['median_m']:.1f} m from GPS")
            except ImportError:
                return {}
            out.setdefault(r["dataset"], []).append(("track", r["name"], p))
    by_ds = {}
    for r in results:
        if "plot" in r and "sources" in r and r["sources"]["ours"]["lm_mean_m"] == r["sources"]["ours"]["lm_mean_m"]:
            by_ds.setdefault(r["dataset"], []).append(r)
    for ds, rs in by_ds.items():
        rs = [r for r in rs if r.get("split") == "report"] or rs  # what a user should expect: not tuned on
        rs = sorted(rs, key=lambda r: r["sources"]["ours"]["lm_mean_m"])
        picks = [("typical", rs[(len(rs) - 1) // 2]), ("worst", rs[-1])] if len(rs) > 1 else [("only", rs[0])]
        for kind, r in picks:
            p = plots_dir / f"{ds}_{kind}.png"
            try:
                plot_trajectory(r, p, f"{ds} {r['name']} ({kind}, {r.get('split', '')} split): landmark error "
                                      f"{r['sources']['ours']['lm_mean_m']:.1f} m")
            except ImportError:
                return {}
            out.setdefault(ds, []).append((kind, r["name"], p))
    return out


# ---------------------------------------------------------------------------
# the report


def _git_describe() -> str:
    try:
        here = Path(__file__).resolve().parents[1]
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                             timeout=5).stdout.strip()
        # the report's own outputs (this file and the plots, rewritten by the run) do not make the code dirty
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)benchmarks/RESULTS.md", ":(exclude)benchmarks/plots"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + (" + uncommitted changes" if dirty else "") if rev else "unknown"
    except Exception:
        return "unknown"


DATASET_TITLES = {
    "oxford_step_counter": "Oxford step counter (accelerometer only, foot-switch steps)",
    "brajdic_harle_handheld": "Brajdic & Harle hand-held walks (manual step counts, counted inside the marked walk window)",
    "ipin2023_track3": "IPIN 2023 Track 3 (hand-held, closed loops, surveyed landmarks)",
    "ms_indoor_location_2020": "Microsoft indoor location 2020, site2/F3 (hand-held flat, surveyor waypoints, open paths)",
    "sensorlogger_gps_walk_ethz": "ETH Zurich Sensor Logger walk (12 min outdoors, flat in hand; scored against its own "
                                  "GPS, which the pipeline never sees)",
    "ipol_healthy_gait_xsens": "IPOL healthy gait (lower-back XSens, 2 x 10 m)",
    "trundlewheel_distance": "Trundle-wheel walks (web DeviceMotion, wheel distance)",
}


def _split_name(name: str):
    """``ipin2023_report_landmark_median_m`` -> ``("ipin2023_*_landmark_median_m", "report")``."""
    for sp in SPLITS:
        tag = f"_{sp}_"
        if tag in name:
            a, b = name.split(tag, 1)
            return f"{a}_*_{b}", sp
    return name, None


def headline_table(h: dict) -> str:
    """All headlines, one row per metric, one column per split."""
    rows: dict = {}
    for name, v in h.items():
        base, sp = _split_name(name)
        rows.setdefault(base, {})[sp] = v
    return _table(["headline (`*` = split)"] + [f"{sp} split" for sp in SPLITS],
                  [[f"`{base}`"] + [_fmt(vals.get(sp), 3) for sp in SPLITS] for base, vals in rows.items()])


def load_baseline(path: Path | None = None) -> dict | None:
    try:
        return read_json(Path(BASELINE if path is None else path))
    except (OSError, ValueError):
        return None


def _is_peer(base: str) -> bool:
    return any(f"_{p}_" in base for p in PEERS)


def before_after_table(h: dict, baseline: dict, peers: bool = False) -> str:
    """Headlines of the code before issue #8 (``baseline_before.json``) against this run, both splits.

    ``peers``: the peers' headlines instead of ours.  Rows in headline order.
    """
    before = baseline.get("headline", {})
    rows: dict = {}
    for name in list(h) + [n for n in before if n not in h]:
        base, sp = _split_name(name)
        if sp is None or _is_peer(base) != peers:
            continue
        rows.setdefault(base, {})[sp] = (before.get(name), h.get(name))
    header = ["headline (`*` = split)"]
    for sp in SPLITS:
        header += [f"{sp}: before", f"{sp}: now", f"{sp}: change"]
    body = []
    for base, vals in rows.items():
        row = [f"`{base}`"]
        for sp in SPLITS:
            b, a = vals.get(sp, (None, None))
            row += [_fmt(b, 3), _fmt(a, 3), _fmt(a - b, 3, True) if a is not None and b is not None else ""]
        body.append(row)
    return _table(header, body)


def _section_headlines(name: str) -> dict:
    """The headlines a benchmark of its own saved in ``benchmarks/<name>`` ({} if it has not run)."""
    try:
        return read_json(Path(__file__).with_name(name)).get("headlines", {})
    except (OSError, ValueError):
        return {}


def _landmark_path_m(results, dataset: str, split: str) -> float | None:
    """Median length (m) of the surveyed-landmark polyline of a dataset's recordings of one split."""
    lengths = []
    for r in results:
        lm = r.get("plot", {}).get("landmarks") if r.get("dataset") == dataset and r.get("split") == split else None
        if lm is not None and len(lm) > 1:
            lengths.append(float(np.sum(np.hypot(*np.diff(np.asarray(lm, float)[:, :2], axis=0).T))))
    return float(np.median(lengths)) if lengths else None


def what_to_expect(results: list, h: dict) -> list[str]:
    """The top of the report: what accuracy a user can expect from what kind of walk, in plain words, from the
    report split's numbers (each sentence only when its numbers are in this run or a saved section)."""
    out = ["## What to expect", "",
           "Measured on recordings by other people that nothing was tuned on (the *report* split below); "
           "your walks will differ, and the company also measures on walks that are not here.", ""]

    def num(name):
        v = h.get(name)
        return v if isinstance(v, (int, float)) and v == v else None

    items = []
    step_hand, step_all = num("handheld_report_step_mae_pct"), num("oxford_report_all_step_mae_pct")
    if step_hand is not None:
        items.append(f"**Steps**: within about {step_hand:.1f} % of the true count with the phone in the hand"
                     + (f", {step_all:.1f} % on average over hand, pockets, bag, armband and a swinging arm"
                        if step_all is not None else "") + ".")
    ipin, path = num("ipin2023_report_landmark_median_m"), _landmark_path_m(results, "ipin2023_track3", "report")
    if ipin is not None:
        dist = num("ipin2023_report_distance_median_abs_pct")
        loop = num("ipin2023_report_loop_closure_median_pct")
        items.append(f"**Hand-held indoors, no GPS** (a museum, phone held in front): about {ipin:.1f} m from the "
                     "surveyed points on average"
                     + (f" over loops of about {path:.0f} m" if path else "")
                     + (f"; the walked distance is right to about {dist:.0f} %" if dist is not None else "")
                     + (f"; a loop ends about {loop:.0f} % of its length away from its start" if loop is not None
                        else "") + ".")
    ms = num("ms_indoor_report_landmark_median_m")
    if ms is not None:
        items.append(f"**Hand-held in a shopping mall**, with a waypoint every few seconds as the only help: "
                     f"about {ms:.1f} m median error at the next waypoints.")
    eth = num("eth_walk_report_gps_median_m")
    gh = _section_headlines("gnss_results.json")
    fused = gh.get("gps_outage_eth_3min_pct")
    if eth is not None:
        items.append(f"**Outdoors without GPS** (12 minutes, phone in the hand): about {eth:.0f} m from the "
                     "real path at the median"
                     + (f"; with GPS, a 3-minute GPS gap ends about {fused:.0f} % of the distance walked in it "
                        "away from the truth" if fused is not None else "") + ".")
    fh = _section_headlines("foot_results.json")
    if fh.get("pyshoe_rmse_median_m") is not None:
        items.append(f"**IMU on the shoe** (foot mode): about {100 * fh['pyshoe_rmse_median_m']:.0f} cm RMS in 3-D "
                     "over short lab walks"
                     + (f"; a walk around a building closes to about {fh['xio_loop_closure_median_pct']:.1f} % of "
                        "its length" if fh.get("xio_loop_closure_median_pct") == fh.get("xio_loop_closure_median_pct")
                        and fh.get("xio_loop_closure_median_pct") is not None else "") + ".")
    flh = _section_headlines("floors_results.json")
    if flh:
        false = flh.get("ipin_report_recordings_with_a_floor_change", 0)
        items.append(f"**Floors** (phones with a barometer): the floor sequence was right in "
                     f"{flh.get('sim_floor_sequence_correct_pct', float('nan')):.0f} % of simulated building walks; "
                     + ("no floor change was reported on any real single-floor walk." if not false else
                        f"{false} real single-floor walks got a floor change they did not have."))
    carry = _carry_expectation()
    if carry:
        items.append(carry)
    out += [f"- {t}" for t in items] + [""]
    return out


def _carry_expectation() -> str | None:
    """The walking direction per carry mode on the simulator's report seeds (benchmarks/walkdir_results.json)."""
    try:
        sim = read_json(Path(__file__).with_name("walkdir_results.json")).get("sim", {})
    except (OSError, ValueError):
        return None
    med = {k.split("/", 1)[1]: v["auto"]["median_abs_deg"] for k, v in sim.items() if k.startswith("report/")}
    if not med or "swinging" not in med:
        return None
    rest = ", ".join(f"{WHERE[m]} {med[m]:.0f} deg" for m in ("pocket", "bag", "ear") if m in med)
    text = ("**Wherever the phone is carried** (simulated walks): the step heading's median error is "
            f"{rest}, found from the acceleration; a phone swung in the hand is the weak case "
            f"({med['swinging']:.0f} deg), and without a gyroscope its steps are undercounted by about 7 %.")
    real = _truth_walk_offsets()
    if real:
        text += (" On real walks with a motion-capture truth of the phone's attitude (report split, "
                 "`TRUTH_WALKS_RESULTS.md`) the walking direction's median error per walk is " + real + ".")
    return text


#: the truth walks' placements in "What to expect", pooled over datasets (RIDI's leg is a trouser pocket)
TRUTH_GROUPS = {"a trouser pocket": ("pocket", "backpocket", "leg"), "a bag": ("bag",),
                "a swinging hand": ("swinging",)}


def _truth_walk_offsets(path: Path | None = None) -> str | None:
    """Per group of placements, the median over the truth walks of the report split of each walk's median error of
    the walking-direction offset against the truth attitude, and the walks counted (None: no results file)."""
    try:
        walks = read_json(path or Path(__file__).with_name("truth_walks_results.json")).get("walks", [])
    except (OSError, ValueError):
        return None
    parts = []
    for label, places in TRUTH_GROUPS.items():
        group = [w for w in walks if w.get("split") == "report" and w.get("placement") in places]
        # a walk that failed, or gave no offset to score, counts as the worst (never dropped)
        errs = [None if w.get("failed") else (w.get("offset_truth") or {}).get("abs_err_deg_median") for w in group]
        if errs:
            med = M.median_counting_failures(errs)
            n = f"{len(errs)} walk" + ("s" if len(errs) != 1 else "")
            parts.append(f"in {label} {med:.0f} deg ({n})" if math.isfinite(med) else
                         f"in {label}: most of its {n} failed")
    return ", ".join(parts) or None


#: the carry modes in "What to expect"
WHERE = {"pocket": "in a pocket", "bag": "in a bag", "ear": "at the ear"}


def build(run_info: dict, plots: dict, out_path: Path, argv=None) -> str:
    results = run_info["results"]
    h = headline(results)
    lines = ["# Benchmark results", ""]
    lines += what_to_expect(results, h)
    cmd = "python -m benchmarks" + ("" if not argv else " " + " ".join(str(a) for a in argv))
    lines += ["## This run", "",
        f"Generated by `{cmd}` on {_dt.date.today().isoformat()}, code `{_git_describe()}`, "
        f"{run_info['jobs']} processes on {platform.machine()} ({os.cpu_count()} cores): "
        f"{len(results)} recordings in {run_info['wall_s']:.0f} s ({'quick subset' if run_info['quick'] else 'subset --only ' + ','.join(run_info['only']) if run_info.get('only') else 'full run'}"
        f"{'' if not run_info.get('split') else ', ' + run_info['split'] + ' split only'}). "
        f"Heading peers: {', '.join(run_info['peers']) or 'none'}.",
        "",
        "Data: `../shared/data` (recordings by other people; never copied into this repository). "
        "Metric definitions: `benchmarks/metrics.py`; how each dataset is read: `benchmarks/datasets/`.",
        "",
        "**Splits** (`benchmarks/splits.py`): every recording is in the *tuning* split (parameters may be "
        "chosen on it) or the *report* split (nothing is tuned on it; the targets are checked on it). "
        "IPIN 2023: routes 01, 02, 21, 22 tuning, 04, 05, 23, 24 report; Microsoft traces: odd-numbered files "
        "(sorted by name) tuning, even report; the ETH walk, Oxford, Brajdic-Harle and the trundle wheel: report; "
        "IPOL: tuning (the stride model was fitted on it). Every number below names its split.",
        "",
        "## Targets (report split)",
        "",
    ]
    rows = []
    for t in evaluate_targets(h):
        lim = t["limit"]
        ref = f"{t['op']} {_fmt(lim, 2)}" + (f" (`{t['ref']}`)" if isinstance(t["ref"], str) else "")
        status = {True: "met", False: "**missed**", None: "no data"}[t["met"]]
        rows.append([t["text"], f"`{t['metric']}`", _fmt(t["value"], 2), ref, status])
    lines += [_table(["target", "headline", "measured", "target", "status"], rows), ""]
    lines += ["How the headlines are made (each over the recordings of its split only): step-count MAE = mean over "
              "recordings of |our count - true count| / true count; IPIN/MS landmark error = per recording, the "
              "mean distance between our position and each landmark after the first (track placed at the first "
              "landmark at its time, absolute heading from the magnetometer and the site's declination from the "
              "World Magnetic Model, no rotation fitted), then the median over recordings "
              "(`*_landmark_pooled_median_m` pools all landmarks instead); loop closure = |end - start| of our "
              "track between the first and last landmark / landmark polyline length; ETH walk = median over the "
              "GPS fixes of the distance between the fix and our position at its time (track placed at the first "
              "fix, absolute heading; `*_gps_fit_median_m` after the best rotation about the start). Peers: the "
              "same steps and step lengths with their attitude (`benchmarks/peers.py`). "
              "Formulas: `benchmarks/metrics.py`.", ""]
    baseline = load_baseline()
    if baseline is not None:
        lines += ["## Before and after issue #8", "",
                  f"Before: the code before issue #8 (commit `{baseline.get('code', '?')}`, "
                  f"`benchmarks/baseline_before.json`, made {baseline.get('generated', '?')}); now: this run. "
                  "Same split definitions on both sides. In the before column the ahrs EKF peer was still given "
                  "the median magnetic dip of its whole recording (hindsight; now the site's WMM dip), and the ETH "
                  "walk row was made with the issue #8 reader on the old code.", ""]
        if run_info.get("quick") or run_info.get("split") or run_info.get("only"):
            lines += ["_This run is not a full run: its numbers are over fewer recordings than the before "
                      "column's._", ""]
        lines += ["Ours:", "", before_after_table(h, baseline), "",
                  "The peers (same steps and step lengths, their attitude):", "",
                  before_after_table(h, baseline, peers=True), ""]
    discussion = Path(__file__).with_name("discussion.md")
    if discussion.exists():  # hand-written: why targets are missed, what was tried (kept across runs)
        lines += [discussion.read_text().rstrip(), ""]
    lines += ["## Headline numbers", "", headline_table(h), ""]

    errors = [r for r in results if "error" in r]
    by_ds: dict = {}
    for r in results:
        by_ds.setdefault(r["dataset"], []).append(r)
    for ds, info in run_info["datasets"].items():
        rs_all = [r for r in by_ds.get(ds, []) if "error" not in r]
        lines += [f"## {DATASET_TITLES.get(ds, ds)}", ""]
        per = ", ".join(f"{n} {sp}" for sp, n in info.get("splits", {}).items() if n)
        lines.append(f"`{ds}`: {info['n_run']} of {info['n_trials']} recordings run ({per}).")
        lines.append("")
        for sp in SPLITS:
            rs = [r for r in rs_all if r.get("split") == sp]
            if not rs:
                continue
            lines += [f"### {ds}: {sp} split ({len(rs)} recordings)", ""]
            if any("steps_true" in r for r in rs):
                lines += [step_table([r for r in rs if "steps_true" in r]), ""]
                no_gt = [r["name"] for r in rs if "steps_true" not in r and "sources" not in r
                         and "ref_sources" not in r]
                if no_gt:
                    lines += [f"Without step ground truth (run, not scored): {', '.join(no_gt)}.", ""]
            elif any("distance_err_pct" in r for r in rs):
                lines += [step_table(rs), ""]
            if any("sources" in r for r in rs):
                lines += [landmark_tables(rs), ""]
            if any("ref_sources" in r for r in rs):
                lines += [reference_tables(rs), ""]
        rs = rs_all
        for kind, name, p in plots.get(ds, []):
            rel = os.path.relpath(p, out_path.parent)
            lines += [f"{kind.capitalize()} trajectory ({name}): ![{ds} {kind}]({rel})", ""]
        labels = sorted({lab for r in rs for lab in r.get("labels", [])})
        if labels:
            lines += ["Pipeline labels seen: " + "; ".join(f"_{x}_" for x in labels), ""]
        nan = [f"{r['name']} ({r['attitude_nan_pct']:.0f} %)" for r in rs if r.get("attitude_nan_pct", 0) > 0]
        if nan:
            lines += ["**Our attitude went NaN** (share of the attitude log) in: " + ", ".join(nan) +
                      ". Those steps fall back to a fixed heading.", ""]
        perr = sorted({f"{k}: {v}" for r in rs for k, v in r.get("peer_errors", {}).items()})
        if perr:
            lines += ["Peer failures: " + "; ".join(perr), ""]
    if errors:
        lines += ["## Recordings that failed", ""]
        lines += [f"* {r['dataset']}/{r['name']}: {r['error']}" for r in errors]
        lines.append("")
    if run_info.get("import_errors"):
        lines += ["## Dataset readers not available", ""]
        lines += [f"* {k}: {v}" for k, v in run_info["import_errors"].items()]
        lines.append("")
    if run_info.get("stride_section"):
        lines += [run_info["stride_section"].rstrip(), "",
                  "_Splits of the step-length study: the IPOL walks are the tuning split (the models are fitted on "
                  "them; the numbers above are leave-one-subject-out); its IPIN 2023 rows pool both IPIN splits "
                  "(tuning and report routes) and its trundle-wheel rows are report split._", ""]
    runtime = M.nanmean([r.get("pipeline_s") for r in results])
    per_ev = [r["pipeline_s"] / r["events"] * 1e6 for r in results if r.get("events")]
    lines += ["## Run time", "",
              f"Pipeline: {_fmt(runtime, 2)} s per recording on average, "
              f"median {_fmt(M.nanmedian(per_ev), 1)} us per sensor event (acc+gyro+mag); "
              f"peers: {_fmt(M.nanmean([r.get('peer_runtime_s') for r in results]), 2)} s per landmark recording."
              + _engine_note(results), ""]
    return "\n".join(lines)


def _engine_note(results: list[dict]) -> str:
    """Which engine ran our pipeline and how many peer runs came from the cache (issue #13), as a sentence."""
    engines: dict = {}
    for r in results:
        e = r.get("engine")
        if e:
            key = "fast path" if e == "fast" else "reference (Pipeline.run)"
            engines[key] = engines.get(key, 0) + 1
    n_cached = sum(len(r.get("peers_cached", ())) for r in results)
    parts = [f"{k} on {v} recording{'s' if v != 1 else ''}" for k, v in engines.items()]
    out = f" Our pipeline ran on the {' and the '.join(parts)}." if parts else ""
    if n_cached:
        out += f" {n_cached} peer runs were read from the peer cache (the peers' attitudes of an earlier run)."
    return out


#: markdown sections other benchmark modules write, appended to RESULTS.md
SECTIONS = ("GNSS_RESULTS.md", "GNSS_FAULTS_RESULTS.md", "VELOCITY_RESULTS.md", "FOOT_RESULTS.md", "BAD_INPUT_RESULTS.md",
            "FLOORS_RESULTS.md", "INDOOR_RESULTS.md", "CARRY_RESULTS.md", "WALKDIR_RESULTS.md", "THROUGHPUT_RESULTS.md")


def _section_files() -> list[Path]:
    return [f for f in (Path(__file__).with_name(s) for s in SECTIONS) if f.exists()]


def _sections_text() -> str:
    """The sections written by the benchmarks of their own (GPS, foot-mounted INS, bad input), as appended."""
    return "".join("\n\n" + f.read_text().strip() for f in _section_files())


def write(run_info: dict, out_path: Path, plots_dir: Path, argv=None) -> None:
    out_path = Path(out_path)
    plots = make_plots(run_info["results"], Path(plots_dir))
    text = build(run_info, plots, out_path, argv)
    # the sections written by the benchmarks of their own, kept when this file is rebuilt
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(text + _sections_text() + "\n")


def refresh_sections(out_path: Path | None = None) -> None:
    """Fold the current sections into an existing RESULTS.md without rerunning its benchmark.

    Everything from the first section heading found in the file on is replaced by the sections as they
    are now (a benchmark of its own calls this after writing its section).
    """
    out_path = Path(out_path) if out_path is not None else Path(__file__).with_name("RESULTS.md")
    if not out_path.exists():
        return
    text = out_path.read_text()
    heads = ["\n" + f.read_text().lstrip().splitlines()[0] + "\n" for f in _section_files()]
    cut = min((text.find(h) for h in heads if h in text), default=-1)
    out_path.write_text((text[:cut] if cut >= 0 else text).rstrip("\n") + "\n" + _sections_text() + "\n")
