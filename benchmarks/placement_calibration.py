"""The simulator's carried placements against the tuning split's real recordings (issue #25 section 2).

``python -m benchmarks.placement_calibration [--seeds N] [--extra DIR]`` prints a table of gait statistics per
recording: the real tuning walks off the hand (``phone_walks_more/thomasdingemanse_lopen``, probably a trouser
pocket; ``psy901/SensorActivity`` ``walking_100_new``, upright top down, accelerometer only) and the simulator's
pocket and swinging placements on the carry benchmark's tuning seeds (:func:`benchmarks.carry.sim_walk`).

The statistics are measured here with numpy on a 50 Hz grid, over the walking part (the middle 80 % of the
recording), independent of the pipeline's detectors:

``f_step``
    step frequency (Hz): the strongest peak of the norm's spectrum in 0.6-3 Hz, doubled when the stride line
    (half of it) is the stronger one (a limb's norm).
``norm_sd``
    standard deviation of the acceleration norm (m/s^2).
``r_step``, ``r_stride``
    unbiased normalised autocorrelation of the norm at the step and the stride lag (from ``f_step``).
``peak_ratio``
    the near leg against the far leg: the norm low-passed at 5 Hz, folded over the stride (the stride period
    from ``f_step``), the highest point of each half-stride above the mean; the weaker over the stronger (1: both
    legs alike).
``impact_hf``
    RMS of the norm above 8 Hz (m/s^2): the heel strikes' sharp part.
``gyro_rms``, ``gyro_p99``, ``axis_share``
    RMS and 99th percentile of the gyroscope's rate (rad/s) and the share of its variance on its main axis.
``gyro_skew``
    median over 4-s windows of the ``|skewness|`` of the rate about the window's main axis (the thigh's slow
    stance and quick swing against an arm's pendulum).
``tilt_rms_deg``
    RMS angle between the 0.2-s mean of the specific force and its mean direction (deg).

Nothing here tunes the pipeline: the table is the before/after evidence of the simulator's calibration
(``desktop.placements``' pocket and swinging constants), stated in ``benchmarks/CARRY_RESULTS.md``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

GRID_HZ = 50.0


def _grid(t_ns, values, t0, t1):
    t = np.arange(t0, t1, 1.0 / GRID_HZ)
    ts = (np.asarray(t_ns, dtype=np.int64) - np.int64(0)) * 1e-9
    return t, np.stack([np.interp(t, ts, values[:, i]) for i in range(values.shape[1])], axis=1)


def _lowpass(x, cutoff_hz):
    from scipy.signal import butter, filtfilt

    b, a = butter(2, cutoff_hz / (0.5 * GRID_HZ))
    return filtfilt(b, a, x, axis=0)


def _highpass(x, cutoff_hz):
    from scipy.signal import butter, filtfilt

    b, a = butter(2, cutoff_hz / (0.5 * GRID_HZ), btype="high")
    return filtfilt(b, a, x, axis=0)


def _autocorr(x, lag):
    x = x - x.mean()
    n = len(x)
    if lag <= 0 or lag >= n:
        return math.nan
    return float(np.dot(x[:-lag], x[lag:]) / (n - lag) / (np.dot(x, x) / n))


def gait_stats(t_ns, acc, gyro=None, *, gyro_t_ns=None, trim: float = 0.1) -> dict:
    """The statistics of the module docstring for one recording (acc (n, 3) m/s^2 with gravity; gyro rad/s)."""
    ts = np.asarray(t_ns, dtype=np.int64) * 1e-9
    span = ts[-1] - ts[0]
    t0, t1 = ts[0] + trim * span, ts[-1] - trim * span
    t, a = _grid(t_ns, np.asarray(acc, float), t0, t1)
    norm = np.linalg.norm(a, axis=1)
    x = norm - norm.mean()
    freqs = np.fft.rfftfreq(len(x), 1.0 / GRID_HZ)
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    band = (freqs > 0.6) & (freqs < 3.0)
    f_top = float(freqs[band][np.argmax(spec[band])])
    # the step line, or the stride line of a limb: the step line is then at twice it
    k2 = np.argmin(np.abs(freqs - 2.0 * f_top))
    f_step = 2.0 * f_top if (2.0 * f_top < 3.2 and spec[k2] > 0.3 * spec[band].max()) else f_top
    lag_step = int(round(GRID_HZ / f_step))
    out = {"f_step": f_step, "norm_sd": float(norm.std()), "r_step": _autocorr(norm, lag_step),
           "r_stride": _autocorr(norm, 2 * lag_step)}
    # near against far leg: the low-passed norm folded over the stride
    lp = _lowpass(norm, 5.0)
    stride = 2 * lag_step
    n_str = len(lp) // stride
    if n_str >= 3:
        fold = lp[:n_str * stride].reshape(n_str, stride).mean(axis=0) - lp.mean()
        h = stride // 2
        # both halves as circular windows starting at the stronger peak minus a quarter stride
        k = int(np.argmax(fold))
        roll = np.roll(fold, -(k - h // 2))
        p1, p2 = float(roll[:h].max()), float(roll[h:].max())
        out["peak_ratio"] = min(p1, p2) / max(p1, p2) if max(p1, p2) > 0 else math.nan
    out["impact_hf"] = float(np.sqrt(np.mean(_highpass(norm, 8.0) ** 2)))
    gdir = a.mean(axis=0)
    gdir /= np.linalg.norm(gdir)
    sm = _lowpass(a, 1.0 / 0.2 * 0.44)  # about a 0.2-s mean
    cosang = np.clip((sm @ gdir) / np.linalg.norm(sm, axis=1), -1.0, 1.0)
    out["tilt_rms_deg"] = math.degrees(float(np.sqrt(np.mean(np.arccos(cosang) ** 2))))
    if gyro is not None and len(gyro):
        _, g = _grid(gyro_t_ns, np.asarray(gyro, float), t0, t1)
        rate = np.linalg.norm(g, axis=1)
        gc = g - g.mean(axis=0)
        ev = np.linalg.eigvalsh(gc.T @ gc)
        out.update(gyro_rms=float(np.sqrt(np.mean(rate ** 2))), gyro_p99=float(np.percentile(rate, 99)),
                   axis_share=float(ev[-1] / ev.sum()), gyro_skew=_window_skew(g))
    return out


def _window_skew(g, window_s: float = 4.0, hop_s: float = 0.5, min_rms_rad_s: float = 0.5) -> float:
    """Median over 4-s windows (turning faster than ``min_rms_rad_s`` about their main axis) of the ``|skewness|``
    of the rate about the window's main axis (:func:`core.pdr.carry.rotation_skew`)."""
    from core.pdr.carry import rotation_skew

    n, hop = int(window_s * GRID_HZ), int(hop_s * GRID_HZ)
    out = []
    for i in range(0, len(g) - n, hop):
        wc = g[i:i + n] - g[i:i + n].mean(axis=0)
        p = wc @ np.linalg.eigh(wc.T @ wc)[1][:, -1]
        if float(np.sqrt(np.mean(p * p))) >= min_rms_rad_s:
            out.append(rotation_skew(p))
    return float(np.median(out)) if out else math.nan


