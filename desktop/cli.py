"""The ``pdr`` command: replay recordings through the pipeline, export tracks, make simulated walks.

Errors in the input end in one line ``pdr: error: FILE:LINE: what is wrong``
and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from core import __version__
from core.importers import FORMATS as _IMPORT_FORMATS
from core.recording import Recording, RecordingError, read_recording, write_recording
from core.pdr.heading_smoother import HEADING_SMOOTHERS
from desktop.engine import ENGINES, run_pipeline

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
    """``(lat, lon)`` of the recording's first *good* fix (:func:`core.gnss.base.first_good_fix`), or None."""
    from core.gnss.base import first_good_fix

    fix = first_good_fix(rec.streams.get("gps"))
    return None if fix is None else (fix[1], fix[2])


def place_site(args, rec: Recording, pipeline, plan=None) -> tuple[dict | None, list]:
    """Magnetic declination (and the field's strength and dip) of the World Magnetic Model at the walk's place
    and date, given to the attitude filter before the run, when the place is known (``--origin`` or a good GPS
    fix), at the recording's date (a recording without one: :data:`UNDATED_MODEL_DATE`); ``--declination``
    overrides it.  Returns (summary, lines)."""
    if args.declination is not None:
        return ({"declination_deg": args.declination, "source": "--declination"},
                [f"declination   {args.declination:+.1f} deg (--declination)"])
    from core.gnss.base import first_good_fix

    fix = first_good_fix(rec.streams.get("gps"))
    if args.origin is not None:
        (lat, lon), alt, t_ns, where = args.origin, 0.0, rec.t0_ns, "--origin"
    elif fix is not None:
        t_ns, lat, lon, alt = fix
        where = "the first good GPS fix"
    elif getattr(plan, "georef", None) is not None:  # --map: the floor plan says where the building is
        (lat, lon), alt, t_ns, where = plan.georef.origin, 0.0, rec.t0_ns, "the floor plan's geo-reference"
    else:
        return ({"declination_deg": 0.0, "source": "unknown place"},
                ["declination   0 (place unknown: headings are magnetic; give --origin LAT,LON or --declination)"])
    off = rec.metadata.get("unix_offset_ns")
    undated = not isinstance(off, int)
    if undated and "simulator" in rec.metadata:  # a synthetic field (its declination in its metadata), no place's
        return ({"declination_deg": 0.0, "source": "no date"},
                ["declination   0 (the recording has no date for the magnetic model; give --declination)"])
    when_ns = UNDATED_MODEL_UNIX_NS if undated else off + int(t_ns)
    try:
        site = pipeline.set_site(lat, lon, alt if math.isfinite(alt) else 0.0, when_ns)
    except (ImportError, ValueError) as e:
        return {"declination_deg": 0.0, "source": f"magnetic model failed: {e}"}, [f"declination   0 ({e})"]
    d = site.get("declination_deg") or 0.0
    if undated:  # a date-less export (phyphox without meta/time.csv): the place's declination, at the model's epoch
        where += f"; the recording has no date: the model at {UNDATED_MODEL_DATE}, give --declination to override"
    return ({"declination_deg": d, "source": f"World Magnetic Model at {where}", "lat_deg": lat, "lon_deg": lon},
            [f"declination   {d:+.1f} deg (World Magnetic Model at {lat:.4f}, {lon:.4f}: {where})"])


#: the magnetic model's date for a recording without one (a phyphox export without meta/time.csv): the newest
#: model's epoch.  The declination moves by a fraction of a degree a year (in Europe about 0.15 deg); leaving it
#: at 0 would be off by the whole declination (4 deg in northern Germany, -9 deg in Korea, 13 deg in Seattle)
UNDATED_MODEL_DATE = "2025-01-01"
UNDATED_MODEL_UNIX_NS = 1_735_689_600_000_000_000


GPS_MODES = ("auto", "off", "chen", "kubrak")


#: the latest end of a --gps-outage (s after the start): 1e9 s, 31 years, keeps it a 64-bit nanosecond count
MAX_OUTAGE_END_S = 1e9


def _parse_outage(text: str):
    try:
        start, length = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--gps-outage wants START_S:LENGTH_S (seconds), got {text!r}") from None
    if not (math.isfinite(start) and math.isfinite(length) and start >= 0 and length > 0):
        raise argparse.ArgumentTypeError(f"--gps-outage {text!r}: START_S >= 0 and LENGTH_S > 0 seconds")
    if start + length > MAX_OUTAGE_END_S:  # the end must be a nanosecond count on the recording's clock
        raise argparse.ArgumentTypeError(f"--gps-outage {text!r}: START_S + LENGTH_S must be at most "
                                         f"{MAX_OUTAGE_END_S:.0e} s (a walk is hours, not centuries)")
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


def build_pipeline(args, gnss=None, profile=None):
    """The pipeline of ``args``: the stride model (``--stride-c``, ``--stride-model``, else the profile's
    model with the user's factor) and height (``--height``, else the profile's)."""
    from core.pdr.pipeline import Pipeline
    from core.pdr.stride import WeinbergStride

    height = args.height if args.height is not None else (profile.height_m if profile is not None else None)
    kw = {"height_m": height, "use_magnetometer": not args.no_mag,
          "heading_smoother": getattr(args, "heading_smoother", None) or "off"}
    if args.stride_c is not None:
        kw["stride_model"] = WeinbergStride(coefficient=args.stride_c)
    elif profile is not None and args.stride_model in (None, profile.model):
        kw["stride_model"] = profile.stride_model()  # the user's calibrated factor on the profile's model
    else:
        from core.pdr.stride_models import load_stride_model
        kw["stride_model"] = load_stride_model(args.stride_model or "default")
    if args.height is not None and not uses_height(kw["stride_model"]):
        print(f"note          --height {args.height:g} m is ignored: the stride model does not use the height "
              "(only weinberg_bp does)", file=sys.stderr)
    p = Pipeline(gnss=gnss, **kw)  # the default filter, with its magnetometer calibration
    if args.declination is not None:
        p.attitude.declination_rad = math.radians(args.declination)
    return p


#: the app's profile file, in the app's settings folder (app.settings.PROFILE_FILE)
PROFILE_FILE = "profile.json"


def default_profile_path() -> Path:
    """The profile the app keeps on this computer: ``$PDR_APP_DATA/profile.json``, else in Kivy's
    ``user_data_dir`` for the app "pdr" (``$XDG_CONFIG_HOME`` or ``~/.config`` on Linux, ``~/Library/Application
    Support`` on macOS, ``%APPDATA%`` on Windows)."""
    d = os.environ.get("PDR_APP_DATA")
    if not d:
        if sys.platform == "darwin":
            d = os.path.expanduser("~/Library/Application Support/pdr")
        elif sys.platform.startswith("win"):
            d = os.path.join(os.environ.get("APPDATA", os.path.expanduser("~")), "pdr")
        else:
            d = os.path.join(os.path.expanduser(os.environ.get("XDG_CONFIG_HOME") or "~/.config"), "pdr")
    return Path(d) / PROFILE_FILE


def _load_profile(path: str):
    from core.pdr.calibration import UserProfile

    return UserProfile.load(path) if Path(path).exists() else UserProfile()


def choose_profile(args, demo: bool = False):
    """``(profile, path, saved_back)``: ``--profile PATH`` (created if missing, what GPS teaches is saved back),
    else the app's stored profile when there is one (read only), never with ``--no-profile`` or for the demo."""
    if getattr(args, "no_profile", False):
        return None, None, False
    if getattr(args, "profile", None):
        return _load_profile(args.profile), args.profile, True
    path = default_profile_path()
    if demo or not path.is_file():
        return None, None, False
    from core.pdr.calibration import CalibrationError, UserProfile
    try:
        return UserProfile.load(path), str(path), False
    except CalibrationError as e:
        raise CalibrationError(f"{e} (the stored profile; --no-profile ignores it)") from None


def profile_line(profile, path, args) -> str:
    """What of the profile this run uses, in one summary line."""
    used = []
    if args.stride_c is None and args.stride_model in (None, profile.model):
        n = len(profile.calibrations)
        used.append(f"stride x{profile.c_scale:.3f} on model {profile.model}"
                    + (f" ({n} calibration walk{'s' if n != 1 else ''})" if n else " (not calibrated)"))
    else:
        used.append("stride factor not used (another stride model chosen)")
    if args.height is None and profile.height_m is not None:
        used.append(f"height {profile.height_m:.2f} m")
    if (profile.gps or {}).get("stride_scale"):
        used.append(f"GPS stride x{profile.gps['stride_scale']:.3f} for GPS fusion")
    return f"profile       {path}: " + ", ".join(used)


class _Progress:
    """Progress on stderr for long work: shown once it has taken ``after_s``, tty or not.

    On a terminal one line is rewritten (every 5 %); otherwise (a log, CI) a
    line is printed every 10 %, so a pipe is not flooded.  ``--progress``
    shows it from the start, ``--no-progress`` never.
    """

    def __init__(self, label: str, enabled: bool = True, *, after_s: float = 2.0, tty: bool | None = None,
                 clock=time.monotonic, total: int | None = None):
        self.label = label
        self.total = total  #: a count of items (files): shown as "k/n" beside the per cent
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
        count = f"  {round(frac * self.total)}/{self.total}" if self.total else ""
        sys.stderr.write(("\r" if self.tty else "") + f"{self.label}: {100 * frac:5.1f} %{count}  ({el:.1f} s)" + end)
        sys.stderr.flush()


#: stream kinds that are sensors (the rest of a recording's streams are ground truth or annotations)
SENSOR_KINDS = ("acc", "gyro", "mag", "rotvec", "gps", "gnss_status", "pressure", "mag_uncal", "gyro_uncal")
#: the line said instead of a track shape when nothing measures the heading
NO_HEADING = ("none: the recording has neither a gyroscope nor a magnetometer, so the steps and the distance "
              "are measured but not the direction (no track shape)")


