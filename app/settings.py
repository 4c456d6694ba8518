"""User settings that persist between runs, and the user's stride profile.

Two JSON files in the app's data directory, both written atomically
(temporary file + rename), so a crash never leaves half a file:

- ``settings.json``: sampling rate, whether live sessions are recorded,
  replay speed, whether GPS is fused into the track ("Use GPS"), the
  tracking mode (hand-held PDR or foot-mounted INS, or auto) and the floor
  plan (a path: our GeoJSON file or a Microsoft floor folder, "" for none;
  :mod:`app.indoor`);
- ``profile.json``: the user's :class:`core.pdr.calibration.UserProfile`
  (format ``pdr-user-profile``): body height, stride model, the per-user
  factor ``c_scale`` and the calibration walks it was pooled from.

The height lives only in the profile (:attr:`Settings.height_m` reads and
writes it), so the settings and the profile cannot disagree.  The pipeline
is built from the profile: ``profile.stride_model()`` (the chosen shipped
model with the user's factor) and the profile's height; with "Use GPS" on
(the default) it also runs the GPS fusion stage,
``Pipeline(..., gnss=core.gnss.fusion.GpsFusion())``
(:meth:`Settings.pipeline_factory`).

Loading never fails: a missing file gives the defaults, a damaged file or an
out-of-range value falls back to the default and says so in
:attr:`Settings.problems`, which the app shows.

Migration: app versions before the profile stored ``height_m``,
``stride_c`` (a Weinberg C from the app's own calibration rule) and
``calibrations`` in ``settings.json``.  When there is no ``profile.json``
yet, the height moves to the profile and ``stride_c`` becomes
``c_scale = stride_c / C`` of the default model; the old calibration list
is not converted (its walks were measured by an older pipeline).  What was
done is in :attr:`Settings.notes`.  The next save writes ``profile.json``
and drops the old keys.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field, replace
from typing import Callable

from core.pdr.calibration import MAX_POOLED, CalibrationError, CalibrationResult, UserProfile, calibrate_known_distance
from core.pdr.stride import StrideModel
from core.pdr.stride_models import StrideModelError, load_stride_model

SETTINGS_FILE = "settings.json"
PROFILE_FILE = "profile.json"

#: Valid ranges: name -> (low, high)
RANGES = {
    "rate_hz": (10.0, 200.0),
}

#: Sampling rates offered in the UI (Hz); 200 is the most without HIGH_SAMPLING_RATE_SENSORS.
RATE_CHOICES = (50, 100, 200)

#: Shipped stride models offered in the UI (``core/pdr/models``)
STRIDE_MODEL_CHOICES = ("default", "weinberg_bp", "chen_linear", "chen_ann")


def profile_path(settings_path: str) -> str:
    """The profile file next to ``settings_path``."""
    return os.path.join(os.path.dirname(os.path.abspath(settings_path)), PROFILE_FILE)


#: the app's choices of GPS filter (core.gnss.FUSIONS, or auto)
GPS_FUSIONS = ("auto", "chen", "kubrak")

#: tracking modes (core.foot.tracker.MODES): auto, hand-held PDR, foot-mounted INS
TRACKING_MODES = ("auto", "handheld", "foot")

#: a phone on the shoe samples at least this fast (Hz): the stance detector and the INS need >= 100 Hz
FOOT_MIN_RATE_HZ = 200.0


@dataclass
class Settings:
    """What the user sets; see the module docstring for persistence."""

    #: sensor sampling rate requested from Android (Hz)
    rate_hz: float = 100.0
    #: record every live session to a file
    record_live: bool = True
    #: replay speed label ("1x", "10x", "max")
    replay_speed: str = "10x"
    #: fuse GPS fixes into the track (core.gnss.make_fusion after the steps)
    use_gps: bool = True
    #: which GPS fusion filter: "auto" (core.gnss.AUTO_FUSION, the benchmark's better one), "chen", "kubrak"
    gps_fusion: str = "auto"
    #: "handheld" (PDR), "foot" (phone or IMU on the shoe: ZUPT INS) or "auto" (a replay: what the recording
    #: declares or its signals show, :func:`core.foot.tracker.choose_mode`; live: hand-held)
    tracking_mode: str = "auto"
    #: the floor plan under the track (app.indoor.load_plan: our GeoJSON file or a Microsoft floor folder),
    #: "" for none; read by the UI (walls) and by the tracking service (the particle filter)
    floor_plan: str = ""
    #: height, stride model and calibration (saved to its own file, ``profile.json``)
    profile: UserProfile = field(default_factory=UserProfile)
    #: what was wrong with the stored files (not saved)
    problems: list = field(default_factory=list, compare=False, repr=False)
    #: what loading did besides reading, e.g. a migration (not saved)
    notes: list = field(default_factory=list, compare=False, repr=False)

    # -- the profile --------------------------------------------------------------

    @property
    def height_m(self) -> float | None:
        """The walker's body height (m), None = not given; stored in the profile."""
        return self.profile.height_m

    @height_m.setter
    def height_m(self, height_m: float | None) -> None:
        self.profile = replace(self.profile, height_m=height_m)  # CalibrationError if implausible

    @property
    def stride_model_name(self) -> str:
        return self.profile.model

    def set_stride_model(self, name: str) -> None:
        """Use another stride model.

        The user's factor belongs to a model, so it is recomputed from the
        calibration walks made with ``name`` (pooled as
        :func:`core.pdr.calibration.calibrate_known_distance` pools them), or 1
        if there are none.  Raises ``StrideModelError`` for an unknown model.
        """
        if name == self.profile.model:
            return
        walks = self.calibration_walks(name)
        scale = (sum(c["known_distance_m"] for c in walks) / sum(c["model_distance_m"] for c in walks)
                 if walks else 1.0)
        self.profile = replace(self.profile, model=name, c_scale=scale)

    def calibration_walks(self, model_name: str | None = None) -> list[dict]:
        """The calibration walks the factor of ``model_name`` (default: the profile's model) is pooled from."""
        model_id = getattr(load_stride_model(model_name or self.profile.model), "model_id", None)
        return [c for c in self.profile.calibrations if c.get("model_id") == model_id][-MAX_POOLED:]

    def stride_model(self) -> StrideModel:
        """The profile's model with the user's factor."""
        return self.profile.stride_model()

    def pipeline_kwargs(self) -> dict:
        """Keyword arguments for :class:`core.pdr.pipeline.Pipeline` (without the GPS stage)."""
        return {"height_m": self.height_m, "stride_model": self.stride_model()}

    def choose_tracking_mode(self, recording=None) -> tuple[str, str]:
        """``(mode, why)``: "handheld" or "foot" for a replay of ``recording``, or for live tracking (None).

        Live with "auto" is hand-held: nothing is known of the walk before it starts, and a phone on the
        shoe is a choice the user makes in Settings.
        """
        if recording is None:
            if self.tracking_mode == "auto":
                return "handheld", "live tracking is hand-held unless Foot is chosen in Settings"
            return self.tracking_mode, "chosen in Settings"
        from core.foot.tracker import choose_mode  # noqa: PLC0415 - core's stages on use

        mode, why = choose_mode(recording, self.tracking_mode)
        return mode, ("chosen in Settings" if self.tracking_mode != "auto" else why)

    def live_rate_hz(self) -> float:
        """The sampling rate to ask the sensors for: the setting, at least :data:`FOOT_MIN_RATE_HZ` on the shoe."""
        if self.choose_tracking_mode(None)[0] == "foot":
            return max(self.rate_hz, FOOT_MIN_RATE_HZ)
        return self.rate_hz

    def pipeline_factory(self, recording=None) -> Callable:
        """``() -> Pipeline`` with the settings as they are now (a later change needs a new factory).

        ``recording``: the recording to be replayed (None: live), for the tracking mode
        (:meth:`choose_tracking_mode`).  Foot mode gives a :class:`core.foot.tracker.FootTracker` (the
        foot INS behind the same streaming interface; the TCKF with a waist magnetometer, else ZUPT only;
        no GPS fusion).  Hand-held mode gives the PDR pipeline, with its own fusion stage
        (:func:`core.gnss.make_fusion`, the filter of :attr:`gps_fusion`) when :attr:`use_gps` is on, so a
        new track starts the fusion afresh (unanchored), but from what earlier walks with GPS taught:
        Chen's filter starts from the profile's GPS stride scale and heading model (:meth:`learn_from_gps`
        keeps them).
        """
        if self.choose_tracking_mode(recording)[0] == "foot":
            from core.foot.tracker import FootTracker, foot_settings_for  # noqa: PLC0415

            fs, waist = foot_settings_for(recording)
            return lambda: FootTracker(fs, waist_device=waist)
        from core.gnss import make_fusion, settings_from_profile  # noqa: PLC0415 - core's stages on use
        from core.pdr.pipeline import Pipeline  # noqa: PLC0415

        kw = self.pipeline_kwargs()
        use_gps = bool(self.use_gps)
        name = self.gps_fusion_name()
        gkw = settings_from_profile(name, self.profile)
        # the session keeps the steps (on disk: core.export.StepFile); the pipeline keeps none, the GPS fusion
        # writes its fused steps and fix records to disk too (keep_history=False; issue #30)
        return lambda: Pipeline(**kw, keep_steps=False,
                                gnss=make_fusion(name, keep_history=False, **gkw) if use_gps else None)

    def gps_fusion_name(self) -> str:
        """The filter :attr:`gps_fusion` stands for ("auto": the benchmark's better one)."""
        from core.gnss import AUTO_FUSION  # noqa: PLC0415

        return AUTO_FUSION if self.gps_fusion == "auto" else self.gps_fusion

    def load_floor_plan(self):
        """``(plan, name, problem)``: the chosen floor plan (None, "", "" without one; None, "", why when it
        cannot be read: the app goes on without it and says so)."""
        if not self.floor_plan:
            return None, "", ""
        from app.indoor import load_plan, plan_label  # noqa: PLC0415

        try:
            plan = load_plan(self.floor_plan)
        except (ValueError, OSError) as e:
            return None, "", f"floor plan not used: {e}"
        return plan, plan_label(plan, self.floor_plan), ""

    def learn_from_gps(self, pipeline) -> bool:
        """Keep in the profile what a live walk's GPS taught (Chen: stride scale, heading model; Kubrak: the
        velocity model's coefficients); True if anything."""
        from core.gnss import profile_after  # noqa: PLC0415

        gnss = getattr(pipeline, "gnss", None)
        if gnss is None:
            return False
        new = profile_after(self.profile, gnss)
        changed = new is not self.profile
        self.profile = new
        return changed

    def calibrate(self, steps, known_distance_m) -> CalibrationResult:
        """Refine the profile from the steps of a walk of known length (:func:`calibrate_known_distance`).

        Raises :class:`core.pdr.calibration.CalibrationError` with a message for
        the user; the profile is unchanged then.
        """
        result = calibrate_known_distance(steps, known_distance_m, profile=self.profile)
        self.profile = result.profile
        return result

    # -- validation and persistence -----------------------------------------

    def validate(self) -> list[str]:
        """Reset invalid values to their defaults; returns what was reset."""
        out = []
        defaults = Settings()
        for name, (lo, hi) in RANGES.items():
            v = getattr(self, name)
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi
            if not ok:
                out.append(f"{name}={v!r} outside {lo:g}..{hi:g}; using {getattr(defaults, name)!r}")
                setattr(self, name, getattr(defaults, name))
            else:
                setattr(self, name, float(v))
        for name in ("record_live", "use_gps"):
            if not isinstance(getattr(self, name), bool):
                out.append(f"{name}={getattr(self, name)!r} is not true/false; using True")
                setattr(self, name, True)
        if self.gps_fusion not in GPS_FUSIONS:
            out.append(f"gps_fusion={self.gps_fusion!r} unknown; using 'auto'")
            self.gps_fusion = "auto"
        if self.tracking_mode not in TRACKING_MODES:
            out.append(f"tracking_mode={self.tracking_mode!r} unknown; using 'auto'")
            self.tracking_mode = "auto"
        if not isinstance(self.floor_plan, str):
            out.append(f"floor_plan={self.floor_plan!r} is not a path; using none")
            self.floor_plan = ""
        if self.replay_speed not in ("1x", "10x", "max"):
            out.append(f"replay_speed={self.replay_speed!r} unknown; using '10x'")
            self.replay_speed = "10x"
        return out

    def to_dict(self) -> dict:
        """What goes into ``settings.json`` (the profile has its own file)."""
        return {"rate_hz": self.rate_hz, "record_live": self.record_live, "replay_speed": self.replay_speed,
                "use_gps": self.use_gps, "gps_fusion": self.gps_fusion, "tracking_mode": self.tracking_mode,
                **({"floor_plan": self.floor_plan} if self.floor_plan else {})}  # no key: no plan

    @classmethod
    def load(cls, path: str) -> "Settings":
        """Settings from ``path`` and the profile next to it (see the module docstring)."""
        s = cls()
        data: dict = {}
        if os.path.exists(path):
            try:
                with open(path, encoding="utf-8") as f:
                    data = json.load(f)
                if not isinstance(data, dict):
                    raise ValueError("not a JSON object")
            except (OSError, ValueError) as e:
                s.problems.append(f"{path}: could not read settings ({e}); using defaults")
                data = {}
        for k in [*s.to_dict(), "floor_plan"]:
            if k in data:
                setattr(s, k, data[k])
        s.problems.extend(s.validate())
        ppath = profile_path(path)
        if os.path.exists(ppath):
            try:
                s.profile = UserProfile.load(ppath)
            except CalibrationError as e:
                s.problems.append(f"{e}; using an uncalibrated profile")
        else:
            s._migrate(data)
        try:
            load_stride_model(s.profile.model)
        except StrideModelError as e:
            s.problems.append(f"{e}; using the default stride model, uncalibrated")
            s.profile = replace(s.profile, model="default", c_scale=1.0)
        return s

    def _migrate(self, data: dict) -> None:
        """Height and coefficient of a ``settings.json`` written before the profile existed."""
        h = data.get("height_m")
        if h is not None:
            try:
                self.height_m = float(h)
            except (TypeError, ValueError) as e:
                self.problems.append(f"old setting height_m={h!r} ignored: {e}")
        c_old = data.get("stride_c")
        if c_old is None:
            return
        c_default = getattr(getattr(load_stride_model("default"), "coefficient", None), "c", None)
        try:
            scale = float(c_old) / float(c_default)
            self.profile = replace(self.profile, c_scale=scale)  # CalibrationError if out of range
        except (TypeError, ValueError) as e:  # incl. CalibrationError, and a default model without a constant C
            self.notes.append(f"step coefficient C={c_old!r} of an older app version ignored ({e}); "
                              "please calibrate again")
            return
        if math.isclose(scale, 1.0, rel_tol=2e-3):  # the old default C: never calibrated
            self.profile = replace(self.profile, c_scale=1.0)
        else:
            self.notes.append(f"step coefficient C={float(c_old):.3f} of an older app version converted to a "
                              f"factor {scale:.3f} on the default model; a new calibration walk replaces it")

    def save(self, path: str) -> None:
        """Write the profile (next to ``path``), then the settings."""
        self.validate()
        self.profile.save(profile_path(path))
        d = os.path.dirname(os.path.abspath(path))
        os.makedirs(d, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".settings-", suffix=".json", dir=d)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(self.to_dict(), f, indent=1, sort_keys=True)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
