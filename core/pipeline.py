"""The PDR pipeline: all stages composed (Tian et al. 2014, Fig. 2).

Events go in one at a time, in time order, as the phone delivers them::

    gyro  -> AttitudeEKF.predict                        (eqs. 5-7, 11)
    acc   -> AttitudeEKF.update_acc                     (eqs. 12-17)
             GridResampler (uniform grid, default 50 Hz)
               -> StepDetector.update_grid              (eqs. 2-3)
               -> RotationSmoother.update(R of the EKF) (section 4.3)
               -> steps whose heading is due: stride model (eq. 4), DeadReckoner (eq. 1)
    mag   -> AttitudeEKF.update_mag                     (eq. 18)
    gps, rotvec, others -> kept for later stages, ignored by the core PDR

A step is detected at its acceleration peak but completed only
``heading_delay_s`` later, when the causal smoother has caught up with the
heading the walker had at the peak.  The live app therefore sees each step
about half a second after it happened; :meth:`Pipeline.status` gives the
current position at any time.

:meth:`Pipeline.update` (streaming, for the app) and :meth:`Pipeline.run`
(batch, for files) share this one kernel; a test proves they agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from core.attitude import AttitudeEKF
from core.conventions import ACC, GYRO, MAG
from core.deadreckoning import DeadReckoner
from core.dsp import GridResampler
from core.heading import RotationSmoother
from core.recording import Recording, RecordingError
from core.steps import StepDetector, StepEvent
from core.stride import StepFeatures, StrideModel, WeinbergStride

#: Step duration assumed for the first step of a walking bout (s).
DEFAULT_STEP_DURATION_S = 0.55


@dataclass(frozen=True)
class Step:
    """One completed step of the track."""

    index: int  #: 0-based step number
    t_ns: int  #: time of the step (acceleration peak), sensor clock
    length_m: float  #: step length (m)
    heading_rad: float  #: walking heading, counter-clockwise from East (rad)
    east_m: float  #: position after the step (m, ENU)
    north_m: float
    features: StepFeatures  #: what the stride model saw
    mag_trusted: bool  #: whether the last magnetometer reading before the step was used by the EKF


@dataclass(frozen=True)
class Status:
    """Snapshot of the pipeline for a live display."""

    t_ns: int
    n_steps: int
    distance_m: float
    east_m: float
    north_m: float
    heading_rad: float  #: current smoothed walking heading (rad, CCW from East); nan before the first sample
    mag_trusted: bool
    acc_sigma2: float  #: latest adaptive accelerometer variance (eq. 17)
    mag_sigma2: float  #: latest adaptive magnetometer variance (eq. 18)
    labels: tuple[str, ...]  #: degraded modes in force


@dataclass
class Track:
    """The walked track, one row per step (numpy arrays)."""

    t_ns: np.ndarray
    length_m: np.ndarray
    heading_rad: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)

    @classmethod
    def from_steps(cls, steps: list[Step]) -> "Track":
        return cls(
            np.array([s.t_ns for s in steps], dtype=np.int64),
            np.array([s.length_m for s in steps], dtype=float),
            np.array([s.heading_rad for s in steps], dtype=float),
            np.array([s.east_m for s in steps], dtype=float),
            np.array([s.north_m for s in steps], dtype=float),
        )


@dataclass
class AttitudeLog:
    """Attitude diagnostics on the pipeline's grid (batch runs)."""

    t_ns: np.ndarray
    q_wxyz: np.ndarray  #: (n, 4) EKF attitude, body -> ENU
    heading_rad: np.ndarray  #: smoothed walking heading
    acc_sigma2: np.ndarray
    mag_sigma2: np.ndarray
    mag_rejected: np.ndarray  #: bool: last magnetometer reading rejected


@dataclass
class PipelineResult:
    steps: list[Step]
    track: Track
    attitude: AttitudeLog
    labels: tuple[str, ...]
    recording: Recording
    #: counts of what the attitude filter used and rejected
    counters: dict = field(default_factory=dict)

    def summary(self) -> dict:
        rec = self.recording
        tr = self.track
        dist = float(np.sum(tr.length_m))
        fe = float(tr.east_m[-1]) if len(tr) else 0.0
        fn = float(tr.north_m[-1]) if len(tr) else 0.0
        return {
            "duration_s": rec.duration_s,
            "rates_hz": {n: s.rate_hz for n, s in rec.streams.items() if len(s)},
            "n_steps": len(tr),
            "distance_m": dist,
            "final_east_m": fe,
            "final_north_m": fn,
            "start_to_end_m": math.hypot(fe, fn),
            "labels": list(self.labels),
            **self.counters,
        }


