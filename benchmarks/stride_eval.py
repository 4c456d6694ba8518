"""Step-length benchmark: the four stride models on the same steps of real walkers (issue #4).

* **Walks.**  Every recording is run through :class:`core.pdr.pipeline.Pipeline`
  (the step detector and the features the phone will compute); the detected
  steps inside a stretch of known length form a :class:`desktop.stride_training.Walk`.

  - IPOL (lower-back XSens, placement "waist"): per trial the two straight
    10 m legs (the U-turn is left out).  A leg's detected steps are those whose
    acceleration peak lies within half a step of the expected peaks of the
    leg's annotated foot strikes (peaks lag the strikes by about 0.1 s).
    The reference mean step length is 20 m / annotated strikes on the legs.
  - Trundle wheel (one walker, placement undocumented): the whole walk, wheel
    total as distance; for calibration the first 20 wheel metres.
  - IPIN 2023 (hand-held, 2 phones): if ``benchmarks.datasets.ipin2023`` is
    present, the walk from the first to the last landmark, distance = the
    straight landmark-to-landmark polyline.

* **Cross-validation.**  Leave-one-subject-out over the IPOL walkers whose
  height is known (the BP network needs it): each model is fitted on the
  other subjects (the networks keep a quarter of those for early stopping)
  and predicts the held-out subject's walks.  All four models see exactly the
  same steps.

* **Calibration.**  For a held-out subject the fold's model is calibrated
  (:func:`core.pdr.calibration.calibrate_known_distance`) on one of the subject's
  20 m trials and evaluated on each of the subject's other trials; every
  (calibration trial, test trial) pair counts.

``stride_section(data_root)`` returns the Markdown for ``benchmarks/RESULTS.md``.
"""

from __future__ import annotations

import functools
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from core.conventions import CARRY_HANDHELD
from core.pdr.calibration import CalibrationError, calibrate_known_distance
from core.pdr.pipeline import Pipeline
from core.pdr.stride import StepFeatures
from core.pdr.stride_models import lengths_of, save_stride_model, weinberg_root, with_scale
from desktop.stride_training import MODEL_KINDS, TrainConfig, Walk, fit_model

MODEL_LABELS = {
    "weinberg": "Weinberg, constant C",
    "weinberg_bp": "BP network C(height, SF)",
    "chen_linear": "Chen linear (SF, SV)",
    "chen_ann": "Chen network (16 tanh)",
}

#: detected peaks lag the annotated foot strikes by about this much (s), measured on IPOL
PEAK_LAG_S = 0.10
#: a calibration walk on the long walks: this many metres from the start
CALIBRATION_DISTANCE_M = 20.0


# ---------------------------------------------------------------------------
# features and walks


def step_features(recording, height_m: float | None = None) -> list[StepFeatures]:
    """The features of every step the pipeline detects in ``recording``."""
    res = Pipeline(height_m=height_m).run(recording)
    return [s.features for s in res.steps]


def _ipol_trial_walk(trial) -> Walk | None:
    h = trial.subject.get("height_m")
    feats = step_features(trial.load(), h)
    t = np.array([f.t_ns for f in feats], dtype=np.int64)
    keep = np.zeros(len(feats), bool)
    n_ref = 0
    for t0, t1, _length in trial.legs:
        strikes = trial.step_t_ns[(trial.step_t_ns >= t0) & (trial.step_t_ns <= t1)]
        if len(strikes) < 2:
            return None
        n_ref += len(strikes)
        half_ns = int(0.5 * np.median(np.diff(strikes)))
        lag_ns = int(PEAK_LAG_S * 1e9)
        lo = strikes[0] + lag_ns - half_ns
        hi = strikes[-1] + lag_ns + half_ns
        keep |= (t >= lo) & (t <= hi)
    sel = [f for f, k in zip(feats, keep) if k]
    return Walk(name=f"ipol {trial.name}", group=trial.subject["id"], features=sel,
                distance_m=float(sum(leg[2] for leg in trial.legs)), dataset="ipol", placement=trial.placement,
                ref_steps=n_ref, meta={"height_m": h, "trial": trial.name, "age": trial.subject.get("age")})


@functools.lru_cache(maxsize=4)
def ipol_walks(data_root: str) -> tuple[Walk, ...]:
    from benchmarks.datasets import ipol

    root = Path(data_root)
    if not ipol.available(root):
        return ()
    walks = [w for w in (_ipol_trial_walk(t) for t in ipol.trials(root)) if w is not None]
    out, seen = [], set()
    for w in walks:
        # 9-4 repeats 9-3: the same lower-back samples (plus a tail) and the same footsteps but one
        key = (w.group, tuple((f.t_ns, f.acc_max_m_s2, f.acc_min_m_s2) for f in w.features[:20]))
        if key in seen:
            DUPLICATES.append(f"{w.name}: same lower-back data as an earlier trial of {w.group}")
            continue
        seen.add(key)
        out.append(w)
    return tuple(out)


#: trials left out because they duplicate another one (filled by ipol_walks)
DUPLICATES: list[str] = []


@dataclass
class LongWalk:
    """A long hand-held walk: its steps, the distance, and a calibration stretch at its start."""

    name: str
    dataset: str
    placement: str
    features: list[StepFeatures]
    distance_m: float
    #: steps and distance of the first ~20 m (the calibration walk) and of the rest
    calib: Walk | None = None
    rest: Walk | None = None
    notes: str = ""


@functools.lru_cache(maxsize=4)
def trundle_walks(data_root: str) -> tuple[LongWalk, ...]:
    from benchmarks.datasets import trundlewheel

    root = Path(data_root)
    if not trundlewheel.available(root):
        return ()
    out = []
    for tr in trundlewheel.trials(root):
        feats = step_features(tr.load())
        t = np.array([f.t_ns for f in feats], dtype=np.int64)
        calib = rest = None
        if tr.wheel_t_ns is not None and len(tr.wheel_m):
            k = int(np.searchsorted(tr.wheel_m, CALIBRATION_DISTANCE_M))
            t_cut = int(tr.wheel_t_ns[min(k, len(tr.wheel_t_ns) - 1)])
            d_cut = float(tr.wheel_m[min(k, len(tr.wheel_m) - 1)])
            calib = Walk(f"{tr.name} first {d_cut:.0f} m", "trundle", [f for f, ti in zip(feats, t) if ti <= t_cut],
                         d_cut, "trundlewheel", tr.placement)
            rest = Walk(f"{tr.name} rest", "trundle", [f for f, ti in zip(feats, t) if ti > t_cut],
                        float(tr.distance_m) - d_cut, "trundlewheel", tr.placement)
        out.append(LongWalk(tr.name, "trundlewheel", tr.placement, feats, float(tr.distance_m), calib, rest))
    return tuple(out)


