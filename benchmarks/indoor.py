"""Floor-plan particle filter and landmark fixes benchmark (issue #16): ``python -m benchmarks.indoor``.

Writes ``benchmarks/indoor_results.json`` and ``benchmarks/INDOOR_RESULTS.md`` (a section of RESULTS.md);
``--data``, ``--only``, ``--no-write`` as every benchmark (:mod:`benchmarks.options`: a subset or
``--no-write`` writes under ``out/benchmarks/indoor/``).  A recording that fails is a row with its error,
counted as +inf in the medians and listed.

Inputs: the steps of our pipeline, built exactly as the main benchmark builds
it (:func:`benchmarks.run.make_pipeline`: the site's declination), on

* **Microsoft, every floor with a map** (``site*/F*/floor_info.json`` and ``geojson_map.json``; in our
  data site2/F3; :mod:`benchmarks.datasets.ms_indoor`) with the floor's map (:func:`core.indoor.read_ms_floor`): the filter starts at the
  first waypoint (sd ``START_SD_M``) at its time and knows nothing else;
  scored on every later waypoint.  Beside it: the same steps without the
  particle filter (our PDR track, the main benchmark's number) and the
  filter without the map (the map's own share).
* **IPIN 2023** (:mod:`benchmarks.datasets.ipin2023`; no map of floors 0 and
  -2, so fixes only): landmarks ``0, 3, 6, ...`` are given to the filter
  (landmark 0 as its start, the others as fixes of sd ``FIX_SD_M``), the
  others are scored.  Beside it: the PDR track and the filter with only
  the start, on the same landmarks.

Errors: :func:`core.metrics.landmark_errors` (track placed at landmark 0 at
its time, absolute heading), per recording the mean over its scored
landmarks; headlines are the median of those means over the recordings of
the split (the definition of the main benchmark's ``*_landmark_median_m``),
with the pooled median of every scored landmark beside it.

Splits (:mod:`benchmarks.splits`): Microsoft odd-numbered traces and IPIN
routes 01, 02, 21, 22 are tuning, the rest report.  ``--tune`` searches the
filter's settings on the tuning split only; the defaults of
:class:`core.indoor.ParticleConfig` are its result.  Timing (``ms/step``):
wall-clock time of :meth:`ParticleFilter.update` per step in this process.

``python -m benchmarks.indoor [--data DIR] [--jobs N] [--cache FILE] [--tune] [--no-write]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks import splits as S
from benchmarks.datasets import ipin2023, ms_indoor
from benchmarks.options import (add_common, data_root, failed_row, failures_line, median_inf, only_keys,
                                result_path, selected, write_json)
from core.indoor import ParticleConfig, StepArrays, map_match, read_ms_floor
from core.metrics import landmark_errors

HERE = Path(__file__).resolve().parent
RESULTS_JSON = HERE / "indoor_results.json"
RESULTS_MD = HERE / "INDOOR_RESULTS.md"
#: sd of the known start (m): the surveyor's first waypoint
START_SD_M = 0.3
#: sd of a landmark fix (m): the walker steps on a surveyed point
FIX_SD_M = 0.5
#: every FIX_EVERY-th landmark (0, 3, 6, ...) is a fix on IPIN
FIX_EVERY = 3
#: particle counts of the sweep
SWEEP = (100, 200, 300, 500, 1000, 2000)
SEED = 0


# ---------------------------------------------------------------------------
# steps of our pipeline (the slow part; parallel, optionally cached)


def _steps_of(args):
    module, root, index = args
    from benchmarks.run import make_pipeline

    mod = {"ms_indoor": ms_indoor, "ipin2023": ipin2023}[module]
    trial = mod.trials(Path(root))[index]
    try:
        rec = trial.open()
        tr = make_pipeline(trial).run(rec).track
    except Exception as e:  # counted and listed, never dropped (benchmarks.options)
        return {"dataset": trial.dataset, **failed_row(trial.name, S.trial_split(trial), e), "info": dict(trial.info)}
    lm = trial.landmarks
    return {"dataset": trial.dataset, "name": trial.name, "split": S.trial_split(trial), "info": dict(trial.info),
            "t_ns": tr.t_ns, "length_m": tr.length_m, "heading_rad": tr.heading_rad, "east_m": tr.east_m,
            "north_m": tr.north_m,
            "lm_t_ns": lm.t_ns, "lm_east_m": lm.east_m, "lm_north_m": lm.north_m}


def ms_floor_folder(root: Path, info: dict) -> Path:
    """A Microsoft trace's floor folder (``site*/F*``), where its map is."""
    return Path(root) / ms_indoor.NAME / info["site"] / info["floor"]


def has_map(folder: Path) -> bool:
    return any(Path(folder).glob("floor_info.json*")) and any(Path(folder).glob("geojson_map.json*"))