#: below this accelerometer rate (Hz) steps cannot be detected (a step lasts about half a second)
MIN_STEP_RATE_HZ = 10.0
#: a nominal 10 Hz export measures a little under 10 Hz from its timestamps (9.99 Hz on a phyphox Android walk,
#: which counts its steps): the rate test allows this fraction below MIN_STEP_RATE_HZ
STEP_RATE_TOLERANCE = 0.05


def acc_rate_hz(rec: Recording) -> float:
    s = rec.streams.get("acc")
    return float(s.rate_hz) if s is not None and len(s) > 1 else 0.0


def has_heading(args, rec: Recording) -> bool:
    """Whether anything in ``rec`` measures the walking direction (a gyroscope, or a magnetometer not ignored)."""
    return rec.has("gyro") or (rec.has("mag") and not getattr(args, "no_mag", False))


def summary_lines(res, rec: Recording, gps_why: str = "", heading: bool = True) -> list[str]:
    s = res.summary()
    rates = ", ".join(f"{n} {hz:.1f} Hz" for n, hz in s["rates_hz"].items() if n.split("@")[0] in SENSOR_KINDS)
    dist = s["distance_m"]
    lines = [
        f"recording     {rec.source}",
        f"duration      {s['duration_s']:.1f} s",
        f"sensors       {rates}",
        f"steps         {s['n_steps']}" + (f" ({s['n_steps_estimated']} estimated across accelerometer gaps)"
                                             if s.get("n_steps_estimated") else ""),
        f"distance      {dist:.1f} m",
    ]
    if not heading:  # what the recording cannot say is not made up: no position, no heading labels
        return (lines + [f"heading       {NO_HEADING}"] + [f"repaired      {r}" for r in rec.repairs]
                + problem_lines(rec))
    lines += [
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
    lines.extend(carry_lines(s.get("carry"), rec.t0_ns))
    bad = s.get("nonfinite_skipped") or {}
    if bad:
        lines.append("skipped       " + ", ".join(f"{v} non-finite {k} value(s)" for k, v in sorted(bad.items())))
    if res.fusion is not None:
        lines.extend(gps_lines(res, gps_why))
    for lab in res.labels:
        lines.append(f"degraded      {lab}")
    for r in rec.repairs:
        lines.append(f"repaired      {r}")
    return lines + problem_lines(rec)


def problem_lines(rec: Recording) -> list[str]:
    """The stream problems found while reading (:mod:`core.validation`) that changed nothing (gaps, spikes):
    those that did are among the ``repaired`` lines."""
    return [f"stream        {f.text}" for f in getattr(rec, "problems", []) if f.action == "reported"]


def problem_summary(rec: Recording) -> dict:
    """The JSON summary's ``stream_problems`` ({problem: count}), ``stream_findings`` (one per finding) and
    ``repairs`` (every repair made while reading, as the ``repaired`` lines say them)."""
    from core.validation import problem_counts

    found = list(getattr(rec, "problems", []))
    return {"stream_problems": problem_counts(found), "stream_findings": [f.as_dict() for f in found],
            "repairs": list(rec.repairs)}


def foot_rate_problem(rec: Recording, device: str, window_s: float):
    """A ``RATE_TOO_LOW`` finding when the foot IMU is too slow for the ZUPT stance detector (its window of
    ``window_s`` needs :data:`FOOT_MIN_WINDOW_SAMPLES` samples), or None."""
    from core.validation import low_rate_finding

    need = FOOT_MIN_WINDOW_SAMPLES / window_s
    for kind in ("gyro", "acc"):
        name = kind + (f"@{device}" if device else "")
        f = low_rate_finding(rec, name, need, f"the foot-mounted INS (its stance detector decides on a "
                                              f"{window_s:g} s window, {FOOT_MIN_WINDOW_SAMPLES} samples or "
                                              "more)")
        if f is not None:
            return f
    return None


#: fewest samples in the stance detector's window for the foot-mounted INS (at the default 0.1 s: 50 Hz)
FOOT_MIN_WINDOW_SAMPLES = 5


def carry_lines(carry: dict | None, t0_ns: int) -> list[str]:
    """The carry-mode detector's line for the summary (issue #17): time per mode and the changes."""
    if not carry or not carry.get("time_s"):
        return []
    from core.conventions import CARRY_WORDS

    times = carry["time_s"]
    total = sum(times.values()) or 1.0
    share = ", ".join(f"{CARRY_WORDS.get(m, m)} {100 * v / total:.0f} %"
                      for m, v in sorted(times.items(), key=lambda kv: -kv[1]))
    ch = carry.get("changes") or []
    said = "; ".join(f"{(c['t_ns'] - t0_ns) * 1e-9:.0f} s {CARRY_WORDS.get(c['to'], c['to'])}" for c in ch[:6])
    more = ", ..." if len(ch) > 6 else ""
    return [f"carried       {share} of the time"
            + (f"; {len(ch)} change{'s' if len(ch) != 1 else ''} ({said}{more})" if ch else "")]


def _known(sep: str, *items) -> str:
    """``(value, format)`` pairs formatted and joined, leaving out the values that are nan (metric not defined)."""
    return sep.join(f.format(v) for v, f in items if v is not None and v == v)


def truth_lines(errs: dict) -> list[str]:
    """Summary lines of the error against the recording's ground truth (:func:`core.metrics.truth_errors`)."""
    lines = []
    sim = errs.get("simulator")
    if sim:
        n = sim.get("n_steps")
        lines.append(f"truth         {n if n is not None else '?'} steps, {sim['path_m']:.1f} m (simulator)")
        lines.append("truth error   " + _known(", ", (sim["step_count_err_pct"], "steps {:+.1f} %"),
                                            (sim["distance_err_pct"], "distance {:+.1f} %"),
                                            (sim["end_error_m"], "end point {:.2f} m off the true end"),
                                            (sim["loop_closure_pct"], "loop closure {:.2f} %")))
    lm = errs.get("landmarks")
    if lm:
        lines.append(f"truth         {lm['what']}, {lm['path_m']:.1f} m from the first to the last")
        lines.append(f"truth error   at the landmarks: median {lm['median_m']:.1f} m, max {lm['max_m']:.1f} m; after "
                     f"the best-fit rotation ({lm['fit_rotation_deg']:+.1f} deg) median {lm['median_fit_m']:.1f} m")
        lines.append("truth error   " + _known("; ", (lm["distance_err_pct"],
                                                   "distance {:+.1f} % between the first and last landmark"),
                                            (lm["loop_closure_pct"], "loop closure {:.2f} %"),
                                            (lm["segment_heading_deg"],
                                             "segment headings off by {:.1f} deg on average")))
    c = errs.get("steps")
    if c:
        lines.append(f"truth         {c['n_true']} steps ({c['what']})")
        lines.append(f"truth error   steps {c['err_pct']:+.1f} % ({c['n']} counted over the same time)")
    c = errs.get("distance")
    if c:
        lines.append(f"truth         {c['true_m']:.1f} m walked ({c['what']})")
        lines.append(f"truth error   distance {c['err_pct']:+.1f} % ({c['m']:.1f} m over the same time)")
    g = errs.get("gps")
    if g and not lm:  # landmarks are the better truth; GPS only where there is nothing better
        lines.append(f"truth         {g['what']} (a reference, not exact)")
        lines.append(f"truth error   PDR alone from the fixes: median {g['median_m']:.1f} m, 90 % {g['p90_m']:.1f} m, "
                     f"max {g['max_m']:.1f} m; after the best-fit rotation ({g['fit_rotation_deg']:+.1f} deg) median "
                     f"{g['median_fit_m']:.1f} m")
    return lines


def truth_plot(truth, errs: dict, track, fused: bool) -> dict:
    """What ``--plot`` draws of the truth, moved into the track's frame (keywords of :func:`desktop.plot.plot_track`)."""
    from core.metrics import place_reference

    kw: dict = {}
    sim = truth.simulator
    if sim is not None and truth.waypoints_en_m is not None and len(track):
        start = sim.get("start_en_m") or truth.waypoints_en_m[0]
        kw["truth_en"] = truth.waypoints_en_m + place_reference(track, sim.get("walk_start_t_ns", track.t_ns[0]),
                                                                 start)
    lm = truth.landmarks
    if lm is not None and len(track):
        xy = np.column_stack([lm.east_m, lm.north_m])
        kw["landmarks_en"] = xy + place_reference(track, lm.t_ns[0], xy[0])
        kw["landmarks_label"] = f"landmarks ({len(xy)}, truth)"
    if truth.gps is not None and lm is None and not fused and len(track):
        g = truth.gps
        xy = np.column_stack([g.east_m, g.north_m])
        xy = xy + place_reference(track, g.t_ns[0], xy[0])
        kw["reference"] = (f"GPS fixes ({len(xy)}, reference)", xy[:, 0], xy[:, 1])
    return kw


def truth_headline(errs: dict) -> str:
    """The truth error in a few words, for a plot's subtitle or a table cell ('' without truth)."""
    if errs.get("landmarks"):
        lm = errs["landmarks"]
        return f"landmarks: median {lm['median_m']:.1f} m, max {lm['max_m']:.1f} m"
    if errs.get("simulator"):
        s = errs["simulator"]
        return f"truth: distance {s['distance_err_pct']:+.1f} %, end {s['end_error_m']:.2f} m off"
    parts = [f"{k} {errs[k]['err_pct']:+.1f} %" for k in ("steps", "distance") if errs.get(k)]
    if parts:
        return "truth: " + ", ".join(parts)
    if errs.get("gps"):
        return f"PDR alone vs GPS: median {errs['gps']['median_m']:.1f} m"
    return ""


def gps_track_label(fusion, name: str) -> str:
    """What the fused track is, for the plot's title and the GeoJSON: fused with GPS, or dead reckoning where GPS
    was judged unusable, and why (:func:`core.gnss.judge.verdict_text`)."""
    from core.gnss.judge import verdict_text

    return verdict_text(fusion.counters.get("gps_judge"), name)


def _shadow_text(events) -> str:
    """What the shadow filter did while GPS was declared unreliable (Kubrak's summary line)."""
    relocked = sum(e["event"] == "relocked" for e in events)
    adopted = sum(e["event"] == "adopted" for e in events)
    if not (relocked or adopted):
        return ""
    return f" (the shadow filter re-locked to the fixes {relocked} time(s), took over {adopted} time(s))"


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
    if c.get("gps_judge"):
        from core.gnss.judge import verdict_text

        j = c["gps_judge"]
        lines.append(f"gps verdict   {verdict_text(j, name)}; {j['fixes_usable']} of {j['fixes_judged']} screened fixes "
                     f"judged usable, {c.get('fixes_judged_out', 0)} kept from the filter"
                     + (f"; re-locked to GPS {len(c['relocks'])} time(s)" if c.get("relocks") else ""))
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
                     f"{c['heading_bias_deg']:+.1f} deg; GPS declared unreliable {c['variability_detections']} time(s)"
                     + _shadow_text(c.get("shadow_events") or []))
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
    """``--mode``: the mode to run and why (auto: the declared placement, else the foot IMU's signals;
    :func:`core.foot.tracker.choose_mode`, which the app uses too)."""
    mode = getattr(args, "mode", "handheld")
    if mode != "auto":
        return mode, "chosen with --mode"
    from core.foot.tracker import choose_mode as choose

    return choose(rec, "auto", args.foot_device or "")


