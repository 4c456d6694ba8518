"""The residual hard iron an OS calibration leaves, and the gyroscope at rest, on the TUNING recordings (issue #27).

``python -m benchmarks.residual_iron [--data DIR]``   (tuning split only; desktop only)

Why: the simulator's phone has no magnetometer error that is constant along a corridor, real phones have one --
the hard iron the phone's own (OS) calibration leaves, a heading error that depends on the heading.  This measures
how large it is, so the simulator's consistency walks can be given the measured size (``desktop.simulator``'s
``RESIDUAL_HARD_IRON_SD_UT``), not one chosen to hit a band.

1. IPIN 2023 tuning routes (01, 02, 21, 22; their ``mag`` is Android's calibrated stream, no uncalibrated one).
   Each file starts with 20-40 s of waving the phone at one place: a sphere fit (:func:`core.pdr.magcal.fit_sphere`)
   of the calibrated readings while the phone turns (gyroscope above 1 rad/s, 1-s mean, within the first 45 s; after
   the last jump of Android's own calibration, a step of more than 15 uT) gives the hard iron left in them; its two
   halves (alternate 1-s blocks of those readings, so both span the same time and directions) fitted alone give its
   uncertainty.  Also our online calibrator's
   (:class:`~core.pdr.magcal.MagCalibrator`) offset in force at the end of the waving.  ``horiz`` is the part of
   the offset across gravity in the walking pose (the median accelerometer direction after 62 s): the part that turns
   a heading.  The per-axis standard deviation of the residual is estimated with the fits' own noise removed:
   ``sd^2 = mean(b_full^2) - mean(((b_1 - b_2) / 2)^2)`` over files and axes (the halves' half difference has the
   variance of a fit of all readings, for a noise that halves with twice the readings).
2. Microsoft 2020 tuning traces (floor F3, odd files; one OPPO phone held flat): their uncalibrated stream carries
   Android's own hard-iron estimate.  Its changes from one trace to the next (the OS revising its estimate) bound
   how wrong the estimate in force is: for independent errors of sd ``s`` per axis a change has sd ``s sqrt 2``.
   Only x and y count (the phone is flat: its z is the vertical, which turns no heading and is poorly observed).
3. The gyroscope of the IPIN tuning files in the 20-40 s the phone is held still in front of the face (t 36-58 s, the
   gyroscope's 1-s mean below 0.3 rad/s throughout): per-sample standard deviation and the noise density it implies
   (an upper bound: the hand's tremor is in it), and the mean rate (the bias left by Android's gyro calibration,
   plus the hand's slow drift).

Measured 2026-12-07 (tuning split; the tables in ``benchmarks/RESIDUAL_IRON_RESULTS.md``): IPIN |b| median 0.85 uT
(quartiles 0.53-1.26; 0.17-3.94 per file), its part across gravity 0.68 uT, 0.59 uT per axis with the fits' noise
(0.69 uT per axis) removed -- ``desktop.simulator.RESIDUAL_HARD_IRON_SD_UT`` = 0.6; Microsoft: 4 small revisions of
Android's estimate, 1.54 uT rms per horizontal axis (about 1.1 uT of error per axis), and one re-calibration of
(+9.5, +43.0) uT; the gyroscope held still: 5-13 mrad/s/sqrt Hz, 20-40 times the simulator's sensor noise, i.e. the
hand, not the sensor (this window cannot measure the sensor's noise or bias instability).  The horizontal field the
IPIN tuning walks read (calibrated readings across gravity, after 62 s) is 16-26 uT (file medians), the simulator's
bent walks 20 uT: a residual in uT turns the heading about as much in both.

Limits, stated with the numbers: the waving happens at one place, but the hand moves the phone by tens of cm in a
building whose field is bent (the fits' residual RMS is 1-4.5 uT against a sensor noise of about 0.4 uT); the halves
disagree by about as much as the offsets themselves on some files; and it is the residual at the end of the waving:
Android may revise its estimate during the walk (not visible without the uncalibrated stream).  Microsoft's traces
are one phone on two days.
"""

from __future__ import annotations

import argparse
import gzip
import math
import re
from pathlib import Path

import numpy as np

from benchmarks.magcal_check import _default_root, _tag, ipin_files
from benchmarks.splits import TUNING, ms_indoor_split
from core.importers import load_recording
from core.pdr.magcal import MagCalibrator, fit_sphere

WAVING_WITHIN_S = 45.0
WAVING_GYRO_RAD_S = 1.0
OS_JUMP_UT = 15.0
BLOCK_S = 1.0
STILL_S = (36.0, 58.0)
STILL_GYRO_RAD_S = 0.3
WALK_FROM_S = 62.0


def _mean_1s(x: np.ndarray, rate_hz: float) -> np.ndarray:
    n = max(int(round(rate_hz)), 1)
    return np.convolve(x, np.ones(n) / n, "same")


