"""The foot-mounted INS behind the hand-held pipeline's streaming interface, and the choice between them.

The app (:class:`app.session.Session`) and the command line run either chain:

* :func:`choose_mode` decides hand-held PDR or foot-mounted INS for a recording: the user's choice,
  else the placement the recording declares (``device["placement"]``, ``metadata["devices"]``), else
  the IMU's signals (:func:`core.foot.mounting.detect_mounting`).  It returns the mode and why.
* :func:`foot_settings_for` gives the settings the product uses on a recording: the TCKF of
  Song & Park when a waist magnetometer is there, ZUPT only otherwise; the gyroscope's full scale the
  recording declares (:func:`core.foot.saturation.declared_gyro_range`), so clipped readings are repaired.
* :class:`FootTracker` has the streaming interface of :class:`core.pdr.pipeline.Pipeline`
  (``update(stream, t_ns, values)`` -> completed strides, ``finish()``, ``status()``) over
  :class:`core.foot.navigator.FootNavigator`, so the session, the track view, the exports and the
  health panel need no foot-specific code beyond :meth:`FootTracker.health_lines`.  One
  :class:`FootStep` per stride (one stance to the next), not per step: a foot IMU sees every other step.

For a walk of hours the tracker keeps per-stride data only: the navigator's per-sample outputs are
dropped as they are handed out (``keep_samples=False``), so memory does not grow with the sample rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from core.conventions import ACC, MAG
from core.foot.devices import has_imu, stream_name
from core.foot.mounting import FOOT, HANDHELD, detect_mounting
from core.foot.navigator import FootNavigator, FootSettings
from core.foot.saturation import declared_gyro_range
from core.foot.stance import StanceSettings
from core.recording import Recording

#: the modes a user can choose ("auto": :func:`choose_mode` decides)
MODES = ("auto", HANDHELD, FOOT)


def _device_info(recording: Recording, device: str) -> dict:
    """What the recording declares of ``device`` ("" = primary: ``recording.device``, else
    ``metadata["devices"][device]``); {} if nothing."""
    if device:
        devs = recording.metadata.get("devices")
        info = devs.get(device) if isinstance(devs, dict) else None
    else:
        info = recording.device
    return info if isinstance(info, dict) else {}


def _declared_placement(recording: Recording, device: str) -> str:
    """The placement the recording declares for ``device`` ("" = primary), lower case, "" if none."""
    p = _device_info(recording, device).get("placement")
    return p.strip().lower() if isinstance(p, str) else ""


def recording_gyro_range(recording: Recording, device: str = "") -> tuple[float, str]:
    """``(range_rad_s, problem)``: the full scale of ``device``'s gyroscope ("" = primary) as the recording
    declares it (:func:`core.foot.saturation.declared_gyro_range`; nan: unknown or refused, and why)."""
    return declared_gyro_range(_device_info(recording, device))


def _foot_devices(recording: Recording) -> list[str]:
    """Other devices whose declared placement is a foot (for the hint when the primary is not)."""
    devs = recording.metadata.get("devices")
    if not isinstance(devs, dict):
        return []
    return [d for d in devs if isinstance(d, str) and "foot" in _declared_placement(recording, d)
            and has_imu(recording, d)]


def choose_mode(recording: Recording, mode: str = "auto", foot_device: str = "") -> tuple[str, str]:
    """``(mode, why)``: "handheld" or "foot" for ``recording``, and the reason in words.

    ``mode`` other than "auto" is the user's choice.  "auto": a declared placement of the IMU
    (``device["placement"]`` for the primary device, ``metadata["devices"][foot_device]["placement"]``
    for another) containing "foot" or "shoe" gives foot mode, any other declared placement hand-held;
    without one, :func:`core.foot.mounting.detect_mounting` decides from the signals.
    """
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}: one of {', '.join(MODES)}")
    if mode != "auto":
        return mode, "chosen by the user"
    dev = foot_device or ""
    if not has_imu(recording, dev):
        return HANDHELD, "no accelerometer and gyroscope pair" + (f" for device {dev!r}" if dev else "")
    placement = _declared_placement(recording, dev)
    if placement:
        foot = "foot" in placement or "shoe" in placement
        why = f"the recording says the IMU is on the {placement}"
        others = [] if foot or dev else _foot_devices(recording)
        if others:
            why += f"; foot IMUs on device(s) {', '.join(others)} (choose foot mode and the device to use one)"
        return (FOOT if foot else HANDHELD), why
    m = detect_mounting(recording, dev)
    why = (f"detected: window peak rate {m.peak_rate_rad_s:.1f} rad/s, foot-like strides in "
           f"{100 * m.stride_fraction:.0f} % of "
           f"walking ({100 * m.confidence:.0f} % sure)")
    return (FOOT if m.mode == FOOT else HANDHELD), why


def foot_settings_for(recording: Recording | None, *, aid: str | None = None, detector: str = "shoe",
                      waist_device: str | None = "waist", gyro_delay_s: float = 0.0,
                      foot_device: str = "") -> tuple[FootSettings, str | None]:
    """The product's foot settings for ``recording`` and the waist device to use (None: no waist IMU).

    ``aid`` None: "tckf" when the recording has the waist device's accelerometer and magnetometer,
    else "zupt" (a single foot IMU: its magnetometer near the floor is too disturbed to be the default,
    see the benchmark's IPOL table).  ``recording`` None (a live phone on the shoe): no waist device, and
    the stance detector's adaptive threshold causal (:class:`core.foot.stance.StanceSettings`).
    The gyroscope's full scale is the one the recording declares for ``foot_device`` (:func:`recording_gyro_range`;
    live: :meth:`FootTracker.use_device` when the sensors have started).
    """
    waist = waist_device or None
    if waist is not None and (recording is None or not (recording.has(stream_name(ACC, waist))
                                                        and recording.has(stream_name(MAG, waist)))):
        waist = None
    chosen = aid or ("tckf" if waist is not None else "zupt")
    # live (no recording): the adaptive threshold's causal moving minimum, decisions window_s / 2 late
    # instead of (window_s + adaptive_floor_window_s) / 2 (0.05 s against 0.65 s with the defaults)
    stance = StanceSettings(detector=detector, adaptive_floor_causal=recording is None)
    # a replay is smoothed (the navigator's default); live tracking is not (FootTracker turns it off too)
    gyro_range = recording_gyro_range(recording, foot_device)[0] if recording is not None else math.nan
    return (FootSettings(aid=chosen, stance=stance, gyro_delay_s=gyro_delay_s, rts_smoother=recording is not None,
                         gyro_range_rad_s=gyro_range), waist)


@dataclass(frozen=True)
class FootStep:
    """One stride of the foot track, with the fields the track, the exports and the calibration read."""

    index: int  #: 0-based stride number
    t_ns: int  #: end of the stance that ended the stride (sensor clock)
    length_m: float  #: horizontal distance from the previous stance (m)
    heading_rad: float  #: direction of that displacement (rad, CCW from East)
    east_m: float  #: position at the stance (m, ENU, from the alignment point)
    north_m: float
    up_m: float
    sigma_m: float  #: horizontal position sd at the stance (m; largest of the two)
    aid: str  #: the heading aid applied at this stance ("" none)


class FootTracker:
    """:class:`FootNavigator` with the streaming interface of the hand-held pipeline (see the module docstring).

    Parameters (keyword only)
    -------------------------
    settings : FootSettings, optional
    foot_device, waist_device :
        As for :class:`FootNavigator` (``waist_device=None``: no waist IMU).
    keep_samples : bool
        Keep the navigator's per-sample outputs (False for live tracking: per-stride data only).
    """

    mode = FOOT
    #: no GPS fusion with the foot INS (the session looks for this attribute)
    gnss = None

    def __init__(self, settings: FootSettings | None = None, *, foot_device: str = "",
                 waist_device: str | None = None, keep_samples: bool = False):
        # strides are shown as they come: no smoother (it would move them after the fact, and keep the walk)
        self.settings = replace(settings or FootSettings(), rts_smoother=False)
        self.foot_device = foot_device
        self.waist_device = waist_device
        self.keep_samples = bool(keep_samples)
        #: why the gyroscope's declared full scale was refused ("" when it was not; :meth:`use_device`)
        self.gyro_range_problem = ""
        self.reset()

    def reset(self) -> None:
        self.nav = FootNavigator(self.settings, foot_device=self.foot_device, waist_device=self.waist_device)
        self.steps: list[FootStep] = []
        self.distance_m = 0.0
        self.t_ns: int | None = None
        self._strides_seen = 0
        self._out_seen = 0
        self._nis_seen = 0
        self._sd_m = math.nan
        self._samples = 0
        self._stance_samples = 0
        self._nis_sum = 0.0
        self._nis_n = 0

    def use_device(self, device: dict) -> None:
        """The sensors' description (the session gives its source's ``device`` once they have started): the
        full scale of the gyroscope it declares (:func:`core.foot.saturation.declared_gyro_range`) becomes
        ``settings.gyro_range_rad_s``, so clipped readings are repaired.  Only for the primary device's IMU,
        when the settings have no range yet and before the first sample; a value that cannot be a full scale
        is ignored (nothing repaired) and said in :meth:`diagnostics` and :meth:`health_lines`."""
        if self.foot_device or math.isfinite(self.settings.gyro_range_rad_s) or self.t_ns is not None:
            return
        r, self.gyro_range_problem = declared_gyro_range(device)
        if math.isfinite(r):
            self.settings = replace(self.settings, gyro_range_rad_s=r)
            self.reset()

    def input_streams(self, recording: Recording) -> list[str]:
        """The streams of ``recording`` the tracker reads (a replay must deliver the other devices' too)."""
        return self.nav.input_names(recording)

    # -- streaming ---------------------------------------------------------------------------------
    def update(self, stream: str, t_ns: int, values) -> list[FootStep]:
        """One sensor event; returns the strides completed by it (usually none)."""
        self.t_ns = int(t_ns)
        self.nav.update(stream, t_ns, values)
        return self._collect()

    def finish(self) -> list[FootStep]:
        """End of the stream: the last samples are decided; returns the strides they completed."""
        self.nav.finish()
        return self._collect()

    def _collect(self) -> list[FootStep]:
        nav = self.nav
        st = nav.out_st[self._out_seen:]
        if st:
            sd = nav.out_sd[-1]
            if math.isfinite(sd):
                self._sd_m = sd
            self._samples += len(st)
            self._stance_samples += sum(st)
        nis = nav.zupt_nis[self._nis_seen:]
        if nis:
            self._nis_sum += math.fsum(nis)
            self._nis_n += len(nis)
        if self.keep_samples:
            self._out_seen, self._nis_seen = len(nav.out_st), len(nav.zupt_nis)
        else:  # per-sample outputs were handed out: not kept for hours
            for lst in (nav.out_t, nav.out_p, nav.out_v, nav.out_q, nav.out_st, nav.out_sd, nav.zupt_nis):
                lst.clear()
        new = []
        for s in nav.strides[self._strides_seen:]:
            if not math.isfinite(s.length_m):
                continue  # the alignment stance: the origin, not a stride
            p = s.position_n
            step = FootStep(len(self.steps), int(s.t_end_ns), float(s.length_m), float(s.course_rad),
                            float(p[0]), float(p[1]), float(p[2]), float(self._sd_m), s.aid)
            self.steps.append(step)
            self.distance_m += step.length_m
            new.append(step)
        self._strides_seen = len(nav.strides)
        return new

    # -- what the app shows -------------------------------------------------------------------------
    @property
    def aligned(self) -> bool:
        """The INS is aligned (the first still stance was seen)."""
        return bool(self.nav.ins.initialized)

    def heading_rad(self) -> float:
        """Heading of the foot's forward axis (rad, CCW from East); nan before the alignment."""
        nav = self.nav
        if not nav.ins.initialized or nav.foot_axis_b is None:
            return math.nan
        return float(nav.ins.heading_of(nav.foot_axis_b))

    def labels(self) -> tuple[str, ...]:
        """What the user should know now (like the hand-held pipeline's degraded-mode labels)."""
        out = ["foot-mounted INS"]
        if not self.aligned:
            out.append(f"stand still {self.settings.align_min_s:g} s to align")
        if self.nav.counters.get("skipped_nonfinite"):
            out.append(f"{self.nav.counters['skipped_nonfinite']} bad samples skipped")
        return tuple(out)

    def status(self):
        """A :class:`core.pdr.pipeline.Status` for the status strip (strides as steps; no adaptive variances)."""
        from core.pdr.pipeline import Status  # noqa: PLC0415 - the hand-held chain's display record

        last = self.steps[-1] if self.steps else None
        return Status(self.t_ns or 0, len(self.steps), self.distance_m, last.east_m if last else 0.0,
                      last.north_m if last else 0.0, self.heading_rad(), False, math.nan, math.nan, self.labels())

    def diagnostics(self) -> dict:
        """Running diagnostics as data: samples, stance fraction, mean ZUPT NIS, heading aid use, sd, counters."""
        nav = self.nav
        used = sum(1 for u in nav.heading_updates if u.used)
        return {
            "aid": self.settings.aid,
            "detector": self.settings.stance.detector,
            "aligned": self.aligned,
            "samples": self._samples,
            "stance_fraction": self._stance_samples / self._samples if self._samples else math.nan,
            "zupt_nis_mean": self._nis_sum / self._nis_n if self._nis_n else math.nan,
            "heading_updates_used": used,
            "heading_updates_total": len(nav.heading_updates),
            "position_sd_m": self._sd_m,
            "strides": len(self.steps),
            **nav.counters,
            "ins_rejected": nav.ins.n_rejected,
            "gyro_range_rad_s": self.settings.gyro_range_rad_s,
            "gyro_range_refused": int(bool(self.gyro_range_problem)),
            "gyro_clipped_runs_repaired": nav.clipped_runs_repaired,
        }

    def health_lines(self) -> list[str]:
        """Lines the health panel adds below the sensor table."""
        d = self.diagnostics()
        lines = [f"foot INS: ZUPT EKF, heading aid {d['aid']}, stance detector {d['detector']}"]
        r = d["gyro_range_rad_s"]
        lines.append(f"gyroscope full scale {r:.2f} rad/s: {d['gyro_clipped_runs_repaired']} clipped runs repaired"
                     if math.isfinite(r) else "gyroscope full scale unknown: clipped readings not repaired"
                     + (f" ({self.gyro_range_problem})" if self.gyro_range_problem else ""))
        if not d["aligned"]:
            lines.append(f"not aligned yet: stand still {self.settings.align_min_s:g} s")
            return lines
        frac = d["stance_fraction"]
        nis = d["zupt_nis_mean"]
        lines.append(f"stance {100 * frac:.0f} % of samples, mean ZUPT NIS "
                     + (f"{nis:.2f} (3 expected)" if math.isfinite(nis) else "-"))
        if d["aid"] != "zupt":
            lines.append(f"heading aid used at {d['heading_updates_used']} of {d['heading_updates_total']} stances "
                         f"({d['aid_gated']} gated, {d['aid_unavailable']} without a measurement)")
        sd = d["position_sd_m"]
        lines.append("position sd " + (f"{sd:.2f} m" if math.isfinite(sd) else "-"))
        return lines


__all__ = ["MODES", "FootStep", "FootTracker", "choose_mode", "foot_settings_for", "recording_gyro_range"]
