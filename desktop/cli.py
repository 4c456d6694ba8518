"""The ``pdr`` command: replay recordings through the pipeline, export tracks, make simulated walks.

Errors in the input end in one line ``pdr: error: FILE:LINE: what is wrong``
and exit status 2, never a traceback.
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

from core import __version__
from core.recording import Recording, RecordingError, read_recording, write_recording

DEMO_PATH = Path(__file__).with_name("data") / "demo_walk.csv.gz"

EXIT_INPUT = 2


def load_any(path: str, platform: str | None = None) -> Recording:
    """Read a recording in any supported format (auto-detected); ``platform`` for a Sensor Logger export
    that does not say whether it came from Android or iOS."""
    p = Path(path)
    if p.exists() and not (p.is_file() or p.is_dir()):
        raise RecordingError("not a regular file or folder (a FIFO or a device?): give a recording file", str(path))
    try:
        from core.importers import load_recording
    except ImportError:  # importers not installed: only the native format
        return read_recording(path)
    return load_recording(path, platform=platform)


def load_demo() -> Recording:
    """The bundled simulated demo walk (a closed loop), regenerated if the file is missing."""
    if DEMO_PATH.exists():
        rec = read_recording(str(DEMO_PATH))
    else:  # pragma: no cover - only in a checkout where the file was deleted
        from desktop.simulator import demo_walk
        rec = demo_walk().recording
    rec.source = f"{DEMO_PATH.name} (bundled simulated demo walk)"
    return rec


def _parse_origin(text: str | None):
    if not text:
        return None
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--origin wants LAT,LON in degrees, got {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError(f"--origin {text!r} is not a latitude,longitude in degrees")
    return lat, lon


def _first_gps_origin(rec: Recording):
    s = rec.streams.get("gps")
    if s is not None and len(s):
        return float(s.values[0, 0]), float(s.values[0, 1])
    return None


GPS_MODES = ("auto", "off", "chen", "kubrak")


def _parse_outage(text: str):
    try:
        start, length = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--gps-outage wants START_S:LENGTH_S (seconds), got {text!r}") from None
    if not (math.isfinite(start) and math.isfinite(length) and start >= 0 and length > 0):
        raise argparse.ArgumentTypeError(f"--gps-outage {text!r}: START_S >= 0 and LENGTH_S > 0 seconds")
    return start, length


def gps_choice(args) -> tuple[str, str]:
    """``--gps``: the fusion filter's name ("" when off) and why it was chosen."""
    from core.gnss import AUTO_FUSION, AUTO_FUSION_WHY

    mode = getattr(args, "gps", "auto")
    if mode == "auto":
        return AUTO_FUSION, f"auto: {AUTO_FUSION_WHY}"
    return ("", "off") if mode == "off" else (mode, "chosen with --gps")


def build_gnss(args, rec: Recording, profile=None):
    """The GPS fusion stage for ``--gps`` (None when off or when the recording has no fixes)."""
    mode = getattr(args, "gps", "auto")
    has_gps = rec.has("gps")
    if mode == "off" or (mode == "auto" and not has_gps):
        if getattr(args, "gps_outage", None):
            raise ValueError("--gps-outage needs GPS fusion: the recording has no gps stream" if not has_gps
                             else "--gps-outage has no effect with --gps off")
        return None
    if not has_gps:
        raise ValueError(f"--gps {mode}: the recording has no gps stream "
                         f"(streams: {', '.join(sorted(rec.streams))})")
    from core.gnss import make_fusion

    name, _ = gps_choice(args)
    t0 = rec.t0_ns
    hidden = [(t0 + int(a * 1e9), t0 + int((a + b) * 1e9)) for a, b in (args.gps_outage or [])]
    kw = {}
    if profile is not None:
        from core.gnss import settings_from_profile
        kw = settings_from_profile(name, profile)
    return make_fusion(name, hidden_ns=hidden, **kw)