def floor_plans(root: Path, walks) -> dict:
    """``{"site/floor": FloorPlan}`` of every Microsoft floor the walks are on that has a map."""
    out = {}
    for w in walks:
        if w["dataset"] == ms_indoor.NAME:
            key = w["info"]["site"] + "/" + w["info"]["floor"]
            if key not in out and has_map(ms_floor_folder(root, w["info"])):
                out[key] = read_ms_floor(ms_floor_folder(root, w["info"]))
    return out


def plan_of(plans: dict, w):
    return plans.get(w["info"]["site"] + "/" + w["info"]["floor"]) if w["dataset"] == ms_indoor.NAME else None


#: the array fields of a walk (the rest is plain data)
_ARRAYS = ("t_ns", "length_m", "heading_rad", "east_m", "north_m", "lm_t_ns", "lm_east_m", "lm_north_m")


def load_walks(root: Path, jobs: int = 2, cache: Path | None = None, log=sys.stderr, only=None) -> list[dict]:
    """Our pipeline's steps on every Microsoft trace on a floor with a map and every IPIN route (``only``:
    :func:`benchmarks.options.selected` keys); a recording that fails is a row with ``"failed"``."""
    if cache is not None and Path(cache).exists():  # JSON, never a pickle (tests/test_no_unsafe_loading.py)
        with open(cache, encoding="utf-8") as fh:
            return [{k: (np.asarray(v, dtype=np.int64 if k.endswith("t_ns") else float) if k in _ARRAYS else v)
                     for k, v in w.items()} for w in json.load(fh)]
    tasks = []
    if ms_indoor.available(root):
        tasks += [("ms_indoor", str(root), i) for i, t in enumerate(ms_indoor.trials(root))
                  if has_map(ms_floor_folder(root, t.info)) and selected(only, t.name, t.dataset)]
    if ipin2023.available(root):
        tasks += [("ipin2023", str(root), i) for i, t in enumerate(ipin2023.trials(root))
                  if selected(only, t.name, t.dataset)]
    t0 = time.perf_counter()
    out = []
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as ex:
        for k, w in enumerate(ex.map(_steps_of, tasks), start=1):
            out.append(w)
            print(f"[{k}/{len(tasks)}] {w['dataset']}/{w['name']}: "
                  + (f"FAILED {w['failed']} " if w.get("failed") else f"{len(w['t_ns'])} steps ") +
                  f"({time.perf_counter() - t0:.0f} s)", file=log, flush=True)
    if cache is not None:
        with open(cache, "w", encoding="utf-8") as fh:
            json.dump([{k: (np.asarray(v).tolist() if k in _ARRAYS else v) for k, v in w.items()} for w in out], fh)
    return out


# ---------------------------------------------------------------------------
# one walk


def _errors(t_ns, east, north, heading, w, start=(0.0, 0.0)) -> np.ndarray:
    """Per-landmark errors (landmark 1..N) of a track: :func:`core.metrics.landmark_errors`."""
    return landmark_errors(t_ns, east, north, heading, w["lm_t_ns"], w["lm_east_m"], w["lm_north_m"],
                           start=start).errors_m


def _filter(w, plan, config: ParticleConfig, fixes=(), seed: int = SEED):
    """The filter from landmark 0 on this walk's steps: (result, ms per step)."""
    lt = w["lm_t_ns"]
    start = (int(lt[0]), float(w["lm_east_m"][0]), float(w["lm_north_m"][0]), START_SD_M)
    t = time.perf_counter()
    r = map_match(StepArrays(w["t_ns"], w["length_m"], w["heading_rad"]), plan, start=start, fixes=fixes,
                  config=config, seed=seed, smooth=True)
    ms = 1e3 * (time.perf_counter() - t) / max(len(r), 1)
    return r, ms


def _pf_errors(w, r, smoothed: bool = False) -> np.ndarray:
    keep = w["t_ns"] > w["lm_t_ns"][0]
    h = w["heading_rad"][keep] - r.bias_rad
    e, n = (r.smoothed_east_m, r.smoothed_north_m) if smoothed else (r.east_m, r.north_m)
    return _errors(r.t_ns, e, n, h, w, start=(w["lm_east_m"][0], w["lm_north_m"][0]))