def ipin_iron(rec) -> dict:
    """The residual hard iron of one IPIN file's calibrated ``mag`` (see the module docstring, part 1)."""
    m, g, a = rec.streams["mag"], rec.streams["gyro"], rec.streams["acc"]
    t = (m.t_ns - m.t_ns[0]) * 1e-9
    rate = (len(t) - 1) / (t[-1] - t[0])
    turning = _mean_1s(np.interp(m.t_ns, g.t_ns, np.linalg.norm(g.values, axis=1)), rate) > WAVING_GYRO_RAD_S
    step = np.r_[0.0, np.linalg.norm(np.diff(m.values, axis=0), axis=1)]
    jumps = np.flatnonzero((step > OS_JUMP_UT) & (t < WAVING_WITHIN_S))
    t0 = t[jumps[-1]] + 0.5 if len(jumps) else 0.0
    idx = np.flatnonzero(turning & (t < WAVING_WITHIN_S) & (t > t0))
    off, _, field, res = fit_sphere(m.values[idx])
    block = ((t[idx] - t[idx[0]]) // BLOCK_S).astype(int) % 2  # alternate blocks: the same span and directions
    halves = [fit_sphere(m.values[idx[block == k]])[0] for k in (0, 1)]
    cal = MagCalibrator()
    end = idx[-1] + 1
    cal.run(m.t_ns[:end], m.values[:end])
    ta = (a.t_ns - m.t_ns[0]) * 1e-9
    down = np.median(a.values[ta > WALK_FROM_S], axis=0)
    down /= np.linalg.norm(down)
    # the horizontal field the walk reads: the readings across gravity (the accelerometer's 1-s mean) after 62 s
    acc = np.column_stack([_mean_1s(np.interp(m.t_ns, a.t_ns, a.values[:, k]), rate) for k in range(3)])
    g = acc / np.linalg.norm(acc, axis=1)[:, None]
    walk = t > WALK_FROM_S
    v = m.values[walk]
    h_walk = float(np.median(np.linalg.norm(v - np.einsum("ij,ij->i", v, g[walk])[:, None] * g[walk], axis=1)))
    return {"h_walk_uT": h_walk, "n": len(idx), "t0_s": t0, "os_jumps": len(jumps), "offset_uT": off, "field_uT": field,
            "residual_uT": res, "halves_uT": halves, "horiz_uT": float(np.linalg.norm(off - (off @ down) * down)),
            "ours_uT": np.array(cal.status.offset_uT), "ours_calibrated": cal.calibrated}


def ipin_gyro(rec) -> dict | None:
    """Gyroscope statistics over the still period of one IPIN file (module docstring, part 3)."""
    g = rec.streams["gyro"]
    t = (g.t_ns - rec.streams["mag"].t_ns[0]) * 1e-9
    rate = (len(t) - 1) / (t[-1] - t[0])
    s = (t > STILL_S[0]) & (t < STILL_S[1])
    if not np.all(_mean_1s(np.linalg.norm(g.values, axis=1), rate)[s] < STILL_GYRO_RAD_S):
        return None
    v = g.values[s]
    sd = v.std(axis=0)
    return {"rate_hz": rate, "sd_rad_s": sd, "density": sd / math.sqrt(rate), "mean_rad_s": v.mean(axis=0)}


def ms_os_estimates(root: Path) -> list[tuple[int, int, np.ndarray]]:
    """(file number, first time ms, Android's hard-iron estimate at the trace's start) of every tuning trace of F3."""
    out = []
    files = sorted((root / "ms_indoor_location_2020" / "site2" / "F3" / "path_data_files").glob("*.txt*"))
    for no, f in enumerate(files, 1):
        if ms_indoor_split(no) != TUNING:
            continue
        with gzip.open(f, "rt", errors="replace") as fh:
            for line in fh:
                p = line.rstrip("\n").split("\t")
                if len(p) >= 8 and p[1] == "TYPE_MAGNETIC_FIELD_UNCALIBRATED":
                    try:
                        out.append((no, int(p[0]), np.array([float(x) for x in p[5:8]])))
                    except ValueError:
                        continue
                    break
    return sorted(out, key=lambda r: r[1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.residual_iron", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    args = ap.parse_args(argv)
    root = args.data or _default_root()
    files = ipin_files(root)
    print("## IPIN 2023 tuning routes: hard iron left in Android's calibrated mag (sphere fit over the waving)")
    print("| file | phone | readings | offset (uT) | abs (uT) | horiz (uT) | field (uT) | fit RMS (uT) | halves (uT) | "
          "ours at the waving's end (uT) | walk's horizontal field, median (uT) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    full, half_diff, horiz, mags, ours, gyros = [], [], [], [], [], []
    for p in files:
        rec = load_recording(str(p))
        r = ipin_iron(rec)
        o, (h1, h2) = r["offset_uT"], r["halves_uT"]
        full.append(o)
        half_diff.append((h1 - h2) / 2)
        horiz.append(r["horiz_uT"])
        mags.append(np.linalg.norm(o))
        ours.append(np.linalg.norm(r["ours_uT"]) if r["ours_calibrated"] else math.nan)
        fmt = lambda v: "(" + ", ".join(f"{x:+.1f}" for x in v) + ")"  # noqa: E731
        print(f"| {_tag(p)} | {rec.device.get('model', '?')} | {r['n']} | {fmt(o)} | {mags[-1]:.2f} | "
              f"{r['horiz_uT']:.2f} | {r['field_uT']:.1f} | {r['residual_uT']:.2f} | {fmt(h1)} {fmt(h2)} | "
              f"{fmt(r['ours_uT'])} | {r['h_walk_uT']:.1f} |")
        gyros.append((_tag(p), rec.device.get("model", "?"), ipin_gyro(rec)))
    full, half_diff = np.array(full), np.array(half_diff)
    sd_raw = math.sqrt(np.mean(full ** 2))
    sd_noise = math.sqrt(np.mean(half_diff ** 2))
    sd = math.sqrt(max(sd_raw ** 2 - sd_noise ** 2, 0.0))
    def q(x):
        return f"median {np.nanmedian(x):.2f}, quartiles {np.nanpercentile(x, 25):.2f}-{np.nanpercentile(x, 75):.2f}"

    print(f"\n{len(files)} files: |offset| {q(mags)} uT; horizontal part {q(horiz)} uT; ours at the waving's end "
          f"{q(ours)} uT.  Per axis: rms of the fits {sd_raw:.2f} uT, of their noise (halves) {sd_noise:.2f} uT, "
          f"so the residual's sd about {sd:.2f} uT per axis")

    print("\n## Microsoft 2020 F3 tuning traces (one OPPO PBCM10, held flat): Android's own hard-iron estimate")
    est = ms_os_estimates(root)
    print("| trace | start (unix ms) | Android's estimate (uT) | change from the trace before: x, y (uT) |")
    print("|---|---|---|---|")
    changes = []
    for k, (no, t_ms, b) in enumerate(est):
        d = b - est[k - 1][2] if k else None
        if d is not None and np.any(d != 0):
            changes.append(d[:2])
        print(f"| {no} | {t_ms} | ({b[0]:.2f}, {b[1]:.2f}, {b[2]:.2f}) | "
              f"{'-' if d is None else f'{d[0]:+.2f}, {d[1]:+.2f}'} |")
    c = np.array(changes)
    small = c[np.all(np.abs(c) < 10.0, axis=1)]
    print(f"\n{len(est)} traces, {len(c)} revisions; the revisions below 10 uT ({len(small)}): rms per horizontal axis "
          f"{math.sqrt(np.mean(small ** 2)):.2f} uT, so an estimate error of about "
          f"{math.sqrt(np.mean(small ** 2) / 2):.2f} uT per axis; the others (re-calibrations): "
          + ", ".join(f"({x:+.1f}, {y:+.1f})" for x, y in c[np.any(np.abs(c) >= 10.0, axis=1)]))

    print(f"\n## IPIN tuning: gyroscope while held still in front of the face ({STILL_S[0]:.0f}-{STILL_S[1]:.0f} s)")
    print("| file | phone | rate (Hz) | sd per sample (mrad/s) | density (mrad/s/sqrt Hz) | mean (mrad/s) |")
    print("|---|---|---|---|---|---|")
    dens, means = [], []
    for tag, model, s in gyros:
        if s is None:
            print(f"| {tag} | {model} | - | not still | - | - |")
            continue
        dens.append(np.mean(s["density"]))
        means.append(np.linalg.norm(s["mean_rad_s"]))
        print(f"| {tag} | {model} | {s['rate_hz']:.0f} | " + ", ".join(f"{1e3 * x:.1f}" for x in s["sd_rad_s"])
              + " | " + ", ".join(f"{1e3 * x:.2f}" for x in s["density"]) + " | "
              + ", ".join(f"{1e3 * x:+.1f}" for x in s["mean_rad_s"]) + " |")
    if dens:
        print(f"\n{len(dens)} still periods: noise density (hand tremor included, an upper bound) median "
              f"{1e3 * np.median(dens):.2f} mrad/s/sqrt Hz; |mean rate| median {1e3 * np.median(means):.1f} mrad/s.  "
              "The simulator's defaults: 3 mrad/s per sample at 100 Hz = 0.30 mrad/s/sqrt Hz, a constant bias of "
              "|(2, -1.5, 1)| = 2.7 mrad/s")


if __name__ == "__main__":
    main()