def recording_stats(rec) -> dict:
    acc = rec.streams["acc"]
    gyro = rec.streams.get("gyro") if rec.has("gyro") else None
    return gait_stats(acc.t_ns, acc.values, None if gyro is None else gyro.values,
                      gyro_t_ns=None if gyro is None else gyro.t_ns)


REAL_TUNING = (
    ("lopen (tuning, inferred pocket)", "shared", "phone_walks_more/thomasdingemanse_lopen"),
    ("psy901 (tuning, upright top down)", "extra", "psy901__SensorActivity/walking_100_new"),
)

COLUMNS = ("f_step", "norm_sd", "r_step", "r_stride", "peak_ratio", "impact_hf", "tilt_rms_deg", "gyro_rms",
           "gyro_p99", "axis_share", "gyro_skew")


def sim_rows(placement: str, seeds, **options) -> list[dict]:
    from benchmarks.carry import sim_walk

    rows = []
    for s in seeds:
        walk, _ = sim_walk(placement, s)
        st = recording_stats(walk.recording)
        rows.append(st)
    return rows


def _median(rows, key):
    v = [r[key] for r in rows if key in r and np.isfinite(r[key])]
    return float(np.median(v)) if v else math.nan


def table(lines) -> str:
    out = ["| recording | n | " + " | ".join(COLUMNS) + " |", "|---|---|" + "---|" * len(COLUMNS)]
    for name, rows in lines:
        cells = [("–" if not np.isfinite(_median(rows, c)) else f"{_median(rows, c):.2f}") for c in COLUMNS]
        out.append(f"| {name} | {len(rows)} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    from benchmarks.datasets.base import default_data_root
    from core.importers import load_recording

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--extra", type=Path, default=Path("/work/extra_data"))
    ap.add_argument("--seeds", type=int, default=10, help="tuning seeds 0..N-1 of the simulator (at most 30)")
    args = ap.parse_args(argv)
    root = args.data or default_data_root()
    lines = []
    for name, corpus, rel in REAL_TUNING:
        folder = (root if corpus == "shared" else args.extra) / rel
        if not folder.exists():
            print(f"missing {folder}")
            continue
        lines.append((name, [recording_stats(load_recording(str(folder), warn=False))]))
    seeds = range(min(args.seeds, 30))
    for placement in ("pocket", "swinging"):
        lines.append((f"simulator {placement} (tuning seeds 0-{len(seeds) - 1})", sim_rows(placement, seeds)))
    print(table(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