def eval_ms(w, plan, config: ParticleConfig, seed: int = SEED) -> dict:
    pdr = _errors(w["t_ns"], w["east_m"], w["north_m"], w["heading_rad"], w)
    nomap, _ = _filter(w, None, config, seed=seed)
    mapped, ms = _filter(w, plan, config, seed=seed)
    xy = np.column_stack([mapped.east_m, mapped.north_m])
    pdr_xy = np.column_stack([w["east_m"], w["north_m"]]) - _at(w, w["lm_t_ns"][0]) + [w["lm_east_m"][0],
                                                                                     w["lm_north_m"][0]]
    keep = w["t_ns"] > w["lm_t_ns"][0]
    return {"name": w["name"], "split": w["split"], "n_landmarks": len(w["lm_t_ns"]), "n_steps": len(mapped),
            "pdr_mean_m": float(np.mean(pdr)), "nomap_mean_m": float(np.mean(_pf_errors(w, nomap))),
            "map_mean_m": float(np.mean(_pf_errors(w, mapped))),
            "map_smooth_mean_m": float(np.mean(_pf_errors(w, mapped, True))),
            "map_smooth_outside": int(np.sum(~plan.is_walkable(np.column_stack([mapped.smoothed_east_m,
                                                                                mapped.smoothed_north_m])))),
            "pdr_errors_m": pdr.tolist(), "map_errors_m": _pf_errors(w, mapped).tolist(),
            "map_outside": int(np.sum(~plan.is_walkable(xy))), "pdr_outside": int(np.sum(~plan.is_walkable(pdr_xy[keep]))),
            "bias_deg": math.degrees(mapped.final_bias_rad), "ms_per_step": ms,
            "spread_median_m": float(np.median(mapped.spread_m)) if len(mapped) else math.nan,
            "diagnostics": mapped.diagnostics}


def _at(w, t_ns) -> np.ndarray:
    from core.metrics import positions_at

    return positions_at(w["t_ns"], w["east_m"], w["north_m"], np.array([t_ns], dtype=np.int64))[0]


def eval_ipin(w, config: ParticleConfig, fix_sd_m: float = FIX_SD_M, seed: int = SEED) -> dict:
    k = np.arange(len(w["lm_t_ns"]))
    is_fix = k % FIX_EVERY == 0
    fixes = [(int(w["lm_t_ns"][i]), float(w["lm_east_m"][i]), float(w["lm_north_m"][i]), fix_sd_m)
             for i in k[is_fix][1:]]
    scored = ~is_fix[1:]  # errors_m starts at landmark 1
    pdr = _errors(w["t_ns"], w["east_m"], w["north_m"], w["heading_rad"], w)[scored]
    nofix, _ = _filter(w, None, config, seed=seed)
    fixed, ms = _filter(w, None, config, fixes=fixes, seed=seed)
    e_fix = _pf_errors(w, fixed)[scored]
    e_smooth = _pf_errors(w, fixed, True)[scored]
    return {"name": w["name"], "split": w["split"], "n_landmarks": len(k), "n_scored": int(scored.sum()),
            "n_fixes": len(fixes), "n_steps": len(fixed),
            "pdr_mean_m": float(np.mean(pdr)), "nofix_mean_m": float(np.mean(_pf_errors(w, nofix)[scored])),
            "fix_mean_m": float(np.mean(e_fix)), "fix_smooth_mean_m": float(np.mean(e_smooth)), "fix_errors_m": e_fix.tolist(), "pdr_errors_m": pdr.tolist(),
            "bias_deg": math.degrees(fixed.final_bias_rad), "ms_per_step": ms, "diagnostics": fixed.diagnostics}


# ---------------------------------------------------------------------------
# summaries


def _med(v) -> float:
    """The median, a failed recording (None, nan) counted as +inf (benchmarks.options.median_inf)."""
    return median_inf(v)


def _failed_ms(w) -> dict:
    return {"name": w["name"], "split": w["split"], "failed": w.get("failed") or "fewer than 2 landmarks",
            "floor": w["info"].get("site", "") + "/" + w["info"].get("floor", ""), "n_landmarks": 0, "n_steps": 0,
            "pdr_mean_m": math.inf, "nomap_mean_m": math.inf, "map_mean_m": math.inf, "map_smooth_mean_m": math.inf,
            "map_smooth_outside": 0, "pdr_errors_m": [math.inf], "map_errors_m": [math.inf], "map_outside": 0,
            "pdr_outside": 0, "bias_deg": math.nan, "ms_per_step": 0.0, "spread_median_m": math.nan,
            "diagnostics": {"recoveries": 0, "fix_resets": 0}}


def _failed_ipin(w) -> dict:
    return {"name": w["name"], "split": w["split"], "failed": w.get("failed") or "fewer than 2 landmarks",
            "n_landmarks": 0, "n_scored": 0, "n_fixes": 0, "n_steps": 0, "pdr_mean_m": math.inf,
            "nofix_mean_m": math.inf, "fix_mean_m": math.inf, "fix_smooth_mean_m": math.inf,
            "fix_errors_m": [math.inf], "pdr_errors_m": [math.inf], "bias_deg": math.nan, "ms_per_step": 0.0,
            "diagnostics": {"recoveries": 0, "fix_resets": 0}}