def replay_foot(args, rec: Recording, why: str, outs: dict) -> dict:
    """``--mode foot``: the foot-mounted INS (Song & Park 2018, :mod:`core.foot`); see :func:`replay_recording`."""
    if args.gps == "chen" or args.gps == "kubrak" or args.gps_outage:
        raise ValueError("GPS fusion with the foot-mounted INS is not built; use --gps off (or auto) with --mode foot")
    from core.foot.navigator import FootNavigator
    from core.foot.tracker import foot_settings_for, recording_gyro_range
    from core.metrics import truth_errors, truth_of

    # the product's choice (as in the app): the TCKF with a waist magnetometer, else ZUPT only; the gyroscope's
    # full scale the recording declares (the app writes Android's getMaximumRange), --gyro-range over it
    settings, waist = foot_settings_for(rec, aid=args.aid, detector=args.detector, waist_device=args.waist_device,
                                        gyro_delay_s=args.gyro_delay_ms * 1e-3, foot_device=args.foot_device or "")
    if getattr(args, "no_smoother", False):
        settings = dataclasses.replace(settings, rts_smoother=False)
    range_from, range_problem = "the recording's gyroscope", recording_gyro_range(rec, args.foot_device or "")[1]
    if math.isfinite(getattr(args, "gyro_range", math.nan)):
        settings = dataclasses.replace(settings, gyro_range_rad_s=args.gyro_range)
        range_from, range_problem = "--gyro-range", ""
    slow = foot_rate_problem(rec, args.foot_device or "", settings.stance.window_s)
    if slow is not None:
        raise ValueError(slow.text)
    with _SlowNotice("running the foot-mounted INS", not args.no_progress, 0.0 if args.progress else 2.0):
        res = FootNavigator(settings, foot_device=args.foot_device or "", waist_device=waist).run(rec)
    s = res.summary()
    s["mode"] = "foot"
    s["mode_reason"] = why
    s["smoothed"] = bool(settings.rts_smoother and not s.get("smoother_skipped_too_long"))
    s["gyro_range_rad_s"] = settings.gyro_range_rad_s
    gyro_range = (f"{settings.gyro_range_rad_s:.2f} rad/s ({range_from}): {s['gyro_clipped_runs_repaired']} "
                  "clipped runs repaired" if math.isfinite(settings.gyro_range_rad_s) else
                  "unknown, clipped readings not repaired (--gyro-range RAD_S gives it)"
                  + (f"; {range_problem}" if range_problem else ""))
    track = _stride_track(res)
    truth = truth_of(rec)
    errs = truth_errors(track, truth) if truth else {}
    if errs:
        s["truth"] = errs
    lines = [
        f"recording     {rec.source}",
        f"mode          foot-mounted INS ({why})",
        f"filter        ZUPT EKF{', RTS-smoothed' if s['smoothed'] else ''}, heading aid {s['aid']}, "
        f"stance detector {s['detector']}",
        f"duration      {s['duration_s']:.1f} s at {s['rate_hz']:.0f} Hz",
        f"strides       {s['n_strides']} (stance {100 * s['stance_fraction']:.0f} % of the time)",
        f"gyro range    {gyro_range}",
        f"distance      {s['distance_m']:.1f} m",
        f"final pos     E {s['final_east_m']:+.2f} m, N {s['final_north_m']:+.2f} m, U {s['final_up_m']:+.2f} m",
        f"start-to-end  {s['start_to_end_m']:.2f} m"
        + (f" ({100 * s['start_to_end_m'] / s['distance_m']:.2f} % of the distance)" if s["distance_m"] > 0 else ""),
    ] + truth_lines(errs)
    fsum, flines, per_step = floor_report(args, rec, track)
    if fsum is not None:
        s["floors"] = fsum
        lines += flines
    s.update(problem_summary(rec))
    lines += problem_lines(rec)
    written = _write_outputs(args, outs, rec, track, None, {"floor": per_step} if per_step is not None else None,
                             title_extra="foot INS", subtitle=truth_headline(errs),
                             truth_kw={**truth_plot(truth, errs, track, False), "track_unit": "strides"})
    return {"summary": s, "lines": lines, "written": written}


def _stride_track(res):
    """The foot track as one row per stride (the arrays core.export and the plot take)."""
    from core.pdr.pipeline import Track

    st = [x for x in res.strides if x.length_m == x.length_m]
    return Track(np.array([x.t_end_ns for x in st], dtype=np.int64), np.array([x.length_m for x in st]),
                 np.array([x.course_rad for x in st]), np.array([x.position_n[0] for x in st]),
                 np.array([x.position_n[1] for x in st]))


#: per-recording exports: option -> file name suffix in --out-dir
EXPORTS = {"csv": ".csv", "geojson": ".geojson", "gpx": ".gpx", "plot": ".png", "fixes": ".fixes.csv"}
#: what --out-dir writes unless --export says otherwise
DEFAULT_EXPORTS = ("csv", "geojson")


def check_output_path(option: str, path: str, inputs=()) -> None:
    """Refuse, before any work, an output that cannot be written: ``ValueError`` naming the option and why."""
    if path == "-":
        if option != "--csv":
            raise ValueError(f"{option} -: only --csv can write to stdout")
        return
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{option} {path}: is a folder; give a file name")
    for i in inputs:
        try:
            if i and p.exists() and p.resolve() == Path(i).resolve():
                raise ValueError(f"{option} {path}: would overwrite the recording itself")
        except OSError:
            pass
    _check_writable_folder(option, path, p.parent)
    if p.exists() and not os.access(p, os.W_OK):
        raise ValueError(f"{option} {path}: cannot write there: the file is read-only")


