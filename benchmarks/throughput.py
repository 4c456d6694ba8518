"""Throughput of the hand-held pipeline, stage by stage, against attitude filters of other projects (issue #13).

    python -m benchmarks.throughput                 # one hour at 100 Hz (half an hour): THROUGHPUT_RESULTS.md
    python -m benchmarks.throughput --minutes 5     # a quick look (printed, nothing written)

The walk is simulated once (:func:`desktop.simulator.simulate_walk` along a
:func:`desktop.simulator.street_route`, accelerometer and gyroscope at 100 Hz,
magnetometer at 50 Hz, seed 13) and cached as raw arrays outside the repository
(``$PDR_BENCH_CACHE``, default ``<tmp>/pdr-bench-cache``).  Then, in this one
process and on the same samples:

* **stages**: each stage of :class:`core.pdr.pipeline.Pipeline` fed alone
  with what it gets in the pipeline (the sensor-health checks, the attitude
  EKF with its magnetometer calibration, the calibration alone, the grid
  resampler, the step detector, the heading smoother, Kubrak's speed
  window, and issue #17's carry-mode detector and walking-direction stage,
  each fed per grid sample what the pipeline feeds it), in events (or grid
  samples) per second and microseconds per input, and its cost per pipeline
  event;
* **pipeline, streaming**: ``Pipeline(keep_steps=False).update()`` once per
  event, as the app calls it (the events are made into a list first, so the
  time is the pipeline's alone);
* **pipeline, batch**: ``Pipeline().run(recording)``, which also iterates the
  recording and keeps the attitude log;
* **fast path**: :func:`desktop.fast.run_fast` (the desktop's second
  implementation over whole arrays, numba-compiled where installed), events per
  second after a warm-up call, each of its stages' share, and the compile time
  of its kernels measured apart (a fresh process with an empty numba cache,
  the first call less the second);
* **peers**: ``ahrs``' EKF and Madgwick filters and x-io's ``imufusion``, as
  :mod:`benchmarks.peers` runs them (one call per gyroscope sample, with the
  accelerometer and magnetometer interpolated to it), in samples per second;
  one peer sample stands for the gyroscope, accelerometer and magnetometer
  readings of its interval, so the fair comparison is the real-time factor
  (seconds of walk per second of CPU), given beside the rates;
* **memory**: the peak of a batch run at 10 and 60 minutes, in a fresh
  subprocess each: the growth of the process's peak resident set (``VmHWM``,
  reset through ``/proc/self/clear_refs`` once the recording is loaded; not
  ``ru_maxrss``, which a forked child inherits from its parent) over what it
  held then, per event, and the slope between the two walks;
* **profile**: ``cProfile``'s top functions (own time) of the streaming path on
  the first 10 minutes.

The machine has few cores and other work may run beside the benchmark: every
timing is the process's CPU time, the best of ``--repeat`` runs (3).  ``--minutes N`` simulates an
N-minute walk instead (the memory rows then use N/6 and N minutes); only the
full hour writes ``THROUGHPUT_RESULTS.md`` (and folds it into ``RESULTS.md``),
unless ``--write`` is given.  ``--only PART ... --json RUN.json`` (parts:
``pipeline stages fast memory profile``) reruns only those parts on top of an
earlier run's numbers (the rest is slow): the report's header says which rows
are from which run, and a table sets the rerun rows against the ones they
replaced.
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import io
import json
import math
import os
import platform
import pstats
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.equivalence import cache_dir, load_arrays, save_arrays
from benchmarks.options import out_dir
from core.conventions import ACC, GYRO, MAG

RESULTS_MD = Path(__file__).with_name("THROUGHPUT_RESULTS.md")

#: The lean phone path (issue #13, item 2), commit by commit: instructions per event of the streaming
#: pipeline counted by valgrind (``valgrind --tool=cachegrind --cache-sim=no``, events 2000 to 22000 of
#: the 3-minute walk of this benchmark, the run to event 2000 subtracted) -- deterministic, where the
#: timings of a shared two-core machine moved by 30 % from one run to the next.  Every commit was checked
#: by ``python -m benchmarks.equivalence`` against the results before the first one.
HISTORY = """### The lean phone path, commit by commit

| commit | change | instructions per event | against the start |
|---|---|---:|---:|
| 2436ca6 | before the speed work | 181,368 | 1.00 |
| 88337b3 | `AttitudeEKF.predict` in plain floats: the covariance as four 3 x 3 blocks of floats, `F P F^T + Q` written out | 158,890 | 0.88 |
| 4d7872f | the per-event windows (gyroscope spread, accelerometer direction and norm) on locals, the running median by `accumulate`/`bisect`, the zero-rate test's cheap spans first | 149,128 | 0.82 |
| 4415ada | `predict`'s three block products as one `c - a b` helper, no comprehensions | 141,907 | 0.78 |
| c1fc5cd | `UpdateFlags` filled at once; the magnetometer's navigation-frame sum written out | 136,595 | 0.75 |

