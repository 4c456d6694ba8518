"""The benchmark run: every dataset present, our pipeline and the peers on each recording.

``python -m benchmarks [--data DIR] [--quick] [--out FILE] [--plots DIR] [--only DATASET] [--jobs N] [--split S]
[--engine auto|fast|reference] [--peer-cache DIR | --no-peer-cache]``

For every trial of every dataset module found under the data root:

1. load it (``Trial.open``) and run our pipeline once, built by
   :func:`make_pipeline` (the walker's height when the dataset gives it, the
   site's magnetic declination; the one construction the normal run and the
   tuning harness :mod:`benchmarks.tune` share);
2. steps: count in the walk window (the whole recording when the dataset
   marks none), step-count error, step timing F1 against the true instants;
   other counters' counts as peers;
3. distance: sum of our step lengths in the walk window (or in the trial's
   measured ``legs``) against the truth;
4. landmarks: our track and every heading peer's (:mod:`benchmarks.peers`:
   same steps, same lengths, only the attitude differs; the peers' magnetic
   headings corrected by the site's declination afterwards), against the
   landmarks (:func:`benchmarks.metrics.landmark_errors`);
5. reference track (the ETH walk's own GPS, removed from the recording
   before anything runs): the same tracks against every fix, time-aligned
   (:func:`benchmarks.metrics.reference_track_errors`).

Every result row carries its split (``"split"``: ``tuning`` or ``report``,
declared in :mod:`benchmarks.splits`); ``--split`` runs one split only.

Trials run in parallel processes (``--jobs``, default 2); progress goes to
stderr, one line per recording.  Two things make a rerun cheap (issue #13):
our pipeline runs on the fast desktop path (:func:`desktop.fast.run_fast`,
the same results within 1e-9) when numba is installed (``--engine``), and
the peers' attitudes, which do not depend on our code, are kept in
``out/benchmarks/peer_cache`` between runs (``--peer-cache``,
``--no-peer-cache``; :func:`benchmarks.peers.peer_attitude` says what a
stored result must match).  The Markdown report and the plots are made
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
from benchmarks import splits as S
from benchmarks.datasets.base import Trial, default_data_root
from benchmarks.headline import evaluate_targets, headline
from benchmarks.options import selected
from desktop.engine import ENGINES

#: dataset modules in report order (ipol and trundlewheel belong to the stride-length work; optional)
DATASET_MODULES = ("oxford", "brajdic_harle", "ipin2023", "ms_indoor", "eth_walk", "ipol", "trundlewheel")
#: dataset modules with long recordings, started first
LONG_FIRST = ("eth_walk", "trundlewheel")


def _is_dataset_name(key: str) -> bool:
    """``key`` names a dataset (its module or its folder), not part of a recording's name."""
    if key in DATASET_MODULES:
        return True
    for name in DATASET_MODULES:
        try:
            if importlib.import_module(f"benchmarks.datasets.{name}").NAME == key:
                return True
        except Exception:  # a reader in progress: dataset_modules reports it
            continue
    return False


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
    * the ETH walk: its one recording;
    * IPOL, trundle wheel: the first four.

    The subset mixes both splits; the guard's headlines are per split.
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
# our pipeline, built in one place


def set_declination(pipeline, declination_rad: float) -> None:
    """Give our attitude filter the site's magnetic declination (rad, east positive).

    The one place the benchmark sets it: today ``AttitudeEKF.declination_rad``
    (read at every magnetometer update, so setting it after construction is
    the same as passing it to the constructor).
    """
    att = pipeline.attitude
    if not hasattr(att, "declination_rad"):
        raise TypeError(f"{type(att).__name__} has no declination_rad setting: adapt benchmarks.run.set_declination")
    att.declination_rad = float(declination_rad)


def make_pipeline(trial: Trial, **overrides):
    """Our pipeline for one trial: ``core.pdr.pipeline.Pipeline(**defaults, **overrides)``.

    Defaults from the trial: ``height_m`` (when the dataset knows the
    walker's height).  ``overrides`` go to ``Pipeline`` unchanged (e.g.
    ``attitude=SomeFilter(...)``, ``stride_model=...``) and win over the
    defaults.  Then the site's magnetic declination (a fact of the trial, not
    a setting) is given to whatever attitude filter the pipeline has
    (:func:`set_declination`), so our headings are true-north headings.
    """
    from core.pdr.pipeline import Pipeline

    kwargs = {"height_m": trial.subject.get("height_m") if trial.subject else None}
    kwargs.update(overrides)
    pipe = Pipeline(**kwargs)
    set_declination(pipe, trial.declination_rad or 0.0)
    site = getattr(trial, "site", None)
    outdoors = getattr(trial, "reference_track", None) is not None  # the walk had good GPS fixes
    if site is not None and outdoors and hasattr(pipe.attitude, "set_site_field"):
        # outdoors, the site's WMM field strength and dip: what a live app knows from its GPS fix.
        # Indoors (IPIN, Microsoft) the building bends the field and it is not given (seen on IPIN
        # route 04, report split: an offset estimated from the WMM there ruined three loops).
        _, dip, total = site.magnetic_field()
        pipe.attitude.set_site_field(total, dip)
    return pipe