def _check_writable_folder(option: str, path: str, folder: Path) -> None:
    """``folder`` exists or can be made, and a file can be written in it (tried: permissions alone do not say,
    e.g. for root or on a read-only file system); the folder is left made, as the export would make it."""
    import tempfile

    folder = folder if str(folder) else Path(".")
    anc = folder
    while not anc.exists() and anc.parent != anc:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():
        raise ValueError(f"{option} {path}: cannot write there: {anc} is a file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".pdr-write-test-", dir=str(folder))
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise ValueError(f"{option} {path}: cannot write there: {e.strerror or e} ({folder})") from None


def recording_stem(path: str | None) -> str:
    """A file name stem for a recording's exports: its name without recording suffixes."""
    if path is None:
        return "demo_walk"
    name = Path(path.rstrip("/")).name
    for suf in (".gz", ".zip", ".txt", ".csv", ".log"):
        if name.lower().endswith(suf) and len(name) > len(suf):
            name = name[: -len(suf)]
    return name or "recording"


def resolve_outputs(args, stem: str, out_dir: str | None = None) -> dict:
    """Option -> path of every export of one recording: the explicit ``--csv`` etc., and with ``--out-dir``
    the ``--export`` formats as ``OUT_DIR/STEM.suffix``."""
    outs = {k: getattr(args, k, None) for k in EXPORTS}
    out_dir = out_dir if out_dir is not None else getattr(args, "out_dir", None)
    if out_dir:
        for k in export_formats(args):
            if not outs.get(k):
                outs[k] = str(Path(out_dir) / (stem + EXPORTS[k]))
    return {k: v for k, v in outs.items() if v}


def export_formats(args) -> list[str]:
    text = getattr(args, "export", None)
    if not text:
        return list(DEFAULT_EXPORTS)
    names = [{"png": "plot"}.get(x.strip(), x.strip()) for x in text.split(",") if x.strip()]
    bad = [x for x in names if x not in EXPORTS]
    if bad:
        raise ValueError(f"--export {text!r}: unknown format {bad[0]!r}; choose from csv, geojson, gpx, png, fixes")
    return names


def _write_track_csv(dest: str, track, origin, floors=None, carry=None) -> None:
    """core.export's track CSV, with ``lat_deg, lon_deg`` columns when the track is placed, a ``floor``
    column when the barometer gave one per step and a ``carry`` column (the carry mode at each step, issue
    #17) when the pipeline detected it; ``-`` is stdout."""
    import csv

    from core import export
    from core.geodesy import enu_to_geodetic

    columns = {}
    if origin is not None:
        lat, lon = enu_to_geodetic(np.asarray(track.east_m, float), np.asarray(track.north_m, float), origin)
        columns["lat_deg"] = [f"{v:.8f}" for v in np.atleast_1d(lat)]
        columns["lon_deg"] = [f"{v:.8f}" for v in np.atleast_1d(lon)]
    if floors is not None:
        columns["floor"] = [str(int(fl)) for fl in floors]
    if carry is not None:
        columns["carry"] = [str(c) for c in carry]
    if dest == "-":
        csv.writer(sys.stdout, lineterminator="\n").writerows(export.track_csv_rows(track, columns))
        sys.stdout.flush()
        return
    export.write_track_csv(dest, track, columns)


def _height_m(text: str) -> float:
    """``--height``: a body height in metres; centimetres are recognised and refused with the fix."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of metres") from None
    if 100.0 <= v <= 250.0:
        raise argparse.ArgumentTypeError(f"{text} looks like centimetres: give metres, e.g. {v / 100:.2f}")
    if not (math.isfinite(v) and 1.0 <= v <= 2.5):
        raise argparse.ArgumentTypeError(f"{text} m is not a plausible body height (1.0 to 2.5 m)")
    return v


def uses_height(model) -> bool:
    """Whether a stride model takes the walker's height as an input (its own or its coefficient's)."""
    names = getattr(model, "input_names", None) or getattr(getattr(model, "coefficient", None), "input_names", None)
    return "height_m" in (names or ())


def _positive_m(text: str) -> float:
    v = float(text)
    if not (math.isfinite(v) and 1.0 <= v <= 20.0):
        raise argparse.ArgumentTypeError(f"{text}: a storey is 1 to 20 m high")
    return v


def floor_report(args, rec: Recording, track) -> tuple[dict | None, list, list | None]:
    """The barometer's floors (:mod:`core.floors`) when the recording has pressure: ``(summary for --json,
    summary lines, the floor of every step of track)``; ``(None, [], None)`` without a barometer."""
    if not rec.has("pressure"):
        return None, [], None
    from core.floors import FloorEstimator

    res = FloorEstimator(storey_height_m=args.storey_height).run(
        rec.streams["pressure"], gps=rec.streams["gps"] if rec.has("gps") else None)
    s = res.summary()
    moves = [c for c in res.changes if c.floors]
    s["changes"] = [{"t_s": round((c.t_mid_ns - rec.t0_ns) * 1e-9, 1), "floors": c.floors, "kind": c.kind,
                     "delta_m": round(c.delta_m, 2), "rate_m_s": round(c.rate_m_s, 3), "floor_after": c.floor_after}
                    for c in moves]
    s["storey_height_m"] = args.storey_height
    if moves:
        said = ", ".join(f"{c.kind} {c.floors:+d} at {(c.t_mid_ns - rec.t0_ns) * 1e-9:.0f} s" for c in moves[:6])
        line = (f"floors        {len(moves)} change{'s' if len(moves) > 1 else ''} ({said}"
                + (", ..." if len(moves) > 6 else "") + f"), ends on floor {s['final_floor']:+d} "
                f"(barometer, storey {args.storey_height:g} m)")
    else:
        line = f"floors        no floor change (barometer; altitude range {s['altitude_range_m']:.1f} m)"
    if s["slopes"]:
        line += f"; {s['slopes']} slope{'s' if s['slopes'] > 1 else ''} (ramps, hills or outdoors)"
    return s, [line], res.floor_at(track.t_ns).tolist()


def load_map(args):
    """``--map``: a floor plan (:mod:`core.indoor`): our GeoJSON file, a Microsoft floor folder
    (``floor_info.json``) or an IPIN ``floormaps`` folder (a ``.cal`` and ``--map-floor``); None without."""
    if not getattr(args, "map", None):
        return None
    from core.indoor import read_geojson, read_ipin_floor, read_ms_floor

    path = Path(args.map)
    if path.is_dir():
        if any(path.glob("floor_info.json*")):
            return read_ms_floor(path)
        if any(path.glob("*.cal")):
            if args.map_floor is None:
                raise ValueError(f"--map {path}: an IPIN floor-image folder needs --map-floor N")
            from desktop.floor_images import read_floor_image

            return read_ipin_floor(path, args.map_floor, read_image=read_floor_image)
        raise ValueError(f"--map {path}: a folder without floor_info.json (Microsoft) or a .cal (IPIN)")
    if not path.exists():
        raise ValueError(f"--map {path}: no such file")
    return read_geojson(path)


def _floats(text: str, n: int, default_sd: float, want: str) -> tuple:
    """``n`` numbers and an optional positive sd (``default_sd`` without it), comma separated."""
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) not in (n, n + 1) or not all(math.isfinite(x) for x in v) or (len(v) == n + 1 and v[n] <= 0):
        raise argparse.ArgumentTypeError(f"{text!r}: want {want}")
    return (*v[:n], v[n] if len(v) == n + 1 else default_sd)


def _parse_fix(text: str):
    return _floats(text, 3, 2.0, "T_S,EAST_M,NORTH_M[,SD_M] (seconds from the start, plan metres)")


def _parse_start(text: str):
    return _floats(text, 2, 1.0, "EAST_M,NORTH_M[,SD_M] (plan metres)")


def map_start(args, rec: Recording, plan, track, truth) -> tuple[dict, str]:
    """Where the particle filter starts: ``(map_match keywords, why)``; ValueError when nothing says."""
    t0 = int(track.t_ns[0]) - 1 if len(track) else rec.t0_ns
    if args.start is not None:
        e, n, sd = args.start
        return {"start": (t0, e, n, sd)}, f"--start {e:g}, {n:g} (+- {sd:g} m)"
    lm = truth.landmarks if truth is not None else None
    if lm is not None and getattr(lm, "origin_lat_lon", None) is None and len(lm.t_ns):
        return ({"start": (int(lm.t_ns[0]), float(lm.east_m[0]), float(lm.north_m[0]), 1.0)},
                "the recording's first landmark")
    from core.gnss.base import first_good_fix

    fix = first_good_fix(rec.streams.get("gps"))
    if fix is not None and plan.georef is not None:
        g = rec.streams["gps"]
        hacc = float(g.values[int(np.searchsorted(g.t_ns, fix[0])), 3])
        return {"start_gps": (fix[0], fix[1], fix[2], hacc)}, "the first good GPS fix"
    raise ValueError("--map needs a start: --start EAST_M,NORTH_M in the plan's metres (or a recording with "
                     "landmarks in plan metres, or a good GPS fix and a georeferenced plan)")


def map_report(args, rec: Recording, plan, track, truth) -> tuple[object, dict, list, dict]:
    """The particle filter on the plan (:func:`core.indoor.map_match`): ``(map-matched Track, summary,
    lines, per-step export properties)``.  The exported track is the batch smoother's."""
    from core.indoor import map_match
    from core.pdr.pipeline import Track

    kw, why = map_start(args, rec, plan, track, truth)
    fixes = [(rec.t0_ns + int(round(t * 1e9)), e, n, sd) for t, e, n, sd in (args.fix or ())]
    mm = map_match(track, plan, fixes=fixes, smooth=True, **kw)
    keep = np.isin(track.t_ns, mm.t_ns)
    east = mm.smoothed_east_m if mm.smoothed_east_m is not None else mm.east_m
    north = mm.smoothed_north_m if mm.smoothed_north_m is not None else mm.north_m
    mt = Track(mm.t_ns, np.asarray(track.length_m)[keep] * mm.scale, np.asarray(track.heading_rad)[keep] - mm.bias_rad,
               np.asarray(east, float), np.asarray(north, float))
    d = mm.diagnostics
    walkable = plan.is_walkable(np.column_stack([east, north])) if len(east) else np.zeros(0, bool)
    summ = {"plan": plan.name or str(args.map), "start": why, "steps": len(mm), "fixes": len(fixes),
            "final_heading_bias_deg": math.degrees(mm.final_bias_rad),
            "final_spread_m": float(mm.spread_m[-1]) if len(mm) else math.nan,
            "outside_walkable": int(np.sum(~walkable)), "diagnostics": d}
    lines = [f"map           {summ['plan']}: particle filter from {why}"
             + (f", {len(fixes)} fix{'es' if len(fixes) > 1 else ''}" if fixes else "")
             + f"; heading bias {summ['final_heading_bias_deg']:+.1f} deg, spread {summ['final_spread_m']:.1f} m "
             f"at the end; {summ['outside_walkable']} positions outside the walkable area"]
    if d.get("recoveries"):
        lines.append(f"map           {d['recoveries']} time(s) every particle hit a wall (recovered)")
    props = {"raw_east_m": [round(float(v), 3) for v in np.asarray(track.east_m)[keep]],
             "raw_north_m": [round(float(v), 3) for v in np.asarray(track.north_m)[keep]],
             "spread_m": [round(float(v), 3) for v in mm.spread_m]}
    return mt, summ, lines, props


def plan_track_to_enu(track, georef):
    """A track in a floor plan's metres -> the same track in metres East/North of the plan's geo-reference
    origin (:meth:`core.indoor.floorplan.Georeference.plan_to_enu`; headings turned by its rotation), so that
    the exports' lat/lon are the plan's own (issue #29: map-matched exports used to land at 0, 0)."""
    from core.pdr.pipeline import Track

    en = georef.plan_to_enu(np.column_stack([np.asarray(track.east_m, float), np.asarray(track.north_m, float)]))
    return Track(np.asarray(track.t_ns), np.asarray(track.length_m, float),
                 np.asarray(track.heading_rad, float) + georef.rotation_rad, en[:, 0], en[:, 1])