@functools.lru_cache(maxsize=4)
def ipin_walks(data_root: str) -> tuple[LongWalk, ...]:
    """IPIN 2023 loops, if the dataset reader of the IPIN helper is present (else nothing)."""
    try:
        from benchmarks.datasets import ipin2023
    except ImportError:
        return ()
    root = Path(data_root)
    try:
        if not ipin2023.available(root):
            return ()
        trials = ipin2023.trials(root)
    except Exception:  # a reader still being written must not break this benchmark
        return ()
    out = []
    for tr in trials:
        rec = tr.open()  # fills in the landmarks
        lm = tr.landmarks
        if lm is None or len(lm.t_ns) < 3:
            continue
        feats = step_features(rec)
        t = np.array([f.t_ns for f in feats], dtype=np.int64)
        seg = np.hypot(np.diff(lm.east_m), np.diff(lm.north_m))
        # per landmark segment: steps and straight distance
        segs = []
        for k in range(len(seg)):
            sel = [f for f, ti in zip(feats, t) if lm.t_ns[k] < ti <= lm.t_ns[k + 1]]
            segs.append((sel, float(seg[k])))
        # a segment whose straight distance is far below its steps (a detour or a wait) is not a reference
        good = [(s, d) for s, d in segs if len(s) == 0 or d / len(s) >= 0.3]
        dropped = len(segs) - len(good)
        all_feats = [f for s, _ in good for f in s]
        total = sum(d for _, d in good)
        calib_f, calib_d, k = [], 0.0, 0
        while k < len(good) and calib_d < CALIBRATION_DISTANCE_M:
            calib_f += good[k][0]
            calib_d += good[k][1]
            k += 1
        rest_f = [f for s, _ in good[k:] for f in s]
        rest_d = sum(d for _, d in good[k:])
        group = str(tr.subject.get("id") or tr.info.get("phone") or "ipin")
        calib = Walk(f"{tr.name} first {calib_d:.0f} m", group, calib_f, calib_d, "ipin2023", tr.placement)
        rest = Walk(f"{tr.name} rest", group, rest_f, rest_d, "ipin2023", tr.placement) if rest_d > 0 else None
        out.append(LongWalk(tr.name, "ipin2023", tr.placement, all_feats, total, calib, rest,
                            notes=f"{dropped} segment(s) dropped" if dropped else ""))
    return tuple(out)


# ---------------------------------------------------------------------------
# the study


def distance_error_pct(model, walk: Walk) -> float:
    est = float(lengths_of(model, walk.features).sum())
    return 100.0 * (est - walk.distance_m) / walk.distance_m


@dataclass
class Study:
    walks: list[Walk]  #: IPOL walks used in the CV (subjects with height)
    excluded: list[str]  #: why walks/subjects were left out
    #: per model kind: per walk name: LOSO error (%)
    loso_err: dict = field(default_factory=dict)
    #: per model kind: per walk name: per-step estimated lengths (LOSO)
    loso_len: dict = field(default_factory=dict)
    #: per model kind: list of (test walk, calibration walk, error %) after calibration
    calib_err: dict = field(default_factory=dict)
    #: per model kind: the model fitted on all subjects
    final: dict = field(default_factory=dict)
    #: hand-held / long walks evaluated with the final models: rows of dicts
    long_rows: list = field(default_factory=list)
    #: constant C fitted on the long hand-held walks (by dataset)
    long_constant: dict = field(default_factory=dict)
    fold_reports: dict = field(default_factory=dict)
    #: BP network LOSO with other hyper-parameters: rows (label, median, mean)
    bp_sensitivity: list = field(default_factory=list)
    #: trundle wheel: calibrate on one whole walk, score the other: rows (model kind, calib walk, test walk, err %)
    cross_walk: list = field(default_factory=list)
    #: IPOL: median pairwise |C_i / C_j - 1| (%) between a subject's trials with the *annotated* step counts:
    #: the scatter of the 20 m reference itself, a floor for any calibration scored on these trials
    reference_floor_pct: float = math.nan
    cfg: TrainConfig = field(default_factory=TrainConfig)


def run_study(data_root, cfg: TrainConfig | None = None, *, sensitivity: bool = True) -> Study:
    cfg = cfg or TrainConfig()
    data_root = str(Path(data_root))
    all_walks = list(ipol_walks(data_root))
    walks = [w for w in all_walks if w.meta.get("height_m")]
    excluded = sorted({w.group for w in all_walks if not w.meta.get("height_m")})
    study = Study(walks, [f"{g}: no height in the metadata" for g in excluded] + sorted(set(DUPLICATES)), cfg=cfg)
    groups = sorted({w.group for w in walks}, key=lambda g: int(g.split("-")[-1]))
    for kind in MODEL_KINDS:
        study.loso_err[kind], study.loso_len[kind], study.calib_err[kind] = {}, {}, []
    for g in groups:
        train = [w for w in walks if w.group != g]
        test = [w for w in walks if w.group == g]
        for kind in MODEL_KINDS:
            model = fit_model(kind, train, cfg)
            study.fold_reports.setdefault(kind, {})[g] = getattr(model, "train_report", None)
            for w in test:
                study.loso_err[kind][w.name] = distance_error_pct(model, w)
                study.loso_len[kind][w.name] = lengths_of(model, w.features)
            for wc in test:
                try:
                    res = calibrate_known_distance(wc.features, wc.distance_m, model)
                except CalibrationError:
                    continue
                scaled = with_scale(model, res.scale)
                for wt in test:
                    if wt is not wc:
                        study.calib_err[kind].append((wt.name, wc.name, distance_error_pct(scaled, wt)))
    for kind in MODEL_KINDS:
        study.final[kind] = fit_model(kind, walks, cfg)
    study.reference_floor_pct = _reference_floor(walks)
    if sensitivity:
        for label, c in _bp_variants(cfg):
            errs = []
            for g in groups:
                model = fit_model("weinberg_bp", [w for w in walks if w.group != g], c)
                errs += [abs(distance_error_pct(model, w)) for w in walks if w.group == g]
            study.bp_sensitivity.append((label, float(np.median(errs)), float(np.mean(errs))))
    _long_walks(study, data_root)
    return study


def _bp_variants(cfg: TrainConfig):
    from dataclasses import replace

    return [("no weight decay, 6 hidden", replace(cfg, bp_weight_decay=0.0, bp_hidden=6)),
            ("weight decay 1e-3, 3 hidden", replace(cfg, bp_hidden=3)),
            ("weight decay 1e-3, 12 hidden", replace(cfg, bp_hidden=12))]


