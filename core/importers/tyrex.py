"""Reader for an Android or iPhone walk of the Tyrex attitude benchmark with its Qualisys truth (Michel, Genevès,
Fourati & Layaïda, "On attitude estimation with smartphones", PerCom 2017;
``tyrex-team/benchmarks-attitude-smartphones``).

Format
======
A walk is a folder ``datasets/android/<name>/`` (``<name>`` as ``Jakob_Nexus5_NoDist_Swinging``) and the motion
capture of the same walk, ``datasets/qualisys/<name>.mat`` (found two folders up, or given).  The folder's text files
have one sample a line, numbers separated by spaces, the first the time in s (the phone's clock, from the start of
the recording), no header::

    accelerometer.txt              t, x, y, z   m/s^2, Android TYPE_ACCELEROMETER (gravity included), device axes
    gyroscope-calibrated.txt       t, x, y, z   rad/s, Android TYPE_GYROSCOPE (the benchmark's own choice)
    magnetometer-calibrated.txt    t, x, y, z   uT, Android TYPE_MAGNETIC_FIELD (optional)
    timeAlignment.txt              one number, s: phone time + it = Qualisys time (the benchmark's alignment of the
                                   acceleration norms, its ``findTimeDiffBetweenQualisysAndSmartphone.m``)

Extra columns on a line are ignored (the benchmark drops them too); a line with fewer than four numbers is a bad
line (skipped and counted, or past :func:`core.recording.bad_lines_tolerated` a :class:`RecordingError`).

An iPhone walk (``datasets/ios/<name>/``, ``Jakob_iPhone5_NoDist_FrontPocket``) is told by its ``description.txt``
and differs as the benchmark's ``loadiOSDataset.m`` reads it::

    accelerometer.txt              t, x, y, z   g, CoreMotion's raw accelerometer: the inertial force, so the values
                                   are multiplied by -9.80665 (the Android sign and unit, gravity included)
    gyroscope.txt                  t, x, y, z   rad/s, CoreMotion's raw gyroscope
    magnetometer-calibrated.txt    t, x, y, z, accuracy   uT (optional)
    description.txt                ``[Time]`` ``BootTime = <s>``: the times above minus it are the phone's time
                                   that ``timeAlignment.txt`` aligns

The ``.mat`` is found by the folder's name without regard to case (the repository's folder
``Jakob_iPhone4S_NoDist_Backpocket`` has ``Jakob_iPhone4S_NoDist_BackPocket.mat``).

The ``.mat`` is Qualisys Track Manager's MAT export (level 5 with QTM's own header text; read with
:mod:`core.importers.matv5`): one structure with ``Frames``, ``FrameRate`` (Hz) and ``RigidBodies``, whose first
body's ``Positions`` (1 x 3 x N, mm) and ``Rotations`` (1 x 9 x N: a 3 x 3 matrix column-major, body -> the room, as
the benchmark's ``loadQualisysDataset.m`` reads it) are the truth; a lost frame is NaN (dropped).  Frame ``k`` is at
Qualisys time ``k / FrameRate``, so at phone time ``k / FrameRate - timeAlignment``.  The room frame is z up (the
phone is at 0.8-1.3 m), x and y a horizontal pair, not geographic.  The rigid body is the marker handler the phone
is fixed in, whose axes are not promised to be the phone's: its rotation is ``truth_body_attitude``
(:data:`core.importers._common.TRUTH_BODY_ATTITUDE`, ``w, x, y, z``, body -> the frame of ``posi``), the positions
``posi`` (``east_m, north_m, up_m`` = the room's x, y, z in m).

Streams: ``acc``, ``gyro``, ``mag`` where present, ``posi`` and ``truth_body_attitude``.

Detection (:func:`core.importers.detect_format`)
================================================
A walk is what a user points at: its folder ``datasets/android/<name>/``, or one of its files
(``accelerometer.txt``, ``gyroscope-calibrated.txt``, ``magnetometer-calibrated.txt``, ``timeAlignment.txt``):
either reads the folder, and the folder finds its truth ``../../qualisys/<name>.mat``.  The files have no header,
so the folder is tested by its content (:func:`looks_like_folder`): ``accelerometer.txt``,
``gyroscope-calibrated.txt`` and ``timeAlignment.txt`` are there, and the accelerometer's first lines are
(:func:`looks_like`) at least 3, and nine in ten, lines of 4-8 numbers separated by spaces (the first line too),
times in s from the start (0 to a day, not decreasing), a median ``|a|`` of 5-15 m/s^2 (gravity included).  An
iPhone walk (``datasets/ios/<name>/``) holds ``accelerometer.txt``, ``gyroscope.txt``, ``timeAlignment.txt`` and
``description.txt``; its accelerometer is in g (a median ``|a|`` of 0.5-1.5) on the phone's boot clock (no upper
bound on the times).  No
other format read here has such lines (Brajdic & Harle's text has the time in ns and a type; the others separate
with commas, tabs or ``;``).  A missing truth is a :class:`RecordingError` saying where it was looked for (the
dataset's layout).  The ``.mat`` itself (QTM's MAT export, its header text ``QTM_ver``) is refused pointing at
the walk folder when that is there (:func:`walk_of_truth`), so a folder of the whole dataset replays each walk
once.  Zip archives and gzip files are not read.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from core import quaternion as quat
from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2
from core.importers._common import (
    POSI, TRUTH_BODY_ATTITUDE, acceleration_in_m_s2, feed_lines, finish, first_bad_time, head_bytes, head_lines,
    open_text,
)
from core.importers.matv5 import read_mat
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)

FORMAT = "tyrex"
POSI_COLUMNS = ["east_m", "north_m", "up_m"]
FILES = {ACC: "accelerometer.txt", GYRO: "gyroscope-calibrated.txt", MAG: "magnetometer-calibrated.txt"}
#: an iPhone walk's files (module doc)
IOS_FILES = {ACC: "accelerometer.txt", GYRO: "gyroscope.txt", MAG: "magnetometer-calibrated.txt"}
IOS_DESCRIPTION_FILE = "description.txt"
ALIGNMENT_FILE = "timeAlignment.txt"


#: the walk's files a user may point at (each reads its folder)
WALK_FILES = (*FILES.values(), ALIGNMENT_FILE)
#: and an iPhone walk's own
IOS_WALK_FILES = (IOS_FILES[GYRO], IOS_DESCRIPTION_FILE)
#: files a walk folder must hold (the magnetometer is optional)
NEEDED = (FILES[ACC], FILES[GYRO], ALIGNMENT_FILE)
#: files an iPhone walk folder must hold
IOS_NEEDED = (IOS_FILES[ACC], IOS_FILES[GYRO], ALIGNMENT_FILE, IOS_DESCRIPTION_FILE)
#: the text at the start of a QTM MAT export's header
QTM_MAGIC = b"QTM_ver"


def looks_like(head: str, ios: bool = False) -> bool:
    """True if the first lines of a text are ``accelerometer.txt`` lines of a Tyrex walk (module doc, *Detection*);
    ``ios``: an iPhone walk's (g, times from the phone's boot: no upper bound)."""
    lines = head_lines(head)
    rows = []
    for i, ln in enumerate(lines):
        f = ln.split()
        try:
            if not 4 <= len(f) <= 8 or "," in ln or ";" in ln:
                raise ValueError
            rows.append([float(x) for x in f[:4]])
        except ValueError:
            if i == 0:
                return False
    if len(rows) < max(3, 0.9 * len(lines)):
        return False
    v = np.asarray(rows, dtype=float)
    if not np.all(np.isfinite(v)):
        return False
    t = v[:, 0]
    norm = float(np.median(np.linalg.norm(v[:, 1:4], axis=1)))
    if ios:
        return bool(np.all(t >= 0.0) and np.all(np.diff(t) >= 0.0) and 0.5 <= norm <= 1.5)
    return bool(np.all((t >= 0.0) & (t < 86400.0)) and np.all(np.diff(t) >= 0.0) and 5.0 <= norm <= 15.0)


def looks_like_folder(path: str) -> bool:
    """True if ``path`` is a Tyrex walk folder: its needed files there, the accelerometer's content right."""
    path = str(path)
    if not os.path.isdir(path):
        return False
    ios = all(os.path.isfile(os.path.join(path, n)) for n in IOS_NEEDED)
    if not ios and not all(os.path.isfile(os.path.join(path, n)) for n in NEEDED):
        return False
    try:
        head = head_bytes(os.path.join(path, FILES[ACC]), 65536)
    except OSError:
        return False
    return looks_like(head.decode("latin-1"), ios=ios)