def _write_outputs(args, outs: dict, rec, track, origin, extra, title_extra: str = "", others=None, fixes=None,
                   subtitle: str = "", fix_records=None, truth_kw=None, plan=None) -> list:
    """Write ``outs``.  With a floor ``plan`` the track is in the plan's metres: its geo-reference places the
    exports (``--origin`` is then the plan's origin when the plan has none); the plot stays in plan metres."""
    plot_track_ = track
    if plan is not None:
        georef = getattr(plan, "georef", None)
        if georef is None and args.origin is not None:
            from core.indoor.floorplan import Georeference

            georef = Georeference(*args.origin)
        if georef is not None:
            track, origin = plan_track_to_enu(track, georef), georef.origin
        else:
            origin = None
    else:
        origin = args.origin or origin or _first_gps_origin(rec)
    offset = rec.metadata.get("unix_offset_ns")
    written = []
    if origin is None and (outs.get("geojson") or outs.get("gpx")):
        why = ("the floor plan has no geo-reference and there is no --origin" if plan is not None else
               "no GPS fix of 12 m or better, no --origin")
        print(f"note          the track is not placed on the map ({why}): "
              "GeoJSON/GPX coordinates are around 0, 0; give --origin LAT,LON", file=sys.stderr)
    from core import export
    for out in outs.values():
        if out != "-":  # outputs may go into a folder that does not exist yet (out/ by default in the README)
            Path(out).parent.mkdir(parents=True, exist_ok=True)
    if outs.get("csv"):
        _write_track_csv(outs["csv"], track, origin, (extra or {}).get("floor"), (extra or {}).get("carry"))
        written.append("(stdout)" if outs["csv"] == "-" else outs["csv"])
    if outs.get("geojson"):
        export.write_track_geojson(outs["geojson"], track, origin, {"source": rec.source, "track": title_extra}, extra,
                                   fix_records)
        written.append(outs["geojson"])
    if outs.get("fixes"):
        if fix_records is None:
            raise ValueError("--fixes needs GPS fusion: the recording has no gps stream, or --gps off")
        export.write_fixes_csv(outs["fixes"], fix_records)
        written.append(outs["fixes"])
    if outs.get("gpx"):
        export.write_track_gpx(outs["gpx"], track, origin, offset if isinstance(offset, int) else None,
                               point_properties=extra)
        written.append(outs["gpx"])
    if outs.get("plot"):
        from desktop.plot import plot_track
        plot_track(outs["plot"], plot_track_, title=f"PDR: {Path(rec.source.split(' ')[0]).name}" +
                   (f" ({title_extra})" if title_extra else ""), others=others, fixes=fixes,
                   subtitle=subtitle, **(truth_kw or {}))
        written.append(outs["plot"])
    return written


def replay_recording(args, rec: Recording, outs: dict, demo: bool = False, progress=None) -> dict:
    """Replay one recording with ``args``' settings and write ``outs``.

    Returns ``{"summary": JSON-able dict, "lines": summary lines, "written": paths}``.
    """
    mode, why = choose_mode(args, rec)
    if mode == "foot":
        return replay_foot(args, rec, why, outs)
    from core.metrics import truth_errors, truth_of

    profile, profile_path, save_back = choose_profile(args, demo)
    gnss = build_gnss(args, rec, profile)
    if outs.get("fixes") and gnss is None:  # before the run, not after it
        raise ValueError("--fixes needs GPS fusion: the recording has no gps stream, or --gps off")
    heading = has_heading(args, rec) or gnss is not None
    if not heading and (outs.get("geojson") or outs.get("gpx")):
        raise ValueError(f"--{'geojson' if outs.get('geojson') else 'gpx'}: the recording has neither a gyroscope "
                         "nor a magnetometer, so it has no track shape to place on a map (steps and distance only)")
    plan = load_map(args)
    if plan is not None:  # where the particles start is known before the long part, or refused
        from core.pdr.pipeline import Track

        map_start(args, rec, plan, Track(np.array([rec.t0_ns], np.int64), *(np.zeros(1),) * 4), truth_of(rec))
    pipeline = build_pipeline(args, gnss, profile)
    site, site_lines = place_site(args, rec, pipeline, plan) if not args.no_mag else (None, [])
    res, engine = run_pipeline(pipeline, rec, args.engine, progress)
    gps_why = gps_choice(args)[1] if gnss is not None else ""
    fused = res.fusion is not None and res.fusion.origin_lat_lon is not None and len(res.fusion.steps)
    track = res.fusion.track() if fused else res.track
    truth = truth_of(rec)
    map_lines, map_props, plot_kw, raw = [], {}, {}, None
    if plan is not None:
        raw = track
        track, map_summary, map_lines, map_props = map_report(args, rec, plan, raw, truth)
        from core.metrics import track_start

        plot_kw = {"walls": plan.walls, "start_en": track_start(track), "track_label": "map-matched"}
    coarse = acc_rate_hz(rec) < MIN_STEP_RATE_HZ * (1.0 - STEP_RATE_TOLERANCE)
    errs = truth_errors(track, truth, dr_track=res.track) if truth and not coarse else {}
    summary = {**res.summary(), "mode": "handheld", "mode_reason": why, "engine": engine, **problem_summary(rec)}
    if coarse:  # no steps to count: say so instead of scoring 0 steps as -100 %
        summary["steps_measured"] = False
    if plan is not None:
        summary["map"] = {**map_summary, "truth_without_map": truth_errors(raw, truth) if truth else {}}
    if not heading:
        summary.update(heading="none", final_east_m=None, final_north_m=None, start_to_end_m=None, labels=[])
    if gnss is not None:
        summary.update(gps_fusion=gnss.name, gps_fusion_reason=gps_why)
        if res.fusion is not None:
            from core.gnss.judge import verdict_text

            judge = res.fusion.counters.get("gps_judge")
            summary.update(gps_verdict=verdict_text(judge, gnss.name), gps_judge=judge,
                           gps_relocks=res.fusion.counters.get("relocks", []))
    if errs:
        summary["truth"] = errs
    lines = summary_lines(res, rec, gps_why, heading)
    lines = lines[:1] + [f"mode          hand-held PDR ({why})"] + lines[1:] + (site_lines if heading else [])
    if engine != "reference":  # the phone's code is the default; say when another engine ran, or why not
        lines.append("engine        " + ("the fast desktop path (desktop.fast; the same results within 1e-9)"
                                         if engine == "fast" else engine))
    hs = res.counters.get("heading_smoother")
    if hs is not None:  # a replay's heading smoother (issue #27): what it did, in one line
        done = ", ".join(f"{k.replace('_deg', '')} {v:+.1f} deg" for k, v in hs.items() if k.endswith("_deg"))
        lines.append(f"heading       smoothed ({pipeline.heading_smoother}): {hs['verdict']}" + (f"; {done}" if done else ""))
    if coarse:
        lines = [ln for ln in lines if not ln.startswith(("steps ", "distance ", "final pos", "start-to-end"))]
        lines.insert(3, f"steps         not measured: the accelerometer is sampled at {acc_rate_hz(rec):.1f} Hz, step "
                        f"detection needs at least {MIN_STEP_RATE_HZ:g} Hz")
    if site is not None:
        summary["declination"] = site
    if profile is not None:
        lines.append(profile_line(profile, profile_path, args))
        summary["profile"] = {"path": str(profile_path), **profile.to_dict()}
    lines += map_lines + truth_lines(errs)
    extra = track.point_properties() if fused and plan is None else None
    if map_props:
        extra = {**(extra or {}), **map_props}
    if getattr(pipeline, "carry", None) is not None and len(res.steps) == len(track):
        extra = {**(extra or {}), "carry": [st.carry_mode for st in res.steps]}
    fsum, flines, per_step = floor_report(args, rec, track)
    if fsum is not None:
        summary["floors"] = fsum
        lines += flines
        extra = {**(extra or {}), "floor": per_step}
    others, fixes = {}, None
    if raw is not None and len(track):  # the raw track from the same start, for comparison
        from core.metrics import track_start

        (ms_e, ms_n), (r_e, r_n) = track_start(track), track_start(raw)
        others["without the map"] = (np.asarray(raw.east_m) + ms_e - r_e, np.asarray(raw.north_m) + ms_n - r_n)
    if fused and outs.get("plot"):
        others["dead reckoning only"] = (res.track.east_m, res.track.north_m)
        fx = [f for f in res.fusion.fixes if f.east_m == f.east_m]
        fixes = ([f.east_m for f in fx], [f.north_m for f in fx], [f.accepted for f in fx], [f.reason for f in fx])
        if getattr(args, "gps_outage", None):  # the hidden windows, shaded and named on the plot
            plot_kw["hidden"] = [(rec.t0_ns + int(a * 1e9), rec.t0_ns + int((a + b) * 1e9),
                                  f"GPS hidden {a:.0f}-{a + b:.0f} s (--gps-outage {a:g}:{b:g})")
                                 for a, b in args.gps_outage]
    s = summary
    sub = (f"{s['n_steps']} steps, {s['distance_m']:.1f} m"
           + (f", start-to-end {s['start_to_end_m']:.2f} m" if heading else "")
           + (f"; {truth_headline(errs)}" if errs else ""))
    plotted = []
    if not heading:  # no invented track: a distance plot, and the CSV without positions or headings
        from core.pdr.pipeline import Track

        nan = np.full(len(track), np.nan)
        track = Track(track.t_ns, track.length_m, nan, nan, nan)
        if outs.get("plot"):
            from desktop.plot import plot_distance

            plot_distance(outs["plot"], track, title=f"Steps: {Path(rec.source.split(' ')[0]).name}", subtitle=sub)
            plotted = [outs["plot"]]
            outs = {k: v for k, v in outs.items() if k != "plot"}
    written = plotted + _write_outputs(args, outs, rec, track, res.fusion.origin_lat_lon if fused else None, extra,
                             gps_track_label(res.fusion, gnss.name) if fused else "", others, fixes, sub,
                             res.fusion.fixes if res.fusion is not None else None,
                             {**(truth_plot(truth, errs, track, bool(fused)) if errs else {}), **plot_kw} or None,
                             plan=plan)
    if profile is not None and save_back and res.fusion is not None:
        from core.gnss import profile_after
        new = profile_after(profile, pipeline.gnss)
        if new is not profile:
            new.save(profile_path)
            written.append(profile_path)
    return {"summary": summary, "lines": lines, "written": written}


