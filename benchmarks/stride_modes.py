"""Stride per carry mode (issue #25 section 4): should Weinberg's length (eq. 4) be scaled by the detected carry mode?

``python -m benchmarks.stride_modes [--split tuning|report] [--cache FILE] [--data DIR] [--extra DIR] [--extra2 DIR]``

Every real walk of the split with a distance truth, each step with the carry mode the pipeline gave it:

* the truth walks (:mod:`benchmarks.truth_walks`: OxIOD Vicon, RIDI Tango; the product's default path, the step
  lengths it gave; truth: the path from the first step to the last, as that benchmark measures it),
* IPIN 2023's routes (surveyed landmark stretches, detours dropped as in :func:`benchmarks.stride_eval.ipin_walks`;
  the carry mode the default ``Pipeline()`` detected, not the dataset's "hand"),
* the phone walks of :func:`benchmarks.stride_eval.phone_walks` (GPS chords, counted clips with a stated path:
  ``python -m tools.train_stride --phones``' walks; lengths ``C * (A_max - A_min) ** 0.25`` with the shipped C).

A walk's error with per-mode scales ``s`` is ``sum(s[mode] * L) / truth - 1`` (GPS chords: the median over the
chords, as :meth:`benchmarks.stride_eval.PhoneWalk.error_pct`).  :func:`fit_scales` fits a scale for a mode (never
hand-held) only where at least :data:`MIN_WALKS` walks of at least :data:`MIN_WALKERS` walkers are over
:data:`MIN_SHARE` of their steps in it: per walk the scale that zeroes its error, then ``1 / mean(1 / s)`` over
the sources (datasets) of the mean over each source's walks (zero mean signed error, every source alike; the rule of
:func:`benchmarks.stride_eval.fit_phone_c`).  Transfer: leave one walk out and leave one source out (the scales
refitted without it, the support rule applied again), against no scale.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import default_data_root
from benchmarks.options import read_json, write_json
from core.conventions import CARRY_HANDHELD

MIN_SHARE = 0.8
MIN_WALKS = 2
MIN_WALKERS = 2


@dataclass
class ModeWalk:
    """A walk with a distance truth: per stretch the steps' lengths (m, scale 1), their carry modes, the truth (m)."""

    name: str
    source: str  #: the dataset (a source of walks: a phone, a lab)
    walker: str  #: who walked (as far as the source tells)
    split: str
    truth: str
    stretches: list = field(default_factory=list)  #: [(lengths np.ndarray, modes tuple, truth_m)]

    def error_pct(self, scales: dict | None = None) -> float:
        scales = scales or {}
        est = np.array([float(np.sum(np.array([scales.get(m, 1.0) for m in modes]) * lens))
                        for lens, modes, _ in self.stretches])
        d = np.array([t for _, _, t in self.stretches], float)
        if self.truth == "gps_chords":
            return 100.0 * (float(np.median(est / d)) - 1.0)
        return 100.0 * (float(est.sum() / d.sum()) - 1.0)

    def mode_share(self) -> tuple[str, float]:
        modes = [m for _, ms, _ in self.stretches for m in ms]
        if not modes:
            return "no step", 0.0
        m = max(set(modes), key=modes.count)
        return m, modes.count(m) / len(modes)

    def shares(self) -> dict:
        modes = [m for _, ms, _ in self.stretches for m in ms]
        return {m: modes.count(m) / len(modes) for m in sorted(set(modes))} if modes else {}

    def scale_needed(self, mode: str, others: dict | None = None) -> float:
        """The scale of ``mode`` (the other modes at ``others``, else 1) that zeroes the walk's error (bisection)."""
        lo, hi = 0.2, 5.0
        f = lambda s: self.error_pct({**(others or {}), mode: s})  # noqa: E731
        if f(lo) > 0 or f(hi) < 0:
            return math.nan
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if f(mid) < 0 else (lo, mid)
        return 0.5 * (lo + hi)