def summarise(ms_rows, ipin_rows, split: str) -> dict:
    ms = [r for r in ms_rows if r["split"] == split]
    ip = [r for r in ipin_rows if r["split"] == split]
    h = {}
    if ms:
        h.update({
            "ms_map_landmark_median_m": _med([r["map_mean_m"] for r in ms]),
            "ms_nomap_landmark_median_m": _med([r["nomap_mean_m"] for r in ms]),
            "ms_landmark_median_m": _med([r["pdr_mean_m"] for r in ms]),
            "ms_map_landmark_pooled_median_m": _med([e for r in ms for e in r["map_errors_m"]]),
            "ms_map_smoothed_landmark_median_m": _med([r["map_smooth_mean_m"] for r in ms]),
            "ms_map_smoothed_outside_estimates": int(sum(r["map_smooth_outside"] for r in ms)),
            "ms_landmark_pooled_median_m": _med([e for r in ms for e in r["pdr_errors_m"]]),
            "ms_map_outside_estimates": int(sum(r["map_outside"] for r in ms)),
            "ms_pdr_outside_estimates": int(sum(r["pdr_outside"] for r in ms)),
            "ms_steps": int(sum(r["n_steps"] for r in ms)), "ms_recordings": len(ms),
            "map_ms_per_step": float(np.sum([r["ms_per_step"] * r["n_steps"] for r in ms])
                                     / max(1, sum(r["n_steps"] for r in ms))),
            "ms_recoveries": int(sum(r["diagnostics"]["recoveries"] for r in ms)),
            "ms_failed": sum(1 for r in ms if r.get("failed")),
            "ms_floors": sorted({r["floor"] for r in ms if r.get("floor")}),
        })
    if ip:
        h.update({
            "ipin_fix_landmark_median_m": _med([r["fix_mean_m"] for r in ip]),
            "ipin_nofix_landmark_median_m": _med([r["nofix_mean_m"] for r in ip]),
            "ipin_landmark_median_m": _med([r["pdr_mean_m"] for r in ip]),
            "ipin_fix_landmark_pooled_median_m": _med([e for r in ip for e in r["fix_errors_m"]]),
            "ipin_fix_smoothed_landmark_median_m": _med([r["fix_smooth_mean_m"] for r in ip]),
            "ipin_recordings": len(ip), "ipin_failed": sum(1 for r in ip if r.get("failed")),
            "ipin_ms_per_step": float(np.sum([r["ms_per_step"] * r["n_steps"] for r in ip])
                                      / max(1, sum(r["n_steps"] for r in ip))),
        })
    return h


def _ok(w) -> bool:
    return not w.get("failed") and len(w["lm_t_ns"]) >= 2


def evaluate(walks, plans: dict, config: ParticleConfig, split: str | None = None, fix_sd_m: float = FIX_SD_M,
             seed: int = SEED):
    """Rows of every walk of ``split``; a walk that failed (or whose filter fails) is a row with
    ``"failed"`` and +inf errors: counted in the medians, listed in the report."""
    ws = [w for w in walks if split is None or w["split"] == split]
    ms_rows, ip_rows = [], []
    for w in ws:
        if w["dataset"] == ms_indoor.NAME and plan_of(plans, w) is not None:
            try:
                row = eval_ms(w, plan_of(plans, w), config, seed) if _ok(w) else _failed_ms(w)
            except Exception as e:
                row = _failed_ms({**w, "failed": failed_row(w["name"], w["split"], e)["failed"]})
            row["floor"] = w["info"]["site"] + "/" + w["info"]["floor"]
            ms_rows.append(row)
        elif w["dataset"] == ipin2023.NAME:
            try:
                ip_rows.append(eval_ipin(w, config, fix_sd_m, seed) if _ok(w) else _failed_ipin(w))
            except Exception as e:
                ip_rows.append(_failed_ipin({**w, "failed": failed_row(w["name"], w["split"], e)["failed"]}))
    return ms_rows, ip_rows


def sweep(walks, plans: dict, config: ParticleConfig, split: str) -> list[dict]:
    """Particle count against accuracy and time: the filter with the map on the Microsoft traces of ``split``
    (the failed ones are the evaluation's rows, not repeated here)."""
    out = []
    ws = [w for w in walks if w["dataset"] == ms_indoor.NAME and w["split"] == split and _ok(w)
          and plan_of(plans, w) is not None]
    for n in SWEEP:
        c = dataclasses.replace(config, n_particles=n)
        live, smooth, outside, steps, t_ms, rec = [], [], 0, 0, 0.0, 0
        for w in ws:
            plan = plan_of(plans, w)
            r, ms = _filter(w, plan, c)
            live.append(float(np.mean(_pf_errors(w, r))))
            smooth.append(float(np.mean(_pf_errors(w, r, True))))
            outside += int(np.sum(~plan.is_walkable(np.column_stack([r.east_m, r.north_m]))))
            steps += len(r)
            t_ms += ms * len(r)
            rec += r.diagnostics["recoveries"]
        out.append({"n_particles": n, "ms_map_landmark_median_m": _med(live),
                    "ms_map_smoothed_landmark_median_m": _med(smooth), "outside": outside, "recoveries": rec,
                    "map_ms_per_step": t_ms / max(steps, 1)})
    return out