def _jsonable(obj):
    """``obj`` with every non-finite float as None (JSON has no NaN or Infinity) and numpy numbers as Python's."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def dump_json(obj) -> str:
    return json.dumps(_jsonable(obj), indent=1, default=str, allow_nan=False)


def cmd_replay(args) -> int:
    inputs = list(args.recording or [])
    if len(inputs) == 1 and is_folder_of_recordings(inputs[0]):
        found, _ = collect_recordings(inputs)
        if len(found) == 1:  # a folder holding one recording (an export unpacked into a folder): that one
            inputs = found
        else:
            return cmd_replay_batch(args, inputs)
    if len(inputs) > 1:
        return cmd_replay_batch(args, inputs)
    path = inputs[0] if inputs else None
    outs = resolve_outputs(args, recording_stem(path))
    check_outputs(args, outs, inputs)
    with _SlowNotice(f"reading {path}", not args.no_progress and path is not None, 0.0 if args.progress else 2.0):
        rec = load_demo() if path is None else load_any(path, args.platform)
    prog = _Progress("replay", not args.no_progress, after_s=0.0 if args.progress else 2.0)
    r = replay_recording(args, rec, outs, demo=path is None, progress=prog)
    stdout_taken = args.json or outs.get("csv") == "-"
    if args.json:
        print(dump_json(r["summary"]))
    else:
        print("\n".join(r["lines"]), file=sys.stderr if stdout_taken else sys.stdout)
    for w in r["written"]:
        if w != "(stdout)":
            print(f"wrote         {w}", file=sys.stderr if stdout_taken else sys.stdout)
    return 0


def check_outputs(args, outs: dict, inputs=()) -> None:
    """Every output of this run can be written (before the long part), and stdout has one user."""
    if args.json and outs.get("csv") == "-":
        raise ValueError("--json and --csv - both want stdout: write one of them to a file")
    if getattr(args, "out_dir", None):
        d = Path(args.out_dir)
        if d.exists() and not d.is_dir():
            raise ValueError(f"--out-dir {args.out_dir}: is a file, not a folder")
        _check_writable_folder("--out-dir", args.out_dir, d)
    for k, v in outs.items():
        check_output_path(f"--{k}", v, inputs)


# ---------------------------------------------------------------------------
# several recordings at once

#: folders this deep below a given folder are searched for recordings
MAX_FOLDER_DEPTH = 6


def _detect(path: str) -> str | None:
    try:
        from core.importers import detect_format
    except ImportError:  # pragma: no cover - importers not installed
        return "pdr-recording"
    try:
        return detect_format(path)
    except (RecordingError, OSError):
        return None


def is_folder_of_recordings(path: str, _depth: int = 0) -> bool:
    """A folder that is not itself a recording.  A Sensor Logger or phyphox export folder is one (the importers
    recognise it); a folder whose content the importers recognise only because it holds such exports in
    subfolders, or holds recordings of another format beside them, is a folder of recordings."""
    if not os.path.isdir(path):
        return False
    fmt = _detect(path)
    if fmt is None:
        return True
    try:
        entries = [e for e in os.scandir(path) if not e.name.startswith(".")]
    except OSError:
        return False
    for e in entries:
        if e.is_dir():
            if _depth < 2 and _detect(e.path) is not None and not is_folder_of_recordings(e.path, _depth + 1):
                return True  # an export folder inside
        elif e.is_file():
            f = _detect(e.path)
            if f is not None and f != fmt:
                return True  # a recording of another format beside it
    return False


def collect_recordings(inputs) -> tuple[list[str], list[str]]:
    """The recordings among ``inputs`` (files, recording folders, folders of them searched recursively):
    ``(recordings, skipped)``, the skipped being files in a searched folder that are no recording."""
    found, skipped = [], []

    def walk(folder: Path, depth: int):
        try:
            entries = sorted(folder.iterdir(), key=lambda q: q.name)
        except OSError as e:
            raise RecordingError(f"cannot list the folder: {e.strerror or e}", str(folder)) from None
        for q in entries:
            if q.name.startswith("."):
                continue
            if q.is_dir():
                if _detect(str(q)) is not None:
                    found.append(str(q))
                elif depth < MAX_FOLDER_DEPTH:
                    walk(q, depth + 1)
            elif q.is_file():
                (found if _detect(str(q)) is not None else skipped).append(str(q))

    for i in inputs:
        if not os.path.exists(i):
            raise RecordingError("cannot open: no such file or folder", i)
        if is_folder_of_recordings(i):
            walk(Path(i), 1)
        else:
            found.append(i)  # a file is read (and its error reported) even if it is no recording
    return found, skipped


def unique_stems(paths) -> list[str]:
    """Export names for ``paths``: the recording's stem, with the parent folders' names where stems repeat."""
    stems = [recording_stem(p) for p in paths]
    for _ in range(4):
        seen: dict = {}
        for k, st in enumerate(stems):
            seen.setdefault(st, []).append(k)
        dup = [ks for ks in seen.values() if len(ks) > 1]
        if not dup:
            return stems
        for ks in dup:
            for k in ks:
                parts = Path(paths[k].rstrip("/")).parts
                depth = stems[k].count("__") + 2
                stems[k] = "__".join(parts[-depth:-1] + (recording_stem(paths[k]),)) if len(parts) >= depth \
                    else stems[k]
    seen = {}
    for k, st in enumerate(stems):  # still the same: number them
        n = seen.get(st, 0)
        seen[st] = n + 1
        if n:
            stems[k] = f"{st}_{n + 1}"
    return stems


def replay_file(path: str, stem: str, args) -> dict:
    """One recording of a batch (in a worker process): never raises, the error is in the row."""
    row = {"path": path, "ok": False}
    args = argparse.Namespace(**{**vars(args), "no_progress": True})  # the batch's progress line is the only one
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rec = load_any(path, args.platform)
            outs = resolve_outputs(args, stem)
            r = replay_recording(args, rec, outs)
            row.update(ok=True, summary=_jsonable(r["summary"]), written=r["written"])
        except (RecordingError, ValueError) as e:
            row.update(error=str(e), exit=EXIT_INPUT)
        except (OSError, RuntimeError) as e:
            row.update(error=str(e), exit=1)
        except Exception as e:  # noqa: BLE001 - one recording's failure must not end the batch
            row.update(error=f"internal error: {type(e).__name__}: {e}", exit=1)
    row["warnings"] = [str(w.message) for w in caught
                       if issubclass(w.category, UserWarning) and not issubclass(w.category, DeprecationWarning)]
    return row


def main_carry_mode(carry: dict | None) -> str:
    """The carry mode of most of the walking time (issue #17), "-" without a carry-mode detector."""
    walking = {m: v for m, v in ((carry or {}).get("time_s") or {}).items() if m != "still"}
    return max(walking, key=walking.get) if walking else "-"


def batch_table(rows) -> list[str]:
    """The summary table of a batch: one line per recording, then the totals."""
    names = [os.path.relpath(r["path"]) if not os.path.isabs(r["path"]) else r["path"] for r in rows]
    w = max([len("recording")] + [len(n) for n in names])
    head = (f"{'recording':<{w}}  {'tracker':<9}  {'carried':<8}  {'duration':>9}  {'steps':>6}  {'distance':>9}  "
            f"{'start-to-end':>12}  truth error")
    lines = [head, "-" * len(head)]
    steps = dist = dur = 0.0
    for name, r in zip(names, rows):
        if not r["ok"]:
            lines.append(f"{name:<{w}}  error: {r['error']}")
            continue
        s = r["summary"]
        n = s.get("n_steps", s.get("n_strides", 0)) or 0
        d, se = s.get("distance_m") or 0.0, s.get("start_to_end_m")
        steps, dist, dur = steps + n, dist + d, dur + (s.get("duration_s") or 0.0)
        se_txt = f"{se:.2f} m" if se is not None else "-"
        tracker = {"handheld": "phone PDR", "foot": "foot INS"}.get(s.get("mode", ""), s.get("mode", ""))
        lines.append(f"{name:<{w}}  {tracker:<9}  {main_carry_mode(s.get('carry')):<8}  "
                     f"{s.get('duration_s') or 0.0:>7.1f} s  {n:>6d}  "
                     f"{d:>7.1f} m  {se_txt:>12}  {truth_headline(s.get('truth') or {}) or '-'}")
    ok = sum(1 for r in rows if r["ok"])
    lines.append("-" * len(head))
    lines.append(f"{len(rows)} recording{'s' if len(rows) != 1 else ''}, {ok} replayed, {len(rows) - ok} failed; "
                 f"{int(steps)} steps, {dist:.1f} m, {dur / 60:.1f} min in all")
    return lines


def cmd_replay_batch(args, inputs) -> int:
    """``pdr replay A B FOLDER ...``: every recording on all cores, one table (or JSON document)."""
    given = [f"--{k}" if k != "plot" else "--plot" for k in EXPORTS if getattr(args, k, None)]
    if given:
        raise ValueError(f"{given[0]} names one file: with several recordings use --out-dir DIR (and --export "
                         "FORMATS) for one set of files per recording")
    export_formats(args)
    if getattr(args, "out_dir", None):
        check_outputs(args, {})
    paths, skipped = collect_recordings(inputs)
    if not paths:
        raise RecordingError("no recordings found (formats: see pdr replay --help)", ", ".join(inputs))
    stems = unique_stems(paths)
    for f in skipped:
        print(f"pdr: skipped {f}: not a recording", file=sys.stderr)
    jobs = max(1, min(args.jobs or os.cpu_count() or 1, len(paths)))
    prog = _Progress("replay", not args.no_progress, after_s=0.0 if args.progress else 2.0, total=len(paths))
    rows: list = [None] * len(paths)
    if jobs == 1:
        for k, (pth, st) in enumerate(zip(paths, stems)):
            rows[k] = replay_file(pth, st, args)
            prog((k + 1) / len(paths))
    else:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futs = {pool.submit(replay_file, pth, st, args): k for k, (pth, st) in enumerate(zip(paths, stems))}
            for done, fut in enumerate(as_completed(futs), 1):
                rows[futs[fut]] = fut.result()
                prog(done / len(paths))
    for r in rows:
        for w in r.get("warnings", ()):
            print(f"pdr: warning: {w}" if r["path"] in w else f"pdr: warning: {r['path']}: {w}", file=sys.stderr)
        for w in r.get("written", ()):
            print(f"wrote         {w}", file=sys.stderr)
    failed = [r for r in rows if not r["ok"]]
    if args.json:
        print(dump_json({"n_recordings": len(rows), "n_failed": len(failed), "skipped": skipped,
                         "recordings": [{k: v for k, v in r.items() if k != "exit"} for r in rows]}))
    else:
        print("\n".join(batch_table(rows)))
    return max([r.get("exit", 0) for r in failed], default=0)


def cmd_simulate(args) -> int:
    from desktop import simulator

    if args.shape == "demo":
        walk = simulator.demo_walk(seed=args.seed)
    else:
        shapes = {"square": [(0, 0), (20, 0), (20, 20), (0, 20), (0, 0)], "line": [(0, 0), (0, 50)],
                  "turn": [(0, 0), (0, 20), (20, 20)]}
        walk = simulator.simulate_walk(shapes[args.shape], rate_hz=args.rate, seed=args.seed)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)  # out/ by default in the README, as for replay
    write_recording(args.out, walk.recording)
    print(f"wrote {args.out}: {walk.recording.duration_s:.1f} s, {len(walk.truth.step_t_ns)} steps, "
          f"{walk.truth.path_length_m:.1f} m")
    return 0