def build_pipeline(args, gnss=None):
    from core.pdr.pipeline import Pipeline
    from core.pdr.stride import WeinbergStride

    kw = {"height_m": args.height, "use_magnetometer": not args.no_mag}
    if args.stride_c is not None:
        kw["stride_model"] = WeinbergStride(coefficient=args.stride_c)
    else:
        from core.pdr.stride_models import load_stride_model
        kw["stride_model"] = load_stride_model(args.stride_model)
    p = Pipeline(gnss=gnss, **kw)  # the default filter, with its magnetometer calibration
    p.attitude.declination_rad = math.radians(args.declination)
    return p


def _load_profile(path: str):
    from core.pdr.calibration import UserProfile

    return UserProfile.load(path) if Path(path).exists() else UserProfile()


class _Progress:
    """Progress on stderr for long work: shown once it has taken ``after_s``, tty or not.

    On a terminal one line is rewritten (every 5 %); otherwise (a log, CI) a
    line is printed every 10 %, so a pipe is not flooded.  ``--progress``
    shows it from the start, ``--no-progress`` never.
    """

    def __init__(self, label: str, enabled: bool = True, *, after_s: float = 2.0, tty: bool | None = None,
                 clock=time.monotonic):
        self.label = label
        self.enabled = enabled
        self.after_s = float(after_s)
        self.tty = sys.stderr.isatty() if tty is None else bool(tty)
        self.clock = clock
        self.last = -1.0
        self.t0 = clock()
        self.shown = False

    def __call__(self, frac: float) -> None:
        if not self.enabled:
            return
        el = self.clock() - self.t0
        if el < self.after_s and not self.shown:
            return
        step = 0.05 if self.tty else 0.10
        if frac - self.last < step and frac < 1.0:
            return
        if frac >= 1.0 and not self.shown:
            return  # finished before it was worth showing
        self.last = frac
        self.shown = True
        end = "\n" if (frac >= 1.0 or not self.tty) else ""
        sys.stderr.write(("\r" if self.tty else "") + f"{self.label}: {100 * frac:5.1f} %  ({el:.1f} s)" + end)
        sys.stderr.flush()


def summary_lines(res, rec: Recording, gps_why: str = "") -> list[str]:
    s = res.summary()
    rates = ", ".join(f"{n} {hz:.1f} Hz" for n, hz in s["rates_hz"].items())
    dist = s["distance_m"]
    lines = [
        f"recording     {rec.source}",
        f"duration      {s['duration_s']:.1f} s",
        f"sensors       {rates}",
        f"steps         {s['n_steps']}",
        f"distance      {dist:.1f} m",
        f"final pos     E {s['final_east_m']:+.1f} m, N {s['final_north_m']:+.1f} m (start at 0, 0)",
        f"start-to-end  {s['start_to_end_m']:.2f} m"
        + (f" ({100 * s['start_to_end_m'] / dist:.2f} % of the distance walked)" if dist > 0 else ""),
    ]
    used, rej = s.get("mag_used", 0), s.get("mag_rejected", 0)
    att = s.get("attitude") or {}
    if used + rej:
        why = {k: v for k, v in (att.get("mag_reasons") or {}).items() if k not in ("used", "initialising") and v > 0}
        top = ", ".join(f"{k} {v}" for k, v in sorted(why.items(), key=lambda kv: -kv[1])[:3])
        lines.append(f"magnetometer  {used} readings used, {rej} rejected ({100 * rej / (used + rej):.1f} %)"
                     + (f": {top}" if top else ""))
    if att.get("gyro_bias_rad_s"):
        b = att["gyro_bias_rad_s"]
        lines.append(f"gyro bias     ({1e3 * b[0]:+.2f}, {1e3 * b[1]:+.2f}, {1e3 * b[2]:+.2f}) mrad/s, "
                     f"heading +- {math.degrees(att.get('heading_sd_rad', math.nan)):.1f} deg at the end")
    bad = s.get("nonfinite_skipped") or {}
    if bad:
        lines.append("skipped       " + ", ".join(f"{v} non-finite {k} value(s)" for k, v in sorted(bad.items())))
    truth = rec.metadata.get("truth") if isinstance(rec.metadata.get("truth"), dict) else None
    if truth:
        lines.append(f"truth         {truth.get('n_steps')} steps, {truth.get('path_length_m', float('nan')):.1f} m "
                     f"(simulator)")
    if res.fusion is not None:
        lines.extend(gps_lines(res, gps_why))
    for lab in res.labels:
        lines.append(f"degraded      {lab}")
    for r in rec.repairs:
        lines.append(f"repaired      {r}")
    return lines


