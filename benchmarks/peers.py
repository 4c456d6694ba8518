"""Heading peers: other attitude estimators run on the same recording, dead-reckoned with OUR steps.

Every peer produces an attitude time series ``q`` (w, x, y, z, body -> ENU,
the :mod:`core` convention).  Its per-step heading is then made exactly as the
pipeline makes ours, so that **only the attitude differs**:

1. sample the peer's rotation matrix ``R(q)`` on the pipeline's uniform grid
   (latest peer sample at or before each grid time);
2. smooth it with the pipeline's own :class:`core.pdr.heading.RotationSmoother`
   (same cut-off, same forward axis);
3. read the smoothed heading at ``t_step + heading_delay_s``, the instant at
   which the pipeline reads ours;
4. dead-reckon with our step lengths (:func:`benchmarks.metrics.dead_reckon`).

Peers (all optional; a missing package or stream just drops that peer).
Same treatment as ours (issue #8): every peer runs on its documented
settings, none is tuned on any split, and none is given anything a live
filter could not know -- a peer sees the recording causally (sample by
sample) plus, at most, what a phone knows before the walk from a coarse
location fix and its clock (the site's World Magnetic Model, through
:mod:`core.geodesy`), exactly as our pipeline gets the site's declination.

``rotvec``
    The phone's own attitude: the Android rotation vector logged in the file
    (``rotvec`` stream: GetSensorData ``AHRS`` lines, ``TYPE_ROTATION_VECTOR``).
``imufusion``
    x-io Technologies' Fusion AHRS (``pip install imufusion``): gain 0.5,
    gyroscope range 2000 deg/s, acceleration and magnetic rejection 10 deg,
    5 s rejection timeout -- the settings of the Fusion README's example
    (its recommended use; the bare constructor defaults switch rejection
    off), with its gyroscope bias estimator on its defaults.  Not tuned by
    us.  The ENU convention is set through the settings attribute: imufusion
    1.3.3's ``AhrsSettings(convention=...)`` keyword is parsed but not applied.
``madgwick``
    ``ahrs.filters.Madgwick`` (``pip install ahrs``), MARG update with its
    default gain.  It estimates body -> North-West-Up; we rotate its output to ENU.
``ekf``
    ``ahrs.filters.EKF`` in its ENU frame, fixed noises (its defaults).  Its
    magnetic reference is the one thing its documentation asks the user for
    (its default is the World Magnetic Model at Munich): it gets the **WMM
    dip angle at the recording's site and date** (``magnetic_dip_rad``), what
    a live filter with a location fix knows before the first sample.  Until
    issue #8 it was given the median dip of the whole recording, which no
    live filter can know; without a site it keeps its own default.  Its
    ENU model references gravity as ``(0, 0, -1)``, so it is given the
    negated accelerometer (checked on a simulated tilted, turning phone in
    ``tests/test_peers.py``; fed the raw specific force it settles upside down).

The gyro-based peers run on the gyroscope timestamps with ``dt`` from them;
accelerometer and magnetometer are interpolated linearly to those instants.
They start from the same TRIAD attitude (first accelerometer and magnetometer
readings) except imufusion, which runs its own start-up.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core import quaternion as quat
from core.conventions import ACC, GYRO, MAG, ROTVEC
from core.pdr.heading import RotationSmoother
from core.recording import Recording

ALL_PEERS = ("rotvec", "imufusion", "madgwick", "ekf")
#: peers cheap enough for the quick run
QUICK_PEERS = ("rotvec", "imufusion")

STANDARD_GRAVITY = 9.80665
#: rotation taking North-West-Up coordinates to East-North-Up (90 deg about Up)
_Q_NWU_TO_ENU = quat.from_axis_angle((0.0, 0.0, 1.0), math.pi / 2)


@dataclass
class Attitude:
    """An attitude time series: ``t_ns`` (n,) and ``q_wxyz`` (n, 4) body -> ENU."""

    t_ns: np.ndarray
    q_wxyz: np.ndarray


def available_peers(names=ALL_PEERS) -> list[str]:
    """The peers whose packages are importable."""
    out = []
    for name in names:
        try:
            if name == "imufusion":
                import imufusion  # noqa: F401
            elif name in ("madgwick", "ekf"):
                import ahrs  # noqa: F401
        except ImportError:
            continue
        out.append(name)
    return out


# ---------------------------------------------------------------------------
# inputs


def synced_imu(rec: Recording, with_mag: bool = True):
    """Gyro timestamps and acc / mag linearly interpolated to them: ``t_ns, gyr, acc, mag``."""
    g = rec.stream(GYRO, "gyro-based peers")
    a = rec.stream(ACC, "gyro-based peers")
    t = g.t_ns
    lo = max(int(a.t_ns[0]), int(t[0]))
    hi = min(int(a.t_ns[-1]), int(t[-1]))
    m = None
    if with_mag and rec.has(MAG):
        s = rec.streams[MAG]
        lo, hi = max(lo, int(s.t_ns[0])), min(hi, int(s.t_ns[-1]))
    keep = (t >= lo) & (t <= hi)
    t = t[keep]
    gyr = g.values[keep]
    x = (t - t[0]).astype(float)

    def interp(stream):
        xs = (stream.t_ns - t[0]).astype(float)
        return np.column_stack([np.interp(x, xs, stream.values[:, k]) for k in range(3)])

    acc = interp(a)
    if with_mag and rec.has(MAG):
        m = interp(rec.streams[MAG])
    return t, gyr, acc, m


def dip_angle_rad(acc: np.ndarray, mag: np.ndarray) -> float:
    """Median magnetic dip (rad, positive down) from paired specific force and field readings.

    A diagnostic: over a whole recording it is hindsight, so no peer is given it.
    """
    an = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    mn = mag / np.linalg.norm(mag, axis=1, keepdims=True)
    return float(np.median(np.arcsin(np.clip(-np.sum(an * mn, axis=1), -1.0, 1.0))))


def _dts(t_ns: np.ndarray) -> np.ndarray:
    dt = np.diff(t_ns, prepend=t_ns[0]).astype(float) * 1e-9
    if len(dt) > 1:
        dt[0] = dt[1]
    return np.clip(dt, 1e-4, 0.1)


# ---------------------------------------------------------------------------
# the peers' attitudes


def attitude_rotvec(rec: Recording, **_site) -> Attitude:
    s = rec.stream(ROTVEC, "the phone's rotation vector")
    q = s.values / np.linalg.norm(s.values, axis=1, keepdims=True)
    return Attitude(s.t_ns.copy(), q)


def attitude_imufusion(rec: Recording, **_site) -> Attitude:
    import imufusion

    t, gyr, acc, mag = synced_imu(rec)
    dt = _dts(t)
    rate = 1.0 / float(np.median(dt))
    settings = imufusion.AhrsSettings(sample_rate=rate, gain=0.5, gyroscope_range=2000.0,
                                      acceleration_rejection=10.0, magnetic_rejection=10.0,
                                      rejection_timeout=5.0)
    settings.convention = imufusion.CONVENTION_ENU  # the constructor keyword is ignored (imufusion 1.3.3)
    ahrs = imufusion.Ahrs()
    ahrs.set_settings(settings)
    bias = imufusion.Bias()
    bias.set_settings(imufusion.BiasSettings(sample_rate=rate))
    gyr_dps = np.degrees(gyr)
    acc_g = acc / STANDARD_GRAVITY
    out = np.empty((len(t), 4))
    for i in range(len(t)):
        g = bias.update(gyr_dps[i])
        ahrs.set_sample_period(float(dt[i]))
        if mag is None:
            ahrs.update_no_magnetometer(g, acc_g[i])
        else:
            ahrs.update(g, acc_g[i], mag[i])
        out[i] = ahrs.get_quaternion()
    return Attitude(t, out)


def _triad(acc, mag):
    return quat.from_two_vectors_enu(tuple(acc), tuple(mag))


def attitude_madgwick(rec: Recording, **_site) -> Attitude:
    from ahrs.filters import Madgwick

    t, gyr, acc, mag = synced_imu(rec)
    if mag is None:
        raise ValueError("madgwick peer needs a magnetometer")
    dt = _dts(t)
    f = Madgwick()
    q = np.array(quat.multiply(quat.conjugate(_Q_NWU_TO_ENU), _triad(acc[0], mag[0])))  # start in NWU
    out = np.empty((len(t), 4))
    for i in range(len(t)):
        q = f.updateMARG(q, gyr[i], acc[i], mag[i], dt=float(dt[i]))
        out[i] = quat.multiply(_Q_NWU_TO_ENU, tuple(q))
    return Attitude(t, out)


def attitude_ekf(rec: Recording, magnetic_dip_rad: float | None = None, **_site) -> Attitude:
    """ahrs' EKF; ``magnetic_dip_rad``: the site's WMM dip (None: the library's default reference, Munich)."""
    from ahrs.filters import EKF

    t, gyr, acc, mag = synced_imu(rec)
    if mag is None:
        raise ValueError("ekf peer needs a magnetometer")
    dt = _dts(t)
    ref = None if magnetic_dip_rad is None else math.degrees(float(magnetic_dip_rad))
    f = EKF(frame="ENU", magnetic_ref=ref)
    f.mag = mag  # its per-sample update() predicts the magnetometer only when this attribute is set
    q = np.array(_triad(acc[0], mag[0]))
    out = np.empty((len(t), 4))
    down = -acc  # its ENU model expects gravity (0, 0, -1), not the specific force the phone reports
    for i in range(len(t)):
        q = f.update(q, gyr[i], down[i], mag[i], dt=float(dt[i]))
        out[i] = q
    return Attitude(t, out)


ATTITUDE = {"rotvec": attitude_rotvec, "imufusion": attitude_imufusion, "madgwick": attitude_madgwick,
            "ekf": attitude_ekf}


def can_run(name: str, rec: Recording) -> bool:
    if name == "rotvec":
        return rec.has(ROTVEC)
    if name == "imufusion":
        return rec.has(GYRO) and rec.has(ACC)
    return rec.has(GYRO) and rec.has(ACC) and rec.has(MAG)


# ---------------------------------------------------------------------------
# per-step headings


def step_headings(att: Attitude, step_t_ns, *, grid_rate_hz: float = 50.0, cutoff_hz: float = 0.5,
                  delay_s: float | None = None, forward_b=(0.0, 1.0, 0.0), step_duration_s=None) -> np.ndarray:
    """Per-step walking heading (rad) from an attitude series, made exactly as the pipeline makes ours.

    The rotation matrices are sampled on a uniform ``grid_rate_hz`` grid,
    low-passed by :class:`core.pdr.heading.RotationSmoother`, and each step
    gets :func:`core.pdr.heading.interval_heading` over its delay-compensated
    interval ``[t - duration + delay, t + delay]`` (the pipeline's rule).
    ``step_duration_s`` defaults to the time since the previous step, or
    :data:`core.pdr.pipeline.DEFAULT_STEP_DURATION_S` for the first step of a
    bout (a gap over 1.5 s, the detector's ``max_step_interval_s``).
    """
    from core.pdr.heading import interval_heading
    from core.pdr.pipeline import DEFAULT_STEP_DURATION_S

    steps = np.asarray(step_t_ns, dtype=np.int64)
    smoother = RotationSmoother(cutoff_hz=cutoff_hz, grid_rate_hz=grid_rate_hz, forward_b=forward_b)
    delay = smoother.delay_s if delay_s is None else float(delay_s)
    if len(att.t_ns) == 0 or len(steps) == 0:
        return np.full(len(steps), np.nan)
    if step_duration_s is None:
        d = np.diff(steps, prepend=steps[0]) * 1e-9
        d[(d <= 0) | (d > 1.5)] = DEFAULT_STEP_DURATION_S
    else:
        d = np.asarray(step_duration_s, dtype=float)
    period_ns = int(round(1e9 / grid_rate_hz))
    grid = np.arange(int(att.t_ns[0]), int(att.t_ns[-1]) + 1, period_ns, dtype=np.int64)
    idx = np.searchsorted(att.t_ns, grid, side="right") - 1
    east = np.empty(len(grid))
    north = np.empty(len(grid))
    for j, i in enumerate(idx):
        smoother.update(quat.to_matrix(tuple(att.q_wxyz[i])))
        east[j], north[j] = smoother.forward_east, smoother.forward_north
    delay_ns = int(round(delay * 1e9))
    return np.array([interval_heading(grid, east, north, int(t) + delay_ns - int(dk * 1e9), int(t) + delay_ns)
                     for t, dk in zip(steps, d)])


#: bump when a peer's wrapper above changes what it returns (the cache's key also holds this file's digest)
CACHE_VERSION = 1


def _peer_version(name: str) -> str:
    """The installed version of the package behind a peer ("" for ``rotvec``, the phone's own)."""
    from importlib import metadata

    dist = {"imufusion": "imufusion", "madgwick": "ahrs", "ekf": "ahrs"}.get(name)
    if dist is None:
        return ""
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "?"


def cache_key(name: str, rec: Recording, magnetic_dip_rad: float | None) -> str:
    """What a peer's attitude depends on, as a hex digest: the peer and its package's version, this module's
    source (its wrappers and settings), the site's dip, and every timestamp and value of the streams it
    reads (gyroscope, accelerometer, magnetometer, rotation vector)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"{CACHE_VERSION}|{name}|{_peer_version(name)}|{magnetic_dip_rad!r}|".encode())
    h.update(Path(__file__).read_bytes())
    for stream in (GYRO, ACC, MAG, ROTVEC):
        if rec.has(stream):
            s = rec.streams[stream]
            h.update(stream.encode())
            h.update(np.ascontiguousarray(s.t_ns, dtype=np.int64).tobytes())
            h.update(np.ascontiguousarray(s.values, dtype=np.float64).tobytes())
    return h.hexdigest()


def _write_attitude(path: Path, att: Attitude) -> None:
    """``att`` as raw little-endian numbers: the count (int64), the times (int64), the quaternions (4 float64 each);
    written to a temporary name and renamed (another process may be reading the folder)."""
    t = np.ascontiguousarray(att.t_ns, dtype="<i8")
    q = np.ascontiguousarray(att.q_wxyz, dtype="<f8").reshape(len(t), 4)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(np.array([len(t)], dtype="<i8").tobytes() + t.tobytes() + q.tobytes())
    os.replace(tmp, path)


def _read_attitude(path: Path) -> Attitude | None:
    """What :func:`_write_attitude` wrote, or None for a file of the wrong size (damaged, cut short)."""
    data = path.read_bytes()
    if len(data) < 8:
        return None
    n = int(np.frombuffer(data, dtype="<i8", count=1)[0])
    if n < 0 or len(data) != 8 + 8 * n + 32 * n:
        return None
    t = np.frombuffer(data, dtype="<i8", count=n, offset=8).astype(np.int64)
    q = np.frombuffer(data, dtype="<f8", count=4 * n, offset=8 + 8 * n).reshape(n, 4).astype(np.float64)
    return Attitude(t, q)


def peer_attitude(name: str, rec: Recording, magnetic_dip_rad: float | None = None,
                  cache_dir: Path | None = None) -> tuple[Attitude, bool]:
    """A peer's attitude over ``rec``, from ``cache_dir`` when an earlier run stored it: ``(attitude, cached)``.

    A peer's output depends only on the recording, the site and the peer (never on our pipeline), so a
    benchmark rerun or a parameter sweep need not run it again; :func:`cache_key` says what a stored
    result must match.  Stored as raw numbers (:func:`_write_attitude`: nothing is unpickled); a damaged
    file is run again and replaced.
    """
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / f"{name}-{cache_key(name, rec, magnetic_dip_rad)}.att"
        if path.exists():
            att = _read_attitude(path)
            if att is not None:
                return att, True
    att = ATTITUDE[name](rec, magnetic_dip_rad=magnetic_dip_rad)
    if path is not None:
        _write_attitude(path, att)
    return att, False


def run_peers(rec: Recording, step_t_ns, names=ALL_PEERS, magnetic_dip_rad: float | None = None,
              cache_dir: Path | None = None, cached: list | None = None, **heading_kw) -> tuple[dict, dict]:
    """Per-step headings of every peer that can run: ``({name: headings}, {name: error message})``.

    ``magnetic_dip_rad``: the site's World Magnetic Model dip, for the peers
    that take a magnetic reference (``ekf``); ``cache_dir``: where the peers'
    attitudes are kept between runs (:func:`peer_attitude`; None: always run
    them), ``cached`` receives the names of the peers read from it;
    ``heading_kw`` go to :func:`step_headings`.
    """
    out, errors = {}, {}
    for name in names:
        if not can_run(name, rec):
            continue
        try:
            att, hit = peer_attitude(name, rec, magnetic_dip_rad, cache_dir)
            if hit and cached is not None:
                cached.append(name)
            out[name] = step_headings(att, step_t_ns, **heading_kw)
        except ImportError as e:
            errors[name] = f"not installed ({e.name})"
        except Exception as e:  # a peer failing must not stop the benchmark
            errors[name] = f"{type(e).__name__}: {e}"
    return out, errors
