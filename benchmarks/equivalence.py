"""The pipeline's results on real recordings, stored and compared: the guard of the speed work (issue #13).

    python -m benchmarks.equivalence --save       # store the results of the code as it is now
    python -m benchmarks.equivalence              # compare the code as it is now with the stored results

An optimisation of the per-event code must not change what the pipeline
computes.  Before a change, ``--save`` runs :class:`core.pdr.pipeline.Pipeline`
(defaults, batch ``run()``) on a set of real recordings and stores, per
recording, the step times, lengths, headings and positions, the attitude log
on the grid (quaternion, smoothed heading, eqs. 17-18 variances, magnetometer
rejections) and the summary (counters, labels).  After it, the comparison
reruns them and reports the largest absolute difference per quantity
(positions and lengths in metres, headings in radians, compared modulo 2 pi);
it fails when any exceeds ``--tol`` (1e-9) or when a count, label or integer
differs.  Floats in the summary (NIS sums, biases, distances) are compared
to ``tol`` times ``max(1, |value|)``.

The recordings (``--data``, default ``../shared/data``): four IPIN 2023
track-3 logfiles (GetSensorData, hand-held, 5-13 minutes), the ETH Sensor Logger
walk (12 minutes outdoors) and the bundled demo (``desktop/data``); the
recordings that are not there are skipped and named.  ``--quick``: the demo
and one IPIN logfile.  ``--fast``: the results of the fast desktop path
(:func:`desktop.fast.run_fast`, a second implementation over whole arrays)
instead of ``Pipeline().run``, compared with results stored from the phone's
path: the two implementations held to each other on all six recordings.
Both run the default pipeline, carry-mode detection (issue #17) included;
``--no-carry`` runs both without it (store with ``--save --no-carry`` then).

The stored results live outside the repository (``--store``, default
``$PDR_BENCH_CACHE/equivalence.json``, ``$PDR_BENCH_CACHE`` defaulting to
``<tmp>/pdr-bench-cache``), and so do the recordings as ``--save`` read them:
the comparison replays those, so a change to a reader is not taken for one of
the pipeline's.  The results also record a digest of the core modules the
pipeline loads outside the files under change (stride models, conventions), so
that a difference caused by someone else's change is told apart.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
IPIN = ("IPIN2023_T3_TrainingTrial01_repetition01", "IPIN2023_T3_TrainingTrial04_repetition02",
        "IPIN2023_T3_TrainingTrial22_repetition03", "IPIN2023_T3_TrainingTrial24_repetition04")
#: the per-event files the speed work changes; every other core module is digested (see the docstring)
UNDER_CHANGE = ("core/dsp.py", "core/quaternion.py", "core/kalman.py", "core/pdr/pipeline.py", "core/pdr/steps.py",
                "core/pdr/attitude.py", "core/pdr/attitude_qekf.py", "core/pdr/heading.py", "core/pdr/magcal.py",
                "core/pdr/deadreckoning.py")


def cache_dir() -> Path:
    """The benchmarks' cache outside the repository (``$PDR_BENCH_CACHE`` or ``<tmp>/pdr-bench-cache``)."""
    d = Path(os.environ.get("PDR_BENCH_CACHE") or Path(tempfile.gettempdir()) / "pdr-bench-cache")
    d.mkdir(parents=True, exist_ok=True)
    return d


def save_arrays(base: Path, arrays: dict[str, np.ndarray], meta: dict | None = None) -> None:
    """Arrays as one raw file (``base.bin``) and a JSON index of names, dtypes and shapes (``base.json``).

    No pickle and no ``np.load`` (the product loads nothing unsafely: ``tests/test_no_unsafe_loading.py``).
    """
    index, offset = [], 0
    tmp = base.with_name(base.name + ".tmp")
    with open(tmp, "wb") as f:
        for name, a in arrays.items():
            a = np.ascontiguousarray(a)
            index.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset})
            f.write(a.tobytes())
            offset += a.nbytes
    os.replace(tmp, base.with_name(base.name + ".bin"))
    base.with_name(base.name + ".json").write_text(json.dumps({"arrays": index, "meta": meta or {}}, default=str))


def load_arrays(base: Path) -> tuple[dict[str, np.ndarray], dict] | None:
    """What :func:`save_arrays` wrote (arrays, meta), or None when it is not there."""
    binf, jsf = base.with_name(base.name + ".bin"), base.with_name(base.name + ".json")
    if not (binf.exists() and jsf.exists()):
        return None
    d = json.loads(jsf.read_text())
    out = {}
    for e in d["arrays"]:
        dt = np.dtype(e["dtype"])
        n = int(np.prod(e["shape"], dtype=np.int64))
        out[e["name"]] = np.fromfile(binf, dtype=dt, count=n, offset=e["offset"]).reshape(e["shape"])
    return out, d["meta"]


def default_data_root() -> Path:
    return REPO.parent / "shared" / "data"