def _reference_floor(walks: Sequence[Walk]) -> float:
    from core.pdr.stride_models import weinberg_root

    pairs = []
    for g in {w.group for w in walks}:
        ws = [w for w in walks if w.group == g and w.ref_steps and w.n_steps]
        c = [w.distance_m / (float(weinberg_root(w.features).mean()) * w.ref_steps) for w in ws]
        pairs += [abs(a / b - 1) for i, a in enumerate(c) for j, b in enumerate(c) if i != j]
    return 100.0 * float(np.median(pairs)) if pairs else math.nan


def _long_walks(study: Study, data_root: str) -> None:
    from desktop.stride_training import fit_constant

    longs = list(trundle_walks(data_root)) + list(ipin_walks(data_root))
    for lw in longs:
        whole = Walk(lw.name, lw.dataset, lw.features, lw.distance_m, lw.dataset, lw.placement)
        row = {"walk": lw.name, "dataset": lw.dataset, "placement": lw.placement, "distance_m": lw.distance_m,
               "n_steps": len(lw.features), "notes": lw.notes}
        for kind, model in study.final.items():
            row[kind] = distance_error_pct(model, whole)
            if lw.calib is not None and lw.rest is not None and lw.rest.n_steps:
                try:
                    res = calibrate_known_distance(lw.calib.features, lw.calib.distance_m, model)
                    row[kind + "_cal"] = distance_error_pct(with_scale(model, res.scale), lw.rest)
                except CalibrationError as e:
                    row[kind + "_cal"] = math.nan
                    row["notes"] = (row["notes"] + "; " if row["notes"] else "") + str(e)[:60]
        study.long_rows.append(row)
    trundle = [lw for lw in longs if lw.dataset == "trundlewheel"]
    for kind, model in study.final.items():
        for lc in trundle:
            for lt in trundle:
                if lc is lt:
                    continue
                try:
                    res = calibrate_known_distance(lc.features, lc.distance_m, model)
                except CalibrationError:
                    continue
                whole = Walk(lt.name, lt.dataset, lt.features, lt.distance_m)
                study.cross_walk.append((kind, lc.name, lt.name, distance_error_pct(with_scale(model, res.scale), whole)))
    by_ds: dict[str, list[Walk]] = {}
    for lw in longs:
        by_ds.setdefault(lw.dataset, []).append(Walk(lw.name, lw.dataset, lw.features, lw.distance_m))
    for ds, ws in by_ds.items():
        study.long_constant[ds] = fit_constant(ws).coefficient.c


# ---------------------------------------------------------------------------
# reporting


def _abs_stats(values) -> tuple[float, float, float]:
    a = np.abs(np.asarray(list(values), float))
    a = a[np.isfinite(a)]
    if not a.size:
        return math.nan, math.nan, math.nan
    return float(np.median(a)), float(np.mean(a)), float(np.max(a))


def summary(study: Study) -> dict:
    """Headline numbers per model: LOSO and calibrated median/mean/max |distance error| (%)."""
    out = {}
    for kind in MODEL_KINDS:
        med, mean, mx = _abs_stats(study.loso_err[kind].values())
        cmed, cmean, cmx = _abs_stats(e for _, _, e in study.calib_err[kind])
        out[kind] = {"loso_median": med, "loso_mean": mean, "loso_max": mx,
                     "cal_median": cmed, "cal_mean": cmean, "cal_max": cmx}
    return out


def choose_default(study: Study) -> str:
    """The shipped default: the BP network if it beats constant-C Weinberg in the CV, else constant C."""
    s = summary(study)
    bp, const = s["weinberg_bp"], s["weinberg"]
    if bp["loso_median"] < const["loso_median"] and bp["loso_mean"] < const["loso_mean"]:
        return "weinberg_bp"
    return "weinberg"


def _long_summary(study: Study, dataset: str) -> dict:
    rows = [r for r in study.long_rows if r["dataset"] == dataset]
    out = {}
    for k in MODEL_KINDS:
        out[k] = (_abs_stats(r[k] for r in rows)[0], _abs_stats(r.get(k + "_cal", math.nan) for r in rows)[0])
    return out