# -- collecting ---------------------------------------------------------------------------------------------------
def truth_mode_walks(extra2: Path, split: str) -> list[ModeWalk]:
    from benchmarks.real_walks import run_default, step_arrays
    from benchmarks.truth_walks import path_length_m, read_walk, truth_walks

    out = []
    for w in truth_walks(extra2):
        if w.split != split:
            continue
        rec = read_walk(w)
        res, pipe, _ = run_default(rec, w.path.parent)
        # ridi_<walker>_..., tyrex_<walker>_...
        walker = (w.name.split("_")[1] if w.dataset.startswith(("ridi", "tyrex"))
                  else f"oxiod {w.path.parents[2].name}/{w.path.parents[1].name}")
        mw = ModeWalk(w.name, w.dataset, walker, split, "truth path")
        if len(res.steps) >= 2:
            posi = rec.streams["posi"]
            st_t = np.array([s.t_ns for s in res.steps], np.int64)
            truth_m = path_length_m(posi.t_ns, posi.values[:, :2], int(st_t[0]), int(st_t[-1]))
            steps = res.steps[1:]  # the steps after the first, as the truth's span (benchmarks.truth_walks)
            mw.stretches = [(np.array([s.length_m for s in steps]), tuple(s.carry_mode for s in steps), truth_m)]
        out.append(mw)
        print(f"  {w.name}: {len(res.steps)} steps, {mw.mode_share()}", file=sys.stderr)
    return out



def save_walks(path: Path, walks: list) -> None:
    """The collected walks as JSON (no pickle: benchmarks read nothing that can run code)."""
    write_json(path, [{"name": w.name, "source": w.source, "walker": w.walker, "split": w.split, "truth": w.truth,
                       "stretches": [[lens, list(modes), t] for lens, modes, t in w.stretches]} for w in walks],
               digits=None, indent=None)


def load_walks(path: Path) -> list:
    """What :func:`save_walks` wrote."""
    return [ModeWalk(r["name"], r["source"], r["walker"], r["split"], r["truth"],
                     [(np.array(lens, float), tuple(modes), float(t)) for lens, modes, t in r["stretches"]])
            for r in read_json(path)]

def ipin_mode_walks(data_root: Path, split: str) -> list[ModeWalk]:
    from benchmarks.datasets import ipin2023
    from benchmarks.splits import split_of
    from core.pdr.pipeline import Pipeline

    if not ipin2023.available(data_root):
        return []
    out = []
    for tr in ipin2023.trials(data_root):
        if split_of("ipin2023_track3", {"route": tr.name[1:3]}) != split:
            continue
        rec = tr.open()
        lm = tr.landmarks
        if lm is None or len(lm.t_ns) < 3:
            continue
        steps = Pipeline().run(rec).steps
        t = np.array([s.t_ns for s in steps], np.int64)
        seg = np.hypot(np.diff(lm.east_m), np.diff(lm.north_m))
        mw = ModeWalk(tr.name, "ipin2023_track3", str(tr.subject.get("id") or tr.info.get("phone") or "ipin"),
                      split, "landmarks")
        for k in range(len(seg)):
            sel = np.flatnonzero((t > lm.t_ns[k]) & (t <= lm.t_ns[k + 1]))
            if len(sel) and seg[k] / len(sel) < 0.3:  # a detour or a wait (stride_eval.ipin_walks' rule)
                continue
            mw.stretches.append((np.array([steps[i].length_m for i in sel]),
                                 tuple(steps[i].carry_mode for i in sel), float(seg[k])))
        out.append(mw)
        print(f"  {tr.name}: {len(steps)} steps, {mw.mode_share()}", file=sys.stderr)
    return out