#: the headlines whose spread over filter seeds is reported
SEED_HEADLINES = ("ms_map_landmark_median_m", "ms_map_smoothed_landmark_median_m", "ipin_fix_landmark_median_m",
                  "ipin_fix_smoothed_landmark_median_m")


def seed_spread(walks, plans, config: ParticleConfig, seeds=range(1, 5)) -> dict:
    """Min and max of the headlines over other filter seeds, per split."""
    out = {}
    for sp in S.SPLITS:
        hs = [summarise(*evaluate(walks, plans, config, split=sp, seed=sd), sp) for sd in seeds]
        out[sp] = {k: [min(h[k] for h in hs), max(h[k] for h in hs)] for k in SEED_HEADLINES if all(k in h for h in hs)}
    return out


# ---------------------------------------------------------------------------
# the IPIN floor -1 map: a format check (no route of ours is on that floor)


def ipin_map_check(root: Path) -> dict | None:
    """Read ``Map_Floor_-01.png`` with its ``.cal``; place the nine ``references.csv`` points (lat/lon) on it.

    The image draws each reference point as an orange dot: the distance (m) from where our georeference
    puts the point to the nearest orange pixel checks the ``.cal`` reader (centre, scale, rotation sign).
    """
    import csv

    from PIL import Image

    from core.indoor import read_ipin_cal, read_ipin_floor
    from desktop.floor_images import read_floor_image

    folder = Path(root) / "ipin2023_track3" / "floormaps"
    if not (folder / "Map_Floor_-01.png").exists():
        return None
    t = time.perf_counter()
    plan = read_ipin_floor(folder, -1, read_image=read_floor_image)
    t_read = time.perf_counter() - t
    cal = read_ipin_cal(next(iter(sorted(folder.glob("*.cal")))))[-1]
    Image.MAX_IMAGE_PIXELS = None
    with Image.open(folder / cal.image) as im:
        rgb = np.asarray(im.convert("RGB"))
    rows, cols = rgb.shape[:2]
    r, g, b = (rgb[..., k].astype(np.int16) for k in range(3))
    dot_r, dot_c = np.nonzero((r > 190) & (g > 130) & (g < 200) & (b < 90))  # the reference dots' orange
    del rgb, r, g, b
    dots = np.column_stack([dot_c, dot_r]).astype(float)
    out = []
    with open(folder / "references.csv", newline="") as fh:
        for ref in csv.DictReader(fh):
            x, y = plan.georef.from_geodetic(float(ref["Lat"]), float(ref["Lon"]))[0]
            px = np.array([cols / 2.0 + x / cal.m_per_px, rows / 2.0 - y / cal.m_per_px])
            d = float(np.min(np.hypot(*(dots - px).T))) * cal.m_per_px if len(dots) else math.nan
            out.append({"point": ref["pointID"], "to_dot_m": round(d, 3)})
    return {"walls": int(len(plan.walls)), "read_s": round(t_read, 1), "image_px": [cols, rows],
            "m_per_px": cal.m_per_px, "rotation_deg": cal.rotation_deg, "references": out,
            "max_to_dot_m": max(o["to_dot_m"] for o in out)}


# ---------------------------------------------------------------------------
# tuning (tuning split only)

#: the grid searched by --tune, one setting at a time from the defaults (coordinate descent, one pass).
#: The defaults of ParticleConfig come from three passes on the tuning split (scores: the sum of the two
#: live headlines, mean of seeds 0 and 1): from heading 6 deg, bias 15 deg / 0.5 deg a step, length 0.08,
#: scale 0.10 (4.57 m) over bias_sd 15-35 deg, bias_rw 0.3-0.8, length_sd 0.05-0.12, scale_sd 0.05-0.15
#: (-> 4.02 m); then bias_rw 0.8-1.6, length_sd 0.12-0.20, scale_sd 0.02-0.05, heading_sd 3-10,
#: bias_sd 10-20 (-> 3.69 m); then this grid, which kept them (3.69 m).
TUNE_GRID = {
    "heading_sd_rad": [math.radians(v) for v in (10, 14, 18)],
    "bias_rw_rad": [math.radians(v) for v in (1.0, 1.6, 2.4)],
    "length_sd": [0.12, 0.20],
    "scale_sd": [0.02, 0.05],
    "bias_sd_rad": [math.radians(v) for v in (10, 15)],
}
#: filter seeds every setting is scored on (one seed's numbers move by tenths of a metre)
TUNE_SEEDS = (0, 1)