`python -m benchmarks.equivalence` after each: steps, step times and lengths identical; positions within
1.4e-13 m, headings within 7.7e-14 rad, the attitude quaternions within 1.5e-15, the summary within 1.4e-14
(relative) on four IPIN 2023 logfiles, the ETH Sensor Logger walk and the demo."""
REPO = Path(__file__).resolve().parents[1]
RATE_HZ = 100.0
SEED = 13
PEERS = ("ekf", "madgwick", "imufusion")
PEER_LABEL = {"ekf": "ahrs EKF", "madgwick": "ahrs Madgwick", "imufusion": "imufusion (C)"}


# ---------------------------------------------------------------------------
# the walk


def walk(minutes: float):
    """The simulated walk of ``minutes`` (a :class:`core.recording.Recording`), cached."""
    from core.recording import Recording, make_stream

    sim = (REPO / "desktop" / "simulator.py").read_bytes()
    key = hashlib.sha256(sim).hexdigest()[:10]
    base = cache_dir() / f"throughput_walk_{minutes:g}min_{RATE_HZ:g}hz_seed{SEED}_{key}"
    if load_arrays(base) is None:
        from desktop.simulator import simulate_walk, street_route

        route = street_route(1.26 * 60.0 * minutes, seed=SEED)  # 1.26 m/s: the simulator's cruise speed
        rec = simulate_walk(route, rate_hz=RATE_HZ, seed=SEED).recording
        save_arrays(base, {**{f"{n}_t": rec.streams[n].t_ns for n in (ACC, GYRO, MAG)},
                           **{f"{n}_v": rec.streams[n].values for n in (ACC, GYRO, MAG)}})
    d, _ = load_arrays(base)
    return Recording({n: make_stream(n, d[f"{n}_t"], d[f"{n}_v"]) for n in (ACC, GYRO, MAG)},
                     source=f"simulated walk, {minutes:g} min")


def _best(fn, repeat: int) -> float:
    """Smallest CPU time (s) of this process over ``repeat`` calls of ``fn()``.

    CPU time, not wall time: on a shared two-core machine the wall time also counts the time other
    processes held the core; for this single-threaded code the two agree on a quiet machine.
    """
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


# ---------------------------------------------------------------------------
# the stages, each alone


def stage_timings(rec, events: list, repeat: int) -> list[dict]:
    """One row per stage: inputs, best time, and what it costs per pipeline event."""
    from core.dsp import GridResampler
    from core.pdr.attitude import AttitudeEKF
    from core.pdr.heading import RotationSmoother
    from core.pdr.magcal import MagCalibrator
    from core.pdr.pipeline import SATURATION_FLOOR, SensorHealth
    from core.pdr.steps import StepDetector
    from core.pdr.velocity import SpeedFeatureWindow
    from core import quaternion as quat

    n_events = len(events)
    rows = []

    def row(name, what, n, seconds, note=""):
        rows.append({"stage": name, "inputs": what, "n": n, "seconds": seconds, "per_s": n / seconds,
                     "us_per_input": 1e6 * seconds / n, "us_per_event": 1e6 * seconds / n_events, "note": note})

    def health():
        h = {s: SensorHealth(SATURATION_FLOOR[s]) for s in (ACC, GYRO, MAG)}
        for s, t, v in events:
            h[s].update(t, v[0], v[1], v[2])

    row("sensor health", "events", n_events, _best(health, repeat), "saturation and dead-sensor checks")

    def attitude():
        a = AttitudeEKF(mag_calibrator=MagCalibrator())
        pred, acc, mag = a.predict, a.update_acc, a.update_mag
        for s, t, v in events:
            (pred if s == GYRO else acc if s == ACC else mag)(t, v[0], v[1], v[2])
        return a

    row("attitude EKF", "events", n_events, _best(attitude, repeat), "with its magnetometer calibration")
    mag_events = [(t, v) for s, t, v in events if s == MAG]

    def magcal():
        c = MagCalibrator()
        for t, v in mag_events:
            c.update(t, v[0], v[1], v[2])

    row("magnetometer calibration", "mag events", len(mag_events), _best(magcal, repeat), "inside the EKF's time")
    acc_events = [(t, math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])) for s, t, v in events if s == ACC]

    def grid():
        g = GridResampler(rate_hz=50.0)
        out = []
        for t, x in acc_events:
            out.extend(g.update(t, x))
        return out

    row("grid resampler", "acc events", len(acc_events), _best(grid, repeat), "|a| onto the 50 Hz grid")
    samples = grid()

    def steps():
        d = StepDetector()
        for t, x in samples:
            d.update_grid(t, x)

    row("step detector", "grid samples", len(samples), _best(steps, repeat), "eqs. 2-3")

    def speed():
        w = SpeedFeatureWindow()
        for t, x in samples:
            w.update(t, x)
        w.features()

    row("speed window", "grid samples", len(samples), _best(speed, repeat), "Kubrak's eq.-1 regressors")
    # per grid sample what the pipeline has when it makes it (an accelerometer reading at or after the sample):
    # that reading, the last gyroscope reading, the EKF's attitude once started, and whether the detector found
    # a step there
    a = AttitudeEKF(mag_calibrator=MagCalibrator())
    det = StepDetector()
    feed, k = [], 0
    grid_t = [t for t, _ in samples]
    gyro_v = None
    for s, t, v in events:
        if s == GYRO:
            a.predict(t, v[0], v[1], v[2])
            gyro_v = v
        elif s == MAG:
            a.update_mag(t, v[0], v[1], v[2])
        else:
            a.update_acc(t, v[0], v[1], v[2])
            while k < len(grid_t) and grid_t[k] <= t:
                step = det.update_grid(grid_t[k], samples[k][1]) is not None
                feed.append((grid_t[k], a.q if a.initialized else None, v, gyro_v, step))
                k += 1
    started = [f for f in feed if f[1] is not None]
    mats = [quat.to_matrix(f[1]) for f in started]

    def smoother():
        sm = RotationSmoother(forward_b="auto")
        for m in mats:
            sm.update(m)

    row("heading smoother", "grid samples", len(mats), _best(smoother, repeat), "section 4.3, from R")
    row_carry, row_walkdir = _stage_inputs_issue17(feed, started, mats)
    if row_carry is not None:
        row("carry-mode detector", "grid samples", len(feed), _best(row_carry, repeat),
            "issue #17: core.pdr.carry, the detector alone (its per-mode step detectors not counted)")
    if row_walkdir is not None:
        row("walking direction", "grid samples", len(started), _best(row_walkdir, repeat),
            "issue #17: core.pdr.walkdir, fed every grid sample after the attitude's start")
    return rows


def _stage_inputs_issue17(feed: list, started: list, mats: list):
    """The carry-mode detector's and the walking-direction stage's timed loops (None where core has no such stage).

    Both are made as the pipeline makes them (its grid rate, its heading delay) and fed what it feeds them:
    the detector every grid sample's accelerometer reading and the last gyroscope reading; the walking
    direction, after the attitude's start, the attitude, that reading, the smoother's forward vector and axis
    (from an untimed smoother pass) and the step flag.
    """
    from core.pdr.heading import RotationSmoother
    from core.pdr.pipeline import Pipeline

    try:
        from core.pdr.carry import CarryModeDetector
    except ImportError:  # pragma: no cover - before issue #17's stage
        CarryModeDetector = None
    try:
        from core.pdr.walkdir import WalkingDirection
    except ImportError:  # pragma: no cover
        WalkingDirection = None
    p = Pipeline(keep_steps=False)
    carry = walkdir = None
    if CarryModeDetector is not None:
        def carry():
            c = CarryModeDetector(grid_rate_hz=p.grid_rate_hz)
            up = c.update_grid
            for t, _, av, gv, _ in feed:
                if gv is None:
                    up(t, av[0], av[1], av[2])
                else:
                    up(t, av[0], av[1], av[2], gv[0], gv[1], gv[2])
    if WalkingDirection is not None:
        sm = RotationSmoother(forward_b="auto")
        fwd = []
        for m in mats:
            sm.update(m)
            fwd.append((sm.forward_east, sm.forward_north, sm.forward_b))
        wd_in = [(t, q, av, fe, fn, step, axis) for (t, q, av, _, step), (fe, fn, axis) in zip(started, fwd)]

        def walkdir():
            w = WalkingDirection(grid_rate_hz=p.grid_rate_hz, delay_s=p.heading_delay_s)
            up = w.update
            for t, q, av, fe, fn, step, axis in wd_in:
                up(t, q, av[0], av[1], av[2], fe, fn, step, axis)
    return carry, walkdir


# ---------------------------------------------------------------------------
# the pipeline and the peers


def pipeline_timings(rec, events: list, repeat: int) -> list[dict]:
    from core.pdr.pipeline import Pipeline

    n = len(events)
    out = []

    def streaming():
        p = Pipeline(keep_steps=False)
        up = p.update
        for e in events:
            up(e[0], e[1], e[2])
        p.finish()

    def batch():
        Pipeline().run(rec)

    def iterate():
        for _ in rec.events([GYRO, ACC, MAG]):
            pass

    for name, fn, note in (("pipeline, streaming", streaming, "update() per event, keep_steps=False (the app; "
                                                            "defaults: carry-mode and walking-direction stages on)"),
                           ("pipeline, batch", batch, "run(): iterates the recording, keeps the attitude log"),
                           ("recording.events()", iterate, "the batch run's event iteration alone")):
        s = _best(fn, repeat)
        out.append({"stage": name, "inputs": "events", "n": n, "seconds": s, "per_s": n / s,
                    "us_per_input": 1e6 * s / n, "us_per_event": 1e6 * s / n, "note": note})
    return out


def fast_timings(rec, repeat: int, carry: bool = True, compile_time: bool = True) -> dict:
    """The fast desktop path on the walk: best CPU time after a warm-up, per stage, and the compile time.

    The default pipeline, carry-mode detection (issue #17) included; ``carry=False`` times it without.
    ``compile_time``: also time a compilation from an empty cache (a fresh process, about a minute).
    """
    from desktop.fast import HAVE_NUMBA, run_fast

    n = sum(len(rec.streams[k]) for k in (ACC, GYRO, MAG))
    run_fast(rec, carry=carry)  # compiled (or loaded from numba's cache) before the timing
    best, stages = math.inf, {}
    for _ in range(repeat):
        tm = {}
        t0 = time.process_time()
        run_fast(rec, timings=tm, carry=carry)
        s = time.process_time() - t0
        if s < best:
            best, stages = s, tm
    row = {"stage": "fast path", "inputs": "events", "n": n, "seconds": best, "per_s": n / best,
           "us_per_input": 1e6 * best / n, "us_per_event": 1e6 * best / n,
           "note": ("desktop.fast.run_fast: arrays and " + ("numba kernels" if HAVE_NUMBA else "kernels as plain Python")
                    + ("" if carry else "; carry=False")),
           "stages": {k: {"seconds": v, "us_per_event": 1e6 * v / n, "share": v / best} for k, v in stages.items()},
           "numba": _version("numba") if HAVE_NUMBA else None}
    row.update(_compile_time() if HAVE_NUMBA and compile_time else {})
    return row


def _version(mod: str) -> str:
    from importlib.metadata import version

    return version(mod)


def _compile_time() -> dict:
    """CPU seconds to compile the fast path's kernels: a fresh process, an empty numba cache, 30 s of walk."""
    import tempfile

    code = ("import time; from benchmarks.throughput import walk; rec = walk(0.5); t0 = time.process_time(); "
            "from desktop.fast import run_fast; run_fast(rec); t1 = time.process_time(); "
            "run_fast(rec); "
            "t2 = time.process_time(); print((t1 - t0) - (t2 - t1))")
    with tempfile.TemporaryDirectory() as cache:
        out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True,
                             env={**os.environ, "NUMBA_CACHE_DIR": cache})
    return {"compile_s": float(out.stdout.strip().splitlines()[-1])}