# ---------------------------------------------------------------------------
# one trial


def _in_window(t_ns: np.ndarray, window) -> np.ndarray:
    if window is None:
        return np.ones(len(t_ns), dtype=bool)
    return (t_ns >= window[0]) & (t_ns <= window[1])


def _peer_headings(trial: Trial, rec, pipe, tr, peer_names, r: dict) -> dict:
    """The peers' per-step headings, magnetic, as our pipeline would smooth and read them (``{name: h}``)."""
    from benchmarks import peers as P

    if not peer_names or not len(tr):
        return {}
    dip = trial.site.magnetic_field()[1] if trial.site is not None else None
    t_peer = time.perf_counter()
    cached: list = []
    ph, perr = P.run_peers(rec, tr.t_ns, names=peer_names, magnetic_dip_rad=dip, cache_dir=_SETTINGS["peer_cache"],
                           cached=cached, grid_rate_hz=pipe.grid_rate_hz, cutoff_hz=pipe.smoother.cutoff_hz,
                           delay_s=pipe.heading_delay_s, forward_b=pipe.smoother.forward_b)
    r["peer_runtime_s"] = r.get("peer_runtime_s", 0.0) + time.perf_counter() - t_peer
    r["peers_cached"] = r.get("peers_cached", []) + cached
    if perr:
        r["peer_errors"] = perr
    return ph


def _finite_headings(h) -> np.ndarray:
    h = np.asarray(h, dtype=float)
    if len(h) and not np.all(np.isfinite(h)):
        h = np.where(np.isfinite(h), h, np.nanmean(h) if np.any(np.isfinite(h)) else 0.0)
    return h


def _placed_track(t_ns, east_m, north_m, seg, t_anchor_ns: int, anchor_en) -> np.ndarray:
    """The track's positions of the steps ``seg`` for a plot, shifted so it is at ``anchor_en`` at ``t_anchor_ns``."""
    start = M.positions_at(t_ns, east_m, north_m, np.array([t_anchor_ns], dtype=np.int64))[0]
    xy = np.column_stack([east_m[seg], north_m[seg]]) - start
    return np.vstack([[0.0, 0.0], xy]) + list(anchor_en)