def render_markdown(study: Study) -> str:
    s = summary(study)
    walks = study.walks
    subjects = sorted({w.group for w in walks}, key=lambda g: int(g.split("-")[-1]))
    n_steps = sum(w.n_steps for w in walks)
    n_ref = sum(w.ref_steps for w in walks)
    heights = [next(w.meta["height_m"] for w in walks if w.group == g) for g in subjects]
    ref_sl = [sum(w.distance_m for w in walks if w.group == g) / sum(w.ref_steps for w in walks if w.group == g)
              for g in subjects]
    r_h_sl = float(np.corrcoef(heights, ref_sl)[0, 1]) if len(subjects) > 2 else math.nan
    subj_c = [sum(w.distance_m for w in walks if w.group == g)
              / float(sum(lengths_of(study.final["weinberg"], w.features).sum() for w in walks if w.group == g))
              * study.final["weinberg"].coefficient.c for g in subjects]
    c_spread = float(np.std(subj_c) / np.mean(subj_c))
    ages = [a for a in (next(w.meta.get("age") for w in walks if w.group == g) for g in subjects) if a]
    default = choose_default(study)
    lines = ["## Step length (issue #4)", ""]
    lines += [
        f"**Data.** IPOL healthy-gait trials, **lower-back XSens (placement: waist)**, {len(subjects)} subjects with a "
        f"known height ({min(w.meta['height_m'] for w in walks) * 100:.0f}-"
        f"{max(w.meta['height_m'] for w in walks) * 100:.0f} cm), {len(walks)} trials of 2 x 10 m, "
        f"{n_steps} steps detected by `core.pdr.pipeline` on the straight legs ({n_ref} annotated; U-turns left out). "
        + ("Left out: " + "; ".join(study.excluded) + ". " if study.excluded else "")
        + "**Leave-one-subject-out** cross-validation: each model is fitted on the other subjects (the networks keep "
        "a quarter of those for early stopping) and scored on the held-out one; all four models see the same "
        "steps. Distance error = (sum of the model's step lengths over the detected steps - 20 m) / 20 m. "
        "'After calibration': the held-out subject's model is calibrated (`core.pdr.calibration."
        "calibrate_known_distance`) on one of the subject's 20 m trials and scored on each of the others "
        "(all pairs).",
        "",
        "| model | LOSO \\|distance error\\|, median | mean | max | after 20 m calibration, median | mean | max |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind in MODEL_KINDS:
        r = s[kind]
        lines.append(f"| {MODEL_LABELS[kind]} | {r['loso_median']:.2f} % | {r['loso_mean']:.2f} % | "
                     f"{r['loso_max']:.1f} % | {r['cal_median']:.2f} % | {r['cal_mean']:.2f} % | {r['cal_max']:.1f} % |")
    lines.append("")
    bp, const = s["weinberg_bp"], s["weinberg"]
    if default == "weinberg_bp":
        verdict = (f"The BP network beats constant-C Weinberg in cross-validation (median {bp['loso_median']:.2f} % "
                   f"vs {const['loso_median']:.2f} %, mean {bp['loso_mean']:.2f} % vs {const['loso_mean']:.2f} %); "
                   "it is the shipped default.")
    else:
        per_subject = []
        for g in subjects:
            names = [w.name for w in walks if w.group == g]
            d_bp = np.mean([abs(study.loso_err["weinberg_bp"][n]) for n in names])
            d_c = np.mean([abs(study.loso_err["weinberg"][n]) for n in names])
            per_subject.append((d_bp - d_c, g, d_bp, d_c))
        worse = [f"{g} ({next(w.meta['height_m'] for w in walks if w.group == g) * 100:.0f} cm: "
                 f"{b:.1f} % vs {c:.1f} %)" for d, g, b, c in sorted(per_subject, reverse=True) if d > 1.0]
        better = [g for d, g, b, c in per_subject if d < -1.0]
        verdict = (f"**The BP network of Tian et al. does not beat constant-C Weinberg on this data.** "
                   f"Median |error| {bp['loso_median']:.2f} % vs {const['loso_median']:.2f} %, but mean "
                   f"{bp['loso_mean']:.2f} % vs {const['loso_mean']:.2f} % and worst case {bp['loso_max']:.1f} % vs "
                   f"{const['loso_max']:.1f} %: it is better by more than a point for {len(better)} subject(s) and "
                   f"worse by more than a point for {len(worse)}"
                   + (f" ({', '.join(worse)})" if worse else "") + ". "
                   f"The shipped default (`core/pdr/models/default.json`) is therefore **constant-C Weinberg, C = "
                   f"{study.final['weinberg'].coefficient.c:.3f}**, fitted on all {len(subjects)} subjects. Why the "
                   "network cannot help here: a subject's C is steady from trial to trial, but differs between "
                   f"subjects by +-{100 * c_spread:.0f} % (SD of the subjects' C) in a way that height (and step "
                   "frequency, which Weinberg's fourth root already reflects) does not predict: across the subjects, "
                   f"height and reference step length correlate at r = {r_h_sl:+.2f}.")
    lines += [verdict, ""]
    if study.bp_sensitivity:
        lines += ["The verdict does not hang on the network's settings (BP network, LOSO |error|). The shipped "
                  f"settings ({study.cfg.bp_hidden} tanh hidden units, weight decay {study.cfg.bp_weight_decay:g}) "
                  "were picked after a sweep on this same cross-validation, which flatters the network if anything; "
                  "there is no separate test set of walkers with heights to do better:", "",
                  "| BP network variant | median | mean |", "|---|---|---|",
                  f"| shipped settings | {bp['loso_median']:.2f} % | {bp['loso_mean']:.2f} % |"]
        lines += [f"| {label} | {med:.2f} % | {mean:.2f} % |" for label, med, mean in study.bp_sensitivity]
        lines += [f"| (constant-C Weinberg) | {const['loso_median']:.2f} % | {const['loso_mean']:.2f} % |", ""]
    ipin = _long_summary(study, "ipin2023")
    has_ipin = any(r["dataset"] == "ipin2023" for r in study.long_rows)
    lines += [
        "**Targets** (shipped default, only the height known, walkers the model never saw):",
        "",
        f"* IPOL waist, LOSO: median {s[default]['loso_median']:.2f} % -> "
        f"**{'met' if s[default]['loso_median'] <= 3.0 else 'not met'}** (target <= 3 %).",
    ]
    if has_ipin:
        lines.append(f"* IPIN hand-held loops (other walkers, other placement, model trained on IPOL only): median "
                     f"{ipin[default][0]:.2f} % -> **{'met' if ipin[default][0] <= 3.0 else 'not met'}**.")
    lines += [
        f"* After the known-distance calibration (target median <= 1.5 %): IPOL {s[default]['cal_median']:.2f} % -> "
        f"**{'met' if s[default]['cal_median'] <= 1.5 else 'not met'}**"
        + (f"; IPIN (calibrated on the first ~20-45 m of a loop, scored on the rest) {ipin[default][1]:.2f} % -> "
           f"**{'met' if ipin[default][1] <= 1.5 else 'not met'}**." if has_ipin else "."),
        f"* The IPOL calibration number cannot go much below **{study.reference_floor_pct:.1f} %**, the median "
        "trial-to-trial scatter of a subject's C computed with the *annotated* step counts: the 20 m reference "
        "(where exactly the walker started and turned) and the walker's own variation from one 20 m trial to "
        "the next. IPOL can show that calibration removes the between-subject error; it cannot show 1.5 %.",
        "",
    ]
    # Table 1 of the paper, per subject
    lines += ["Per subject, as Table 1 of Tian et al. 2014: reference mean step length = 20 m / annotated strikes "
              "on the legs; estimated = mean of the model's per-step lengths over the detected steps (LOSO); "
              "SD = standard deviation of those per-step estimates (m).", "",
              "| subject | height (cm) | trials | reference SL (m) | " +
              " | ".join(f"{MODEL_LABELS[k]}: SL (SD)" for k in MODEL_KINDS) + " |",
              "|---|---|---|---|" + "---|" * len(MODEL_KINDS)]
    for g in subjects:
        ws = [w for w in walks if w.group == g]
        ref = sum(w.distance_m for w in ws) / sum(w.ref_steps for w in ws)
        cells = []
        for k in MODEL_KINDS:
            ls = np.concatenate([study.loso_len[k][w.name] for w in ws])
            cells.append(f"{ls.mean():.3f} ({ls.std():.3f})")
        lines.append(f"| {g} | {ws[0].meta['height_m'] * 100:.0f} | {len(ws)} | {ref:.3f} | "
                     + " | ".join(cells) + " |")
    lines.append("")
    # per recording
    lines += ["Walked-distance error per IPOL recording, % (LOSO, signed; 'cal' = mean |error| after calibrating on "
              "each of the subject's other trials):", "",
              "| trial | height (cm) | steps annotated/detected | " + " | ".join(MODEL_LABELS[k] for k in MODEL_KINDS)
              + " | " + " | ".join(f"{MODEL_LABELS[k]}, cal" for k in MODEL_KINDS) + " |",
              "|---|---|---|" + "---|" * (2 * len(MODEL_KINDS))]
    for w in walks:
        errs = [f"{study.loso_err[k][w.name]:+.1f}" for k in MODEL_KINDS]
        cals = []
        for k in MODEL_KINDS:
            e = [abs(x) for name, _, x in study.calib_err[k] if name == w.name]
            cals.append(f"{np.mean(e):.1f}" if e else "-")
        lines.append(f"| {w.meta['trial']} | {w.meta['height_m'] * 100:.0f} | {w.ref_steps}/{w.n_steps} | "
                     + " | ".join(errs) + " | " + " | ".join(cals) + " |")
    lines.append("")
    # long / hand-held walks
    if study.long_rows:
        lines += ["**Other placements.** The models fitted on all IPOL (waist) subjects, applied unchanged. Heights "
                  "are unknown in these datasets, so the BP network falls back to its constant C. 'cal': "
                  "calibrated on the first stretch of the same walk (IPIN: the first landmark segments adding up "
                  "to >= 20 m; trundle wheel: the first 20 wheel metres), scored on the rest. IPIN distance = the "
                  "straight landmark-to-landmark polyline (a segment with fewer than 0.3 m per detected step, i.e. "
                  "a wait or a detour, is dropped with its steps).", ""]
        if has_ipin:
            lines += ["| IPIN hand-held, median \\|error\\| | " + " | ".join(MODEL_LABELS[k] for k in MODEL_KINDS)
                      + " |", "|---|" + "---|" * len(MODEL_KINDS),
                      "| uncalibrated | " + " | ".join(f"{ipin[k][0]:.2f} %" for k in MODEL_KINDS) + " |",
                      "| calibrated | " + " | ".join(f"{ipin[k][1]:.2f} %" for k in MODEL_KINDS) + " |", ""]
        lines += ["| walk | placement | distance (m) | steps | " + " | ".join(MODEL_LABELS[k] for k in MODEL_KINDS)
                  + " | " + " | ".join(f"{MODEL_LABELS[k]}, cal" for k in MODEL_KINDS) + " | notes |",
                  "|---|---|---|---|" + "---|" * (2 * len(MODEL_KINDS)) + "---|"]
        for r in study.long_rows:
            errs = [f"{r[k]:+.1f}" for k in MODEL_KINDS]
            cals = [f"{r.get(k + '_cal', math.nan):+.1f}" for k in MODEL_KINDS]
            lines.append(f"| {r['walk']} | {r['placement']} | {r['distance_m']:.0f} | {r['n_steps']} | "
                         + " | ".join(errs) + " | " + " | ".join(cals) + f" | {r['notes']} |")
        lines.append("")
        if study.cross_walk:
            lines += ["Trundle wheel, calibrated on one whole walk (~400 m) and scored on the other: "
                      + "; ".join(f"{MODEL_LABELS[k]} {c} -> {t}: {e:+.1f} %" for k, c, t, e in study.cross_walk
                                  if k == default) + ".", ""]
        if study.long_constant:
            cs = ", ".join(f"{ds}: C = {c:.3f}" for ds, c in study.long_constant.items())
            lines += [f"Constant C fitted on these walks themselves: {cs}; on the IPOL waist walks: "
                      f"C = {study.final['weinberg'].coefficient.c:.3f}.", ""]
    lines += [
        f"**What this data can and cannot show.** {len(subjects)} IPOL walkers (heights "
        f"{min(heights) * 100:.0f}-{max(heights) * 100:.0f} cm"
        + (f", ages {min(ages)}-{max(ages)}" if ages else "") + f") are few for a network whose input is "
        f"the height: it sees {len(set(heights))} distinct heights. Each IPOL trial is only 2 x 10 m "
        "(about 30 steps), so one missed or extra step is 3 %, and the 10 m legs are nominal (start and turn "
        "positions are not annotated). The waist sensor is not a phone: a belt-worn phone should behave alike, "
        "a hand-held one differs in amplitude (the IPIN rows test exactly that transfer). No dataset here has "
        "hand-held walks *and* heights, so the height input of the BP network has never been trained or tested "
        "on a hand-held phone. The trundle-wheel walker's placement is undocumented (the signals suggest a "
        "swinging hand or a pocket) and needs a very different C: only calibration helps there.",
        "",
    ]
    return "\n".join(lines)


def write_models(study: Study, out_dir: Path, cfg: TrainConfig, created: str = "") -> list[Path]:
    """Write the four final models and ``default.json`` (a copy of the chosen one) to ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    s = summary(study)
    subjects = sorted({w.group for w in study.walks})
    default = choose_default(study)
    written = []
    for kind, model in study.final.items():
        training = {
            "data": "IPOL healthy-gait dataset (Voisard et al., IPOL 2023), lower-back XSens, 2 x 10 m trials",
            "placement": "waist",
            "subjects": len(subjects), "walks": len(study.walks),
            "steps": int(sum(w.n_steps for w in study.walks)),
            "heights_m": sorted({w.meta["height_m"] for w in study.walks}),
            "features": "core.pdr.pipeline StepFeatures (low-pass filtered acceleration norm)",
            "objective": "mean squared relative walked-distance error per walk",
            "seed": cfg.seed, "tool": "tools/train_stride.py",
            "loso_cv_abs_distance_error_pct": {k: round(v, 3) for k, v in s[kind].items()},
            "ipin_handheld_median_abs_error_pct": (
                {"uncalibrated": round(_long_summary(study, "ipin2023")[kind][0], 3),
                 "calibrated": round(_long_summary(study, "ipin2023")[kind][1], 3)}
                if any(r["dataset"] == "ipin2023" for r in study.long_rows) else None),
            "constant_c_fitted_per_dataset": {"ipol_waist": round(study.final["weinberg"].coefficient.c, 4),
                                              **{k: round(v, 4) for k, v in study.long_constant.items()}},
            "hyper_parameters": {"bp_hidden": cfg.bp_hidden, "chen_hidden": cfg.chen_hidden,
                                 "bp_weight_decay": cfg.bp_weight_decay, "chen_weight_decay": cfg.chen_weight_decay,
                                 "learning_rate": cfg.learning_rate, "patience": cfg.patience,
                                 "restarts": cfg.restarts, "val_fraction": cfg.val_fraction},
            "report": getattr(model, "train_report", None),
        }
        meta = dict(name=kind, description=MODEL_LABELS[kind], placement="waist", created=created,
                    training=training)
        p = out_dir / f"{kind}.json"
        save_stride_model(model, p, **meta)
        written.append(p)
        if kind == default:
            meta = dict(meta, name="default", description=f"default = {MODEL_LABELS[kind]} ({kind})")
            p = out_dir / "default.json"
            save_stride_model(model, p, **meta)
            written.append(p)
    return written


def stride_section(data_root) -> str:
    """Markdown for benchmarks/RESULTS.md: the LOSO study of the four stride models (trains them; ~1 min)."""
    root = Path(data_root)
    if not ipol_walks(str(root)):
        return "## Step length (issue #4)\n\nIPOL dataset not found under the data root: no step-length results.\n"
    return render_markdown(run_study(root))


# ---------------------------------------------------------------------------
# distance without calibration on phones (issue #25)
#
# The default C above is a lower-back sensor's (IPOL).  A phone in the hand or in a pocket sees another
# acceleration amplitude for the same step, so the default is refitted on the phones of the tuning split
# (:func:`fit_phone_c`) and scored on every phone walk of the report split that has a distance truth.

#: a GPS chord stretch: this long (s), fixes with reported accuracy at most this (m), chord / path at least this
CHORD_WINDOW_S = 40.0
CHORD_MAX_HACC_M = 10.0
CHORD_MIN_STRAIGHTNESS = 0.97
CHORD_MIN_M = 30.0
#: the loop of ``phone_walks_more/aymdi_data`` (its README: 116 m and 168 steps)
AYMDI_LOOP_M = 116.0


#: the carry mode of a step whose walk did not record one (the trundle wheel: placement unknown)
MODE_NOT_RECORDED = "not recorded"


@dataclass
class PhoneWalk:
    """A phone walk with a distance truth: its stretches ``(features, distance_m)`` and how they were measured.

    ``modes``: per stretch, the carry mode of each of its steps (the pipeline's, issue #17, or the dataset's
    declared placement; empty: :data:`MODE_NOT_RECORDED`).  ``steps_error_pct``: the walk's steps against its counted steps, where counted (a distance
    error that is a step-count error no stride model can fix)."""

    name: str
    dataset: str
    split: str
    truth: str  #: "landmarks" (surveyed), "gps_chords" (straight GPS stretches), "loop" (stated length), "wheel"
    stretches: list  #: [(features, distance_m)]
    carry_time_s: dict = field(default_factory=dict)
    modes: list = field(default_factory=list)  #: [[carry mode of each step] per stretch]
    steps_error_pct: float = math.nan

    @property
    def distance_m(self) -> float:
        return float(sum(d for _, d in self.stretches))

    def stretch_modes(self, k: int) -> list:
        return list(self.modes[k]) if k < len(self.modes) else [MODE_NOT_RECORDED] * len(self.stretches[k][0])

    def main_mode(self) -> str:
        """The carry mode of most of the walk's steps inside its stretches."""
        counts: dict = {}
        for k in range(len(self.stretches)):
            for m in self.stretch_modes(k):
                counts[m] = counts.get(m, 0) + 1
        return max(counts, key=counts.get) if counts else MODE_NOT_RECORDED

    def c_needed(self) -> float:
        """The constant C that gives this walk's distance: the ratio of sums over its stretches, or for GPS
        chords the median over the stretches (a fix's jump spoils one stretch, not the walk)."""
        ratio = 1.0 + self.error_pct(1.0) / 100.0
        return 1.0 / ratio if ratio > 0 else math.inf  # no step measured: no C gives its distance

    def error_pct(self, c) -> float:
        """Signed distance error (%) of Weinberg's eq. 4 with ``c``: a constant, or a :class:`CarryC` (C per
        carry mode).  Ratio of sums over the stretches; for GPS chords the median of the stretches' ratios."""
        est = []
        for k, (f, _) in enumerate(self.stretches):
            cs = c.of_modes(self.stretch_modes(k)) if isinstance(c, CarryC) else float(c)
            est.append(float(np.sum(cs * weinberg_root(f))))
        d = np.array([d for _, d in self.stretches], float)
        est = np.array(est)
        if self.truth == "gps_chords":
            return 100.0 * (float(np.median(est / d)) - 1.0)
        return 100.0 * (float(est.sum() / d.sum()) - 1.0)