def tune(walks, plans, log=sys.stderr) -> ParticleConfig:
    """Coordinate descent over :data:`TUNE_GRID` on the tuning split; the score is the sum of the two
    live-filter headlines, averaged over :data:`TUNE_SEEDS`."""
    tw = [w for w in walks if w["split"] == S.TUNING]

    def score(c):
        hs = [summarise(*evaluate(tw, plans, c, seed=sd), S.TUNING) for sd in TUNE_SEEDS]
        ms = float(np.mean([h["ms_map_landmark_median_m"] for h in hs]))
        ip = float(np.mean([h["ipin_fix_landmark_median_m"] for h in hs]))
        return ms + ip, ms, ip

    best = ParticleConfig()
    best_s = score(best)[0]
    print(f"tune defaults: {best_s:.3f}", file=log, flush=True)
    for name, values in TUNE_GRID.items():
        for v in values:
            if math.isclose(v, getattr(best, name)):
                continue
            c = dataclasses.replace(best, **{name: v})
            s, ms, ip = score(c)
            print(f"tune {name}={v:.4g}: {s:.3f} (ms {ms:.2f}, ipin {ip:.2f})", file=log, flush=True)
            if s < best_s - 1e-9:
                best, best_s = c, s
    print(f"tuned: {best} -> {best_s:.3f}", file=log)
    return best


# ---------------------------------------------------------------------------
# report