def _pooled(profile) -> int:
    """How many calibration walks the profile's factor is pooled from (core.pdr.calibration's rule)."""
    from core.pdr.calibration import MAX_POOLED

    last = profile.calibrations[-1].get("model_id") if profile.calibrations else None
    return min(sum(1 for c in profile.calibrations if c.get("model_id") == last), MAX_POOLED)


def cmd_calibrate(args) -> int:
    """``pdr calibrate RECORDING --distance M | --from-gps``: fit the user's stride and store it in the profile."""
    from core.pdr.calibration import CalibrationError, UserProfile

    path = args.profile or str(default_profile_path())
    check_output_path("--profile", path, [args.recording])
    profile = UserProfile.load(path) if Path(path).is_file() else UserProfile()
    if args.height is not None:
        from dataclasses import replace
        profile = replace(profile, height_m=args.height)  # CalibrationError if implausible
    if args.stride_model and args.stride_model != profile.model:
        from core.pdr.stride_models import load_stride_model
        load_stride_model(args.stride_model)  # a bad name: one line, before the run
    with _SlowNotice(f"reading {args.recording}", not args.no_progress):
        rec = load_any(args.recording, args.platform)
    prog = _Progress("calibrate", not args.no_progress)
    lines = [f"recording     {rec.source}"]
    if args.distance is not None:
        from core.pdr.calibration import calibrate_known_distance
        from core.pdr.pipeline import Pipeline
        from core.pdr.stride_models import load_stride_model

        model = args.stride_model or profile.model
        pipe = Pipeline(height_m=profile.height_m, stride_model=load_stride_model(model))  # unscaled, no GPS
        res = pipe.run(rec, progress=prog)
        r = calibrate_known_distance(res.steps, args.distance, model=model, profile=profile)
        new = r.profile
        lines += [f"walk          {r.n_steps} steps over {r.known_distance_m:g} m: {r.mean_step_length_m:.2f} m a step",
                  f"model         {model}: {r.model_distance_m:.1f} m for this walk unscaled, so this walk asks for "
                  f"x{r.walk_scale:.3f}",
                  f"stored        stride factor x{r.scale:.3f} on model {model} (pooled over {_pooled(new)} "
                  f"calibration walk(s)), was x{profile.c_scale:.3f}"]
        lines += [f"note          {w}" for w in r.warnings]
        out = {"method": "known distance", "known_distance_m": r.known_distance_m, "n_steps": r.n_steps,
               "model": model, "model_distance_m": r.model_distance_m, "walk_scale": r.walk_scale,
               "c_scale": r.scale, "c_scale_before": profile.c_scale}
    else:
        if not rec.has("gps"):
            raise ValueError(f"--from-gps: the recording has no gps stream (streams: {', '.join(sorted(rec.streams))})"
                             "; walk a measured distance and use --distance M")
        from core.gnss import make_fusion, profile_after, settings_from_profile
        from core.pdr.pipeline import Pipeline

        fusion = make_fusion("chen", **settings_from_profile("chen", profile))
        pipe = Pipeline(height_m=profile.height_m, stride_model=profile.stride_model(), gnss=fusion)
        res = pipe.run(rec, progress=prog)
        new = profile_after(profile, pipe.gnss)
        tr = pipe.gnss.trainer
        if new is profile:
            from core.gnss.training import MIN_PROFILE_GPS_M
            raise CalibrationError(
                f"--from-gps: the walk's good GPS taught too little: {tr.stride_gps_distance_m:.0f} m of straight, "
                f"steady walking with good fixes, {MIN_PROFILE_GPS_M:.0f} m needed; walk longer in the open, or "
                "walk a measured distance and use --distance M")
        g = new.gps
        lines.append(f"gps           {tr.stride_gps_distance_m:.0f} m of straight, steady walking with good fixes")
        if "stride_scale" in g and g.get("stride_scale") != (profile.gps or {}).get("stride_scale"):
            lines.append(f"stored        GPS stride scale x{g['stride_scale']:.3f} (on top of the stride factor "
                         f"x{new.c_scale:.3f}): GPS fusion starts from it (pdr replay and the app); walks without GPS "
                         "use the stride factor, which --distance calibrates")
        if "heading_model" in g:
            coef = (g["heading_model"] or {}).get("coefficients_deg") or [0.0]
            lines.append(f"stored        heading offset {coef[0]:+.1f} deg (the phone's heading error model, eq. 12 "
                         "of Chen et al. 2010)")
        out = {"method": "gps", "gps_m": tr.stride_gps_distance_m, "gps": g,
               "pdr_distance_m": float(res.track.length_m.sum())}
    new.save(path)
    lines.append(f"profile       {path}")
    if args.json:
        print(dump_json({**out, "profile_path": path, "profile": new.to_dict()}))
    else:
        print("\n".join(lines))
    return 0


INFO_COLUMNS = (
    ("stream", "the stream's name (acc, gyro, mag, gps, posi: ground-truth landmarks, ...; kind@device for a "
               "second device)"),
    ("events", "number of events (readings)"),
    ("rate Hz", "events per second over the stream's span"),
    ("jitter ms", "standard deviation of the intervals between events, gaps left out (the app's health panel "
                  "computes it the same way, core.recording.jitter_s)"),
    ("gaps", "intervals longer than 2.5 times the local median interval"),
    ("rate chg", "places where the sampling rate changes by more than a factor 1.5"),
    ("columns [unit]", "the values of each event and their units"),
)


def info_table(rec: Recording) -> list[str]:
    """``pdr info``'s stream table: one aligned row per stream under the headers of :data:`INFO_COLUMNS`."""
    rows = []
    for n, s in rec.streams.items():
        st = s.interval_stats_s()
        jit = 1e3 * st["jitter_s"]
        rows.append((n, f"{len(s):d}", f"{s.rate_hz:.1f}", f"{jit:.2f}" if jit == jit else "-", f"{st['gaps']}",
                     f"{st.get('rate_changes', 0)}", f"{', '.join(s.columns)} [{s.unit}]"))
    heads = [h for h, _ in INFO_COLUMNS]
    w = [max([len(heads[k])] + [len(r[k]) for r in rows]) for k in range(len(heads))]

    def fmt(r):
        return "  ".join([r[0].ljust(w[0])] + [r[k].rjust(w[k]) for k in range(1, 6)] + [r[6]]).rstrip()

    return [fmt(heads)] + [fmt(r) for r in rows]


def cmd_info(args) -> int:
    with _SlowNotice(f"reading {args.recording}", not getattr(args, "no_progress", False)):
        rec = load_any(args.recording)
    fmt = _detect(args.recording)
    print(f"recording  {rec.source}")
    if fmt:
        print(f"format     {fmt}")
    print(f"duration   {rec.duration_s:.1f} s")
    print()
    print("\n".join(info_table(rec)))
    print()
    if rec.device:
        print(f"device     {json.dumps(rec.device)}")
    for r in rec.repairs:
        print(f"repaired   {r}")
    return 0