@dataclass(frozen=True)
class CarryC:
    """Weinberg's C per carry mode (issue #25): ``by_mode[mode]``, else ``default``."""

    default: float
    by_mode: tuple = ()  #: ((mode, C), ...)

    def of_modes(self, modes) -> np.ndarray:
        table = dict(self.by_mode)
        return np.array([table.get(m, self.default) for m in modes], float)


def _run_steps(recording):
    """The pipeline's steps on ``recording`` without its GPS (PDR alone), and its carry counters."""
    from core.recording import Recording

    rec = Recording({k: v for k, v in recording.streams.items() if k != "gps"}, dict(recording.device),
                    dict(recording.metadata))
    res = Pipeline().run(rec)
    return res.steps, res.counters.get("carry", {}).get("time_s", {})


def chord_stretches(steps, gps) -> list:
    """``[(features of the steps inside, chord_m)]`` of :func:`chord_spans`."""
    return [([steps[k].features for k in sel], chord) for sel, chord in chord_spans(steps, gps)]


def chord_spans(steps, gps) -> list:
    """Straight stretches of a GPS walk: ``[(indices of the steps inside, chord_m)]``.

    Windows of ``CHORD_WINDOW_S`` over fixes whose reported accuracy is at most ``CHORD_MAX_HACC_M`` (positions
    smoothed over five fixes), kept when the chord is at least ``CHORD_MIN_M`` and ``CHORD_MIN_STRAIGHTNESS`` of
    the path along the fixes: the position chord, not the Doppler speed, is the distance."""
    from core.geodesy import geodetic_to_enu

    v, tg = np.asarray(gps.values, float), np.asarray(gps.t_ns, np.int64)
    ok = np.isfinite(v[:, 3]) & (v[:, 3] <= CHORD_MAX_HACC_M) & np.isfinite(v[:, 0])
    if ok.sum() < 10:
        return []
    e, n = (np.asarray(a, float) for a in geodetic_to_enu(v[:, 0], v[:, 1], (v[ok][0, 0], v[ok][0, 1])))
    box = np.ones(5) / 5
    es, ns = np.convolve(e, box, mode="same"), np.convolve(n, box, mode="same")
    t = np.array([s.t_ns for s in steps], dtype=np.int64)
    out, i = [], 5
    while i < len(tg) - 5:
        j = int(np.searchsorted(tg, tg[i] + int(CHORD_WINDOW_S * 1e9)))
        if j >= len(tg) - 5:
            break
        if not ok[i - 2:j + 3].all() or j - i < 0.8 * CHORD_WINDOW_S * gps.rate_hz:
            i += 5
            continue
        path = float(np.sum(np.hypot(np.diff(es[i:j + 1]), np.diff(ns[i:j + 1]))))
        chord = float(np.hypot(es[j] - es[i], ns[j] - ns[i]))
        sel = np.flatnonzero((t > tg[i]) & (t <= tg[j]))
        if path > 0 and chord >= CHORD_MIN_M and chord / path >= CHORD_MIN_STRAIGHTNESS:
            out.append((sel, chord))
            i = j
        else:
            i += 2
    return out