def _f(v, nd=2) -> str:
    if isinstance(v, (list, tuple, str)):
        return ", ".join(map(str, v)) if not isinstance(v, str) else v
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def _table(title: str, header: list, rows: list) -> list:
    return ["", f"### {title}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(str(v) for v in r) + " |" for r in rows]


def write_md(out: dict, path: Path) -> None:
    hr, ht = out["headlines"][S.REPORT], out["headlines"][S.TUNING]
    t = out["targets"]
    L = ["## Indoors: floor-plan particle filter and landmark fixes (issue #16)", "",
         "`python -m benchmarks.indoor` (benchmarks/indoor.py; code: core/indoor, docs/indoor.md). "
         f"Particles: {out['config']['n_particles']}, seed {SEED}; start sd {START_SD_M} m, fix sd {FIX_SD_M} m. "
         "Errors: `core.metrics.landmark_errors` (placed at landmark 0, absolute heading); per recording the mean "
         "over its scored landmarks, then the median over the recordings (pooled: median of every scored landmark).",
         "", "### Targets (report split)", "", "| target | value | limit | |", "|---|---|---|---|"]
    for row in t:
        L.append(f"| {row['text']} (`{row['metric']}`) | {_f(row['value'])} | {row['op']} {_f(row['limit'])} | "
                 f"{'met' if row['met'] else '**missed**'} |")
    L += ["", "### Headlines", "", "| headline | report | tuning |", "|---|---|---|"]
    for k in sorted(set(hr) | set(ht)):
        L.append(f"| `{k}` | {_f(hr.get(k), 3)} | {_f(ht.get(k), 3)} |")
    ms_rep = [r for r in out["ms"] if r["split"] == S.REPORT]
    ip_rep = [r for r in out["ipin"] if r["split"] == S.REPORT]
    L += _table("Microsoft, every floor with a map (" + ", ".join(hr.get("ms_floors", [])) + "), only the start "
                "known (report split)",
                ["trace", "waypoints", "steps", "PDR mean (m)", "filter, no map (m)", "filter + map (m)",
                 "smoothed + map (m)", "outside (PDR / map)", "bias (deg)", "recoveries"],
                [[r["name"].split("/", 2)[-1] if not r.get("failed") else f"{r['name']} (failed)", r["n_landmarks"], r["n_steps"], _f(r["pdr_mean_m"]),
                  _f(r["nomap_mean_m"]), _f(r["map_mean_m"]), _f(r["map_smooth_mean_m"]),
                  f"{r['pdr_outside']} / {r['map_outside']}", _f(r["bias_deg"], 1), r["diagnostics"]["recoveries"]]
                 for r in ms_rep])
    L += _table("IPIN 2023, every third landmark a fix (report split)",
                ["recording", "landmarks (scored)", "fixes", "PDR mean (m)", "filter, start only (m)",
                 "filter + fixes (m)", "smoothed + fixes (m)", "bias (deg)", "fix resets"],
                [[r["name"], f"{r['n_landmarks']} ({r['n_scored']})", r["n_fixes"], _f(r["pdr_mean_m"]),
                  _f(r["nofix_mean_m"]), _f(r["fix_mean_m"]), _f(r["fix_smooth_mean_m"]), _f(r["bias_deg"], 1),
                  r["diagnostics"]["fix_resets"]] for r in ip_rep])
    for key, split in (("sweep", S.REPORT), ("sweep_tuning", S.TUNING)):
        L += _table(f"Particle count against accuracy and time (Microsoft with the map, {split} split)",
                    ["particles", "median of means, live (m)", "smoothed (m)", "outside (live)", "recoveries",
                     "ms/step"],
                    [[r["n_particles"], _f(r["ms_map_landmark_median_m"]),
                      _f(r["ms_map_smoothed_landmark_median_m"]), r["outside"], r["recoveries"],
                      _f(r["map_ms_per_step"])] for r in out.get(key, [])])
    spread = out.get("seed_spread", {})
    L += _table("Filter seeds 1-4 beside seed 0 (min - max of the headline)",
                ["headline", "report: seed 0", "report: seeds 1-4", "tuning: seed 0", "tuning: seeds 1-4"],
                [[f"`{k}`", _f(hr.get(k)), "-".join(_f(v) for v in spread.get(S.REPORT, {}).get(k, [])),
                  _f(ht.get(k)), "-".join(_f(v) for v in spread.get(S.TUNING, {}).get(k, []))]
                 for k in SEED_HEADLINES])
    im = out.get("ipin_map")
    if im:
        L += ["", "### The IPIN floor -1 image and its `.cal` (a format check)", "",
              f"`Map_Floor_-01.png` ({im['image_px'][0]} x {im['image_px'][1]} px, {im['m_per_px']} m/px, "
              f"rotation {im['rotation_deg']} deg): {im['walls']} wall segments extracted in {im['read_s']} s. "
              "The nine reference points of `references.csv`, placed from their latitude/longitude by our "
              "georeference, lie this far from the orange dots the image draws for them: "
              + ", ".join(f"{r['point']} {r['to_dot_m']:.2f} m" for r in im["references"])
              + f" (largest {im['max_to_dot_m']:.2f} m; the dots are about 0.3 m wide)."]
    if out.get("failed"):
        L += _table("Recordings that failed (counted as +inf in the medians)", ["recording", "split", "error"],
                    [[r["name"], r["split"], r["failed"]] for r in out["failed"]])
    L += ["", *out.get("notes", [])]
    Path(path).write_text("\n".join(L) + "\n")


TARGETS = (
    ("ms_map_landmark_median_m", "<=", 2.0, "Microsoft with its map, only the start known: median waypoint error (m)"),
    ("ms_map_outside_estimates", "<=", 0, "Microsoft: estimates outside the walkable area"),
    ("ipin_fix_landmark_median_m", "<=", 1.0, "IPIN 2023, every third landmark a fix: median error on the others (m)"),
    ("map_ms_per_step", "<=", 5.0, "time per step with the map (ms, this machine)"),
)


def targets(h: dict) -> list[dict]:
    out = []
    for metric, op, limit, text in TARGETS:
        v = h.get(metric)
        out.append({"metric": metric, "op": op, "limit": limit, "value": v, "text": text,
                    "met": None if v is None else bool(v <= limit)})
    return out


def notes(out: dict) -> list[str]:
    """What the numbers say, in words (targets missed are said first); a subset run (``--only``) without both
    datasets on both splits has no notes."""
    try:
        return _notes(out)
    except (KeyError, TypeError, ValueError):
        return ["### What the numbers say", "", "* A subset run: the notes need both datasets on both splits."]


def _notes(out: dict) -> list[str]:
    hr, ht = out["headlines"][S.REPORT], out["headlines"][S.TUNING]
    sp = out.get("seed_spread", {})

    def rng(split, k):
        v = sp.get(split, {}).get(k)
        return f"{v[0]:.2f}-{v[1]:.2f}" if v else "?"

    worse = [r["name"].split("/")[-1] for r in out["ms"]
             if r["split"] == S.REPORT and r["map_mean_m"] > r["pdr_mean_m"] + 0.5]
    t500 = [r["map_ms_per_step"] for key in ("sweep", "sweep_tuning") for r in out.get(key, [])
            if r["n_particles"] == out["config"]["n_particles"]]
    return [
        "### What the numbers say", "",
        f"* **The live filter (what the app would show) misses both accuracy targets** on the report split: "
        f"Microsoft with its map {hr['ms_map_landmark_median_m']:.2f} m (seeds 1-4: "
        f"{rng(S.REPORT, 'ms_map_landmark_median_m')}; target 2.0; our PDR alone "
        f"{hr['ms_landmark_median_m']:.2f} m, the filter without the map {hr['ms_nomap_landmark_median_m']:.2f} m), "
        f"IPIN with every third landmark a fix {hr['ipin_fix_landmark_median_m']:.2f} m (seeds 1-4: "
        f"{rng(S.REPORT, 'ipin_fix_landmark_median_m')}; target 1.0; PDR alone {hr['ipin_landmark_median_m']:.2f} m).",
        f"* The batch smoother (ancestral paths; for `pdr replay` and exports, not live) meets the IPIN target, "
        f"{hr['ipin_fix_smoothed_landmark_median_m']:.2f} m (seeds 1-4: "
        f"{rng(S.REPORT, 'ipin_fix_smoothed_landmark_median_m')}), and meets the Microsoft one only on some seeds: "
        f"{hr['ms_map_smoothed_landmark_median_m']:.2f} m on seed 0, {rng(S.REPORT, 'ms_map_smoothed_landmark_median_m')}"
        f" on seeds 1-4, so not robustly.",
        f"* No live estimate outside the walkable area ({hr['ms_map_outside_estimates']} of {hr['ms_steps']} on the "
        f"report split; PDR alone: {hr['ms_pdr_outside_estimates']}); the smoother had "
        f"{hr.get('ms_map_smoothed_outside_estimates', 0)}. No recovery was needed on either split.",
        f"* Where the map makes it worse by more than 0.5 m ({', '.join(worse) or 'none'} on the report split): "
        "the cloud takes a "
        "parallel corridor early and the heading bias then follows that corridor (on the tuning split one trace "
        "ends with a -57 deg bias). Only the start is known, so nothing brings it back; a fix (a tap) would.",
        f"* Tuning and report split differ (live Microsoft: tuning {ht['ms_map_landmark_median_m']:.2f} m, report "
        f"{hr['ms_map_landmark_median_m']:.2f} m): with 17-18 short traces and a few lost ones, the median moves by "
        "tenths of a metre with the seed (table above). Settings were scored on two seeds of the tuning split only.",
        f"* Time: {', '.join(f'{v:.1f}' for v in t500)} ms/step with {out['config']['n_particles']} particles in the "
        "two sweeps (report, tuning; the paths for the smoother kept too), on a 2-core machine shared with other "
        "jobs, so the same count varies from run to run; below the 5 ms budget, and more particles gain little.",
        "* The bias as a first-order Gauss-Markov process (`bias_gm=True`) instead of a random walk scored "
        "3.62-3.66 m against 3.69 m on the tuning split (sum of the two live headlines): within the seed noise, "
        "left off. On the same score, `resample_ess` 0.8 and `roughen_k` 0.4 were worse (4.29, 4.42 m), "
        "`roughen_k` 0.1 and 1000 particles no better (3.73 m); the IPIN fix sd (0.3, 0.5, 1.0 m) moved the IPIN "
        "tuning number by less than the seeds do.",
        "* Not done: a whole-floor start (no start known), a corridor-direction prior on the heading, a fixed-lag "
        "smoother for the live display, the Microsoft floor F4 (same format, other traces).",
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.indoor", description=__doc__.split("\n")[0])
    add_common(ap, what="recording names (site2/F3/5dd3..., IPIN2023_T3_...) or datasets")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None, help="JSON cache of the pipeline's steps (read if present)")
    ap.add_argument("--tune", action="store_true", help="search the filter's settings on the tuning split first")
    ap.add_argument("--no-sweep", action="store_true", help="skip the particle-count sweep and the seed spread")
    a = ap.parse_args(argv)
    root = data_root(a)
    walks = load_walks(root, a.jobs, a.cache, only=only_keys(a))
    plans = floor_plans(root, walks)
    print(f"indoor: {len(walks)} recordings, maps of {', '.join(sorted(plans)) or 'no floor'}", file=sys.stderr)
    config = tune(walks, plans) if a.tune else ParticleConfig()
    ms_rows, ip_rows = evaluate(walks, plans, config)
    heads = {sp: summarise(ms_rows, ip_rows, sp) for sp in S.SPLITS}
    out = {"config": dataclasses.asdict(config), "headlines": heads, "targets": targets(heads[S.REPORT]),
           "ms": ms_rows, "ipin": ip_rows,
           "sweep": [] if a.no_sweep else sweep(walks, plans, config, S.REPORT),
           "sweep_tuning": [] if a.no_sweep else sweep(walks, plans, config, S.TUNING),
           "seed_spread": {} if a.no_sweep else seed_spread(walks, plans, config),
           "ipin_map": ipin_map_check(root), "failed": [r for r in ms_rows + ip_rows if r.get("failed")]}
    out["notes"] = notes(out)
    print(json.dumps(heads, indent=1, default=float))
    if out["failed"]:
        print("indoor: " + failures_line(out["failed"]), file=sys.stderr)
    res_json, res_md = result_path(a, RESULTS_JSON, "indoor"), result_path(a, RESULTS_MD, "indoor")
    write_json(res_json, out, digits=None)
    write_md(out, res_md)
    print(f"indoor: wrote {res_md}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
