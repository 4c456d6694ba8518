"""Peak memory and speed of the recording readers on long synthetic walks (issue #12, class 5).

    python -m benchmarks.reader_memory                      # 10 and 60 minutes at 100 Hz, every reader
    python -m benchmarks.reader_memory --minutes 10 --formats pdr,gsd
    python -m benchmarks.reader_memory --code /tmp/old      # the readers of another checkout (before/after)

For each format a walk is written once (cached under ``--cache``): acc and
gyro at 100 Hz, mag at 50 Hz (250 events a second) -- the project format
(``.csv`` and ``.csv.gz``), a GetSensorData logfile (also with AHRS lines),
a Sensor Logger zip and a phyphox zip; ``demo`` is the bundled demo walk.
Each file is then read in fresh subprocesses: once under
:mod:`tracemalloc` (the peak of Python's allocations, numpy's included)
and once without it, reading it ``--repeat`` times for the time (the
fastest read counts; the RSS growth is that process's).
Printed per file: events, the result's own size (timestamps and values),
the peak in bytes per event above that result, the process's peak RSS
growth, and microseconds per event.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import zipfile

import numpy as np

RATES_HZ = {"acc": 100.0, "gyro": 100.0, "mag": 50.0}
T0_NS = 1_000_000_000_000
UNIX0_NS = 1_700_000_000_000_000_000
G = 9.80665


def _signals(minutes: float, seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per stream: (t_ns, values (n, 3)): a phone walking with a 2 Hz step rhythm plus sensor noise."""
    rng = np.random.default_rng(seed)
    out = {}
    for k, (name, rate) in enumerate(RATES_HZ.items()):
        n = int(minutes * 60 * rate)
        t = T0_NS + k * 1000 + np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
        ph = 2 * np.pi * 2.0 * np.arange(n) / rate
        base = {"acc": np.column_stack([0.5 * np.sin(ph), 0.3 * np.cos(ph), G + 1.5 * np.sin(ph)]),
                "gyro": np.column_stack([0.4 * np.sin(ph), 0.2 * np.cos(ph), 0.1 * np.sin(ph / 2)]),
                "mag": np.tile([20.0, 5.0, -40.0], (n, 1))}[name]
        out[name] = (t, base + rng.normal(0, 0.05, (n, 3)))
    return out


def write_pdr(path: str, sig) -> None:
    from core.recording import Recording, make_stream, write_recording
    write_recording(path, Recording({n: make_stream(n, t, v) for n, (t, v) in sig.items()}))


def write_gsd(path: str, sig) -> None:
    tags = {"acc": "ACCE", "gyro": "GYRO", "mag": "MAGN"}
    rows = []
    for name, (t, v) in sig.items():
        s = (t - T0_NS) * 1e-9 + 5000.0
        rows += [(ti, f"{tags[name]};{si - 4999.95:.4f};{si:.4f};{a:.5f};{b:.5f};{c:.5f};3\n")
                 for ti, si, (a, b, c) in zip(t.tolist(), s.tolist(), v.tolist())]
    t, _ = sig["acc"]
    for ti in t[::2].tolist():  # AHRS at 50 Hz
        si = (ti - T0_NS) * 1e-9 + 5000.0
        rows.append((ti + 1, f"AHRS;{si - 4999.95:.4f};{si:.4f};10.5;-3.25;120.75;0.1;0.2;0.3;3\n"))
    rows.sort(key=lambda r: r[0])
    with open(path, "w") as f:
        f.write("% LogFile created by the 'GetSensorData' App for Android.\n% Version 2.21\n")
        f.writelines(r for _, r in rows)


def _sl_csv(t, v) -> str:
    el = (t - t[0]) * 1e-9
    return "time,seconds_elapsed,z,y,x\n" + "".join(
        f"{ti},{e!r},{c!r},{b!r},{a!r}\n" for ti, e, (a, b, c) in zip((t - T0_NS + UNIX0_NS).tolist(), el.tolist(),
                                                                     v.tolist()))


def write_sensorlogger(path: str, sig) -> None:
    files = {"TotalAcceleration.csv": "acc", "Gyroscope.csv": "gyro", "Magnetometer.csv": "mag"}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for fn, name in files.items():
            z.writestr(fn, _sl_csv(*sig[name]))
        z.writestr("Metadata.csv", "version,device name,recording time,platform,appVersion\n"
                                   "3,Bench,2023-11-14_22-13-20,android,1.30.0\n")


def _phy_num(x: float) -> str:
    m, e = f"{x:.9E}".split("E")
    return f"{m}E{int(e)}"