#: the extra corpus of issue #25 (``benchmarks.real_walks --extra``), read when it is there
DEFAULT_EXTRA = Path("/work/extra_data")


def _counted_steps_pct(n_steps: int, counted) -> float:
    return 100.0 * (n_steps / counted - 1.0) if counted else math.nan


def phone_walks(data_root, extra=None, *, split: str | None = None, ipin: bool = True) -> list[PhoneWalk]:
    """Every phone walk with a distance truth under ``data_root`` (and the extra corpus ``extra``, default
    :data:`DEFAULT_EXTRA` if present), with its split (``benchmarks.splits``): IPIN 2023's surveyed landmark
    stretches, every real walk with GPS (:func:`benchmarks.datasets.phone_walks.real_walks`) by its straight
    chords, every counted clip with a stated path, the trundle wheel.  A walk whose run finds no step or no
    chord is kept with an empty truth? No: a GPS walk without one straight chord has no distance truth and is
    listed by :func:`phone_walks_without_truth`; a walk with chords but no steps inside counts at -100 %.
    ``split``: only that split's walks (the others are not run); ``ipin``: False leaves IPIN 2023 out."""
    from benchmarks.datasets.phone_walks import STEP_CLIP, real_walks
    from benchmarks.splits import split_of
    from core.importers import load_recording

    root = Path(data_root)
    if extra is None and DEFAULT_EXTRA.is_dir():
        extra = DEFAULT_EXTRA
    out = []
    for lw in ipin_walks(str(root)) if ipin else ():  # surveyed landmarks, detours dropped (ipin_walks)
        route = lw.name[1:3]
        if split is not None and split_of("ipin2023_track3", {"route": route}) != split:
            continue
        out.append(PhoneWalk(lw.name, "ipin2023_track3", split_of("ipin2023_track3", {"route": route}), "landmarks",
                             [(lw.features, lw.distance_m)], modes=[[CARRY_HANDHELD] * len(lw.features)]))  # "hand"
    for w in real_walks(root, Path(extra) if extra else None):
        if split is not None and w.split != split:
            continue
        try:
            rec = load_recording(str(w.folder), warn=False)
        except Exception as e:  # an unreadable walk is listed, never dropped silently
            print(f"phone_walks: {w.name}: {e}", file=sys.stderr)
            continue
        if w.kind == STEP_CLIP:
            if not w.path_m:
                continue
            steps, carry = _run_steps(rec)
            out.append(PhoneWalk(w.walk, w.dataset, w.split, "loop" if w.closed_loop else "path",
                                 [([s.features for s in steps], float(w.path_m))], carry,
                                 [[s.carry_mode for s in steps]], _counted_steps_pct(len(steps), w.steps_counted)))
            continue
        if "gps" not in rec.streams:
            continue
        steps, carry = _run_steps(rec)
        spans = chord_spans(steps, rec.streams["gps"])
        if not spans:
            continue
        out.append(PhoneWalk(w.walk, w.dataset, w.split, "gps_chords",
                             [([steps[k].features for k in sel], chord) for sel, chord in spans], carry,
                             [[steps[k].carry_mode for k in sel] for sel, _ in spans]))
    for lw in trundle_walks(str(root)) if split in (None, split_of("trundlewheel_distance")) else ():
        out.append(PhoneWalk(lw.name, "trundlewheel_distance", split_of("trundlewheel_distance"), "wheel",
                             [(lw.features, lw.distance_m)]))
    return [w for w in out if w.stretches]


