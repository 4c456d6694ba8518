"""The benchmark run: every dataset present, our pipeline and the peers on each recording.

``python -m benchmarks [--data DIR] [--quick] [--out FILE] [--plots DIR] [--only DATASET] [--jobs N]``

For every trial of every dataset module found under the data root:

1. load it (``Trial.open``) and run :class:`core.pdr.pipeline.Pipeline` once
   (with the walker's height when the dataset gives it);
2. steps: count in the walk window (the whole recording when the dataset
   marks none), step-count error, step timing F1 against the true instants;
   other counters' counts as peers;
3. distance: sum of our step lengths in the walk window (or in the trial's
   measured ``legs``) against the truth;
4. landmarks: our track and every heading peer's (:mod:`benchmarks.peers`:
   same steps, same lengths, only the attitude differs), corrected by the
   site's magnetic declination, against the landmarks
   (:func:`benchmarks.metrics.landmark_errors`).

Trials run in parallel processes (``--jobs``, default 2); progress goes to
stderr, one line per recording.  The Markdown report and the plots are made
by :mod:`benchmarks.report`; :func:`headline` gives the numbers the targets
and the CI guard (:mod:`benchmarks.guard`) look at.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from benchmarks import metrics as M
from benchmarks.datasets.base import Trial, default_data_root
from benchmarks.headline import evaluate_targets, headline

#: dataset modules in report order (ipol and trundlewheel belong to the stride-length work; optional)
DATASET_MODULES = ("oxford", "brajdic_harle", "ipin2023", "ms_indoor", "ipol", "trundlewheel")


def dataset_modules(only: list[str] | None = None) -> tuple[list, dict]:
    """Importable dataset modules ``[module]`` and ``{name: import error}``."""
    mods, errors = [], {}
    for name in DATASET_MODULES:
        try:
            mod = importlib.import_module(f"benchmarks.datasets.{name}")
        except Exception as e:  # a reader in progress must not stop the others
            errors[name] = f"{type(e).__name__}: {e}"
            continue
        if only and not any(o in (name, mod.NAME) for o in only):
            continue
        mods.append(mod)
    return mods, errors


# ---------------------------------------------------------------------------
# the quick subset (CI guard): fixed, documented choices, not tuned per file


def quick_subset(dataset: str, trials: list[Trial]) -> list[int]:
    """Indices of the trials the quick run uses.

    * Oxford: the hand-held traces and the first trace of every other placement
      (the step-count headlines of both targets);
    * Brajdic-Harle: all (short);
    * IPIN 2023: repetitions 01 and 03 of every route (one per phone);
    * MS indoor: every other trace;
    * IPOL, trundle wheel: the first four.
    """
    idx = list(range(len(trials)))
    if dataset == "oxford_step_counter":
        seen, out = set(), []
        for i, t in enumerate(trials):
            if t.placement == "hand" or t.placement not in seen:
                out.append(i)
            seen.add(t.placement)
        return out
    if dataset == "brajdic_harle_handheld":
        return idx
    if dataset == "ipin2023_track3":
        return [i for i, t in enumerate(trials) if t.info.get("repetition") in ("01", "03")]
    if dataset == "ms_indoor_location_2020":
        return idx[::2]
    return idx[:4]


# ---------------------------------------------------------------------------
# one trial


def _in_window(t_ns: np.ndarray, window) -> np.ndarray:
    if window is None:
        return np.ones(len(t_ns), dtype=bool)
    return (t_ns >= window[0]) & (t_ns <= window[1])


def evaluate_trial(trial: Trial, peer_names=(), keep_tracks: bool = True) -> dict:
    """Run the pipeline (and peers) on one trial; every metric its ground truth allows, as a dict."""
    from core.pdr.pipeline import Pipeline

    from benchmarks import peers as P

    t0 = time.perf_counter()
    rec = trial.open()
    t_load = time.perf_counter() - t0
    height = trial.subject.get("height_m") if trial.subject else None
    res = Pipeline(height_m=height).run(rec)
    t_run = time.perf_counter() - t0 - t_load
    tr = res.track
    r: dict = {
        "dataset": trial.dataset, "name": trial.name, "placement": trial.placement, "info": dict(trial.info),
        "labels": list(res.labels), "duration_s": rec.duration_s,
        "events": int(sum(len(s) for n, s in rec.streams.items() if n in ("acc", "gyro", "mag"))),
        "n_steps_total": len(tr), "counters": dict(res.counters), "notes": trial.notes,
    }
    q = res.attitude.q_wxyz
    r["attitude_nan_pct"] = 100.0 * float(np.mean(~np.isfinite(q).all(axis=1))) if len(q) else 0.0
    used, rej = res.counters.get("mag_used", 0), res.counters.get("mag_rejected", 0)
    r["mag_rejected_pct"] = 100.0 * rej / (used + rej) if used + rej else math.nan
    win = _in_window(tr.t_ns, trial.walk_t_ns)

    # -- steps
    n_true = trial.step_count if trial.step_count is not None else (
        len(trial.step_t_ns) if trial.step_t_ns is not None else None)
    if n_true is not None or trial.peer_step_counts:
        r["steps_true"] = n_true
        r["steps_ours"] = int(np.sum(win))
        r["step_err_pct"] = M.step_count_error_pct(r["steps_ours"], n_true) if n_true else math.nan
        r["peer_counts"] = {k: {"count": int(v), "err_pct": M.step_count_error_pct(v, n_true) if n_true else math.nan}
                            for k, v in trial.peer_step_counts.items()}
    if trial.step_t_ns is not None and len(trial.step_t_ns):
        sm = M.match_steps(tr.t_ns[win], trial.step_t_ns)
        r.update(step_f1=sm.f1, step_precision=sm.precision, step_recall=sm.recall, step_lag_s=sm.median_lag_s)

    # -- distance: over the walk window, or over the measured legs when the trial has them
    #    (``legs``: (t_start_ns, t_end_ns, length_m) tuples, e.g. IPOL's two straight 10 m legs)
    legs = getattr(trial, "legs", ()) or ()
    if legs:
        r["distance_true_m"] = float(sum(leg[2] for leg in legs))
        r["distance_ours_m"] = float(sum(np.sum(tr.length_m[_in_window(tr.t_ns, leg[:2])]) for leg in legs))
    elif trial.distance_m:
        r["distance_true_m"] = float(trial.distance_m)
        r["distance_ours_m"] = float(np.sum(tr.length_m[win]))
    if "distance_true_m" in r:
        r["distance_err_pct"] = M.distance_error_pct(r["distance_ours_m"], r["distance_true_m"])

    # -- landmarks
    lm = trial.landmarks
    if lm is not None and len(lm.t_ns) >= 2:
        decl = trial.declination_rad or 0.0
        headings = {"ours": tr.heading_rad}
        t_peer = time.perf_counter()
        if peer_names and len(tr):
            pipe = Pipeline()
            ph, perr = P.run_peers(rec, tr.t_ns, names=peer_names, grid_rate_hz=pipe.grid_rate_hz,
                                   cutoff_hz=pipe.smoother.cutoff_hz, delay_s=pipe.heading_delay_s,
                                   forward_b=pipe.smoother.forward_b)
            headings.update(ph)
            if perr:
                r["peer_errors"] = perr
        r["peer_runtime_s"] = time.perf_counter() - t_peer
        lt = lm.t_ns
        seg = (tr.t_ns > lt[0]) & (tr.t_ns <= lt[-1])
        path = M.polyline_length(lm.east_m, lm.north_m)
        r.update(n_landmarks=len(lt), path_m=path, steps_between_landmarks=int(np.sum(seg)),
                 steps_before_first_landmark=int(np.sum(tr.t_ns <= lt[0])),
                 walk_time_s=(lt[-1] - lt[0]) * 1e-9)
        r["lm_distance_ours_m"] = float(np.sum(tr.length_m[seg]))
        r["lm_distance_err_pct"] = M.distance_error_pct(r["lm_distance_ours_m"], path)
        r["sources"] = {}
        tracks = {}
        for name, h in headings.items():
            h = np.asarray(h, dtype=float) - decl
            if len(h) and not np.all(np.isfinite(h)):
                h = np.where(np.isfinite(h), h, np.nanmean(h) if np.any(np.isfinite(h)) else 0.0)
            e, n = M.dead_reckon(tr.length_m, h)
            le = M.landmark_errors(tr.t_ns, e, n, h, lt, lm.east_m, lm.north_m)
            r["sources"][name] = {
                "lm_mean_m": le.mean_m, "lm_fit_mean_m": le.mean_fit_m, "lm_final_m": le.final_m,
                "loop_pct": le.loop_closure_pct, "seg_heading_deg": le.segment_heading_mae_deg,
                "fit_rotation_deg": math.degrees(le.fit_rotation_rad),
                "lm_errors_m": [float(x) for x in le.errors_m],
            }
            if keep_tracks:
                start = M.positions_at(tr.t_ns, e, n, lt[:1])[0]
                xy = np.column_stack([e[seg], n[seg]]) - start
                xy = np.vstack([[0.0, 0.0], xy]) + [lm.east_m[0], lm.north_m[0]]
                tracks[name] = {"xy": xy, "fit_rotation_rad": le.fit_rotation_rad}
        if keep_tracks:
            r["plot"] = {"landmarks": np.column_stack([lm.east_m, lm.north_m]), "tracks": tracks}
    r["runtime_s"] = time.perf_counter() - t0
    r["load_s"] = t_load
    r["pipeline_s"] = t_run
    return r


# ---------------------------------------------------------------------------
# parallel execution


_TRIALS: dict = {}


def _trials_of(module_name: str, root: str) -> list[Trial]:
    key = (module_name, root)
    if key not in _TRIALS:
        mod = importlib.import_module(f"benchmarks.datasets.{module_name}")
        _TRIALS[key] = mod.trials(Path(root))
    return _TRIALS[key]


def _task(module_name: str, root: str, index: int, peer_names) -> dict:
    trial = _trials_of(module_name, root)[index]
    try:
        return evaluate_trial(trial, peer_names)
    except Exception as e:  # one bad recording must not stop the run
        import traceback

        return {"dataset": trial.dataset, "name": trial.name, "placement": trial.placement,
                "info": dict(trial.info), "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(limit=3)}


def run(root: Path, *, quick: bool = False, only=None, jobs: int = 2, peer_names=None,
        log=sys.stderr) -> dict:
    """Evaluate every trial present; returns ``{"results": [...], "datasets": {...}, ...}``."""
    from benchmarks import peers as P

    root = Path(root)
    if peer_names is None:
        peer_names = P.QUICK_PEERS if quick else P.ALL_PEERS
    peer_names = tuple(P.available_peers(peer_names))
    mods, import_errors = dataset_modules(only)
    tasks, datasets = [], {}
    for mod in mods:
        short = mod.__name__.rsplit(".", 1)[1]
        if not mod.available(root):
            continue
        trials = _trials_of(short, str(root))
        idx = quick_subset(mod.NAME, trials) if quick else list(range(len(trials)))
        datasets[mod.NAME] = {"module": short, "n_trials": len(trials), "n_run": len(idx),
                              "doc": (mod.__doc__ or "").strip().split("\n")[0]}
        tasks += [(short, str(root), i, peer_names) for i in idx]
    print(f"benchmark: {len(tasks)} recordings in {len(datasets)} datasets under {root} "
          f"({'quick' if quick else 'full'} run, {jobs} processes, peers: {', '.join(peer_names) or 'none'})",
          file=log, flush=True)
    t0 = time.perf_counter()
    results = []
    done = 0

    def report(r):
        nonlocal done
        done += 1
        results.append(r)
        print(f"[{done:3d}/{len(tasks)}] {r['dataset']}/{r['name']}: {_progress_line(r)}", file=log, flush=True)

    if jobs <= 1:
        for task in tasks:
            report(_task(*task))
    else:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            futures = [ex.submit(_task, *task) for task in tasks]
            for f in as_completed(futures):
                report(f.result())
    wall = time.perf_counter() - t0
    rank = {name: k for k, name in enumerate(datasets)}
    results.sort(key=lambda r: (rank.get(r["dataset"], len(rank)), r["name"]))
    print(f"benchmark: done in {wall:.0f} s", file=log, flush=True)
    return {"results": results, "datasets": datasets, "import_errors": import_errors, "wall_s": wall,
            "quick": quick, "jobs": jobs, "peers": list(peer_names), "root": str(root)}


def _progress_line(r: dict) -> str:
    if "error" in r:
        return "ERROR " + r["error"]
    parts = [f"{r['runtime_s']:.1f} s"]
    if r.get("steps_true"):
        parts.append(f"steps {r['steps_ours']}/{r['steps_true']} ({r['step_err_pct']:+.1f} %)")
    if "step_f1" in r:
        parts.append(f"F1 {r['step_f1']:.3f}")
    if "distance_err_pct" in r:
        parts.append(f"distance {r['distance_err_pct']:+.1f} %")
    if "sources" in r:
        s = r["sources"]["ours"]
        parts.append(f"landmarks {s['lm_mean_m']:.1f} m (fit {s['lm_fit_mean_m']:.1f} m)")
        if s["loop_pct"] == s["loop_pct"]:
            parts.append(f"loop {s['loop_pct']:.1f} %")
        if "rotvec" in r["sources"]:
            parts.append(f"rotvec {r['sources']['rotvec']['lm_mean_m']:.1f} m")
    return ", ".join(parts)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    ap.add_argument("--quick", action="store_true", help="the quick subset (CI guard) with the cheap peers")
    here = Path(__file__).resolve().parent
    ap.add_argument("--out", type=Path, default=here / "RESULTS.md",
                    help="Markdown report to write (default: benchmarks/RESULTS.md)")
    ap.add_argument("--plots", type=Path, default=here / "plots",
                    help="folder for the PNG plots (default: benchmarks/plots)")
    ap.add_argument("--only", action="append", default=None, metavar="DATASET",
                    help="run only this dataset (module or folder name; repeatable)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="parallel processes (default 2)")
    ap.add_argument("--peers", default=None,
                    help="comma-separated heading peers (default: all installed; quick: rotvec,imufusion)")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    root = args.data or default_data_root()
    if not root.is_dir():
        print(f"benchmark: no data folder at {root}", file=sys.stderr)
        return 2
    peer_names = tuple(p for p in args.peers.split(",") if p) if args.peers is not None else None
    run_info = run(root, quick=args.quick, only=args.only, jobs=args.jobs, peer_names=peer_names)
    if not args.quick and not args.only:
        # issue #4: leave-one-subject-out study of the stride models (trains them; about a minute)
        from benchmarks.stride_eval import stride_section

        print("benchmark: stride-model cross-validation ...", file=sys.stderr, flush=True)
        run_info["stride_section"] = stride_section(root)
    from benchmarks import report

    report.write(run_info, args.out, args.plots, argv=sys.argv[1:] if argv is None else argv)
    h = headline(run_info["results"])
    for t in evaluate_targets(h):
        v = "n/a" if t["value"] is None else f"{t['value']:.2f}"
        lim = "n/a" if t["limit"] is None else f"{t['limit']:.2f}"
        status = {True: "met", False: "MISSED", None: "no data"}[t["met"]]
        print(f"target {t['metric']} = {v} ({t['op']} {lim}): {status}", file=sys.stderr)
    print(f"benchmark: report written to {args.out}", file=sys.stderr)
    return 0