def gps_lines(res, why: str = "") -> list[str]:
    """Summary lines of the GPS fusion: the filter, fixes and their verdicts, what was learnt, outages."""
    fu = res.fusion
    c = fu.counters
    name = c.get("fusion", "chen")
    paper = {"chen": "Chen et al. 2010", "kubrak": "Kubrak et al. 2006"}.get(name, name)
    lines = [f"gps fusion    {name} ({paper}; {why})" if why else f"gps fusion    {name} ({paper})",
             (f"gps           {c['fixes']} fixes: {c['fixes_accepted']} used, {c['fixes_screened_out']} screened out "
              f"(accuracy, speed, C/N0), {c.get('fixes_filter_rejected', 0)} while GPS was unreliable, "
              f"{c['fixes_gated']} rejected by the filter's gate, {c['fixes_hidden']} hidden (outages)")]
    reasons: dict = {}
    for f in fu.fixes:
        if not f.accepted and f.reason != "hidden (outage)":
            key = f.reason.split(":")[0].split(" by ")[0]
            key = "accuracy above the limit" if key.startswith("accuracy") else key
            reasons[key] = reasons.get(key, 0) + 1
    if reasons:
        lines.append("rejected      " + "; ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])))
    if fu.origin_lat_lon is not None:
        lines.append(f"start         {fu.origin_lat_lon[0]:.6f}, {fu.origin_lat_lon[1]:.6f} (WGS-84, from GPS)")
    if name == "chen":
        tr = c.get("training", {})
        hm = tr.get("heading_model", {})
        coef = hm.get("coefficients_deg") or []
        lines.append(f"learnt        stride x{tr.get('stride_scale', 1.0):.3f} ({tr.get('stride_samples', 0)} windows); "
                     f"heading offset {coef[0] if coef else 0.0:+.1f} deg"
                     + (" + harmonics" if hm.get("harmonics_trusted") else " (one-term: headings not yet spread)")
                     + f" ({tr.get('heading_samples', 0)} windows)")
    elif "coefficients" in c:
        a, b, cc = c["coefficients"]
        lines.append(f"learnt        speed = {a:.4f} MEAN + {b:.3f} FREQ + {cc:.3f} STD (eq. 1); heading offset "
                     f"{c['heading_bias_deg']:+.1f} deg; GPS declared unreliable {c['variability_detections']} time(s)")
    if fu.steps:
        last = fu.track()
        lines.append(f"fused end     E {last.east_m[-1]:+.1f} m, N {last.north_m[-1]:+.1f} m, +- {last.sigma_m[-1]:.1f} m"
                     f" (1 sigma); {sum(1 for s in last.source if s == 'dr')} of {len(last)} steps dead reckoning only")
    for o in fu.outages:
        lines.append(f"outage        {o.start_s:.0f} s + {o.length_s:.0f} s: {o.walked_m:.0f} m walked, error at the "
                     f"end {o.end_error_m:.1f} m ({o.end_error_pct:.1f} %), +- {o.sigma_m:.1f} m; rejoined GPS with a "
                     f"{o.jump_m:.1f} m jump")
    return lines


MODES = ("auto", "handheld", "foot")


def choose_mode(args, rec: Recording) -> tuple[str, str]:
    """``--mode``: the mode to run and why (auto: the foot IMU's signals, :func:`core.foot.mounting.detect_mounting`)."""
    mode = getattr(args, "mode", "handheld")
    if mode != "auto":
        return mode, "chosen with --mode"
    from core.foot.devices import has_imu
    from core.foot.mounting import FOOT, detect_mounting

    dev = args.foot_device or ""
    if not has_imu(rec, dev):
        return "handheld", "no accelerometer and gyroscope pair" + (f" for device {dev!r}" if dev else "")
    m = detect_mounting(rec, dev)
    why = (f"detected: peak rate {m.peak_rate_rad_s:.1f} rad/s, stance {100 * m.stance_fraction:.0f} % of walking "
           f"({100 * m.confidence:.0f} % sure)")
    return ("foot" if m.mode == FOOT else "handheld"), why


def cmd_replay_foot(args, rec: Recording, why: str) -> int:
    """``pdr replay --mode foot``: the foot-mounted INS (Song & Park 2018, :mod:`core.foot`)."""
    if args.gps == "chen" or args.gps == "kubrak" or args.gps_outage:
        raise ValueError("GPS fusion with the foot-mounted INS is not built; use --gps off (or auto) with --mode foot")
    from core.foot.navigator import FootNavigator, FootSettings
    from core.foot.stance import StanceSettings

    waist = args.waist_device or None
    if waist is not None and not rec.has(f"acc@{waist}"):
        waist = None  # no waist IMU in this recording
    aid = args.aid or ("tckf" if waist and rec.has(f"mag@{waist}") else "zupt")
    settings = FootSettings(aid=aid, stance=StanceSettings(detector=args.detector),
                            gyro_delay_s=args.gyro_delay_ms * 1e-3)
    res = FootNavigator(settings, foot_device=args.foot_device or "", waist_device=waist).run(rec)
    s = res.summary()
    s["mode_reason"] = why
    if args.json:
        print(json.dumps(s, indent=1, default=float))
    else:
        print("\n".join([
            f"recording     {rec.source}",
            f"mode          foot-mounted INS ({why})",
            f"filter        ZUPT EKF, heading aid {s['aid']}, stance detector {s['detector']}",
            f"duration      {s['duration_s']:.1f} s at {s['rate_hz']:.0f} Hz",
            f"strides       {s['n_strides']} (stance {100 * s['stance_fraction']:.0f} % of the time)",
            f"distance      {s['distance_m']:.1f} m",
            f"final pos     E {s['final_east_m']:+.2f} m, N {s['final_north_m']:+.2f} m, U {s['final_up_m']:+.2f} m",
            f"start-to-end  {s['start_to_end_m']:.2f} m"
            + (f" ({100 * s['start_to_end_m'] / s['distance_m']:.2f} % of the distance)" if s["distance_m"] > 0
               else ""),
        ]))
    track = _stride_track(res)
    written = _write_outputs(args, rec, track, None, None, title_extra="foot INS")
    for w in written:
        print(f"wrote         {w}")
    return 0


def _stride_track(res):
    """The foot track as one row per stride (the arrays core.export and the plot take)."""
    from core.pdr.pipeline import Track

    st = [x for x in res.strides if x.length_m == x.length_m]
    return Track(np.array([x.t_end_ns for x in st], dtype=np.int64), np.array([x.length_m for x in st]),
                 np.array([x.course_rad for x in st]), np.array([x.position_n[0] for x in st]),
                 np.array([x.position_n[1] for x in st]))


def _write_outputs(args, rec, track, origin, extra, title_extra: str = "", others=None, fixes=None,
                   subtitle: str = "", fix_records=None) -> list:
    origin = args.origin or origin or _first_gps_origin(rec)
    offset = rec.metadata.get("unix_offset_ns")
    written = []
    from core import export
    fixes_out = getattr(args, "fixes", None)
    for out in (args.csv, args.geojson, args.gpx, args.plot, fixes_out):
        if out:  # outputs may go into a folder that does not exist yet (out/ by default in the README)
            Path(out).parent.mkdir(parents=True, exist_ok=True)
    if args.csv:
        export.write_track_csv(args.csv, track)
        written.append(args.csv)
    if args.geojson:
        export.write_track_geojson(args.geojson, track, origin, {"source": rec.source, "track": title_extra}, extra,
                                   fix_records)
        written.append(args.geojson)
    if fixes_out:
        if fix_records is None:
            raise ValueError("--fixes needs GPS fusion: the recording has no gps stream, or --gps off")
        export.write_fixes_csv(fixes_out, fix_records)
        written.append(fixes_out)
    if args.gpx:
        export.write_track_gpx(args.gpx, track, origin, offset if isinstance(offset, int) else None,
                               point_properties=extra)
        written.append(args.gpx)
    if args.plot:
        from desktop.plot import plot_track
        truth_en = rec.metadata.get("waypoints_en_m") if rec.metadata.get("simulator") else None
        plot_track(args.plot, track, title=f"PDR: {Path(rec.source.split(' ')[0]).name}" +
                   (f" ({title_extra})" if title_extra else ""), truth_en=truth_en, others=others, fixes=fixes,
                   subtitle=subtitle)
        written.append(args.plot)
    return written


def cmd_replay(args) -> int:
    rec = load_demo() if args.recording is None else load_any(args.recording, args.platform)
    mode, why = choose_mode(args, rec)
    if mode == "foot":
        return cmd_replay_foot(args, rec, why)
    profile = _load_profile(args.profile) if getattr(args, "profile", None) else None
    gnss = build_gnss(args, rec, profile)
    if getattr(args, "fixes", None) and gnss is None:  # before the run, not after it
        raise ValueError("--fixes needs GPS fusion: the recording has no gps stream, or --gps off")
    pipeline = build_pipeline(args, gnss)
    prog = _Progress("replay", not args.no_progress, after_s=0.0 if args.progress else 2.0)
    res = pipeline.run(rec, progress=prog)
    gps_why = gps_choice(args)[1] if gnss is not None else ""
    if args.json:
        extra_json = {"gps_fusion": gnss.name, "gps_fusion_reason": gps_why} if gnss is not None else {}
        print(json.dumps({**res.summary(), "mode": "handheld", "mode_reason": why, **extra_json}, indent=1,
                         default=float))
    else:
        lines = summary_lines(res, rec, gps_why)
        print("\n".join(lines[:1] + [f"mode          hand-held PDR ({why})"] + lines[1:]))
    fused = res.fusion is not None and res.fusion.origin_lat_lon is not None and len(res.fusion.steps)
    track = res.fusion.track() if fused else res.track
    extra = track.point_properties() if fused else None
    others, fixes = {}, None
    if fused and args.plot:
        others["dead reckoning only"] = (res.track.east_m, res.track.north_m)
        fx = [f for f in res.fusion.fixes if f.east_m == f.east_m]
        fixes = ([f.east_m for f in fx], [f.north_m for f in fx], [f.accepted for f in fx])
    s = res.summary()
    written = _write_outputs(args, rec, track, res.fusion.origin_lat_lon if fused else None, extra,
                             f"fused with GPS ({gnss.name})" if fused else "", others, fixes,
                             f"{s['n_steps']} steps, {s['distance_m']:.1f} m, start-to-end "
                             f"{s['start_to_end_m']:.2f} m", res.fusion.fixes if res.fusion is not None else None)
    if profile is not None and res.fusion is not None:
        from core.gnss import profile_after
        new = profile_after(profile, pipeline.gnss)
        if new is not profile:
            new.save(args.profile)
            written.append(args.profile)
    for w in written:
        print(f"wrote         {w}")
    return 0


def cmd_simulate(args) -> int:
    from desktop import simulator

    if args.shape == "demo":
        walk = simulator.demo_walk(seed=args.seed)
    else:
        shapes = {"square": [(0, 0), (20, 0), (20, 20), (0, 20), (0, 0)], "line": [(0, 0), (0, 50)],
                  "turn": [(0, 0), (0, 20), (20, 20)]}
        walk = simulator.simulate_walk(shapes[args.shape], rate_hz=args.rate, seed=args.seed)
    write_recording(args.out, walk.recording)
    print(f"wrote {args.out}: {walk.recording.duration_s:.1f} s, {len(walk.truth.step_t_ns)} steps, "
          f"{walk.truth.path_length_m:.1f} m")
    return 0


def cmd_info(args) -> int:
    rec = load_any(args.recording)
    print(f"recording  {rec.source}")
    print(f"duration   {rec.duration_s:.1f} s")
    for n, s in rec.streams.items():
        st = s.interval_stats_s()
        print(f"  {n:7s} {len(s):7d} events  {s.rate_hz:7.1f} Hz  jitter {1e3 * st['jitter_s']:.2f} ms  "
              f"gaps {st['gaps']}" + (f"  rate changes {st['rate_changes']}" if st.get("rate_changes") else "")
              + f"  [{', '.join(s.columns)}] {s.unit}")
    if rec.device:
        print(f"device     {json.dumps(rec.device)}")
    for r in rec.repairs:
        print(f"repaired   {r}")
    return 0


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pdr", description="Pedestrian dead reckoning for smartphone sensor recordings "
                                "(step detection, step length, adaptive EKF heading, track).")
    p.add_argument("--version", action="version", version=f"pdr {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("replay", help="run the pipeline on a recording and print a summary",
                       description="Run the PDR pipeline on a recording (pdr-recording, GetSensorData, Sensor Logger "
                                   "or phyphox; detected from the content) and print a summary. Without RECORDING, "
                                   "replays the bundled simulated demo walk (a closed loop).")
    r.add_argument("recording", nargs="?", help="recording file or folder (default: the bundled demo walk)")
    r.add_argument("--csv", metavar="PATH", help="write the track as CSV, one row per step (local metres)")
    r.add_argument("--geojson", metavar="PATH", help="write the track as GeoJSON (WGS-84, needs --origin or GPS "
                                                      "in the recording to be placed on the map)")
    r.add_argument("--fixes", metavar="PATH", help="write every GPS fix with its verdict (used, or why not) as CSV "
                                                   "(the GeoJSON carries them too)")
    r.add_argument("--gpx", metavar="PATH", help="write the track as GPX 1.1 with time, step length and bearing "
                                                 "per point (needs gpxpy)")
    r.add_argument("--plot", metavar="PNG", help="draw the track to a PNG file (needs matplotlib)")
    r.add_argument("--origin", type=_parse_origin, metavar="LAT,LON",
                   help="geographic start point for GeoJSON/GPX (default: first GPS fix, else 0,0)")
    r.add_argument("--height", type=float, metavar="M", help="walker's height in metres (for the stride model)")
    r.add_argument("--stride-model", default="default", metavar="NAME|PATH",
                   help="step length model: a shipped name (default, weinberg, weinberg_bp, chen_linear, chen_ann, "
                        "kubrak_velocity: Kubrak et al.'s eq. 1 speed times the step's interval) "
                        "or a model JSON file (default: %(default)s)")
    r.add_argument("--stride-c", type=float, metavar="C", help="constant Weinberg coefficient C (overrides "
                                                                "--stride-model)")
    r.add_argument("--declination", type=float, default=0.0, metavar="DEG",
                   help="magnetic declination, east positive (default 0: headings relative to magnetic north)")
    r.add_argument("--no-mag", action="store_true", help="ignore the magnetometer (heading relative to the start)")
    r.add_argument("--gps", choices=GPS_MODES, default="auto",
                   help="GPS fusion: auto (fuse when the recording has fixes, with the filter the benchmark shows "
                        "better; the summary says which), off, chen (Chen et al. 2010: calibration while GPS is "
                        "good, the step-wise PDR Kalman filter), kubrak (Kubrak et al. 2006: the velocity-model "
                        "Kalman filter with bad-GPS detection)")
    r.add_argument("--gps-outage", type=_parse_outage, action="append", metavar="START_S:LENGTH_S",
                   help="hide the GPS fixes from START_S (seconds from the first sensor event) for LENGTH_S; "
                        "repeatable; the error at the end of each is reported")
    r.add_argument("--profile", metavar="PATH", help="user profile (JSON): its stride scale and heading model start "
                   "the GPS training, and what the walk taught is saved back into it")
    r.add_argument("--mode", choices=MODES, default="auto",
                   help="hand-held PDR or foot-mounted INS (Song & Park 2018); auto (default): detected from the "
                        "IMU's signals (a foot shows long still stances and peak rates of several rad/s)")
    r.add_argument("--foot-device", default="", metavar="NAME",
                   help="foot mode: the device whose streams are the foot IMU ('' = the primary acc/gyro; "
                        "'left_foot' reads acc@left_foot, gyro@left_foot)")
    r.add_argument("--waist-device", default="waist", metavar="NAME",
                   help="foot mode: the device with the waist magnetometer for the course filter (default waist)")
    r.add_argument("--aid", choices=("zupt", "foot_mag", "course", "tckf"), default=None,
                   help="foot mode: heading aid (default tckf with a waist magnetometer, else zupt only)")
    r.add_argument("--detector", choices=("shoe", "song", "amv", "are"), default="shoe",
                   help="foot mode: stance detector (default shoe)")
    r.add_argument("--gyro-delay-ms", type=float, default=0.0, metavar="MS",
                   help="foot mode: the gyroscope lags the accelerometer by this much (ms)")
    r.add_argument("--platform", choices=("android", "ios"), default=None,
                   help="for a Sensor Logger export without Metadata.csv: the phone it came from "
                        "(or set PDR_SENSORLOGGER_PLATFORM)")
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.add_argument("--progress", action="store_true", help="show progress on stderr from the start "
                   "(default: once the replay has taken 2 s, on a terminal or not)")
    r.add_argument("--no-progress", action="store_true", help="never show progress")
    r.set_defaults(func=cmd_replay)

    s = sub.add_parser("simulate", help="write a simulated hand-held walk with ground truth",
                       description="Simulate a phone held in front of the chest on a walk and write it as a "
                                   "pdr-recording (the truth goes into the header's metadata).")
    s.add_argument("out", help="output file (.csv or .csv.gz)")
    s.add_argument("--shape", choices=["demo", "square", "line", "turn"], default="demo", help="path to walk")
    s.add_argument("--rate", type=float, default=100.0, help="accelerometer rate in Hz (default 100)")
    s.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    s.set_defaults(func=cmd_simulate)

    i = sub.add_parser("info", help="describe a recording: streams, rates, jitter, gaps")
    i.add_argument("recording")
    i.set_defaults(func=cmd_info)
    return p


def main(argv=None) -> int:
    parser = make_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = args.func(args)
        except RecordingError as e:
            print(f"pdr: error: {e}", file=sys.stderr)
            code = EXIT_INPUT
        except ValueError as e:  # e.g. a stride model file that cannot be used
            print(f"pdr: error: {e}", file=sys.stderr)
            code = EXIT_INPUT
        except (OSError, RuntimeError) as e:
            print(f"pdr: error: {e}", file=sys.stderr)
            code = 1
        except KeyboardInterrupt:
            print("pdr: interrupted", file=sys.stderr)
            code = 130
    for w in caught:
        if issubclass(w.category, (UserWarning,)) and not issubclass(w.category, DeprecationWarning):
            print(f"pdr: warning: {w.message}", file=sys.stderr)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