def fit_phone_c(walks, split: str = "tuning") -> float:
    """The default C from the phones of ``split`` (the tuning split: the shipped default), every source
    (dataset) weighted alike and every walk alike within it: the C whose mean signed error over the walks is
    zero, ``1 / mean(1 / C_walk)`` (:meth:`PhoneWalk.c_needed`; ``C / C_walk - 1`` is a walk's error)."""
    ws = [w for w in walks if w.split == split and w.c_needed() > 0 and math.isfinite(w.c_needed())]
    if not ws:
        raise ValueError(f"no phone walk with a distance truth in the {split} split")
    groups: dict = {}
    for w in ws:
        groups.setdefault(w.dataset, []).append(1.0 / w.c_needed())
    return float(1.0 / np.mean([np.mean(v) for v in groups.values()]))


#: a walk counts for a carry mode's own C when at least this share of its measured steps are in that mode
CARRY_FIT_MIN_SHARE = 0.8


def mode_share(w: PhoneWalk) -> tuple[str, float]:
    """The main carry mode of ``w``'s measured steps and its share."""
    modes = [m for k in range(len(w.stretches)) for m in w.stretch_modes(k)]
    if not modes:
        return MODE_NOT_RECORDED, 0.0
    m = w.main_mode()
    return m, modes.count(m) / len(modes)


def fit_carry_c(walks, split: str = "tuning") -> CarryC:
    """C per carry mode from the phones of ``split``: a mode with walks (:data:`CARRY_FIT_MIN_SHARE` of their
    steps in it) gets :func:`fit_phone_c` over them, every other mode the fit over all walks."""
    default = fit_phone_c(walks, split)
    by_mode = {}
    for w in walks:
        m, share = mode_share(w)
        if w.split == split and share >= CARRY_FIT_MIN_SHARE:
            by_mode.setdefault(m, []).append(w)
    return CarryC(default, tuple(sorted((m, fit_phone_c(v, split)) for m, v in by_mode.items())))


def leave_one_dataset_out(walks, fit=fit_phone_c, split: str = "tuning") -> list[tuple[str, object, list]]:
    """Transfer on ``split``: per dataset (a source: other phones, other walkers) the fit on the other datasets
    and that fit's signed errors on the held-out dataset's walks: ``[(dataset, fit, [(walk, error %)])]``."""
    ws = [w for w in walks if w.split == split]
    out = []
    for ds in sorted({w.dataset for w in ws}):
        model = fit([w for w in ws if w.dataset != ds], split)
        out.append((ds, model, [(w.name, w.error_pct(model)) for w in ws if w.dataset == ds]))
    return out


def error_stats(errors) -> dict:
    """Median absolute and mean signed error (%) of walks' signed errors; a failed walk (nan) counts as
    +inf in the median and is counted, never dropped."""
    e = np.array([x if math.isfinite(x) else math.inf for x in errors], float)
    fin = e[np.isfinite(e)]
    return {"n": int(e.size), "failed": int(e.size - fin.size),
            "median_abs_pct": float(np.median(np.abs(e))) if e.size else math.nan,
            "mean_signed_pct": float(fin.mean()) if fin.size else math.nan}