def phone_mode_walks(data_root: Path, extra: Path | None, split: str) -> list[ModeWalk]:
    from benchmarks import stride_eval
    from core.pdr.stride import ConstantCoefficient
    from core.pdr.stride_models import weinberg_root

    c = ConstantCoefficient().c
    out = []
    for w in stride_eval.phone_walks(data_root, extra, split=split, ipin=False):
        mw = ModeWalk(w.name, w.dataset, w.dataset, w.split, w.truth)
        for k, (f, d) in enumerate(w.stretches):
            mw.stretches.append((c * weinberg_root(f), tuple(w.stretch_modes(k)), float(d)))
        out.append(mw)
    return out


def collect(data_root: Path, extra: Path | None, extra2: Path | None, split: str) -> list[ModeWalk]:
    walks = ipin_mode_walks(data_root, split) + phone_mode_walks(data_root, extra, split)
    if extra2 is not None:
        walks += truth_mode_walks(extra2, split)
    return walks


# -- fitting ------------------------------------------------------------------------------------------------------
def fit_scales(walks: list[ModeWalk], min_share: float = MIN_SHARE, min_walks: int = MIN_WALKS,
               min_walkers: int = MIN_WALKERS) -> dict:
    """``{mode: scale}`` for the modes the walks support (module doc); hand-held and unsupported modes absent (1)."""
    by_mode: dict = {}
    for w in walks:
        m, share = w.mode_share()
        if share >= min_share and m != CARRY_HANDHELD and w.stretches:
            by_mode.setdefault(m, []).append(w)
    scales = {}
    for m, ws in sorted(by_mode.items()):
        if len(ws) < min_walks or len({(w.source, w.walker) for w in ws}) < min_walkers:
            continue
        groups: dict = {}
        for w in ws:
            s = w.scale_needed(m)
            if math.isfinite(s):
                groups.setdefault(w.source, []).append(1.0 / s)
        if groups:
            scales[m] = float(1.0 / np.mean([np.mean(v) for v in groups.values()]))
    return scales


def stats(errors) -> dict:
    """Count, median absolute and mean signed error (%).  A walk that failed (no steps or no truth: nan) counts
    in the median as +inf, never dropped; the mean is over the walks with an error (a failure has no sign), and
    the count says how many there were."""
    e = np.array([x if math.isfinite(x) else math.inf for x in errors], float)
    fin = e[np.isfinite(e)]
    return {"n": int(e.size), "median_abs": float(np.median(np.abs(e))) if e.size else math.nan,
            "mean_signed": float(fin.mean()) if fin.size else math.nan}


def study(walks: list[ModeWalk]) -> dict:
    """Per walk: the error with no scale, with the scales fitted on every walk (in sample), leave one walk out,
    leave one source out; the scales fitted on all."""
    ws = [w for w in walks if w.stretches]
    full = fit_scales(ws)
    rows = []
    for w in ws:
        lowo = fit_scales([v for v in ws if v is not w])
        loso = fit_scales([v for v in ws if v.source != w.source])
        rows.append({"walk": w, "base": w.error_pct(), "in": w.error_pct(full), "lowo": w.error_pct(lowo),
                     "loso": w.error_pct(loso), "lowo_scales": lowo, "loso_scales": loso})
    nan = math.nan  # a walk without steps or truth is counted, as failed, never dropped (every column alike)
    rows += [{"walk": w, "base": nan, "in": nan, "lowo": nan, "loso": nan} for w in walks if not w.stretches]
    return {"scales": full, "rows": rows, "failed": [w.name for w in walks if not w.stretches]}


def apply_study(walks: list[ModeWalk], scales: dict) -> dict:
    """Fixed ``scales`` (fitted on another split) on ``walks``: per walk the error without and with them."""
    rows = [{"walk": w, "base": w.error_pct() if w.stretches else math.nan,
             "in": w.error_pct(scales) if w.stretches else math.nan} for w in walks]
    return {"scales": scales, "rows": rows, "failed": [w.name for w in walks if not w.stretches]}


def _sc(s: dict) -> str:
    return ", ".join(f"{m} x{v:.3f}" for m, v in sorted(s.items())) or "none"