def peer_timings(rec, repeat: int) -> list[dict]:
    from benchmarks.peers import ATTITUDE, available_peers, synced_imu

    n_samples = len(synced_imu(rec)[0])
    out = []
    for name in PEERS:
        if name not in available_peers((name,)):
            out.append({"peer": name, "missing": True})
            continue
        s = _best(lambda: ATTITUDE[name](rec), repeat)
        out.append({"peer": name, "label": PEER_LABEL[name], "samples": n_samples, "seconds": s,
                    "per_s": n_samples / s, "us_per_sample": 1e6 * s / n_samples})
    return out


# ---------------------------------------------------------------------------
# memory (a subprocess per run) and the profile


def _vm(field: str) -> int:
    """A size line of /proc/self/status (bytes)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise OSError(f"no {field} in /proc/self/status")


def _memory_child(minutes: float) -> None:
    # The peak is the kernel's high-water mark of this process's resident set (VmHWM), reset to the
    # current RSS once the recording is loaded (``5 > /proc/self/clear_refs``).  Not ru_maxrss: a child
    # started by fork and exec inherits its parent's peak there (the benchmark's parent holds hundreds of MB).
    from core.pdr.pipeline import Pipeline

    rec = walk(minutes)
    n = sum(len(rec.streams[k]) for k in (ACC, GYRO, MAG))
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        reset = True
    except OSError:
        reset = False
    rss0 = _vm("VmRSS")
    res = Pipeline().run(rec)
    peak = _vm("VmHWM")
    print(json.dumps({"minutes": minutes, "events": n, "steps": len(res.track), "rss_loaded": rss0,
                      "peak": peak, "peak_reset": reset, "growth": peak - rss0, "bytes_per_event": (peak - rss0) / n}))


def memory(minutes: float) -> dict:
    walk(minutes)  # cache it first: the child then only loads it
    out = subprocess.run([sys.executable, "-m", "benchmarks.throughput", "--memory-child", str(minutes)],
                         cwd=REPO, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def profile(rec, minutes: float = 10.0, top: int = 15) -> tuple[list[dict], float]:
    """cProfile's top functions by own time of the streaming path over the first ``minutes``."""
    from core.pdr.pipeline import Pipeline

    t_end = rec.t0_ns + int(minutes * 60e9)
    events = [e for e in rec.events([GYRO, ACC, MAG]) if e[1] < t_end]
    p = Pipeline(keep_steps=False)
    up = p.update
    pr = cProfile.Profile()
    pr.enable()
    for e in events:
        up(e[0], e[1], e[2])
    pr.disable()
    st = pstats.Stats(pr, stream=io.StringIO())
    total = st.total_tt
    rows = []
    for (file, line, func), (cc, nc, tt, ct, _) in sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:top]:
        where = os.path.relpath(file, REPO) if file.startswith(str(REPO)) and ".venv" not in file else \
            (Path(file).name if file != "~" else "")
        rows.append({"function": f"{where}:{line}({func})" if where else func, "calls": nc, "tottime_s": tt,
                     "cumtime_s": ct, "share": tt / total, "us_per_event": 1e6 * tt / len(events)})
    return rows, total