def evaluate_trial(trial: Trial, peer_names=(), keep_tracks: bool = True, pipeline_overrides=None) -> dict:
    """Run the pipeline (and peers) on one trial; every metric its ground truth allows, as a dict.

    ``pipeline_overrides``: keyword arguments for :func:`make_pipeline`
    (passed on to ``Pipeline``).
    """
    t0 = time.perf_counter()
    split = S.trial_split(trial)
    rec = trial.open()
    t_load = time.perf_counter() - t0
    if trial.reference_track is not None and rec.has("gps"):
        raise RuntimeError(f"{trial.name}: the GPS used as reference is still in the recording")
    pipe = make_pipeline(trial, **(pipeline_overrides or {}))
    res, engine = run_ours(pipe, rec)
    t_run = time.perf_counter() - t0 - t_load
    tr = res.track
    r: dict = {
        "dataset": trial.dataset, "name": trial.name, "split": split, "placement": trial.placement,
        "info": dict(trial.info), "declination_deg": math.degrees(trial.declination_rad or 0.0),
        "labels": list(res.labels), "duration_s": rec.duration_s,
        "events": int(sum(len(s) for n, s in rec.streams.items() if n in ("acc", "gyro", "mag"))),
        "n_steps_total": len(tr), "counters": dict(res.counters), "notes": trial.notes, "engine": engine,
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

    # -- headings of every source, true north: ours has the declination inside, the peers' get it here
    lm = trial.landmarks
    ref = trial.reference_track
    headings = {}
    if (lm is not None and len(lm.t_ns) >= 2) or (ref is not None and len(ref.t_ns) >= 2):
        decl = trial.declination_rad or 0.0
        headings = {"ours": _finite_headings(tr.heading_rad)}
        for name, h in _peer_headings(trial, rec, pipe, tr, peer_names, r).items():
            headings[name] = _finite_headings(np.asarray(h, dtype=float) - decl)

    # -- landmarks
    if lm is not None and len(lm.t_ns) >= 2:
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
            e, n = M.dead_reckon(tr.length_m, h)
            le = M.landmark_errors(tr.t_ns, e, n, h, lt, lm.east_m, lm.north_m)
            r["sources"][name] = {
                "lm_mean_m": le.mean_m, "lm_fit_mean_m": le.mean_fit_m, "lm_final_m": le.final_m,
                "loop_pct": le.loop_closure_pct, "seg_heading_deg": le.segment_heading_mae_deg,
                "fit_rotation_deg": math.degrees(le.fit_rotation_rad),
                "lm_errors_m": [float(x) for x in le.errors_m],
            }
            if keep_tracks:
                tracks[name] = {"xy": _placed_track(tr.t_ns, e, n, seg, lt[0], (lm.east_m[0], lm.north_m[0])),
                                "fit_rotation_rad": le.fit_rotation_rad}
        if keep_tracks:
            r["plot"] = {"landmarks": np.column_stack([lm.east_m, lm.north_m]), "tracks": tracks}

    # -- a dense reference track (GPS): distance from it at every fix, time-aligned
    if ref is not None and len(ref.t_ns) >= 2:
        rt = ref.t_ns
        seg = (tr.t_ns > rt[0]) & (tr.t_ns <= rt[-1])
        r.update(n_fixes=len(rt), ref_path_m=M.polyline_length(ref.east_m, ref.north_m),
                 ref_source=ref.source, ref_hacc_median_m=M.nanmedian(ref.hacc_m) if ref.hacc_m is not None else None,
                 ref_distance_ours_m=float(np.sum(tr.length_m[seg])), ref_time_s=(rt[-1] - rt[0]) * 1e-9,
                 steps_between_fixes=int(np.sum(seg)))
        r["ref_sources"] = {}
        tracks = {}
        for name, h in headings.items():
            e, n = M.dead_reckon(tr.length_m, h)
            te = M.reference_track_errors(tr.t_ns, e, n, rt, ref.east_m, ref.north_m)
            r["ref_sources"][name] = {"median_m": te.median_m, "fit_median_m": te.median_fit_m, "p90_m": te.p90_m,
                                      "final_m": float(te.errors_m[-1]) if len(te.errors_m) else math.nan,
                                      "fit_rotation_deg": math.degrees(te.fit_rotation_rad)}
            if keep_tracks:
                tracks[name] = {"xy": _placed_track(tr.t_ns, e, n, seg, rt[0], (ref.east_m[0], ref.north_m[0])),
                                "fit_rotation_rad": te.fit_rotation_rad}
        if keep_tracks:
            r["ref_plot"] = {"reference": np.column_stack([ref.east_m, ref.north_m]), "tracks": tracks}
    r["runtime_s"] = time.perf_counter() - t0
    r["load_s"] = t_load
    r["pipeline_s"] = t_run
    return r


# ---------------------------------------------------------------------------
# parallel execution


_TRIALS: dict = {}
#: keyword-argument factory for our pipeline in this process (set in the workers by the pool initializer)
_FACTORY = None
#: this process's engine choice (``--engine``) and peer cache folder (None: none); set like the factory
_SETTINGS: dict = {"engine": "reference", "peer_cache": None}


def _set_factory(factory, engine: str = "reference", peer_cache=None) -> None:
    global _FACTORY
    _FACTORY = factory
    _SETTINGS.update(engine=engine, peer_cache=peer_cache)


def run_ours(pipe, rec) -> tuple:
    """``(result, engine that ran)``: :func:`desktop.engine.run_pipeline` on this process's engine."""
    from desktop.engine import run_pipeline

    return run_pipeline(pipe, rec, _SETTINGS["engine"])


def _trials_of(module_name: str, root: str) -> list[Trial]:
    key = (module_name, root)
    if key not in _TRIALS:
        mod = importlib.import_module(f"benchmarks.datasets.{module_name}")
        _TRIALS[key] = mod.trials(Path(root))
    return _TRIALS[key]


def _task(module_name: str, root: str, index: int, peer_names, keep_tracks: bool = True) -> dict:
    trial = _trials_of(module_name, root)[index]
    try:
        overrides = _FACTORY() if _FACTORY is not None else None
        return evaluate_trial(trial, peer_names, keep_tracks=keep_tracks, pipeline_overrides=overrides)
    except Exception as e:  # one bad recording must not stop the run
        import traceback

        return {"dataset": trial.dataset, "name": trial.name, "split": S.trial_split(trial),
                "placement": trial.placement, "info": dict(trial.info), "error": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(limit=3)}


def run(root: Path, *, quick: bool = False, only=None, jobs: int = 2, peer_names=None, split: str | None = None,
        pipeline_kwargs_factory=None, keep_tracks: bool = True, log=sys.stderr, engine: str = "reference",
        peer_cache: Path | None = None) -> dict:
    """Evaluate every trial present; returns ``{"results": [...], "datasets": {...}, ...}``.

    ``split``: only the recordings of this split (:mod:`benchmarks.splits`).
    ``pipeline_kwargs_factory``: a callable with no arguments returning the
    keyword overrides for our pipeline (:func:`make_pipeline`), called once
    per recording so that every recording gets fresh filter objects.  With
    ``jobs > 1`` it reaches the worker processes through the pool's
    initializer (Linux forks them, so a lambda or closure works).
    ``engine``: one of :data:`desktop.engine.ENGINES` (:func:`run_ours`); ``peer_cache``: the
    folder of the peers' stored attitudes (None: run every peer).
    """
    if engine not in ENGINES:
        raise ValueError(f"engine {engine!r}: one of {', '.join(ENGINES)}")  # before the workers start
    from benchmarks import peers as P

    root = Path(root)
    if split is not None:
        S.check_split(split)
    if peer_names is None:
        peer_names = P.QUICK_PEERS if quick else P.ALL_PEERS
    peer_names = tuple(P.available_peers(peer_names))
    keys = [k.strip() for o in (only or ()) for k in str(o).split(",") if k.strip()]
    ds_keys = [k for k in keys if _is_dataset_name(k)]
    name_keys = [k for k in keys if not _is_dataset_name(k)] or None  # parts of recording names
    mods, import_errors = dataset_modules(ds_keys or None)
    tasks, datasets = [], {}
    for mod in mods:
        short = mod.__name__.rsplit(".", 1)[1]
        if not mod.available(root):
            continue
        trials = _trials_of(short, str(root))
        idx = quick_subset(mod.NAME, trials) if quick else list(range(len(trials)))
        idx = [i for i in idx if selected(name_keys, trials[i].name)]
        if name_keys and not idx:
            continue
        if split is not None:
            idx = [i for i in idx if S.trial_split(trials[i]) == split]
            if not idx:
                continue
        datasets[mod.NAME] = {"module": short, "n_trials": len(trials), "n_run": len(idx),
                              "splits": {sp: sum(1 for i in idx if S.trial_split(trials[i]) == sp) for sp in S.SPLITS},
                              "doc": (mod.__doc__ or "").strip().split("\n")[0]}
        tasks += [(short, str(root), i, peer_names, keep_tracks) for i in idx]
    print(f"benchmark: {len(tasks)} recordings in {len(datasets)} datasets under {root} "
          f"({'quick' if quick else 'subset' if keys else 'full'} run{'' if split is None else ', ' + split + ' split'}, "
          f"{jobs} processes, "
          f"peers: {', '.join(peer_names) or 'none'})", file=log, flush=True)
    # the longest recordings first, so that the two processes finish together
    tasks.sort(key=lambda task: task[0] not in LONG_FIRST)
    t0 = time.perf_counter()
    results = []
    done = 0

    def report(r):
        nonlocal done
        done += 1
        results.append(r)
        print(f"[{done:3d}/{len(tasks)}] {r['dataset']}/{r['name']}: {_progress_line(r)}", file=log, flush=True)

    if jobs <= 1:
        previous = (_FACTORY, _SETTINGS["engine"], _SETTINGS["peer_cache"])
        _set_factory(pipeline_kwargs_factory, engine, peer_cache)
        try:
            for task in tasks:
                report(_task(*task))
        finally:
            _set_factory(*previous)
    else:
        with ProcessPoolExecutor(max_workers=jobs, initializer=_set_factory,
                                 initargs=(pipeline_kwargs_factory, engine, peer_cache)) as ex:
            futures = [ex.submit(_task, *task) for task in tasks]
            for f in as_completed(futures):
                report(f.result())
    wall = time.perf_counter() - t0
    rank = {name: k for k, name in enumerate(datasets)}
    results.sort(key=lambda r: (rank.get(r["dataset"], len(rank)), r["name"]))
    print(f"benchmark: done in {wall:.0f} s", file=log, flush=True)
    return {"results": results, "datasets": datasets, "import_errors": import_errors, "wall_s": wall,
            "quick": quick, "only": keys or None, "jobs": jobs, "peers": list(peer_names), "root": str(root), "split": split,
            "engine": engine, "peer_cache": None if peer_cache is None else str(peer_cache)}


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
    if "ref_sources" in r:
        s = r["ref_sources"]["ours"]
        parts.append(f"from GPS: median {s['median_m']:.1f} m (best rotation {s['fit_median_m']:.1f} m)")
    return ", ".join(parts)


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    ap.add_argument("--quick", action="store_true", help="the quick subset (CI guard) with the cheap peers")
    ap.add_argument("--out", type=Path, default=None,
                    help="Markdown report to write (default: out/benchmarks/RESULTS.md; with --write-results "
                         "benchmarks/RESULTS.md)")
    ap.add_argument("--plots", type=Path, default=None,
                    help="folder for the PNG plots (default: beside the report; with --write-results "
                         "benchmarks/plots)")
    ap.add_argument("--write-results", action="store_true",
                    help="rewrite the committed report benchmarks/RESULTS.md and benchmarks/plots (else nothing "
                         "tracked by git is touched)")
    ap.add_argument("--only", action="append", default=None, metavar="NAMES",
                    help="comma-separated datasets (module or folder name) and/or parts of recording names "
                         "(repeatable): run that subset (never with --write-results)")
    ap.add_argument("--no-write", action="store_true",
                    help="the default: write under out/benchmarks/, nothing tracked by git (the same option as "
                         "every benchmark module's; --write-results rewrites the committed report)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="parallel processes (default 2)")
    ap.add_argument("--peers", default=None,
                    help="comma-separated heading peers (default: all installed; quick: rotvec,imufusion)")
    ap.add_argument("--split", choices=S.SPLITS, default=None,
                    help="run only this split (default: both; see benchmarks/splits.py)")
    ap.add_argument("--engine", choices=ENGINES, default="auto",
                    help="our pipeline: the fast desktop path (desktop.fast, the same results within 1e-9) when "
                         "numba is installed (auto, the default), always (fast), or Pipeline.run (reference)")
    ap.add_argument("--peer-cache", type=Path, default=None, metavar="DIR",
                    help="where the peers' attitudes are kept between runs (default: out/benchmarks/peer_cache)")
    ap.add_argument("--no-peer-cache", action="store_true", help="run every peer, read and store nothing")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.write_results and (args.only or args.no_write or args.quick or args.split):
        print("benchmark: --write-results rewrites the committed report from a full run: not with --only, --quick, "
              "--split or --no-write", file=sys.stderr)
        return 2
    here = Path(__file__).resolve().parent
    if args.out is None:
        args.out = here / "RESULTS.md" if args.write_results else here.parent / "out" / "benchmarks" / "RESULTS.md"
    if args.plots is None:
        args.plots = here / "plots" if args.write_results else args.out.parent / "plots"
    root = args.data or default_data_root()
    if not root.is_dir():
        print(f"benchmark: no data folder at {root}", file=sys.stderr)
        return 2
    peer_names = tuple(p for p in args.peers.split(",") if p) if args.peers is not None else None
    cache = None if args.no_peer_cache else (args.peer_cache or here.parent / "out" / "benchmarks" / "peer_cache")
    run_info = run(root, quick=args.quick, only=args.only, jobs=args.jobs, peer_names=peer_names, split=args.split,
                   engine=args.engine, peer_cache=cache)
    if args.only and not run_info["datasets"]:
        names = ", ".join(sorted(DATASET_MODULES))
        print(f"benchmark: --only {','.join(args.only)} matched no recording in {root}"
              f"{' (split ' + args.split + ')' if args.split else ''}: give a dataset ({names}) or part of a "
              "recording's name", file=sys.stderr)
        return 2
    if not args.quick and not args.only and args.split is None:
        # issue #4: leave-one-subject-out study of the stride models (trains them; about a minute)
        from benchmarks.stride_eval import stride_section

        print("benchmark: stride-model cross-validation ...", file=sys.stderr, flush=True)
        run_info["stride_section"] = stride_section(root)
    from benchmarks import report

    report.write(run_info, args.out, args.plots, argv=sys.argv[1:] if argv is None else argv)
    print(f"benchmark: wrote {args.out} and the plots in {args.plots}"
          + ("" if args.write_results else " (the committed report is rewritten only with --write-results)"),
          file=sys.stderr)
    h = headline(run_info["results"])
    for t in evaluate_targets(h):
        v = "n/a" if t["value"] is None else f"{t['value']:.2f}"
        lim = "n/a" if t["limit"] is None else f"{t['limit']:.2f}"
        status = {True: "met", False: "MISSED", None: "no data"}[t["met"]]
        print(f"target {t['metric']} = {v} ({t['op']} {lim}): {status}", file=sys.stderr)
    print(f"benchmark: report written to {args.out}", file=sys.stderr)
    return 0