def write_phone_default(walks, old: dict, path, created: str = "") -> dict:
    """Write ``old`` (a ``default.json`` dict) with C refitted on the tuning split's phones (:func:`fit_phone_c`)
    to ``path``, stating its data, its tuning walks' own C, its tuning error and the leave-one-dataset-out
    transfer (``training.phones``); returns the dict written.  ``python -m tools.train_stride --phones``."""
    from core.pdr.stride_models import model_from_dict

    c_new = fit_phone_c(walks, "tuning")
    training = dict(old.get("training", {}))
    c_old = float(training.get("phones", {}).get("c_before", old["c"]))
    tuning = [w for w in walks if w.split == "tuning"]
    stats = error_stats([w.error_pct(c_new) for w in tuning])
    training["phones"] = {
        "issue": 25, "tool": "python -m tools.train_stride --phones", "split": "tuning",
        "data": "IPIN 2023 tuning routes 01, 02, 21, 22 (hand-held, two phones; surveyed landmark stretches) and "
                "the tuning split's phone walks with GPS (benchmarks.splits.REAL_TUNING_REPOS) by their straight "
                "40-s chords of good fixes: phone_walks_more/thomasdingemanse_lopen (carry detected as bag, "
                "probably a trouser pocket); fif911/ML4QS has no straight chord, psy901/SensorActivity no distance",
        "walks": [{"name": w.name, "dataset": w.dataset, "truth": w.truth, "distance_m": round(w.distance_m, 1),
                   "carry_mode": mode_share(w)[0], "c": round(w.c_needed(), 4)} for w in tuning],
        "rule": "1 / mean over the datasets of (mean over the dataset's walks of 1 / C_walk): zero mean signed "
                "error, every source weighted alike; one C for every carry mode (a per-mode C had one walk "
                "outside the hand and gave the same leave-one-dataset-out errors)",
        "tuning_error_pct": {"median_abs": round(stats["median_abs_pct"], 2),
                             "mean_signed": round(stats["mean_signed_pct"], 2), "walks": stats["n"]},
        "leave_one_dataset_out": [
            {"held_out": ds, "c": round(float(m), 4),
             **{k: round(v, 2) for k, v in error_stats([e for _, e in errs]).items() if k.endswith("_pct")}}
            for ds, m, errs in leave_one_dataset_out(walks)],
        "c_before": c_old,
    }
    d = dict(old, c=c_new, training=training, placement="phone",
             description="Weinberg, constant C refitted on the tuning split's phones (issue #25)")
    if created:
        d["created"] = created
    model_from_dict(d, source=str(path))  # a file the reader takes
    Path(path).write_text(json.dumps(d, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return d


def _c_text(c) -> str:
    if isinstance(c, CarryC):
        return f"{c.default:.4f}" + "".join(f", {m} {v:.4f}" for m, v in c.by_mode)
    return f"{float(c):.4f}"


def phone_distance_markdown(walks, c_before, c_after, lodo=None) -> str:
    """Per walk and per split: the distance error (no calibration, no profile) of the old and the new default
    C (a constant or a :class:`CarryC`); ``lodo``: :func:`leave_one_dataset_out`'s rows on the tuning split."""
    lines = ["## Distance without calibration on phones (issue #25)", "",
             f"Weinberg C before: {_c_text(c_before)}; after: {_c_text(c_after)}.  Steps from `Pipeline()` (the "
             "default step detector, carry detection on, no GPS, no profile); truth: IPIN's surveyed landmark "
             "stretches, the straight 40-s chords of good GPS fixes (accuracy <= 10 m, chord >= 30 m, >= 97 % of the "
             "path; chosen from the fixes alone), a counted clip's stated path, the trundle wheel.  Error = "
             "estimated / true - 1 (GPS chords: the median over the walk's chords).  A walk that lost its steps "
             "keeps its error (steps % where they were counted).", "",
             "| split | walk | dataset | truth | distance m | main carry mode (share) | walk's C | steps vs count % | "
             "error before % | error after % |", "|---|---|---|---|---|---|---|---|---|---|"]
    for split in ("tuning", "report"):
        for w in [w for w in walks if w.split == split]:
            m, share = mode_share(w)
            mode = f"{m} ({100 * share:.0f} %)" if share > 0 else "no step"
            st = f"{w.steps_error_pct:+.1f}" if math.isfinite(w.steps_error_pct) else "–"
            lines.append(f"| {split} | {w.name} | {w.dataset} | {w.truth} | {w.distance_m:.0f} | {mode} "
                         f"| {w.c_needed():.3f} | {st} | {w.error_pct(c_before):+.1f} | {w.error_pct(c_after):+.1f} |")
    lines += ["", "| split | group | walks | median abs before % | mean signed before % | median abs after % | "
              "mean signed after % |", "|---|---|---|---|---|---|---|"]
    for split in ("tuning", "report"):
        ws = [w for w in walks if w.split == split]
        groups = [("all", ws)] + [(f"truth {t}", [w for w in ws if w.truth == t]) for t in sorted({w.truth for w in ws})]
        groups += [(f"dataset {d}", [w for w in ws if w.dataset == d]) for d in sorted({w.dataset for w in ws})]
        modes = [(w, *mode_share(w)) for w in ws]
        groups += [(f"carry {m} (>= {100 * CARRY_FIT_MIN_SHARE:.0f} % of steps)",
                    [w for w, mw, sh in modes if mw == m and sh >= CARRY_FIT_MIN_SHARE])
                   for m in sorted({mw for _, mw, sh in modes if sh >= CARRY_FIT_MIN_SHARE})]
        for label, g in groups:
            if not g:
                continue
            b = error_stats([w.error_pct(c_before) for w in g])
            a = error_stats([w.error_pct(c_after) for w in g])
            lines.append(f"| {split} | {label} | {len(g)} | {b['median_abs_pct']:.1f} | {b['mean_signed_pct']:+.1f} | "
                         f"{a['median_abs_pct']:.1f} | {a['mean_signed_pct']:+.1f} |")
    if lodo:
        lines += ["", "Transfer on the tuning split, leave one dataset out (fit on the other tuning datasets, score the "
                  "held-out one):", "", "| held-out dataset | C fitted without it | walks | median abs % | mean signed % |",
                  "|---|---|---|---|---|"]
        for ds, model, errs in lodo:
            st = error_stats([e for _, e in errs])
            lines.append(f"| {ds} | {_c_text(model)} | {st['n']} | {st['median_abs_pct']:.1f} | "
                         f"{st['mean_signed_pct']:+.1f} |")
    return "\n".join(lines) + "\n"