def walk_folder(path: str) -> str | None:
    """The walk folder ``path`` stands for -- itself, or the folder of one of its :data:`WALK_FILES` -- when that
    is a Tyrex walk (:func:`looks_like_folder`), else None."""
    path = str(path).rstrip("/") or "/"
    if os.path.isfile(path):
        if os.path.basename(path) not in WALK_FILES + IOS_WALK_FILES:
            return None
        path = os.path.dirname(path) or "."
    return path if looks_like_folder(path) else None


def _same_name(directory: str, name: str) -> list[str]:
    """The entries of ``directory`` named ``name`` without regard to case, the exact spelling first (the dataset
    spells one walk ``..._Backpocket`` beside its ``..._BackPocket.mat``); none where the directory is missing."""
    if not os.path.isdir(directory):
        return []
    return sorted((f for f in os.listdir(directory) if f.lower() == name.lower()), key=lambda f: (f != name, f))


def truth_path(folder: str) -> str:
    """Where a walk folder's Qualisys truth is in the dataset's layout: ``../../qualisys/<name>.mat``, the name
    matched without regard to case where the exact one is missing (module doc)."""
    folder = os.path.abspath(str(folder).rstrip("/"))
    name = os.path.basename(folder)
    qdir = os.path.join(os.path.dirname(os.path.dirname(folder)), "qualisys")
    for f in _same_name(qdir, name + ".mat"):
        if os.path.isfile(os.path.join(qdir, f)):
            return os.path.join(qdir, f)
    return os.path.join(qdir, name + ".mat")