def markdown(res: dict, split: str, fitted_on: str = "") -> str:
    rows = res["rows"]
    keys = [k for k in ("base", "in", "lowo", "loso") if all(k in r for r in rows)]
    head = {"base": "no scale", "in": f"scales of the {fitted_on} split" if fitted_on else "in sample",
            "lowo": "leave walk out", "loso": "leave source out"}
    worst_key = "lowo" if "lowo" in keys else "in"
    where = f"fitted on the {fitted_on} split" if fitted_on else "fitted on all its walks"
    lines = [f"Stride per carry mode, {split} split: scales {where}: {_sc(res['scales'])}", "",
             "| walk | source | walker | truth | modes (share of steps) | " + " | ".join(head[k] + " %" for k in keys)
             + " |", "|---|---|---|---|---|" + "---|" * len(keys)]
    for r in rows:
        w = r["walk"]
        sh = ", ".join(f"{m} {100 * v:.0f}" for m, v in sorted(w.shares().items(), key=lambda kv: -kv[1])) or "no step"
        lines.append(f"| {w.name} | {w.source} | {w.walker} | {w.truth} | {sh} | "
                     + " | ".join(f"{r[k]:+.1f}" for k in keys) + " |")
    lines += ["", "| walks | " + " | ".join(head[k] + ": median abs / mean signed %" for k in keys)
              + f" | worst change ({head[worst_key]}, abs points) |", "|---|" + "---|" * (len(keys) + 1)]
    groups = [("all", rows)] + [(f"main mode {m}", [r for r in rows if r["walk"].mode_share()[0] == m])
                                for m in sorted({r["walk"].mode_share()[0] for r in rows})]
    for label, g in groups:
        cols = []
        for k in keys:
            s = stats([r[k] for r in g])
            cols.append(f"{s['median_abs']:.1f} / {s['mean_signed']:+.1f}")
        ch = [abs(r[worst_key]) - abs(r["base"]) for r in g if math.isfinite(r["base"])]
        lines.append(f"| {label} ({len(g)}) | " + " | ".join(cols) + f" | {max(ch) if ch else math.nan:+.1f} |")
    if res["failed"]:
        lines += ["", f"Walks without steps or truth (counted as failed): {', '.join(res['failed'])}"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--split", default="tuning", choices=("tuning", "report"))
    ap.add_argument("--data", type=Path, default=None, help="the data root (default: ../shared/data beside the repo)")
    ap.add_argument("--extra", type=Path, default=None, help="the extra corpus (default: stride_eval's)")
    ap.add_argument("--extra2", type=Path, default=None, help="the truth walks' folder (benchmarks.truth_walks)")
    ap.add_argument("--cache", type=Path, default=None, help="the collected walks (JSON): kept here / read from here")
    ap.add_argument("--fit-cache", type=Path, default=None,
                    help="the tuning split's cache: fit the scales there and apply them, fixed, to --split's walks")
    args = ap.parse_args(argv)
    if args.cache is not None and args.cache.exists():
        walks = load_walks(args.cache)
    else:
        walks = collect(args.data or default_data_root(), args.extra, args.extra2, args.split)
        if args.cache is not None:
            save_walks(args.cache, walks)
    if {w.split for w in walks} - {args.split}:  # a cache of another split would be labelled with this one
        ap.error(f"--cache {args.cache} holds {sorted({w.split for w in walks})} walks, not --split {args.split}'s")
    if args.fit_cache is not None:
        fit_on = [w for w in load_walks(args.fit_cache) if w.stretches]
        if {w.split for w in fit_on} - {"tuning"}:
            ap.error(f"--fit-cache {args.fit_cache} must hold tuning walks only (the scales are fitted there)")
        print(markdown(apply_study(walks, fit_scales(fit_on)), args.split, fit_on[0].split if fit_on else "?"))
    else:
        print(markdown(study(walks), args.split))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