def write_phyphox(path: str, sig) -> None:
    heads = {"acc": ("Raw Data.csv", "Acceleration {} (m/s^2)"), "gyro": ("Gyroscope.csv", "Gyroscope {} (rad/s)"),
             "mag": ("Magnetometer.csv", "Magnetic field {} (µT)")}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, (fn, head) in heads.items():
            t, v = sig[name]
            ts = (t - T0_NS) * 1e-9
            text = ",".join(f'"{h}"' for h in ["Time (s)"] + [head.format(a) for a in "xyz"]) + "\n"
            text += "".join(",".join(map(_phy_num, (ti, a, b, c))) + "\n" for ti, (a, b, c) in zip(ts.tolist(),
                                                                                                   v.tolist()))
            z.writestr(fn, text)
        z.writestr("meta/time.csv", '"event","experiment time","system time","system time text"\n'
                                    '"START",0.000000000E0,1700000000.000,"2023-11-14 23:13:20.000 UTC+01:00"\n')
        z.writestr("meta/device.csv", '"property","value"\n"version","1.1.15"\n"deviceModel","Pixel 7"\n'
                                      '"deviceBrand","google"\n')


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: format -> (file name, writer (None: a file of the repository), reader call)
FORMATS = {
    "demo": ("desktop/data/demo_walk.csv.gz", None, "core.recording:read_recording"),
    "pdr": ("walk.csv", write_pdr, "core.recording:read_recording"),
    "pdr.gz": ("walk.csv.gz", write_pdr, "core.recording:read_recording"),
    "gsd": ("logfile.txt", write_gsd, "core.importers:read_getsensordata"),
    "sensorlogger": ("sensorlogger.zip", write_sensorlogger, "core.importers:read_sensorlogger"),
    "phyphox": ("phyphox.zip", write_phyphox, "core.importers:read_phyphox"),
}

_CHILD = r"""
import gc, json, sys, time, tracemalloc, warnings, importlib


def hwm():  # peak resident memory of this process (bytes); ru_maxrss would include the parent's before exec
    with open("/proc/self/status") as f:
        return next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmHWM:"))


mod, fn = sys.argv[2].split(":")
read = getattr(importlib.import_module(mod), fn)
import numpy as np
warnings.simplefilter("ignore")
trace = sys.argv[3] == "1"
gc.collect()
rss0 = hwm()
if trace:
    tracemalloc.start()
dt = float("inf")
for _ in range(int(sys.argv[4])):  # warm: the fastest of a few reads in one process
    rec = None
    t0 = time.perf_counter()
    rec = read(sys.argv[1])
    dt = min(dt, time.perf_counter() - t0)
peak = tracemalloc.get_traced_memory()[1] if trace else 0
n = sum(len(s) for s in rec.streams.values())
result = sum(s.t_ns.nbytes + s.values.nbytes for s in rec.streams.values())
rss = hwm() - rss0
print(json.dumps({"events": n, "result_bytes": result, "peak_bytes": peak, "rss_growth_bytes": rss, "s": dt}))
"""


def measure(path: str, reader: str, code: str | None, trace: bool, repeat: int = 1) -> dict:
    env = dict(os.environ)
    root = code or ROOT
    env["PYTHONPATH"] = root
    out = subprocess.run([sys.executable, "-c", _CHILD, path, reader, "1" if trace else "0", str(repeat)], env=env,
                         cwd=root, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[10.0, 60.0])
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--cache", default=os.path.join("out", "reader_memory"))
    ap.add_argument("--code", help="a checkout whose readers are measured (default: this one)")
    ap.add_argument("--repeat", type=int, default=3, help="timed reads of each file in one process (the fastest "
                                                          "counts)")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args(argv)
    os.makedirs(args.cache, exist_ok=True)
    rows = []
    print(f"{'file':32s} {'events':>9s} {'result MB':>9s} {'peak MB':>8s} {'B/ev>res':>8s} {'RSS MB':>7s} "
          f"{'us/ev':>6s}")
    for minutes in args.minutes:
        sig = None
        for fmt in args.formats.split(","):
            fname, writer, reader = FORMATS[fmt]
            if writer is None:  # a file of the repository
                if minutes != args.minutes[0]:
                    continue
                path = os.path.join(ROOT, fname)
            else:
                path = os.path.abspath(os.path.join(args.cache, f"{minutes:g}min_{fname}"))
            if not os.path.exists(path):
                sig = sig or _signals(minutes)
                tmp = path[:-3] + ".tmp.gz" if fname.endswith(".gz") else path + ".tmp"
                writer(tmp, sig)
                os.replace(tmp, path)
            m = measure(path, reader, args.code, trace=True)
            timed = measure(path, reader, args.code, trace=False, repeat=args.repeat)
            n = m["events"]
            row = {"format": fmt, "minutes": minutes, "file_bytes": os.path.getsize(path), "events": n,
                   "result_bytes": m["result_bytes"], "peak_bytes": m["peak_bytes"],
                   "peak_above_result_per_event": (m["peak_bytes"] - m["result_bytes"]) / n,
                   "peak_per_event": m["peak_bytes"] / n,
                   "rss_growth_bytes": timed["rss_growth_bytes"], "us_per_event": timed["s"] / n * 1e6}
            rows.append(row)
            print(f"{os.path.basename(path):32s} {n:9d} {row['result_bytes'] / 1e6:9.1f} "
                  f"{row['peak_bytes'] / 1e6:8.1f} {row['peak_above_result_per_event']:8.0f} "
                  f"{row['rss_growth_bytes'] / 1e6:7.1f} {row['us_per_event']:6.2f}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