def walk_of_truth(path: str, head: bytes) -> str | None:
    """The walk folder ``../../android/<name>/`` (or ``../../ios/<name>/``, the name matched without regard to
    case) of a Qualisys export ``qualisys/<name>.mat`` when it is there."""
    if not head.startswith(QTM_MAGIC):
        return None
    stem = os.path.basename(str(path))
    if not stem.lower().endswith(".mat"):
        return None
    root = os.path.dirname(os.path.dirname(os.path.abspath(str(path))))
    for platform in ("android", "ios"):
        pdir = os.path.join(root, platform)
        for name in _same_name(pdir, stem[:-4]):
            if looks_like_folder(os.path.join(pdir, name)):
                return os.path.join(pdir, name)
    return None


def _table(path: str, repairs: list[str], limit: int | None) -> np.ndarray:
    """The ``(n, 4)`` numbers (t, x, y, z) of one sensor file, bad lines skipped (module doc)."""
    rows, bad, count = [], [], [0]

    def line_of(n: int, line: str) -> None:
        count[0] = n
        f = line.split()
        if not f:
            return
        try:
            v = [float(x) for x in f[:4]]
        except ValueError:
            v = []
        if len(v) < 4 or not all(np.isfinite(v)):
            bad.append(RecordingError("not four numbers (t, x, y, z)", path, n))
        else:
            rows.append(v)

    def chunk(first: int, lines) -> None:
        for i, line in enumerate(lines):
            line_of(first + i, line)

    with open_text(path, repairs, limit) as text:
        feed_lines(text, path, repairs, chunk, bad, line_of)
    skip_bad_lines(bad, count[0], path, repairs)
    if not rows:
        raise RecordingError("no samples", path)
    return np.asarray(rows, dtype=float)


def _alignment_s(path: str) -> float:
    with open(path, encoding="latin-1") as f:
        words = f.read().split()
    try:
        value = float(words[0])
    except (IndexError, ValueError):
        raise RecordingError("not one number (the phone-to-Qualisys time offset, s)", path) from None
    if not np.isfinite(value) or abs(value) > 3600.0:
        raise RecordingError(f"time offset {value!r} s is not usable", path)
    return value


def _boot_time_s(path: str) -> float:
    """``BootTime`` of an iPhone walk's ``description.txt`` (module doc)."""
    with open(path, encoding="latin-1") as f:
        for line in f:
            key, _, value = line.partition("=")
            if key.strip() == "BootTime":
                try:
                    t = float(value)
                except ValueError:
                    break
                if np.isfinite(t):
                    return t
                break
    raise RecordingError("no usable BootTime = <s> line", path)


def qualisys_truth(mat_path: str, limit: int | None = MAX_UNCOMPRESSED_BYTES):
    """``(t_s, positions_m (n, 3), rotations (n, 3, 3))`` of a QTM MAT export's first rigid body, Qualisys time,
    lost frames dropped (module doc)."""
    with open(mat_path, "rb") as f:
        m = read_mat(f, mat_path, max_uncompressed_bytes=limit, objects=True)
    if not m.names():
        raise RecordingError("no variable", mat_path)
    d = m[m.names()[0]]
    if not isinstance(d, dict) or "RigidBodies" not in d or "FrameRate" not in d:
        raise RecordingError("not a Qualisys export (a structure with RigidBodies and FrameRate)", mat_path)
    rb = d["RigidBodies"]
    rb = rb[0] if isinstance(rb, list) and rb else rb
    if not isinstance(rb, dict) or "Positions" not in rb or "Rotations" not in rb:
        raise RecordingError("RigidBodies has no Positions and Rotations", mat_path)
    rate = float(np.asarray(d["FrameRate"]).ravel()[0])
    pos = np.asarray(rb["Positions"], dtype=float)
    rot = np.asarray(rb["Rotations"], dtype=float)
    if pos.ndim != 3 or pos.shape[:2] != (1, 3) or rot.shape != (1, 9, pos.shape[2]) or not rate > 0:
        raise RecordingError(f"rigid body of shapes {pos.shape} / {rot.shape} at {rate} Hz: expected 1 x 3 x N and "
                             "1 x 9 x N at a positive rate", mat_path)
    pos = pos[0].T / 1000.0
    r = rot[0].T.reshape(-1, 3, 3).transpose(0, 2, 1)  # column-major 3 x 3: r[k][:, j] = column j
    t = np.arange(len(pos)) / rate
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(r), axis=(1, 2))
    ok &= np.abs(np.linalg.det(np.where(ok[:, None, None], r, np.eye(3)))) > 0.9
    return t[ok], pos[ok], r[ok]