def recordings(root: Path, quick: bool = False) -> tuple[dict[str, Path], list[str]]:
    """``{name: path}`` of the recordings present, and the names missing."""
    want = {"demo": REPO / "desktop" / "data" / "demo_walk.csv.gz"}
    for name in IPIN[:1] if quick else IPIN:
        want[name] = root / "ipin2023_track3" / "logfiles" / f"{name}.txt.gz"
    if not quick:
        want["eth_walk"] = root / "sensorlogger_gps_walk_ethz" / "2023-03-17_15-50-47"
    have = {k: p for k, p in want.items() if p.exists()}
    return have, sorted(set(want) - set(have))


def other_core_digest() -> str:
    """SHA-256 over the core modules the pipeline loads, outside :data:`UNDER_CHANGE`."""
    import core.pdr.pipeline  # noqa: F401

    files = sorted({Path(m.__file__).resolve() for k, m in list(sys.modules.items())
                    if (k == "core" or k.startswith("core.")) and not k.startswith("core.importers")
                    and getattr(m, "__file__", None)})
    h = hashlib.sha256()
    for p in files:
        rel = p.relative_to(REPO).as_posix()
        if rel not in UNDER_CHANGE:
            h.update(rel.encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def _recording(path: str, refresh: bool):
    """The recording as read when the results were stored (cached: a change to a reader is not ours)."""
    import warnings

    from core.importers import load_recording
    from core.recording import Recording, Stream

    base = cache_dir() / f"equivalence_rec_{Path(path).name}"  # one cache whichever checkout runs this
    if refresh or load_arrays(base) is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = load_recording(path)
        save_arrays(base, {**{f"t{i}": s.t_ns for i, s in enumerate(rec.streams.values())},
                           **{f"v{i}": s.values for i, s in enumerate(rec.streams.values())}},
                    {"streams": [[s.name, list(s.columns), s.unit, s.note] for s in rec.streams.values()],
                     "device": rec.device, "metadata": rec.metadata, "source": rec.source})
    d, m = load_arrays(base)
    streams = {name: Stream(name, d[f"t{i}"], d[f"v{i}"], tuple(cols), unit, note)
               for i, (name, cols, unit, note) in enumerate(m["streams"])}
    return Recording(streams, m["device"], m["metadata"], [], m["source"])


def results_of(path: str, refresh: bool = False, fast: bool = False, carry: bool = True) -> dict:
    """Run the default pipeline (or the fast path) on one recording; what is stored of it (JSON-able)."""
    from core.pdr.pipeline import Pipeline

    rec = _recording(path, refresh)
    t0 = time.perf_counter()
    if fast:
        from desktop.fast import run_fast

        res = run_fast(rec, carry=carry)
    else:
        res = Pipeline(carry=carry).run(rec)
    seconds = time.perf_counter() - t0
    tr, att = res.track, res.attitude
    return {
        "events": int(sum(len(rec.streams[n]) for n in ("acc", "gyro", "mag") if rec.has(n))),
        "seconds": seconds,
        "step_t_ns": tr.t_ns.tolist(), "length_m": tr.length_m.tolist(), "heading_rad": tr.heading_rad.tolist(),
        "east_m": tr.east_m.tolist(), "north_m": tr.north_m.tolist(),
        "mag_trusted": [bool(s.mag_trusted) for s in res.steps],
        "att_t_ns": att.t_ns.tolist(), "att_q": att.q_wxyz.ravel().tolist(),
        "att_heading_rad": att.heading_rad.tolist(), "att_acc_sigma2": att.acc_sigma2.tolist(),
        "att_mag_sigma2": att.mag_sigma2.tolist(), "att_mag_rejected": att.mag_rejected.tolist(),
        "summary": json.loads(json.dumps(res.summary(), default=float)),
    }


def run_all(paths: dict[str, Path], jobs: int, refresh: bool = False, fast: bool = False,
            carry: bool = True) -> dict[str, dict]:
    names = list(paths)
    if jobs <= 1:
        return {n: results_of(str(paths[n]), refresh, fast, carry) for n in names}
    with ProcessPoolExecutor(jobs) as ex:
        return dict(zip(names, ex.map(results_of, [str(paths[n]) for n in names], [refresh] * len(names),
                                      [fast] * len(names), [carry] * len(names))))


def _nan_equal_diff(a: np.ndarray, b: np.ndarray, angle: bool = False) -> float:
    """Largest absolute difference of two float arrays; inf when their NaNs differ."""
    na, nb = np.isnan(a), np.isnan(b)
    if not np.array_equal(na, nb):
        return math.inf
    d = a[~na] - b[~nb]
    if angle:
        d = (d + math.pi) % (2 * math.pi) - math.pi
    return float(np.max(np.abs(d))) if d.size else 0.0


ANGLES = {"heading_rad", "att_heading_rad"}
EXACT = {"step_t_ns", "att_t_ns", "mag_trusted", "att_mag_rejected"}


def _compare_tree(a, b, path: str, tol: float, out: list) -> float:
    """Walk two summaries; append mismatches to ``out``; returns the largest relative float difference."""
    worst = 0.0
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            out.append(f"{path}: keys {sorted(set(a) ^ set(b))} differ")
        for k in set(a) & set(b):
            worst = max(worst, _compare_tree(a[k], b[k], f"{path}.{k}", tol, out))
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: length {len(a)} != {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            worst = max(worst, _compare_tree(x, y, f"{path}[{i}]", tol, out))
    elif isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
            if math.isnan(a) or math.isnan(b):
                if not (math.isnan(a) and math.isnan(b)):
                    out.append(f"{path}: {a!r} != {b!r}")
                return worst
            d = abs(a - b) / max(1.0, abs(a))
            if d > tol:
                out.append(f"{path}: {a!r} != {b!r}")
            worst = max(worst, d)
        else:
            out.append(f"{path}: {a!r} != {b!r}")
    elif a != b:
        out.append(f"{path}: {a!r} != {b!r}")
    return worst


def compare(old: dict, new: dict, tol: float) -> tuple[dict[str, float], list[str]]:
    """Largest differences per quantity over the recordings, and the mismatches beyond ``tol``."""
    worst: dict[str, float] = {}
    bad: list[str] = []
    for name, o in old.items():
        n = new.get(name)
        if n is None:
            continue
        for key, ov in o.items():
            if key in ("seconds", "events", "summary"):
                continue
            nv = n[key]
            if key in EXACT:
                if ov != nv:
                    bad.append(f"{name}.{key}: differs ({len(ov)} against {len(nv)} values)")
                    worst[key] = math.inf
                else:
                    worst.setdefault(key, 0.0)
                continue
            if len(ov) != len(nv):
                bad.append(f"{name}.{key}: {len(ov)} values against {len(nv)}")
                worst[key] = math.inf
                continue
            d = _nan_equal_diff(np.array(ov, dtype=float), np.array(nv, dtype=float), angle=key in ANGLES)
            worst[key] = max(worst.get(key, 0.0), d)
            if d > tol:
                bad.append(f"{name}.{key}: max abs difference {d:.3g}")
        w = _compare_tree(o["summary"], n["summary"], f"{name}.summary", tol, bad)
        worst["summary (relative)"] = max(worst.get("summary (relative)", 0.0), w)
    return worst, bad


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.equivalence", description=__doc__.split("\n")[0])
    ap.add_argument("--save", action="store_true", help="store the results of the code as it is now")
    ap.add_argument("--store", type=Path, default=None, help="the stored results (default: in the cache dir)")
    ap.add_argument("--data", type=Path, default=None, help="data root (default ../shared/data)")
    ap.add_argument("--quick", action="store_true", help="the demo and one IPIN logfile")
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--fast", action="store_true",
                    help="the fast desktop path's results (desktop.fast.run_fast)")
    ap.add_argument("--no-carry", action="store_true", help="the pipeline without carry-mode detection")
    args = ap.parse_args(argv)
    if args.fast and args.save:
        raise SystemExit("--fast compares with results stored from Pipeline.run; it stores none")
    store = args.store or cache_dir() / "equivalence.json"
    paths, missing = recordings(args.data or default_data_root(), args.quick)
    if missing:
        print("missing, skipped: " + ", ".join(missing), file=sys.stderr)
    t0 = time.perf_counter()
    carry = not args.no_carry
    new = run_all(paths, args.jobs, refresh=args.save, fast=args.fast, carry=carry)
    wall = time.perf_counter() - t0
    for name, r in new.items():
        print(f"{name:45s} {r['events']:8d} events {len(r['step_t_ns']):5d} steps {r['seconds']:6.1f} s "
              f"{r['events'] / r['seconds']:8.0f} events/s")
    print(f"wall {wall:.1f} s")
    digest = other_core_digest()
    if args.save:
        store.write_text(json.dumps({"other_core_digest": digest, "carry": carry, "recordings": new}))
        print(f"stored {store}")
        return 0
    saved = json.loads(store.read_text())
    if saved.get("carry", True) != carry:
        print(f"NOTE: the stored results were {'with' if saved.get('carry', True) else 'without'} carry-mode "
              f"detection, these {'with' if carry else 'without'} (store with the same --no-carry setting)",
              file=sys.stderr)
    if saved["other_core_digest"] != digest:
        print("NOTE: core modules outside the files under change differ from the stored run's: "
              "a difference may come from them", file=sys.stderr)
    worst, bad = compare(saved["recordings"], new, args.tol)
    for k, v in sorted(worst.items()):
        print(f"  max abs difference {k:22s} {v:.3g}")
    if bad:
        print(f"DIFFERENT beyond {args.tol:g}:\n  " + "\n  ".join(bad[:40]))
        return 1
    print(f"equivalent to {args.tol:g} on {len(new)} recordings")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
