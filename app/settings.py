"""User settings that persist between runs, and the stride calibration rule.

Stored as JSON (``settings.json`` in the app's user data directory), written
atomically (temporary file + rename) so a crash never leaves half a file.
Loading never fails: a missing file gives the defaults, a damaged file or an
out-of-range value falls back to the default and says so in
:attr:`Settings.problems`, which the app shows.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass, field, fields

from core.stride import ConstantCoefficient, WeinbergStride

SETTINGS_FILE = "settings.json"

#: Weinberg coefficient used before any calibration (core's default).
DEFAULT_STRIDE_C = ConstantCoefficient().c

#: Valid ranges: name -> (low, high)
RANGES = {
    "height_m": (1.0, 2.5),
    "stride_c": (0.1, 1.5),
    "rate_hz": (10.0, 200.0),
}

#: Sampling rates offered in the UI (Hz); 200 is the most without HIGH_SAMPLING_RATE_SENSORS.
RATE_CHOICES = (50, 100, 200)


class CalibrationError(ValueError):
    """A calibration walk that cannot give a sensible coefficient."""


@dataclass
class Settings:
    """What the user sets; see the module docstring for persistence."""

    #: the walker's body height (m); None = not given
    height_m: float | None = None
    #: Weinberg step-length coefficient C (eq. 4), from stride calibration
    stride_c: float = DEFAULT_STRIDE_C
    #: sensor sampling rate requested from Android (Hz)
    rate_hz: float = 100.0
    #: record every live session to a file
    record_live: bool = True
    #: replay speed label ("1x", "10x", "max")
    replay_speed: str = "10x"
    #: past calibrations, newest last: dicts with time, known_m, pdr_m, c_old, c_new
    calibrations: list = field(default_factory=list)
    #: what was wrong with the stored file (not saved)
    problems: list = field(default_factory=list, compare=False, repr=False)

    # -- pipeline parameters --------------------------------------------------

    def stride_model(self) -> WeinbergStride:
        return WeinbergStride(coefficient=self.stride_c)

    def pipeline_kwargs(self) -> dict:
        """Keyword arguments for :class:`core.pipeline.Pipeline`."""
        return {"height_m": self.height_m, "stride_model": self.stride_model()}

    # -- validation and persistence -----------------------------------------

    def validate(self) -> list[str]:
        """Reset invalid values to their defaults; returns what was reset."""
        out = []
        defaults = Settings()
        for name, (lo, hi) in RANGES.items():
            v = getattr(self, name)
            if v is None and name == "height_m":
                continue
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi
            if not ok:
                out.append(f"{name}={v!r} outside {lo:g}..{hi:g}; using {getattr(defaults, name)!r}")
                setattr(self, name, getattr(defaults, name))
            else:
                setattr(self, name, float(v))
        if not isinstance(self.record_live, bool):
            out.append(f"record_live={self.record_live!r} is not true/false; using True")
            self.record_live = True
        if self.replay_speed not in ("1x", "10x", "max"):
            out.append(f"replay_speed={self.replay_speed!r} unknown; using '10x'")
            self.replay_speed = "10x"
        if not isinstance(self.calibrations, list):
            self.calibrations = []
        return out

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("problems")
        return d

    @classmethod
    def load(cls, path: str) -> "Settings":
        s = cls()
        if not os.path.exists(path):
            return s
        try:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as e:
            s.problems.append(f"{path}: could not read settings ({e}); using defaults")
            return s
        names = {f.name for f in fields(cls)} - {"problems"}
        for k, v in data.items():
            if k in names:
                setattr(s, k, v)
        s.problems.extend(s.validate())
        return s

    def save(self, path: str) -> None:
        self.validate()
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

    # -- calibration ---------------------------------------------------------

    def apply_calibration(self, known_distance_m: float, pdr_distance_m: float) -> float:
        """Set :attr:`stride_c` from a calibration walk (see :func:`calibrate_coefficient`); returns it."""
        c_new = calibrate_coefficient(self.stride_c, known_distance_m, pdr_distance_m)
        self.calibrations.append({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "known_m": float(known_distance_m),
                                  "pdr_m": float(pdr_distance_m), "c_old": self.stride_c, "c_new": c_new})
        self.stride_c = c_new
        return c_new


def calibrate_coefficient(c_old: float, known_distance_m: float, pdr_distance_m: float, *,
                          min_distance_m: float = 5.0, max_ratio: float = 2.0) -> float:
    """New Weinberg coefficient after walking a known distance.

    Step length is proportional to ``C`` (eq. 4), so the distance the
    pipeline measured with ``c_old`` scales to the known one with
    ``C_new = C_old * known_distance / pdr_distance``.  (Per-user models from
    ``core.calibration`` can replace this rule later; callers only see this
    function.)

    Raises :class:`CalibrationError` for a walk shorter than
    ``min_distance_m``, a PDR distance of zero (no steps detected), or a
    correction by more than ``max_ratio`` either way (a typo in the distance,
    or the wrong walk).
    """
    for name, v in (("known distance", known_distance_m), ("measured distance", pdr_distance_m),
                    ("current coefficient", c_old)):
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise CalibrationError(f"{name} must be a number, got {v!r}")
    if c_old <= 0:
        raise CalibrationError(f"current coefficient must be positive, got {c_old}")
    if known_distance_m < min_distance_m:
        raise CalibrationError(f"walk at least {min_distance_m:g} m for a calibration "
                               f"(entered {known_distance_m:g} m)")
    if pdr_distance_m <= 0:
        raise CalibrationError("no steps were detected during the calibration walk")
    ratio = known_distance_m / pdr_distance_m
    if not 1.0 / max_ratio <= ratio <= max_ratio:
        raise CalibrationError(f"known distance {known_distance_m:g} m and measured {pdr_distance_m:.1f} m differ "
                               f"by more than a factor {max_ratio:g}; check the distance and walk again")
    lo, hi = RANGES["stride_c"]
    c_new = c_old * ratio
    if not lo <= c_new <= hi:
        raise CalibrationError(f"the new coefficient {c_new:.3f} is outside {lo:g}..{hi:g}")
    return c_new