class _SlowNotice:
    """A status line on stderr when a step without progress of its own (reading a file) takes over ``after_s``:
    ``pdr: reading X ...`` once, then how long it took."""

    def __init__(self, what: str, enabled: bool = True, after_s: float = 2.0):
        self.what, self.enabled, self.after_s = what, enabled, after_s
        self.shown = False
        self._timer = None
        self._t0 = 0.0

    def _show(self):
        self.shown = True
        sys.stderr.write(f"pdr: {self.what} ...\n")
        sys.stderr.flush()

    def __enter__(self):
        import threading

        self._t0 = time.monotonic()
        if self.enabled:
            self._timer = threading.Timer(self.after_s, self._show)
            self._timer.daemon = True
            self._timer.start()
        return self

    def __exit__(self, *exc):
        if self._timer is not None:
            self._timer.cancel()
        if self.shown:
            sys.stderr.write(f"pdr: {self.what}: done in {time.monotonic() - self._t0:.1f} s\n")
        return False


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pdr", description="Pedestrian dead reckoning for smartphone sensor recordings "
                                "(step detection, step length, adaptive EKF heading, track).")
    p.add_argument("--version", action="version", version=f"pdr {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("replay", help="run the pipeline on recordings and print a summary",
                       description="Run the PDR pipeline on a recording (pdr-recording, GetSensorData, Sensor Logger, "
                                   "phyphox or one of the research formats listed below; detected from the content) "
                                   "and print a summary, with the error "
                                   "against the ground truth the recording carries (landmarks, simulator truth, "
                                   "GPS). Without RECORDING, replays the bundled simulated demo walk (a closed "
                                   "loop). With several recordings or a folder of them, replays them all on all "
                                   "cores and prints one table (exports per recording with --out-dir).",
                       epilog="Outputs are checked before the run: one that cannot be written exits 2. The user "
                              "profile of `pdr calibrate` (the app's, or --profile) sets the stride factor and "
                              "height unless --no-profile, --stride-c, --stride-model or --height say otherwise. "
                              "Formats read: " + ", ".join(sorted(_IMPORT_FORMATS)) + " (pdr info FILE says which "
                              "one a file is).")
    r.add_argument("recording", nargs="*", help="recording files or folders; a folder that is no recording itself "
                   "is searched for recordings (default: the bundled demo walk)")
    r.add_argument("--csv", metavar="PATH", help="write the track as CSV, one row per step (local metres, and "
                   "lat_deg/lon_deg when the track is placed by GPS or --origin); '-' writes it to stdout (the "
                   "summary then goes to stderr)")
    r.add_argument("--geojson", metavar="PATH", help="write the track as GeoJSON (WGS-84, needs --origin or GPS "
                                                      "in the recording to be placed on the map)")
    r.add_argument("--fixes", metavar="PATH", help="write every GPS fix with its verdict (used, or why not) as CSV "
                                                   "(the GeoJSON carries them too)")
    r.add_argument("--gpx", metavar="PATH", help="write the track as GPX 1.1 with time, step length and bearing "
                                                 "per point (needs gpxpy)")
    r.add_argument("--plot", metavar="PNG", help="draw the track to a PNG file (needs matplotlib)")
    r.add_argument("--origin", type=_parse_origin, metavar="LAT,LON",
                   help="geographic start point for GeoJSON/GPX (default: first GPS fix, else 0,0)")
    r.add_argument("--map", metavar="PLAN",
                   help="a floor plan for the particle filter (core.indoor): our GeoJSON, a Microsoft floor "
                        "folder (floor_info.json) or an IPIN floormaps folder (with --map-floor); the summary, "
                        "exports and plot give the map-matched track, the raw one beside it")
    r.add_argument("--map-floor", type=int, default=None, metavar="N", help="--map: the IPIN floor number")
    r.add_argument("--start", type=_parse_start, default=None, metavar="E,N[,SD]",
                   help="--map: where the walk starts, in the plan's metres (default: the recording's first "
                        "landmark, else its first good GPS fix)")
    r.add_argument("--fix", type=_parse_fix, action="append", default=None, metavar="T_S,E,N[,SD]",
                   help="--map: a position fix, seconds from the start and plan metres (an 'I am here'); repeatable")
    r.add_argument("--height", type=_height_m, metavar="M",
                   help="walker's body height in metres (1.0-2.5), as in the app's profile; only the weinberg_bp "
                        "stride model uses it, the other shipped models ignore it (the summary says so)")
    r.add_argument("--storey-height", type=_positive_m, default=3.5, metavar="M",
                   help="height of one storey of the building (m) for the barometer's floor count "
                        "(default %(default)s; recordings with pressure only)")
    r.add_argument("--stride-model", default=None, metavar="NAME|PATH",
                   help="step length model: a shipped name (default, weinberg, weinberg_bp, chen_linear, chen_ann, "
                        "kubrak_velocity: Kubrak et al.'s eq. 1 speed times the step's interval) "
                        "or a model JSON file (default: the profile's model with its factor, else 'default')")
    r.add_argument("--stride-c", type=float, metavar="C", help="constant Weinberg coefficient C (overrides "
                                                                "--stride-model)")
    r.add_argument("--declination", type=float, default=None, metavar="DEG",
                   help="magnetic declination, east positive (default: the World Magnetic Model's at the walk's "
                        "place and date when --origin or a good GPS fix gives the place, else 0: headings "
                        "relative to magnetic north)")
    r.add_argument("--no-mag", action="store_true", help="ignore the magnetometer (heading relative to the start)")
    r.add_argument("--gps", choices=GPS_MODES, default="auto",
                   help="GPS fusion: auto (fuse when the recording has fixes, with Kubrak's filter, better than "
                        "Chen's on the tuning split's indoor loops and noisy-GPS walks; the summary says which and "
                        "why; fixes the GPS judge finds unusable are not used and the track is then dead "
                        "reckoning), off, chen (Chen et al. 2010: calibration while GPS is "
                        "good, the step-wise PDR Kalman filter), kubrak (Kubrak et al. 2006: the velocity-model "
                        "Kalman filter with bad-GPS detection)")
    r.add_argument("--gps-outage", type=_parse_outage, action="append", metavar="START_S:LENGTH_S",
                   help="hide the GPS fixes from START_S (seconds from the first sensor event) for LENGTH_S; "
                        "repeatable; the error at the end of each is reported")
    r.add_argument("--profile", metavar="PATH", help="user profile (JSON) instead of the stored one: its stride "
                   "factor and height are used, its GPS stride scale and heading model start the GPS training, and "
                   "what the walk's GPS taught is saved back into it (the stored profile is only read)")
    r.add_argument("--no-profile", action="store_true", help="ignore the stored user profile (default: the one "
                   "`pdr calibrate` and the app keep, if there is one; see `pdr calibrate --help`)")
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
    r.add_argument("--detector", choices=("shoe", "song", "amv", "are", "learned"), default="shoe",
                   help="foot mode: stance detector (default shoe; learned: the logistic model in "
                        "core/foot/models, issue #27)")
    r.add_argument("--gyro-delay-ms", type=float, default=0.0, metavar="MS",
                   help="foot mode: the gyroscope lags the accelerometer by this much (ms)")
    r.add_argument("--gyro-range", type=float, default=float("nan"), metavar="RAD_S",
                   help="foot mode: the gyroscope's full scale (rad/s): readings within 1 %% of it are clipped "
                        "and repaired (default: the one the recording declares, as the app writes it; else "
                        "unknown, none repaired)")
    r.add_argument("--no-smoother", action="store_true",
                   help="foot mode: the forward filter's track only (default: RTS-smoothed over the whole walk, "
                        "each sample from the samples before and after it; the live app never smooths)")
    r.add_argument("--platform", choices=("android", "ios"), default=None,
                   help="for a Sensor Logger export without Metadata.csv: the phone it came from "
                        "(or set PDR_SENSORLOGGER_PLATFORM)")
    r.add_argument("--heading-smoother", choices=HEADING_SMOOTHERS, default="off",
                   help="hand-held, replays only (issue #27): off (default, the live app's heading); rts: every "
                        "step's heading from an RTS backward pass over the attitude filter's run; start: a second "
                        "pass started from the heading that pass gives at the start. Runs on the reference engine "
                        "(the fast path does not mirror it); not applied with GPS fusion. Off by default: on the "
                        "IPIN tuning split neither helped (benchmarks/ABLATION_RESULTS.md)")
    r.add_argument("--engine", choices=ENGINES, default="auto",
                   help="hand-held pipeline: the fast desktop path over whole arrays (the same results within 1e-9) "
                        "when numba is installed (auto, the default; pip install '.[fast]'), always (fast; slow "
                        "without numba), or the phone's per-event code (reference); GPS fusion included. Its first "
                        "use compiles for about a minute (numba caches the result)")
    r.add_argument("--json", action="store_true", help="print the summary as one JSON document on stdout (status "
                   "lines go to stderr; with several recordings: one document with a row per recording)")
    r.add_argument("--out-dir", metavar="DIR", help="write each recording's exports into DIR as NAME.csv, "
                   "NAME.geojson, ... (the formats of --export)")
    r.add_argument("--export", metavar="FORMATS", help="with --out-dir: comma-separated formats among csv, geojson, "
                   "gpx, png, fixes (default: csv,geojson)")
    r.add_argument("--jobs", type=int, default=None, metavar="N", help="with several recordings: replay N at a time "
                   "(default: all cores)")
    r.add_argument("--progress", action="store_true", help="show progress on stderr from the start "
                   "(default: once reading or replaying has taken 2 s, on a terminal or not)")
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

    c = sub.add_parser("calibrate", help="fit the user's stride on a walk and store it in the profile",
                       description="Fit the walker's stride factor on a recording and store it in the user profile "
                                   "the app uses (pdr replay then uses it, unless --no-profile). --distance M: the "
                                   "walk was M metres, measured (the factor is pooled with the last walks made with "
                                   "the same model). --from-gps: learn from the recording's good GPS (straight, "
                                   "steady stretches; GPS fusion starts from it).")
    c.add_argument("recording", help="the calibration walk (any format pdr replay reads)")
    how = c.add_mutually_exclusive_group(required=True)
    how.add_argument("--distance", type=float, metavar="M", help="the distance walked, in metres, measured")
    how.add_argument("--from-gps", action="store_true", help="learn from the recording's GPS fixes (Chen et al. 2010)")
    c.add_argument("--profile", metavar="PATH", help="profile file (default: the app's, "
                   "$PDR_APP_DATA/profile.json or ~/.config/pdr/profile.json)")
    c.add_argument("--height", type=_height_m, metavar="M",
                   help="walker's body height in metres (1.0-2.5), stored in the profile")
    c.add_argument("--stride-model", default=None, metavar="NAME|PATH", help="the model the factor belongs to "
                   "(default: the profile's, else 'default')")
    c.add_argument("--platform", choices=("android", "ios"), default=None,
                   help="for a Sensor Logger export without Metadata.csv: the phone it came from")
    c.add_argument("--json", action="store_true", help="print what was stored as JSON")
    c.add_argument("--no-progress", action="store_true", help="never show progress")
    c.set_defaults(func=cmd_calibrate)

    i = sub.add_parser("info", help="describe a recording: streams, rates, jitter, gaps",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Describe a recording: its format, duration and one row per stream:\n\n"
                                   + "\n".join(f"  {h:<15} {d}" for h, d in INFO_COLUMNS)
                                   + "\n\nthen the device and any repairs made while reading.")
    i.add_argument("recording")
    i.add_argument("--no-progress", action="store_true", help="no status line when reading takes a while")
    i.set_defaults(func=cmd_info)
    return p


def main(argv=None) -> int:
    parser = make_parser()
    args = parser.parse_args(argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = args.func(args)
            sys.stdout.flush()  # a closed pipe shows here, not at exit
        except BrokenPipeError:  # `pdr info X | head -1`: the reader has what it wanted; not an error
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush writes nowhere
            code = 0
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