# ---------------------------------------------------------------------------
# the report


def machine() -> dict:
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    vers = {}
    for mod in ("numpy", "ahrs", "imufusion"):
        try:
            from importlib.metadata import version
            vers[mod] = version(mod.replace("ahrs", "AHRS") if mod == "ahrs" else mod)
        except Exception:
            vers[mod] = "not installed"
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                            text=True).stdout.strip() or os.environ.get("PDR_BENCH_COMMIT", "?")  # an exported tree
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "implementation": platform.python_implementation(), **vers, "commit": commit,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def _walk_name(minutes: float) -> str:
    return "one-hour" if minutes == 60 else f"{minutes:g}-minute"


def markdown(d: dict) -> str:
    m = d["machine"]
    walk_s = d["walk_seconds"]
    L = ["## Throughput (issue #13)", "",
         f"`python -m benchmarks.throughput` ({d['seconds'] / 60:.0f} minutes here): a {_walk_name(d['minutes'])} "
         f"simulated walk at "
         f"100 Hz (acc and gyro 100 Hz, mag 50 Hz: {d['events']:,} events, {d['samples']:,} gyroscope samples), "
         f"run in one process on {m['cpu']} ({m['cores']} cores), CPython {m['python']}, numpy {m['numpy']}, "
         f"ahrs {m['ahrs']}, imufusion {m['imufusion']}; commit {m['commit']}, {m['date']}.  Every time is the "
         f"process's CPU time, the best of {d['repeat']} runs (other work shared the machine's two cores).", "",
         *([_rerun_header(d), ""] if d.get("parts") else [d["rerun"], ""] if d.get("rerun") else []),
         *_against_previous(d),
         "### Pipeline and stages", "",
         "| what | inputs | per second | µs per input | µs per pipeline event | note |",
         "|---|---|---:|---:|---:|---|"]
    fast = [d["fast"]] if d.get("fast") else []
    for r in d["pipeline"] + fast + d["stages"]:
        L.append(f"| {r['stage']} | {r['n']:,} {r['inputs']} | {r['per_s']:,.0f} | {r['us_per_input']:.2f} | "
                 f"{r['us_per_event']:.2f} | {r['note']} |")
    L += ["", "A stage's cost per pipeline event is its time divided by all the walk's events; the stages "
          "together do not add up to the pipeline (it also dispatches, gates, keeps the forward-vector "
          "history and completes the steps).", ""]
    if d.get("fast"):
        L += _fast_section(d)
    stream = d["pipeline"][0]
    rtf = walk_s / stream["seconds"]
    L += ["### Against other projects' attitude filters", "",
          "Same samples, same process.  A peer's sample is one gyroscope reading with the accelerometer and "
          "magnetometer interpolated to it: it stands for about 2.5 of our events (two 100 Hz readings and "
          "half a 50 Hz one), and a peer estimates the attitude only, where the pipeline also detects steps, "
          "smooths the heading, calibrates the magnetometer and reckons.  The real-time factor (seconds of "
          "walk per second of CPU) compares like with like.", "",
          "| what | samples or events per second | real-time factor | pipeline streaming's events/s over its rate "
          "| pipeline streaming's real-time factor over its |", "|---|---:|---:|---:|---:|",
          f"| pipeline, streaming | {stream['per_s']:,.0f} events/s | {rtf:,.0f} | | |"]
    for p in d["peers"]:
        if p.get("missing"):
            L.append(f"| {p['peer']} | not installed | | | |")
            continue
        prtf = walk_s / p["seconds"]
        L.append(f"| {p['label']} | {p['per_s']:,.0f} samples/s | {prtf:,.0f} | {stream['per_s'] / p['per_s']:.2f} "
                 f"| {rtf / prtf:.2f} |")
    L += ["", "### Memory of a batch run", "",
          "Peak resident set of a fresh process running `Pipeline().run()` (the kernel's high-water mark `VmHWM`, "
          "reset once the recording is loaded), above what it held then: the recording's own arrays are not "
          "counted, what the run allocates (numpy's buffers and lazily imported modules included) is.", "",
          "| walk | events | steps | peak growth | bytes per event |", "|---|---:|---:|---:|---:|"]
    for r in d["memory"]:
        L.append(f"| {r['minutes']:g} min | {r['events']:,} | {r['steps']:,} | {r['growth'] / 1e6:.1f} MB | "
                 f"{r['bytes_per_event']:.0f} |")
    if len(d["memory"]) == 2:
        m0, m1 = d["memory"]
        slope = (m1["growth"] - m0["growth"]) / max(m1["events"] - m0["events"], 1)
        if slope > 0:
            L += ["", f"Between the two walks the peak grows by **{slope:.0f} bytes per event** (the slope: what a "
                  f"longer walk costs); the rest is a fixed {(m0['growth'] - slope * m0['events']) / 1e6:.0f} MB of "
                  "first use (BLAS buffers, lazily imported modules, the calibration's fits), which the shorter "
                  "walk's per-event figure carries."]
        else:
            L += ["", f"The one-hour walk's peak is no higher than the 10-minute walk's ({slope:.0f} bytes per event "
                  "between them: the growth per event is below what the fixed first use -- BLAS buffers, lazily "
                  "imported modules, the calibration's fits, numpy's allocator -- varies from one process to the "
                  "next), so the shorter walk's per-event figure is that fixed cost spread over fewer events."]
    L += ["", f"`Pipeline.run` (issue #13 item 4) makes Python objects of a time slice of 16,384 events at a time "
          "and keeps its attitude log in typed columns (57 bytes a grid sample, 11 a pipeline event), so its memory "
          "grows with the steps and the log only; before, the whole walk's event lists (about 80 bytes an event) and "
          "a list of row tuples (about 80 more) made it 233 bytes an event."]
    L += ["", f"### Where the streaming path spends its time", "",
          f"`cProfile` on the first {min(10.0, d['minutes']):g} minutes of the walk (the profiler itself roughly doubles the time: "
          f"{d['profile_total_s']:.1f} s under it), the top functions by own time:", "",
          "| function | calls | own time (s) | share | µs per event |", "|---|---:|---:|---:|---:|"]
    for r in d["profile"]:
        L.append(f"| `{r['function']}` | {r['calls']:,} | {r['tottime_s']:.2f} | {100 * r['share']:.1f} % | "
                 f"{r['us_per_event']:.2f} |")
    if d.get("before"):
        b, a = d["before"], d["pipeline"]
        L += ["", "### Before and after", "",
              f"The same benchmark run on the code before the speed work ({b['commit']}) and after it, the "
              f"{b['minutes']:g}-minute walk, CPU time, best of {b['repeat']}, one after the other:", "",
              "| what | before, per second | after, per second | before, µs per input | after, µs per input |",
              "|---|---:|---:|---:|---:|"]
        after = {r["stage"]: r for r in d.get("after_short", a + d["stages"])}
        for r in b["pipeline"] + b["stages"]:
            n = after.get(r["stage"])
            if n is not None:
                L.append(f"| {r['stage']} | {r['per_s']:,.0f} | {n['per_s']:,.0f} | {r['us_per_input']:.2f} | "
                         f"{n['us_per_input']:.2f} |")
        L += ["", "Stages the speed work did not touch (the event iteration, the magnetometer calibration, the "
              "heading smoother) moved by up to 40 % between the two runs: the noise of a shared machine, even in "
              "CPU time.  The instruction counts below are the deterministic measure."]
    L += ["", HISTORY]
    if d.get("notes"):
        L += ["", *d["notes"]]
    return "\n".join(L) + "\n"