class Pipeline:
    """Step detection, step length, adaptive EKF heading and dead reckoning, composed.

    Parameters
    ----------
    height_m : float or None
        The walker's height (m), passed to the stride model with every step.
    stride_model : core.stride.StrideModel or None
        Step length model; default :class:`core.stride.WeinbergStride` with a constant coefficient.
    step_detector, attitude, smoother : optional
        Pre-configured stages (:class:`StepDetector`, :class:`AttitudeEKF`,
        :class:`RotationSmoother`); defaults suit a hand-held phone.
    grid_rate_hz : float
        Uniform grid rate for the step detector and the heading smoother (Hz).
    heading_delay_s : float or None
        How long after its peak a step's heading is read (s); ``None``
        uses the smoother's group delay.
    use_magnetometer : bool
        False: heading from gyroscope and accelerometer only, relative to the start.
    log : bool
        Keep an :class:`AttitudeLog` (batch runs turn it on).
    """

    def __init__(self, *, height_m: float | None = None, stride_model: StrideModel | None = None,
                 step_detector: StepDetector | None = None, attitude: AttitudeEKF | None = None,
                 smoother: RotationSmoother | None = None, grid_rate_hz: float = 50.0,
                 heading_delay_s: float | None = None, use_magnetometer: bool = True, log: bool = False):
        self.height_m = height_m
        self.stride_model = stride_model or WeinbergStride()
        self.grid_rate_hz = float(grid_rate_hz)
        self.detector = step_detector or StepDetector(grid_rate_hz=grid_rate_hz)
        self.attitude = attitude or AttitudeEKF(use_magnetometer=use_magnetometer)
        if not use_magnetometer:
            self.attitude.use_magnetometer = False
        self.smoother = smoother or RotationSmoother(grid_rate_hz=grid_rate_hz)
        for stage in (self.detector, self.smoother):
            if abs(stage.grid_rate_hz - self.grid_rate_hz) > 1e-9:
                raise ValueError("step detector, smoother and pipeline must share one grid_rate_hz")
        self.heading_delay_s = self.smoother.delay_s if heading_delay_s is None else float(heading_delay_s)
        self.log = log
        self.reset()

    def reset(self) -> None:
        self.detector.reset()
        self.attitude.reset()
        self.smoother.reset()
        self.reckoner = DeadReckoner()
        self.grid = GridResampler(rate_hz=self.grid_rate_hz)
        self._pending: list[tuple[int, StepEvent]] = []
        self._delay_ns = int(self.heading_delay_s * 1e9)
        self.steps: list[Step] = []
        self.t_ns = 0
        self.seen: dict[str, int] = {}
        self._log: list[tuple] = []

    # -- streaming --------------------------------------------------------------
    def update(self, stream: str, t_ns: int, values) -> list[Step]:
        """Process one sensor event; returns the steps it completed (usually none)."""
        self.seen[stream] = self.seen.get(stream, 0) + 1
        self.t_ns = t_ns
        if stream == GYRO:
            self.attitude.predict(t_ns, values[0], values[1], values[2])
            return []
        if stream == MAG:
            self.attitude.update_mag(t_ns, values[0], values[1], values[2])
            return []
        if stream != ACC:
            return []  # gps, rotvec, ...: not used by the core PDR
        ax, ay, az = values[0], values[1], values[2]
        self.attitude.update_acc(t_ns, ax, ay, az)
        done: list[Step] = []
        norm = math.sqrt(ax * ax + ay * ay + az * az)  # eq. 2
        for tg, x in self.grid.update(t_ns, norm):
            if self.grid.restarted and self.detector.n_grid:
                self.detector.restart_bout()
            ev = self.detector.update_grid(tg, x)
            if ev is not None:
                self._pending.append((ev.t_ns + self._delay_ns, ev))
            if self.attitude.initialized:
                heading = self.smoother.update(self.attitude.matrix())
            else:
                heading = math.nan
            if self.log:
                a = self.attitude
                self._log.append((tg, a.q, heading, a.acc_sigma2, a.mag_sigma2, a.mag_rejected))
            while self._pending and self._pending[0][0] <= tg:
                done.append(self._complete(self._pending.pop(0)[1]))
        return done

    def finish(self) -> list[Step]:
        """End of data: complete the steps still waiting for their heading."""
        done = [self._complete(ev) for _, ev in self._pending]
        self._pending = []
        return done

    def _complete(self, ev: StepEvent) -> Step:
        duration = ev.duration_s if ev.duration_s == ev.duration_s else DEFAULT_STEP_DURATION_S
        feats = StepFeatures(t_ns=ev.t_ns, duration_s=duration, acc_max_m_s2=ev.acc_max_m_s2,
                             acc_min_m_s2=ev.acc_min_m_s2, acc_var_m2_s4=ev.acc_var_m2_s4, height_m=self.height_m)
        length = self.stride_model.length_m(feats)  # eq. 4
        heading = self.smoother.heading_rad
        if heading != heading:  # no attitude yet (no magnetometer reading so far)
            heading = self.attitude.initial_yaw_rad
        east, north = self.reckoner.update(length, heading)  # eq. 1
        step = Step(len(self.steps), ev.t_ns, length, heading, east, north, feats,
                    not self.attitude.mag_rejected and self.attitude.use_magnetometer)
        self.steps.append(step)
        return step

    def labels(self) -> tuple[str, ...]:
        out = []
        if not self.seen.get(GYRO) and self.seen.get(ACC):
            out.append("no gyroscope: heading from accelerometer and magnetometer only (noisy while walking)")
        if not self.attitude.use_magnetometer:
            out.append("magnetometer off: heading is relative to the start (first step points North)")
        elif not self.seen.get(MAG) and self.seen.get(ACC):
            out.append("no magnetometer: heading is relative to the start (first step points North)")
        return tuple(out)

    def status(self) -> Status:
        a = self.attitude
        return Status(self.t_ns, self.reckoner.n_steps, self.reckoner.distance_m, self.reckoner.east_m,
                      self.reckoner.north_m, self.smoother.heading_rad,
                      a.use_magnetometer and a.n_mag_used > 0 and not a.mag_rejected,
                      a.acc_sigma2, a.mag_sigma2, self.labels())

    # -- batch -----------------------------------------------------------------
    def run(self, recording: Recording, progress=None) -> PipelineResult:
        """Process a whole recording with the streaming kernel; returns track and diagnostics.

        ``progress``, if given, is called with the fraction done (0..1) every
        few thousand events.  Raises :class:`core.recording.MissingSensorError`
        without an accelerometer.
        """
        recording.stream(ACC, "step detection needs the accelerometer")
        log, self.log = self.log, True
        self.reset()
        use = [n for n in (GYRO, ACC, MAG) if recording.has(n)]
        try:
            total = sum(len(recording.streams[n]) for n in use)
            update = self.update
            for k, (name, t, vals) in enumerate(recording.events(use)):
                update(name, t, vals)
                if progress is not None and k % 5000 == 0:
                    progress(k / total)
            self.finish()
            if progress is not None:
                progress(1.0)
        finally:
            self.log = log
        rows = self._log
        a = self.attitude
        att = AttitudeLog(
            np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[1] for r in rows], dtype=float).reshape(-1, 4),
            np.array([r[2] for r in rows], dtype=float),
            np.array([r[3] for r in rows], dtype=float),
            np.array([r[4] for r in rows], dtype=float),
            np.array([r[5] for r in rows], dtype=bool),
        )
        counters = {"mag_used": a.n_mag_used, "mag_rejected": a.n_mag_rejected, "acc_rejected": a.n_acc_rejected}
        return PipelineResult(list(self.steps), Track.from_steps(self.steps), att, self.labels(), recording,
                              counters)


def run_recording(recording: Recording, **params) -> PipelineResult:
    """Convenience: ``Pipeline(**params).run(recording)``."""
    if not isinstance(recording, Recording):
        raise RecordingError("run_recording needs a core.recording.Recording")
    return Pipeline(**params).run(recording)
