"""Magnetometer calibration and trust (core.pdr.magcal) on real recordings (desktop only).

``python -m benchmarks.magcal_check [--data DIR] [--skip-qsf]``

1. ETH Sensor Logger walk (report split; nothing tuned on it): the
   uncalibrated stream ``mag_uncal`` through :class:`MagCalibrator`, and the
   batch fits of the whole stream (:func:`fit_ellipsoid`, :func:`fit_sphere`)
   against the expected field (about 48 uT, dip about 63 deg in Zurich).
2. IPIN 2023 tuning routes (01, 02, 21, 22 only, the split of
   ``benchmarks/splits.py``; the defaults were chosen on these): the phone's
   own calibrated ``mag`` stream through :class:`MagCalibrator` -- when the
   first fit is accepted, the fitted field and residual, and the spread of
   the norm over the waving (12-30 s) with Android's calibration alone and
   with ours on top.
3. The same files through :class:`QuasiStaticField`, with the attitude of a
   small gyro + accelerometer filter written here (tilt from gravity, yaw
   from the gyro only, like the attitude filter's prediction): the fraction
   of walking readings trusted, and the tilt-compensated magnetometer
   heading error of the device y axis against the landmark segments (per
   file, the circular mean error is removed: the phone is not held exactly
   along the path), per reading and as segment means.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

import numpy as np

from core import quaternion as quat
from core.geodesy import geodetic_to_enu
from core.importers import load_recording
from core.pdr.magcal import EllipsoidFitError, MagCalibrator, QuasiStaticField, fit_ellipsoid, fit_sphere

IPIN_TUNING_ROUTES = ("01", "02", "21", "22")
IPIN_DECLINATION_DEG = 4.02  # WMM at the Museum Industriekultur, Nuremberg (benchmarks/datasets/ipin2023.py)
ETH_EXPECTED_FIELD_UT = 48.0


def _default_root() -> Path:
    return Path(__file__).resolve().parents[2] / "shared" / "data"


# ---------------------------------------------------------------------------
# 1. ETH


def eth(root: Path) -> None:
    folder = root / "sensorlogger_gps_walk_ethz" / "2023-03-17_15-50-47"
    rec = load_recording(str(folder))
    print(f"## ETH walk ({folder.name}); streams: {', '.join(sorted(rec.streams))}")
    mu = rec.streams["mag_uncal"]
    mc = rec.streams["mag"]
    cal = MagCalibrator()
    cov_max = 0.0
    reasons: dict[str, int] = {}
    attempt = cal.attempt

    def watched(t_ns):  # record the coverage and the reason of every attempt
        nonlocal cov_max
        attempt(t_ns)
        st = cal.status
        cov_max = max(cov_max, st.coverage)
        key = st.reason.split(" ")[0]
        reasons[key] = reasons.get(key, 0) + 1

    cal.attempt = watched
    cal.run(mu.t_ns, mu.values)
    st = cal.status
    print(f"- online MagCalibrator on mag_uncal ({len(mu)} readings, {mu.duration_s:.0f} s): state '{st.state}', "
          f"last reason '{st.reason}', accepted fits {st.n_accepted}, largest coverage {cov_max:.2f}; "
          f"attempt outcomes {reasons}")
    nu = np.linalg.norm(mu.values, axis=1)
    nc = np.linalg.norm(mc.values, axis=1)
    android_offset = np.median(mu.values - mc.values[np.searchsorted(mc.t_ns, mu.t_ns).clip(0, len(mc) - 1)], axis=0)
    print(f"- |mag_uncal| mean {nu.mean():.1f} uT; Android's calibrated |mag| mean {nc.mean():.1f} uT "
          f"({nc.mean() - ETH_EXPECTED_FIELD_UT:+.1f} uT from {ETH_EXPECTED_FIELD_UT:g}); Android's offset "
          f"{np.round(android_offset, 1)} uT")
    try:
        o, a, f, r = fit_ellipsoid(mu.values)
        print(f"- batch fit_ellipsoid: offset {np.round(o, 1)}, field {f:.1f} uT, residual {r:.2f} uT")
    except EllipsoidFitError as e:
        print(f"- batch fit_ellipsoid of the whole stream: {e}")
    o, a, f, r = fit_sphere(mu.values)
    n = np.linalg.norm(mu.values - o, axis=1)
    print(f"- batch fit_sphere (hard iron only) of the whole stream: offset {np.round(o, 1)} uT, field {f:.1f} uT, "
          f"residual {r:.2f} uT; calibrated |m| mean {n.mean():.1f} uT = {n.mean() - ETH_EXPECTED_FIELD_UT:+.1f} uT "
          f"from {ETH_EXPECTED_FIELD_UT:g}")
    # what the geometry allows: the phone is flat, so x/y of the offset come from the circle the field draws
    acc = rec.streams["acc"]
    up = acc.values[np.searchsorted(acc.t_ns, mu.t_ns).clip(0, len(acc) - 1)]
    up /= np.linalg.norm(up, axis=1)[:, None]
    tilt = np.degrees(np.arccos(np.clip(up[:, 2], -1, 1)))
    flat = tilt < 10.0
    xy = mu.values[flat, :2]
    design = np.c_[2 * xy, np.ones(len(xy))]
    th = np.linalg.lstsq(design, np.sum(xy * xy, axis=1), rcond=None)[0]
    h_r = math.sqrt(th[2] + th[0] ** 2 + th[1] ** 2)
    bz = float(np.median(mu.values[flat, 2])) + math.sqrt(max(ETH_EXPECTED_FIELD_UT ** 2 - h_r ** 2, 0.0))
    print(f"- tilt of the screen normal: median {np.median(tilt):.0f} deg, 99th percentile "
          f"{np.percentile(tilt, 99):.0f} deg (the phone never turns over).  Circle of the flat readings: centre "
          f"({th[0]:.1f}, {th[1]:.1f}) uT, radius {h_r:.1f} uT (horizontal field; 48 uT at 63 deg dip gives 21.8); "
          f"a 48 uT field would put the z offset at {bz:.0f} uT")


# ---------------------------------------------------------------------------
# 2. IPIN calibrator


def ipin_files(root: Path) -> list[Path]:
    out = []
    for p in sorted((root / "ipin2023_track3" / "logfiles").glob("*.txt*")):
        m = re.search(r"TrainingTrial(\d+)_repetition(\d+)", p.name)
        if m and m.group(1) in IPIN_TUNING_ROUTES:
            out.append(p)
    return out


def _tag(p: Path) -> str:
    m = re.search(r"TrainingTrial(\d+)_repetition(\d+)", p.name)
    return f"T{m.group(1)}r{m.group(2)}"


def ipin_calibration(files, recs) -> None:
    print("\n## IPIN 2023 tuning routes: MagCalibrator (defaults) on the phone's calibrated 'mag'")
    print("| file | phone | first fit (s) | model | field (uT) | residual (uT) | axis ratio | |offset| (uT) | "
          "fits | norm std 12-30 s: Android / +ours at 30 s (uT) | at end: field (uT) | state |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    firsts = []
    for p, rec in zip(files, recs):
        m = rec.streams["mag"]
        cal = MagCalibrator()
        tr = cal.run(m.t_ns, m.values)
        st = cal.status
        t = (m.t_ns - m.t_ns[0]) * 1e-9
        ref = m.values[(t > 12) & (t < 30)]
        raw_std = float(np.std(np.linalg.norm(ref, axis=1)))
        at30 = [f for f in tr.fits if (f.t_fit_ns - m.t_ns[0]) * 1e-9 <= 30.0]
        ours = (float(np.std(np.linalg.norm((ref - np.array(at30[-1].offset_uT)) @ np.array(at30[-1].soft_iron).T,
                                            axis=1))) if at30 else raw_std)
        if tr.fits:
            f = tr.fits[0]
            first = (f.t_fit_ns - m.t_ns[0]) * 1e-9
            firsts.append(first)
            print(f"| {_tag(p)} | {rec.device.get('model', '?')} | {first:.1f} | {f.model} | {f.field_uT:.1f} | "
                  f"{f.residual_uT:.2f} | {f.axis_ratio:.2f} | {np.linalg.norm(f.offset_uT):.1f} | {st.n_accepted} | "
                  f"{raw_std:.2f} / {ours:.2f} | {st.field_uT:.1f} | {st.state} |")
        else:
            firsts.append(math.nan)
            print(f"| {_tag(p)} | {rec.device.get('model', '?')} | - | - | - | - | - | - | 0 | {raw_std:.2f} / - | - | "
                  f"{st.state}: {st.reason} |")
    f = np.array(firsts)
    print(f"\naccepted in {np.isfinite(f).sum()}/{len(f)} files; first fit median {np.nanmedian(f):.1f} s, "
          f"max {np.nanmax(f):.1f} s after the start")


# ---------------------------------------------------------------------------
# 3. IPIN QSF


def gyro_tilt_attitude(rec, k_tilt_rad_s: float = 0.5) -> np.ndarray:
    """Attitude (n_mag, 4) at every magnetometer reading: gyro integration with an accelerometer tilt
    correction (Mahony-style proportional feedback, only when |acc| is within 1.5 m/s^2 of g), no
    magnetometer; the start is TRIAD from the first accelerometer and magnetometer readings."""
    g, a, m = rec.streams["gyro"], rec.streams["acc"], rec.streams["mag"]
    events = sorted([(t, 0, i) for i, t in enumerate(g.t_ns.tolist())]
                    + [(t, 1, i) for i, t in enumerate(a.t_ns.tolist())]
                    + [(t, 2, i) for i, t in enumerate(m.t_ns.tolist())])
    gv, av, mv = g.values.tolist(), a.values.tolist(), m.values.tolist()
    out = np.full((len(m), 4), np.nan)
    q = acc = t_prev = None
    for t, kind, i in events:
        if kind == 1:
            acc = av[i]
        elif kind == 2:
            if q is None and acc is not None:
                q, t_prev = quat.from_two_vectors_enu(tuple(acc), tuple(mv[i])), t
            if q is not None:
                out[i] = q
        elif q is not None:
            dt = (t - t_prev) * 1e-9
            t_prev = t
            if not 0.0 < dt < 0.5:
                continue
            w = list(gv[i])
            na = math.sqrt(sum(x * x for x in acc))
            if abs(na - 9.81) < 1.5:
                r = quat.to_matrix(q)
                up = (r[2][0], r[2][1], r[2][2])  # nav up in body coordinates
                v = [x / na for x in acc]
                e = (v[1] * up[2] - v[2] * up[1], v[2] * up[0] - v[0] * up[2], v[0] * up[1] - v[1] * up[0])
                w = [w[j] + k_tilt_rad_s * e[j] for j in range(3)]
            angle = math.sqrt(sum(x * x for x in w)) * dt
            if angle > 0:
                q = quat.normalize(quat.multiply(q, quat.from_axis_angle(tuple(w), angle)))
    return out


def heading_error_rad(rec, mag_cal_b, q) -> np.ndarray:
    """Tilt-compensated magnetometer heading of the device y axis minus the landmark segment's direction
    (rad; nan off the segments, within 1.5 s of a landmark or on segments shorter than 3 m)."""
    m = rec.streams["mag"]
    p = rec.streams["posi"]
    cols = list(p.columns)
    lat, lon = p.values[:, cols.index("lat_deg")], p.values[:, cols.index("lon_deg")]
    east, north = geodetic_to_enu(lat, lon, (float(lat[0]), float(lon[0])))
    truth = np.full(len(m), np.nan)
    for i in range(len(p) - 1):
        if math.hypot(east[i + 1] - east[i], north[i + 1] - north[i]) < 3.0:
            continue
        s = (m.t_ns > p.t_ns[i] + 1.5e9) & (m.t_ns < p.t_ns[i + 1] - 1.5e9)
        truth[s] = math.atan2(north[i + 1] - north[i], east[i + 1] - east[i])
    q = q.copy()
    q[~np.all(np.isfinite(q), axis=1)] = (1.0, 0.0, 0.0, 0.0)  # before the filter starts (never on a segment)
    up = quat.to_matrix_array(q)[:, 2, :]  # nav up in body coordinates
    mh = mag_cal_b - np.einsum("ij,ij->i", mag_cal_b, up)[:, None] * up
    yh = np.array([0.0, 1.0, 0.0]) - up[:, 1:2] * up
    nb = mh / np.linalg.norm(mh, axis=1)[:, None]
    eb = np.cross(nb, up)
    heading = np.arctan2(np.einsum("ij,ij->i", yh, nb), np.einsum("ij,ij->i", yh, eb))
    return np.angle(np.exp(1j * (heading - math.radians(IPIN_DECLINATION_DEG) - truth)))


def ipin_qsf(files, recs, kw=None) -> None:
    kw = kw or {}
    print(f"\n## IPIN 2023 tuning routes: QuasiStaticField ({kw or 'defaults'}) on our calibrated readings")
    print("| file | trusted (walking) | steady | per-reading |heading error| median: trusted / all (deg) | "
          "segment-mean |error| median: trusted / all (deg) |")
    print("|---|---|---|---|---|")
    all_t, all_e, seg_t, seg_a, steady_all = [], [], [], [], []
    for p, rec in zip(files, recs):
        m = rec.streams["mag"]
        mag_cal = MagCalibrator().run(m.t_ns, m.values).mag_cal_b
        q = gyro_tilt_attitude(rec)
        tr = QuasiStaticField(**kw).run(m.t_ns, mag_cal, q)
        err = heading_error_rad(rec, mag_cal, q)
        on = np.isfinite(err)
        err0 = np.angle(np.exp(1j * (err - np.angle(np.mean(np.exp(1j * err[on]))))))
        e_deg = np.degrees(np.abs(err0[on]))
        trusted = tr.trusted[on]
        all_t.append(e_deg[trusted])
        all_e.append(e_deg)
        steady_all.append(tr.steady[on])
        idx = np.flatnonzero(on)
        st_f, sa_f = [], []
        for part in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
            z = np.exp(1j * err0[part])
            tp = tr.trusted[part]
            if len(part) >= 50 and tp.sum() >= 10:
                st_f.append(abs(math.degrees(np.angle(z[tp].mean()))))
                sa_f.append(abs(math.degrees(np.angle(z.mean()))))
        seg_t += st_f
        seg_a += sa_f
        print(f"| {_tag(p)} | {trusted.mean():.2f} | {tr.steady[on].mean():.2f} | "
              f"{np.median(e_deg[trusted]) if trusted.any() else math.nan:.1f} / {np.median(e_deg):.1f} | "
              f"{np.median(st_f) if st_f else math.nan:.1f} / {np.median(sa_f) if sa_f else math.nan:.1f} |")
    t_, e_ = np.concatenate(all_t), np.concatenate(all_e)
    print(f"\nall files: trusted {len(t_) / len(e_):.2f} of the walking readings (steady "
          f"{np.concatenate(steady_all).mean():.2f}); |heading error| trusted median {np.median(t_):.1f} deg, "
          f"90th pct {np.percentile(t_, 90):.1f}; all readings median {np.median(e_):.1f}, 90th pct "
          f"{np.percentile(e_, 90):.1f}; segment means ({len(seg_t)} segments with >= 10 trusted readings): "
          f"trusted-only median {np.median(seg_t):.1f} deg, all readings {np.median(seg_a):.1f} deg")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.magcal_check", description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="data root (default: ../shared/data beside the repo)")
    ap.add_argument("--skip-qsf", action="store_true", help="only the calibration parts")
    args = ap.parse_args(argv)
    root = args.data or _default_root()
    eth(root)
    files = ipin_files(root)
    recs = [load_recording(str(p)) for p in files]
    ipin_calibration(files, recs)
    if not args.skip_qsf:
        ipin_qsf(files, recs)


if __name__ == "__main__":
    main()
