"""Detection of the OxIOD, RIDI and Tyrex formats does not take the other formats' files (synthetic heads written
here).

OxIOD's files have no header: they are recognised by 16 numbers a line, the attitude ranges and Core Motion's
unit gravity (:func:`core.importers.oxiod.looks_like`); RIDI's by its header (``time``, ``acce_*``, ``gyro_*``).
Each other format's head below is still detected as that format, and neither test nor the half-match errors
fire on it; random headerless numeric CSVs are never taken for OxIOD.
"""

import numpy as np
import pytest

from core.importers import OXIOD, RIDI, _half_match, detect_format
from core.importers import oxiod as _oxi
from core.importers import ridi as _ridi
from core.importers import tyrex as _tyrex
from core.recording import MAGIC, RecordingError


def _rows(fmt: str, n: int = 30) -> str:
    return "".join(fmt.format(i=i, t=1_000_000_000_000 + i * 5_000_000, s=i * 0.005) + "\n" for i in range(n))


#: format -> (file name, head): the other formats' headers (or record lines) with a few plausible rows
OTHER_HEADS = {
    "sensorlog": ("walk.csv", "loggingTime(txt),accelerometerTimestamp_sinceReboot(s),"
                              "accelerometerAccelerationX(g),accelerometerAccelerationY(g),"
                              "accelerometerAccelerationZ(g),gyroTimestamp_sinceReboot(s),"
                              "gyroRotationX(rad/s),gyroRotationY(rad/s),gyroRotationZ(rad/s)\n"
                  + _rows("2020-01-01 10:00:00.000,{s},0.01,-0.02,-0.99,{s},0.1,0.2,0.3")),
    "accel-csv": ("walk.csv", "Timestamp,Milliseconds,X,Y,Z\n" + _rows("2020-01-01 10:00:00,{i}0,0.1,0.2,9.8")),
    "sensibility-testbed": ("walk.csv", "Time, x, y, z\n" + _rows("{s}, 0.1, 0.2, 9.8")),
    "matlab-mobile-csv": ("walk.csv", "Acceleration_Timestamp,X,Y,Z\n"
                          + _rows("01-Jan-2020 10:00:00.{i:03d},0.1,0.2,9.8")),
    "physics-toolbox": ("walk.csv", "time,gFx,gFy,gFz,TgF\n" + _rows("{s},0.01,0.02,0.99,0.99")),
    "sensorlogger": ("Accelerometer.csv", "time,seconds_elapsed,z,y,x\n" + _rows("{t},{s},0.1,0.2,0.3")),
    "phyphox": ("Accelerometer.csv", '"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)",'
                                     '"Acceleration z (m/s^2)"\n' + _rows("{s},0.1,0.2,9.8")),
    "trundlewheel": ("log.csv", "time;m_accG_x;m_accG_y;m_accG_z\n" + _rows("{i}0;0.1;0.2;9.8")),
    "x-io": ("sensors.csv", "Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),"
                            "Accelerometer Y (g),Accelerometer Z (g)\n" + _rows("{s},0.1,0.2,0.3,0.01,0.02,0.99")),
    "oxford-step-counter": ("accelerometer.csv", _rows("{t},3,0.1,0.2,9.8")),
    "brajdic-harle": ("trace.dat", _rows("{t} 1 0.1 0.2 9.8")),
    "getsensordata": ("log.txt", _rows("ACCE;{s};{s};0.1;0.2;9.8;3")),
    "msindoor": ("trace.txt", _rows("{t}\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3")),
    "pdr-recording": ("rec.csv", MAGIC + " v1\n"),
}


@pytest.mark.parametrize("fmt", sorted(OTHER_HEADS))
def test_other_formats_heads_are_not_taken_for_oxiod_ridi_or_tyrex(tmp_path, fmt):
    name, head = OTHER_HEADS[fmt]
    p = tmp_path / name
    p.write_text(head)
    assert detect_format(str(p)) == fmt
    assert not _oxi.looks_like(head) and not _oxi.looks_like_vicon(head) and not _ridi.looks_like_csv(head)
    assert not _tyrex.looks_like(head)
    assert _half_match(str(p), head) is None


def test_random_headerless_numbers_are_not_oxiod_and_ridi_needs_its_header(tmp_path):
    rng = np.random.default_rng(11)
    p = tmp_path / "imu1.csv"  # the pair's name: only the content can refuse it
    for _ in range(20):
        n_cols = int(rng.integers(3, 21))
        v = rng.normal(size=(25, n_cols)) * 10.0 ** rng.uniform(-2, 2, size=n_cols)
        p.write_text("".join(",".join(f"{x:.6g}" for x in row) + "\n" for row in v))
        try:
            fmt = detect_format(str(p))
        except RecordingError:
            continue
        assert fmt != OXIOD
    names = ["", *_ridi.DETECT, "pos_x", "pos_y", "pos_z"]
    for k in range(1, len(_ridi.DETECT) + 1):  # any detection column missing: refused, naming it
        header = [c for c in names if c != names[k]]
        q = tmp_path / "data.csv"
        q.write_text(",".join(header) + "\n" + _rows(",".join(["{i}"] + ["0.5"] * (len(header) - 1))))
        with pytest.raises(RecordingError, match=f"without its column\\(s\\) {names[k]}"):
            detect_format(str(q))
    q.write_text(",".join(names) + "\n" + _rows(",".join(["{i}", "{s}"] + ["0.5"] * (len(names) - 2))))
    assert detect_format(str(q)) == RIDI
