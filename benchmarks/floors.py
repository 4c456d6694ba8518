"""Barometric floors benchmark (issue #15, "Barometric floors"): ``python -m benchmarks.floors``.

Writes ``benchmarks/floors_results.json`` and ``benchmarks/FLOORS_RESULTS.md`` (a section of RESULTS.md).

Splits (declared before any threshold of :class:`core.floors.FloorSettings` was chosen):

* simulator: seeds 0-19 are **tuning**, seeds 1000-1039 **report**.  Each seed draws a building walk
  (:func:`building_walk`: 3-8 floor changes by stairs, by lift, with half-storey landings and pauses,
  storeys of 3.0-4.5 m, level stretches of 20-120 s) and a barometer (:class:`desktop.simulator.BarometerModel`
  with weather drift of up to 4 hPa/h, noise, door transients);  and a flat hour per seed (no floor change);
* IPIN 2023 (single-floor routes: every POSI landmark on one floor): the routes' split of
  :mod:`benchmarks.splits` (01, 02, 21, 22 tuning); **target: no floor change on any of them**;
* outdoor walks with a barometer (``sensorlogger_gps_walk_ethz``, ``gps_walks_phone``): report only;
  what the estimator finds beside the GPS altitude's range (a hill is a slope, not a floor).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from benchmarks.options import add_common, data_root, only_keys, out_dir, selected, write_json, writes_committed
from benchmarks.splits import REPORT, TUNING, ipin_split
from core.floors import FloorEstimator, FloorSettings
from desktop.simulator import BarometerModel, floor_profile, simulate_pressure

HERE = Path(__file__).resolve().parent
RESULTS_JSON = HERE / "floors_results.json"
RESULTS_MD = HERE / "FLOORS_RESULTS.md"
SIM_SEEDS = {TUNING: range(0, 20), REPORT: range(1000, 1040)}
#: the barometer's reading rate in the simulator (Hz): phones give 1-25 Hz
SIM_RATE_HZ = 10.0


def building_walk(seed: int):
    """A random walk through a building: ``(segments, truth)`` with truth = [(floors, kind), ...] per change."""
    rng = np.random.default_rng(seed)
    storey = float(rng.uniform(3.0, 4.5))
    segments = [(float(rng.uniform(20, 120)), 0.0)]
    truth = []
    floor = 0
    for _ in range(int(rng.integers(3, 9))):
        kind = "lift" if rng.random() < 0.35 else "stairs"
        n = int(rng.choice([-2, -1, 1, 2] if kind == "lift" else [-1, 1]))
        if floor + n < -2 or floor + n > 6:
            n = -n
        if kind == "lift":  # about 1 m/s, plus starting and stopping
            segments.append((abs(n) * storey / 1.0 + 2.0, n * storey))
        elif rng.random() < 0.4:  # two half flights with a pause on the landing
            pause = float(rng.uniform(2, 15))
            per = float(rng.uniform(6, 10))
            segments += [(per, n * storey / 2, "linear"), (pause, 0.0), (per, n * storey / 2, "linear")]
        else:  # one flight, 0.2-0.35 m/s of rise
            segments.append((abs(n) * storey / float(rng.uniform(0.2, 0.35)), n * storey, "linear"))
        floor += n
        truth.append((n, kind))
        segments.append((float(rng.uniform(20, 120)), 0.0))
    return segments, truth, storey


def _model(rng) -> BarometerModel:
    return BarometerModel(drift_hpa_per_h=float(rng.uniform(-4, 4)), noise_hpa=float(rng.uniform(0.01, 0.04)),
                          transient_hpa=float(rng.uniform(0.05, 0.3)), transients_per_h=float(rng.uniform(0, 30)),
                          quantum_hpa=0.01, temperature_c=float(rng.uniform(0, 30)))


def run_sim(seeds, settings: FloorSettings | None = None) -> list[dict]:
    rows = []
    for seed in seeds:
        segments, truth, storey = building_walk(seed)
        total = sum(seg[0] for seg in segments)
        t = np.arange(0.0, total, 1.0 / SIM_RATE_HZ)
        t_ns = (t * 1e9).astype(np.int64) + 1_000_000_000
        rng = np.random.default_rng(seed + 7)
        st = simulate_pressure(t_ns, floor_profile(t, segments), _model(rng), seed=seed)
        # the user sets the storey height of the building (nominal, 3.5 m unless said): here the truth's
        res = FloorEstimator(settings or FloorSettings(), storey_height_m=storey).run(st)
        found = [(c.floors, c.kind) for c in res.changes if c.floors]
        flat_t = np.arange(0.0, 3600.0, 1.0 / SIM_RATE_HZ)
        flat = FloorEstimator(settings or FloorSettings(), storey_height_m=storey).run(
            simulate_pressure((flat_t * 1e9).astype(np.int64), np.zeros(len(flat_t)), _model(rng), seed=seed + 1))
        rows.append({"seed": seed, "storey_m": storey, "truth": truth, "found": found,
                     "sequence_ok": [n for n, _ in found] == [n for n, _ in truth],
                     "kinds_ok": found == truth,
                     "final_floor_ok": res.summary()["final_floor"] == sum(n for n, _ in truth),
                     "flat_hour_changes": flat.summary()["floor_changes"]})
    return rows


def summarise_sim(rows) -> dict:
    return {"walks": len(rows), "floor_sequence_correct_pct": 100 * float(np.mean([r["sequence_ok"] for r in rows])),
            "kinds_correct_pct": 100 * float(np.mean([r["kinds_ok"] for r in rows])),
            "final_floor_correct_pct": 100 * float(np.mean([r["final_floor_ok"] for r in rows])),
            "changes_true": sum(len(r["truth"]) for r in rows),
            "flat_hours_with_a_false_change": sum(1 for r in rows if r["flat_hour_changes"])}


def _real_recordings(root: Path):
    """(dataset, name, split, loader) of every recording with a barometer we have."""
    from benchmarks.datasets import ipin2023

    for tr in ipin2023.trials(root):
        yield "ipin2023_track3", tr.name, ipin_split(tr.info["route"]), tr.open
    from core.importers import load_recording

    for folder in ("sensorlogger_gps_walk_ethz", "gps_walks_phone"):
        base = Path(root) / folder
        if base.is_dir():
            for d in sorted(p for p in base.iterdir() if p.is_dir()):
                yield folder, d.name, REPORT, (lambda d=d: load_recording(d, warn=False))


def run_real(root: Path, settings: FloorSettings | None = None, keys=None) -> list[dict]:
    """Every recording with a barometer (``keys``: :func:`benchmarks.options.selected`); one that cannot be
    read is a row with its ``error``, listed in the report."""
    rows = []
    for dataset, name, split, load in _real_recordings(root):
        if not selected(keys, dataset, name):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                rec = load()
            except Exception as e:  # noqa: BLE001 - a recording we cannot read is reported, not fatal
                rows.append({"dataset": dataset, "recording": name, "split": split, "error": str(e)})
                continue
        if not rec.has("pressure"):
            continue
        gps = rec.streams["gps"] if rec.has("gps") else None
        res = FloorEstimator(settings).run(rec.streams["pressure"], gps=gps)
        s = res.summary()
        row = {"dataset": dataset, "recording": name, "split": split, "duration_s": rec.duration_s,
               "rate_hz": (len(res.t_ns) - 1) / max((res.t_ns[-1] - res.t_ns[0]) * 1e-9, 1e-9),
               **{k: s[k] for k in ("floor_changes", "floors_visited", "final_floor", "stairs", "lifts", "slopes",
                                    "altitude_range_m", "skipped")},
               "changes": [[round((c.t_start_ns - rec.t0_ns) * 1e-9, 1), c.floors, c.kind, round(c.delta_m, 2),
                            round(c.rate_m_s, 3)] for c in res.changes]}
        if gps is not None:
            alt = gps.values[:, 2]
            alt = alt[np.isfinite(alt)]
            row["gps_altitude_range_m"] = float(np.ptp(alt)) if len(alt) else math.nan
            # the same without the GPS's "outdoors" (what a phone with GPS off would report)
            row["floor_changes_without_gps"] = FloorEstimator(settings).run(rec.streams["pressure"]).summary()[
                "floor_changes"]
        rows.append(row)
    return rows


def headlines(out) -> dict:
    ipin = [r for r in out["real"] if r["dataset"] == "ipin2023_track3" and "error" not in r]
    sim = out["sim"].get(REPORT, {})  # a subset (--only) may have no simulator part
    return {"split": REPORT,
            "sim_floor_sequence_correct_pct": sim.get("floor_sequence_correct_pct"),
            "sim_kinds_correct_pct": sim.get("kinds_correct_pct"),
            "sim_flat_hours_with_a_false_change": sim.get("flat_hours_with_a_false_change"),
            "ipin_report_recordings_with_a_floor_change": sum(1 for r in ipin if r["split"] == REPORT
                                                              and r["floor_changes"]),
            "ipin_tuning_recordings_with_a_floor_change": sum(1 for r in ipin if r["split"] == TUNING
                                                              and r["floor_changes"]),
            "recordings_failed": sum(1 for r in out["real"] if "error" in r)}


def _f(x, nd=1):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def write_markdown(out, path=RESULTS_MD) -> None:
    s = FloorSettings()
    h = out["headlines"]
    L = ["## Barometric floors", "",
         f"`core.floors.FloorEstimator` at its defaults (storey {s.storey_height_m} m, a change starts "
         f"{s.start_fraction:g} storey off the level and ends after {s.settle_s:g} s below "
         f"{s.settle_rate_m_s} m/s; lift above {s.lift_rate_m_s} m/s, slope below {s.min_stairs_rate_m_s} m/s; "
         f"level time constant {s.level_tau_s:g} s). Splits in `benchmarks/floors.py` (declared before tuning).", "",
         "### Simulator (building walks: stairs, lifts, half-storey landings; weather drift up to 4 hPa/h, door "
         "transients)", "",
         "| split | walks | true changes | floor sequence right | stairs/lift right | final floor right | flat hours "
         "with a false change |", "|---|---|---|---|---|---|---|"]
    for split in (REPORT, TUNING):
        m = out["sim"][split]
        L.append(f"| {split} | {m['walks']} | {m['changes_true']} | {m['floor_sequence_correct_pct']:.0f} % | "
                 f"{m['kinds_correct_pct']:.0f} % | {m['final_floor_correct_pct']:.0f} % | "
                 f"{m['flat_hours_with_a_false_change']} of {m['walks']} |")
    ipin = [r for r in out["real"] if r["dataset"] == "ipin2023_track3" and "error" not in r]
    L += ["", "### IPIN 2023 (every route on one floor: no floor change is right)", "",
          "| split | recordings | with a floor change (target 0) | with a slope | altitude range median (m) | "
          "max (m) |", "|---|---|---|---|---|---|"]
    for split in (REPORT, TUNING):
        rs = [r for r in ipin if r["split"] == split]
        if rs:
            rng = [r["altitude_range_m"] for r in rs]
            L.append(f"| {split} | {len(rs)} | {sum(1 for r in rs if r['floor_changes'])} | "
                     f"{sum(1 for r in rs if r['slopes'])} | {np.median(rng):.2f} | {np.max(rng):.2f} |")
    bad = [r for r in ipin if r["floor_changes"]]
    if bad:
        L += ["", "False floor changes: " + "; ".join(f"{r['recording']} ({r['split']}): {r['changes']}"
                                                     for r in bad)]
    other = [r for r in out["real"] if r["dataset"] != "ipin2023_track3"]
    if other:
        L += ["", "### Outdoor walks with a barometer (report)", "",
              "| recording | duration (s) | rate (Hz) | floor changes | same without GPS | slopes | "
              "baro altitude range (m) | GPS altitude range (m) |", "|---|---|---|---|---|---|---|---|"]
        for r in other:
            if "error" in r:
                L.append(f"| {r['dataset']}/{r['recording']} | could not be read: {r['error']} | | | | | |")
                continue
            L.append(f"| {r['dataset']}/{r['recording']} | {r['duration_s']:.0f} | {r['rate_hz']:.1f} | "
                     f"{r['floor_changes']} | {r.get('floor_changes_without_gps', '-')} | {r['slopes']} | "
                     f"{_f(r['altitude_range_m'])} | {_f(r.get('gps_altitude_range_m'))} |")
        L += ["", "Outdoors a change of altitude is a slope, not a floor: a change during which the GPS had a fix "
                  "of 10 m or better counts as a slope (`FloorSettings.outdoor_hacc_m`). That rule was added after "
                  "the barometer alone had reported floor changes on the ETH walk (a hill: about 6 m at 0.1 m/s, "
                  "as fast as slow stairs); the column without GPS shows what it reports without the rule."]
    L += ["", f"Headlines (report): simulator floor sequence right in {h['sim_floor_sequence_correct_pct']:.0f} % "
              f"of walks; IPIN report recordings with a false floor change: "
              f"{h['ipin_report_recordings_with_a_floor_change']}.", ""]
    Path(path).write_text("\n".join(L))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.floors", description=__doc__.split("\n")[0])
    add_common(ap, what="sim or recording names (T05r01, babur_walking) or datasets")
    ap.add_argument("--write-results", action="store_true",
                    help="rewrite the committed floors_results.json, FLOORS_RESULTS.md and fold it into RESULTS.md "
                         "(a full run only; without it the results go to out/benchmarks/floors/)")
    args = ap.parse_args(argv)
    if args.write_results and not writes_committed(args):
        ap.error("--write-results is for a full run: not with --only or --no-write")
    root = data_root(args)
    keys = only_keys(args)
    t0 = time.perf_counter()
    out = {"sim": {}, "real": []}
    for split, seeds in SIM_SEEDS.items() if selected(keys, "sim") else ():
        rows = run_sim(seeds)
        out["sim"][split] = summarise_sim(rows)
        out["sim"][split]["rows"] = rows
        print(f"simulator {split}: {out['sim'][split]['floor_sequence_correct_pct']:.0f} % sequences right",
              file=sys.stderr)
    if root.is_dir() and keys != ["sim"]:
        out["real"] = run_real(root, keys=keys)
    out["headlines"] = headlines(out)
    print(json.dumps(out["headlines"], indent=1))
    print(f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    bad = [r for r in out["real"] if r.get("error")]
    if bad:
        print(f"floors: {len(bad)} failed: " + "; ".join(f"{r['dataset']}/{r['recording']} ({r['error']})"
                                                          for r in bad), file=sys.stderr)
    if args.write_results:
        write_json(RESULTS_JSON, out, digits=None)
        write_markdown(out)
        from benchmarks.report import refresh_sections

        refresh_sections()
    else:
        d = out_dir("floors")
        write_json(d / RESULTS_JSON.name, out, digits=None)
        try:
            write_markdown(out, d / RESULTS_MD.name)
            print(f"floors: wrote {d / RESULTS_MD.name}", file=sys.stderr)
        except (KeyError, TypeError, ValueError, ZeroDivisionError):  # a subset without the simulator's part
            print(f"floors: wrote {d / RESULTS_JSON.name}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