#: the issue's target for the fast desktop path (events per second, whole pipeline, batch)
FAST_TARGET_PER_S = 1_000_000


def _fast_section(d: dict) -> list[str]:
    f = d["fast"]
    batch = d["pipeline"][1]
    nc = d.get("fast_no_carry")
    L = ["### The fast desktop path", "",
         f"`desktop.fast.run_fast` (issue #13 item 3) on the same walk, the default pipeline (carry-mode detection "
         f"and the walking-direction stage included): {f['per_s']:,.0f} events/s ({f['us_per_event']:.2f} µs per "
         f"event), {f['per_s'] / batch['per_s']:.1f} times the batch run (`Pipeline().run`)"
         + (f"; without the carry-mode stage ({nc['note']}) {nc['per_s']:,.0f} events/s" if nc else "")
         + ".  Its results are `Pipeline.run`'s: the same steps and carry modes, positions and headings within "
         "1e-9 (`tests/test_fast_path.py`; " + f.get("equivalence", "`python -m benchmarks.equivalence --fast`") + ").  "
         + (f"numba {f['numba']}; compiling its kernels takes {f['compile_s']:.0f} s of CPU once (a fresh process "
            f"with an empty cache), after which numba's cache loads them in a few seconds."
            if f.get("numba") else "numba was not installed: its kernels ran as plain Python."), "",
         "| stage | CPU s | µs per event | share |", "|---|---:|---:|---:|"]
    for name, r in f["stages"].items():
        L.append(f"| {name} | {r['seconds']:.3f} | {r['us_per_event']:.2f} | {100 * r['share']:.0f} % |")
    top = sorted(f["stages"].items(), key=lambda kv: -kv[1]["seconds"])[:3]
    L += ["", f"Against the issue's target of {FAST_TARGET_PER_S:,} events/s: "
          + ("reached." if f["per_s"] >= FAST_TARGET_PER_S else
             f"missed by a factor of {FAST_TARGET_PER_S / f['per_s']:.1f}.  The largest stages are "
             + ", ".join(f"{k} ({100 * r['share']:.0f} %)" for k, r in top) + ".  What still runs as Python: "
             "the carry detector's decision once per hop (core's scores and hysteresis, about 7,200 hops an hour; its "
             "window features are batched numpy), the magnetometer calibration's fits where one is due (core's "
             "sphere and ellipsoid fits; everything up to them is compiled), and the gates and the completion of "
             "each step (core's stride model and dead reckoner, once per step)."), ""]
    return L


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.throughput", description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0, help="length of the simulated walk (default 60)")
    ap.add_argument("--repeat", type=int, default=3, help="timings are the best of this many runs (default 3)")
    ap.add_argument("--no-peers", action="store_true", help="skip the peers (ahrs' EKF alone takes minutes)")
    ap.add_argument("--write", action="store_true", help="write THROUGHPUT_RESULTS.md even for a short walk")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument("--markdown-only", action="store_true",
                    help="rewrite THROUGHPUT_RESULTS.md from the --json of a run (and --before, --after-short)")
    ap.add_argument("--before", type=Path, default=None,
                    help="with --markdown-only: the --json of a run on the code before the speed work")
    ap.add_argument("--after-short", type=Path, default=None,
                    help="with --markdown-only: the --json of a run of this code on --before's walk")
    ap.add_argument("--only", nargs="+", choices=tuple(PARTS), default=None,
                    help="rerun only these parts on top of the run in --json (updated in place), then write the report")
    ap.add_argument("--data", "--data-root", dest="data", type=Path, default=None,
                    help="accepted as by every benchmark; unused: the walk is simulated (--minutes)")
    ap.add_argument("--no-write", action="store_true",
                    help="write the report under out/benchmarks/throughput/, touch nothing tracked by git")
    ap.add_argument("--memory-child", type=float, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.memory_child is not None:
        _memory_child(args.memory_child)
        return 0
    if args.markdown_only:
        d = json.loads(args.json.read_text())
        if args.before is not None:
            b = json.loads(args.before.read_text())
            d["before"] = {"commit": b["machine"]["commit"], "minutes": b["minutes"], "repeat": b["repeat"],
                           "pipeline": b["pipeline"], "stages": b["stages"]}
        if args.after_short is not None:
            a = json.loads(args.after_short.read_text())
            d["after_short"] = a["pipeline"] + a["stages"]
        _write_report(d, args)
        return 0
    if args.only:
        return _rerun(args)
    t_start = time.perf_counter()
    rec = walk(args.minutes)
    events = list(rec.events([GYRO, ACC, MAG]))
    print(f"{len(events):,} events over {rec.duration_s / 60:.1f} min", file=sys.stderr)
    d = {"machine": machine(), "minutes": args.minutes, "repeat": args.repeat, "events": len(events),
         "walk_seconds": rec.duration_s, "samples": len(rec.streams[GYRO])}
    d["pipeline"] = pipeline_timings(rec, events, args.repeat)
    for r in d["pipeline"]:
        print(f"{r['stage']:28s} {r['per_s']:10,.0f} /s {r['us_per_input']:8.2f} us", file=sys.stderr)
    d["stages"] = stage_timings(rec, events, args.repeat)
    for r in d["stages"]:
        print(f"{r['stage']:28s} {r['per_s']:10,.0f} /s {r['us_per_input']:8.2f} us  {r['us_per_event']:6.2f} "
              f"us/event", file=sys.stderr)
    d["fast"] = fast_timings(rec, args.repeat)
    d["fast_no_carry"] = fast_timings(rec, args.repeat, carry=False, compile_time=False)
    print(f"{'fast path':28s} {d['fast']['per_s']:10,.0f} /s", file=sys.stderr)
    d["peers"] = [] if args.no_peers else peer_timings(rec, args.repeat)
    for p in d["peers"]:
        if not p.get("missing"):
            print(f"{p['label']:28s} {p['per_s']:10,.0f} samples/s", file=sys.stderr)
    del events
    d["memory"] = [memory(m) for m in (args.minutes / 6.0, args.minutes)]
    for r in d["memory"]:
        print(f"memory {r['minutes']:g} min: {r['bytes_per_event']:.0f} bytes/event", file=sys.stderr)
    d["profile"], d["profile_total_s"] = profile(rec, min(10.0, args.minutes))
    d["seconds"] = time.perf_counter() - t_start
    if args.json:
        args.json.write_text(json.dumps(d, indent=1))
    if args.write or args.minutes == 60.0 or args.no_write:
        _write_report(d, args)
    else:
        print(markdown(d))
    print(f"{d['seconds']:.0f} s", file=sys.stderr)
    return 0


#: the parts ``--only`` reruns, as the report's header names them
PARTS = {"pipeline": "the pipeline rows (streaming, batch, the event iteration)", "stages": "the stage rows",
         "fast": "the fast path and its stage timing", "memory": "the memory of a batch run",
         "profile": "the streaming path's profile"}


def _rerun_header(d: dict) -> str:
    """Which rows are from which run: every part rerun on its own, then the run the rest is from."""
    parts = d["parts"]
    said = [f"{PARTS[k]} at commit {v['commit']}, {v['date']}" + (f" ({v['note']})" if v.get("note") else "")
            for k, v in parts.items()]
    rest = ["the peers", "the before-and-after tables"] + [PARTS[k] for k in PARTS if k not in parts]
    return (f"Rerun on their own (`--only`): {'; '.join(said)}; every other number ({', '.join(rest)}) is from "
            f"the run at commit {d['machine']['commit']}, {d['machine']['date']}.")


def _against_previous(d: dict) -> list[str]:
    """The rows of the latest ``--only`` rerun against the same rows of the run they replaced."""
    prev = d.get("previous")
    if not prev:
        return []
    now = {"pipeline": d["pipeline"], "stages": d["stages"], "fast": [d["fast"]] if d.get("fast") else []}
    L = ["### This rerun against the one before", "",
         "| what | before, per second | after, per second | after / before | before: commit |",
         "|---|---:|---:|---:|---|"]
    for part, old in prev.items():
        before = {r["stage"]: r for r in old["rows"]}
        for n in now[part]:
            r = before.get(n["stage"])
            if r is None:
                L.append(f"| {n['stage']} | (a new row) | {n['per_s']:,.0f} | | |")
            else:
                L.append(f"| {n['stage']} | {r['per_s']:,.0f} | {n['per_s']:,.0f} | {n['per_s'] / r['per_s']:.2f} | "
                         f"{old['commit']} ({old['date']}) |")
    return L + ["", "CPU time, best of the runs, on a machine shared with other work: a stage the change did not "
                "touch can move by tens of per cent between two runs.", ""]


def _rerun(args) -> int:
    """``--only``: the chosen parts anew on the walk of the run in ``--json``; the rest of its numbers kept."""
    if args.json is None or not args.json.exists():
        raise SystemExit("--only needs --json: an earlier run's numbers to update")
    d = json.loads(args.json.read_text())
    m = machine()
    parts = d.setdefault("parts", {})
    when = {k: parts.get(k, {"commit": d["machine"]["commit"], "date": d["machine"]["date"]}) for k in PARTS}
    d["previous"] = {}
    rec = walk(d["minutes"]) if {"pipeline", "stages", "fast"} & set(args.only) else None
    events = list(rec.events([GYRO, ACC, MAG])) if {"pipeline", "stages"} & set(args.only) else None
    if "pipeline" in args.only:
        d["previous"]["pipeline"] = {**when["pipeline"], "rows": d["pipeline"]}
        d["pipeline"] = pipeline_timings(rec, events, args.repeat)
        for r in d["pipeline"]:
            print(f"{r['stage']:28s} {r['per_s']:10,.0f} /s", file=sys.stderr)
    if "stages" in args.only:
        d["previous"]["stages"] = {**when["stages"], "rows": d["stages"]}
        d["stages"] = stage_timings(rec, events, args.repeat)
        for r in d["stages"]:
            print(f"{r['stage']:28s} {r['per_s']:10,.0f} /s", file=sys.stderr)
    del events
    if "fast" in args.only:
        if d.get("fast"):
            d["previous"]["fast"] = {**when["fast"], "rows": [{k: v for k, v in d["fast"].items() if k != "stages"}]}
        d["fast"] = fast_timings(rec, args.repeat)
        d["fast_no_carry"] = fast_timings(rec, args.repeat, carry=False, compile_time=False)
        print(f"fast path {d['fast']['per_s']:,.0f} events/s (without carry {d['fast_no_carry']['per_s']:,.0f})",
              file=sys.stderr)
    if "memory" in args.only:
        d["memory"] = [memory(x) for x in (d["minutes"] / 6.0, d["minutes"])]
    if "profile" in args.only:
        d["profile"], d["profile_total_s"] = profile(rec or walk(d["minutes"]), min(10.0, d["minutes"]))
    for k in args.only:
        parts[k] = {"commit": m["commit"], "date": m["date"]}
    d.pop("rerun", None)
    args.json.write_text(json.dumps(d, indent=1))
    _write_report(d, args)
    return 0


def _write_report(d: dict, args) -> None:
    """THROUGHPUT_RESULTS.md (and RESULTS.md's section), or with ``--no-write`` the same file under
    ``out/benchmarks/throughput/`` and nothing tracked by git."""
    if args.no_write:
        path = out_dir("throughput") / RESULTS_MD.name
        path.write_text(markdown(d))
    else:
        path = RESULTS_MD
        path.write_text(markdown(d))
        from benchmarks.report import refresh_sections

        refresh_sections()
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