def read_tyrex(folder: str, *, mat_path: str | None = None, warn: bool = True,
               max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read one Tyrex walk folder (Android, or iPhone when it has a ``description.txt``) and its Qualisys truth
    (module doc)."""
    folder = str(folder).rstrip("/")
    name = os.path.basename(os.path.abspath(folder))
    if mat_path is None:
        mat_path = truth_path(folder)
        if not os.path.isfile(mat_path):
            raise RecordingError(f"no Qualisys truth for this Tyrex walk: {mat_path} is missing (the dataset keeps "
                                 "a walk's motion capture in qualisys/<walk>.mat, two folders above the walk's "
                                 "folder android/<walk>/ or ios/<walk>/)", folder)
    elif not os.path.isfile(mat_path):
        raise RecordingError("cannot open the Qualisys truth: no such file", str(mat_path))
    ios = os.path.isfile(os.path.join(folder, IOS_DESCRIPTION_FILE))
    boot_s = _boot_time_s(os.path.join(folder, IOS_DESCRIPTION_FILE)) if ios else 0.0
    repairs: list[str] = []
    notes: dict = {}
    streams = {}
    for stream, fname in (IOS_FILES if ios else FILES).items():
        path = os.path.join(folder, fname)
        if not os.path.isfile(path):
            if stream == MAG:
                continue
            raise RecordingError(f"no {fname}", folder)
        v = _table(path, repairs, max_uncompressed_bytes)
        j = first_bad_time(v[:, 0])
        if j is not None:
            raise RecordingError(f"time value {j + 1} is not a usable time: {float(v[j, 0])!r}", path)
        v = v[np.argsort(v[:, 0], kind="stable")]
        t_ns = np.round((v[:, 0] - boot_s) * 1e9).astype(np.int64)
        if stream == ACC and ios:
            xyz = -STANDARD_GRAVITY_M_S2 * v[:, 1:]  # CoreMotion's g, inertial force -> the Android sign, m/s^2
        elif stream == ACC:
            xyz = acceleration_in_m_s2(v[:, 1:], fname, path, repairs, notes)
        else:
            xyz = v[:, 1:]
        streams[stream] = make_stream(stream, t_ns, xyz)
    align = os.path.join(folder, ALIGNMENT_FILE)
    if not os.path.isfile(align):
        raise RecordingError(f"no {ALIGNMENT_FILE} in this Tyrex walk's folder (the phone-to-Qualisys clock offset)",
                             folder)
    offset_s = _alignment_s(align)
    t_q, pos, r = qualisys_truth(mat_path, max_uncompressed_bytes)
    t_ns = np.round((t_q - offset_s) * 1e9).astype(np.int64)
    streams[POSI] = make_stream(POSI, t_ns, pos, POSI_COLUMNS, "m,m,m",
                                "ground truth: Qualisys position of the phone's marker handler (the room's x, y, z); "
                                "z up, x and y a horizontal pair in the room's frame, not geographic")
    q = np.array([quat.from_matrix(m) for m in r]).reshape(-1, 4)
    streams[TRUTH_BODY_ATTITUDE] = make_stream(TRUTH_BODY_ATTITUDE, t_ns, q, ["w", "x", "y", "z"], "1",
                                               "ground truth: the Qualisys rotation of the marker handler, body -> "
                                               "the frame of posi; the handler's axes are not promised to be the "
                                               "phone's")
    platform = "ios" if ios else "android"
    meta = {"source_format": FORMAT, "app": f"Tyrex attitude benchmark ({'iPhone' if ios else 'Android'}; Qualisys "
            "truth)", "walk": name,
            "time_base": (f"t_ns = round((time - {boot_s:g}) * 1e9)" if ios else "t_ns = round(time * 1e9)")
                         + f": the phone's time in s; Qualisys frame k at k / rate minus {offset_s:g} s "
                         "(timeAlignment.txt)", **notes}
    if warn and repairs:
        warnings.warn("; ".join(repairs), DamagedFileWarning, stacklevel=2)
    return finish(Recording(streams, device={"app": "Tyrex benchmark", "platform": platform}, metadata=meta,
                            repairs=repairs, source=folder), warn=warn)
