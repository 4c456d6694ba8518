"""Per-user step-length calibration and the user profile.

The app's calibration screen asks the user to walk a known distance (say
20 m) and press stop.  :func:`calibrate_known_distance` takes the steps of
that walk and the distance, and returns a :class:`UserProfile` whose
``c_scale`` makes the stride model reproduce the distance:

    scale = sum(known distances) / sum(model distances, unscaled)

pooled over the user's last :data:`MAX_POOLED` calibration walks made with
the same model, so a second walk refines the first instead of replacing it.
For Weinberg models the scale multiplies ``C`` (eq. 4): it is the
per-user refinement of the coefficient.

The profile is a small JSON file at a path the caller chooses
(format ``pdr-user-profile`` version 1)::

    {"format": "pdr-user-profile", "format_version": 1,
     "height_m": 1.75, "model": "default", "c_scale": 1.043,
     "calibrations": [{"known_distance_m": 20.0, "model_distance_m": 19.18, "n_steps": 29,
                       "model_id": "...", "created": "2024-05-01T10:00:00+00:00"}]}

Silly inputs are refused with a :class:`CalibrationError` whose message tells
the user what to do (walk further, check the distance, ...).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

from core.pdr.stride import StepFeatures, StrideModel
from core.pdr.stride_models import lengths_of, load_stride_model, with_scale

FORMAT_NAME = "pdr-user-profile"
FORMAT_VERSION = 1

#: a calibration walk must be at least this long (m) ...
MIN_DISTANCE_M = 5.0
#: ... and have at least this many steps
MIN_STEPS = 8
#: the implied mean step length (known distance / steps) must lie in this range (m)
STEP_LENGTH_RANGE_M = (0.25, 1.3)
#: the correction factor is refused outside this range ...
SCALE_LIMITS = (0.5, 2.0)
#: ... and flagged (but accepted) outside this one
SCALE_WARN = (0.8, 1.25)
#: how many calibration walks are pooled
MAX_POOLED = 5
#: distances below this give a warning (a longer walk averages more steps)
RECOMMENDED_DISTANCE_M = 15.0


class CalibrationError(ValueError):
    """A calibration walk or profile that cannot be used; the message says why and what to do."""


@dataclass
class UserProfile:
    """What the app knows about its user for step length.

    Attributes
    ----------
    height_m : float or None
        Body height (m), given by the user; fed to the stride model with every step.
    c_scale : float
        Per-user factor on the model's step length (on ``C`` for Weinberg models); 1 = uncalibrated.
    model : str
        The stride model (shipped name or file path) the scale belongs to.
    calibrations : list of dict
        The calibration walks (known and model distance, steps, model id, time), newest last.
    gps : dict
        What walks with good GPS taught: ``stride_scale`` (on top of ``c_scale``), ``stride_gps_m``
        (metres of GPS behind it), ``heading_model`` (coefficients in degrees), ``updated``.
    """

    height_m: float | None = None
    c_scale: float = 1.0
    model: str = "default"
    calibrations: list[dict] = field(default_factory=list)
    #: what GPS taught (core.gnss.training.profile_with_gps_training): stride scale on top of the model and
    #: the heading error model (eq. 12 of Chen et al. 2010); empty until a walk with good GPS
    gps: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.height_m is not None:
            h = float(self.height_m)
            if not (0.9 <= h <= 2.4):
                raise CalibrationError(f"height {h} m is not a plausible body height (0.9-2.4 m); "
                                       "enter the height in metres, e.g. 1.75")
            self.height_m = h
        s = float(self.c_scale)
        if not (SCALE_LIMITS[0] <= s <= SCALE_LIMITS[1]):
            raise CalibrationError(f"c_scale {s} outside {SCALE_LIMITS}")
        self.c_scale = s

    @property
    def calibrated(self) -> bool:
        return bool(self.calibrations)

    def stride_model(self, base: StrideModel | None = None) -> StrideModel:
        """The stride model for this user: ``base`` (default: the profile's model) with ``c_scale`` applied."""
        base = base if base is not None else load_stride_model(self.model)
        return base if self.c_scale == 1.0 else with_scale(base, self.c_scale)

    # -- persistence ------------------------------------------------------------
    def to_dict(self) -> dict:
        d = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION}
        d.update(asdict(self))
        return d

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>") -> UserProfile:
        if not isinstance(d, dict) or d.get("format") != FORMAT_NAME:
            raise CalibrationError(f"{source}: not a {FORMAT_NAME} file")
        ver = d.get("format_version")
        if not isinstance(ver, int) or not 1 <= ver <= FORMAT_VERSION:
            raise CalibrationError(f"{source}: format_version {ver!r} not supported")
        try:
            return cls(height_m=d.get("height_m"), c_scale=float(d.get("c_scale", 1.0)),
                       model=str(d.get("model", "default")), calibrations=list(d.get("calibrations", [])),
                       gps=dict(d.get("gps") or {}))
        except (TypeError, ValueError) as e:
            raise CalibrationError(f"{source}: {e}") from None

    def save(self, path: str | Path) -> None:
        """Write the profile as JSON (atomically: a crash never leaves half a file)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=str(path.parent))
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                json.dump(self.to_dict(), fh, indent=1, allow_nan=False)
                fh.write("\n")
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    @classmethod
    def load(cls, path: str | Path) -> UserProfile:
        path = Path(path)
        try:
            d = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise CalibrationError(f"{path}: no profile file") from None
        except json.JSONDecodeError as e:
            raise CalibrationError(f"{path}: not JSON: {e}") from None
        return cls.from_dict(d, source=str(path))


@dataclass(frozen=True)
class CalibrationResult:
    """What a calibration walk gave."""

    profile: UserProfile  #: the updated profile (save it)
    scale: float  #: the new c_scale (pooled over the recent walks)
    walk_scale: float  #: the factor this walk alone asks for
    known_distance_m: float
    model_distance_m: float  #: the walk's length by the unscaled model
    n_steps: int
    mean_step_length_m: float  #: known distance / steps
    warnings: tuple[str, ...] = ()


def _features(steps_or_features) -> list[StepFeatures]:
    out = []
    for s in steps_or_features:
        f = s if isinstance(s, StepFeatures) else getattr(s, "features", None)
        if not isinstance(f, StepFeatures):
            raise CalibrationError(f"expected pipeline steps or StepFeatures, got {type(s).__name__}")
        out.append(f)
    return out


def calibrate_known_distance(steps_or_features: Iterable, known_distance_m: float,
                             model: StrideModel | str | None = None, *,
                             profile: UserProfile | None = None, now: datetime | None = None) -> CalibrationResult:
    """Refine the user's step-length factor from one walk of known length.

    Parameters
    ----------
    steps_or_features : iterable of core.pdr.pipeline.Step or core.pdr.stride.StepFeatures
        The steps of the calibration walk (from pressing start to pressing stop).
    known_distance_m : float
        The distance actually walked (m).
    model : StrideModel, model name/path, or None
        The *unscaled* model the scale belongs to; default: the profile's model.
    profile : UserProfile or None
        The user's current profile (height, earlier calibrations); a new one if None.
        Steps without a height get the profile's height.

    Returns
    -------
    CalibrationResult
        ``result.profile`` is a new profile (the input is not modified); save it.

    Raises
    ------
    CalibrationError
        Distance not a positive number or too short, too few steps, an implied
        step length no walker has, or a correction the model cannot be that
        wrong by.  The message says what to do.
    """
    profile = profile if profile is not None else UserProfile()
    try:
        d = float(known_distance_m)
    except (TypeError, ValueError):
        raise CalibrationError(f"known distance must be a number of metres, got {known_distance_m!r}") from None
    if not math.isfinite(d) or d <= 0:
        raise CalibrationError(f"known distance must be a positive number of metres, got {known_distance_m!r}")
    if d < MIN_DISTANCE_M:
        raise CalibrationError(f"{d:g} m is too short to calibrate: walk at least {RECOMMENDED_DISTANCE_M:g} m")
    feats = _features(steps_or_features)
    n = len(feats)
    if n < MIN_STEPS:
        raise CalibrationError(f"only {n} steps were detected over {d:g} m: need at least {MIN_STEPS}. "
                               "Hold the phone as when navigating and walk the whole distance")
    mean_len = d / n
    lo, hi = STEP_LENGTH_RANGE_M
    if not lo <= mean_len <= hi:
        raise CalibrationError(
            f"{d:g} m in {n} steps is {mean_len:.2f} m per step, outside {lo}-{hi} m: check the distance "
            "entered (metres?) and that the walk was recorded from start to stop")
    if profile.height_m is not None:
        feats = [f if f.height_m is not None else replace(f, height_m=profile.height_m) for f in feats]
    if model is None:
        model = profile.model
    model_name = model if isinstance(model, str) else profile.model
    base = load_stride_model(model) if isinstance(model, str) else model
    model_d = float(lengths_of(base, feats).sum())
    if not (model_d > 0 and math.isfinite(model_d)):
        raise CalibrationError("the stride model gave no distance for this walk")
    walk_scale = d / model_d
    if not SCALE_LIMITS[0] <= walk_scale <= SCALE_LIMITS[1]:
        raise CalibrationError(
            f"the walk asks for a factor {walk_scale:.2f} on the step length (model: {model_d:.1f} m, "
            f"entered: {d:g} m); that is more than a model error: check the distance entered and "
            "that the phone was carried as usual")
    warnings = []
    if d < RECOMMENDED_DISTANCE_M:
        warnings.append(f"short walk ({d:g} m): a walk of {RECOMMENDED_DISTANCE_M:g} m or more gives a steadier factor")
    if not SCALE_WARN[0] <= walk_scale <= SCALE_WARN[1]:
        warnings.append(f"unusual factor {walk_scale:.2f}: the model's step length was "
                        f"{abs(walk_scale - 1) * 100:.0f} % off for this walk")
    model_id = getattr(base, "model_id", type(base).__name__)
    now = now or datetime.now(timezone.utc)
    entry = {"known_distance_m": d, "model_distance_m": model_d, "n_steps": n, "model_id": model_id,
             "created": now.isoformat(timespec="seconds")}
    history = [c for c in profile.calibrations if c.get("model_id") == model_id]
    if len(history) < len(profile.calibrations):
        warnings.append("earlier calibrations were made with another model version and are not pooled")
    pooled = (history + [entry])[-MAX_POOLED:]
    scale = sum(c["known_distance_m"] for c in pooled) / sum(c["model_distance_m"] for c in pooled)
    new = UserProfile(height_m=profile.height_m, c_scale=scale, model=model_name,
                      calibrations=(profile.calibrations + [entry])[-4 * MAX_POOLED:])
    return CalibrationResult(new, scale, walk_scale, d, model_d, n, mean_len, tuple(warnings))
