"""phyphox exports as the real walks of ``../shared/data/phone_walks_more`` write them (issue #25), synthetic.

* the "Excel" dialect of phyphox 1.1.10 on iOS: a UTF-8 byte-order mark, an unquoted header, ``;`` between
  fields and ``,`` as the decimal mark, ``Linear Accelerometer.csv`` with the *same* header as
  ``Accelerometer.csv`` (only the file name says the gravity is removed), ``-1`` for "no velocity / direction";
* the phone's cached last location handed over at the START (two fixes with the same time 0.02 s, or one at
  0.000 s followed by a gap): dropped and noted;
* a 10 Hz Android export (``Linear Acceleration.csv``, ``Acceleration x (m/s^2)`` headers, no ``meta/``).

The parser's test is property-based: any values hypothesis draws, written in that dialect, read back as the
numbers written.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.importers import detect_format, load_recording
from core.importers.phyphox import CACHED_FIX_WINDOW_S, read_phyphox

G = 9.80665


def excel_num(v: float) -> str:
    """A number as phyphox's Excel dialect writes it: decimal comma, no exponent for ordinary values."""
    return format(float(v), ".10g").replace(".", ",")


def excel_csv(heads, rows) -> bytes:
    text = ";".join(heads) + "\n" + "".join(";".join(excel_num(v) for v in r) + "\n" for r in rows)
    return "\ufeff".encode("utf-8") + text.encode("utf-8")


def back(v: float) -> float:
    return float(excel_num(v).replace(",", "."))


LOC_IOS = ["Time (s)", "Latitude (°)", "Longitude (°)", "Height (m)", "Velocity (m/s)", "Direction (°)",
           "Horizontal Accuracy (m)", "Vertical Accuracy (°)"]
TIME_CSV = ("\ufeffevent;experiment time;system time;system time text\n"
            "START;0;1654608257,581;2022-06-07 15:24:17.581 UTC+02:00\n"
            "PAUSE;30,5;1654608288,081;2022-06-07 15:24:48.081 UTC+02:00\n")


def write_walk(root, acc, lin, gyr, loc) -> None:
    (root / "meta").mkdir(parents=True)
    (root / "Accelerometer.csv").write_bytes(excel_csv(["Time (s)", "X (m/s^2)", "Y (m/s^2)", "Z (m/s^2)"], acc))
    (root / "Linear Accelerometer.csv").write_bytes(excel_csv(["Time (s)", "X (m/s^2)", "Y (m/s^2)", "Z (m/s^2)"],
                                                              lin))
    (root / "Gyroscope.csv").write_bytes(excel_csv(["Time (s)", "X (rad/s)", "Y (rad/s)", "Z (rad/s)"], gyr))
    (root / "Location.csv").write_bytes(excel_csv(LOC_IOS, loc))
    (root / "meta" / "time.csv").write_bytes(TIME_CSV.encode("utf-8"))
    (root / "meta" / "device.csv").write_bytes("\ufeffproperty;value\nversion;1.1.10\ndeviceModel;iPhone12,8\n"
                                               "deviceBrand;Apple\n".encode("utf-8"))


_f = st.floats(-30.0, 30.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(dev=st.lists(st.tuples(_f, _f, _f), min_size=20, max_size=60), rate=st.sampled_from([10.0, 100.7]),
       data=st.data())
def test_excel_dialect_reads_back_the_numbers_written(tmp_path_factory, dev, rate, data):
    root = tmp_path_factory.mktemp("lopen")
    n = len(dev)
    t = 0.0035 + np.arange(n) / rate
    # with gravity: the device's y axis about down (a phone on its long edge) plus the drawn motion / 10
    acc = [(ti, 0.1 * a, -G + 0.1 * b, 0.1 * c) for ti, (a, b, c) in zip(t, dev)]
    lin = [(ti, 0.1 * a, 0.1 * b, 0.1 * c) for ti, (a, b, c) in zip(t, dev)]
    gyr = [(ti + 0.011, 0.01 * a, 0.01 * b, 0.01 * c) for ti, (a, b, c) in zip(t, dev)]
    k = data.draw(st.integers(3, 8))
    lat = [52.3 + data.draw(st.floats(0, 1e-3)) for _ in range(k)]
    loc = [(0.020529985, 52.31473, 4.95371, 1.13, -1, -1, 35, 35),  # cached: two at the same instant
           (0.020529985, 52.31472, 4.95370, 1.14, -1, -1, 35, 35)]
    loc += [(3.09 + i, la, 4.9537 + 1e-5 * i, -0.4, 1.2 if i else -1, 74.3 if i else -1, 5.5, 5.5)
            for i, la in enumerate(lat)]
    write_walk(root, acc, lin, gyr, loc)
    assert detect_format(str(root)) == "phyphox"
    rec = read_phyphox(str(root), warn=False)
    a = rec.streams["acc"]
    assert np.array_equal(a.values, [[back(v) for v in r[1:]] for r in acc])  # with g, not the linear file
    assert rec.metadata["files_used"]["acc"] == "Accelerometer.csv"
    assert "linacc" not in rec.metadata["files_used"]
    assert any("Linear Accelerometer.csv: linear acceleration" in u for u in rec.metadata["unused"])
    assert np.array_equal(rec.streams["gyro"].values, [[back(v) for v in r[1:]] for r in gyr])
    # time: t_ns from the experiment time (START at 0), the Unix time from meta/time.csv's decimal comma
    assert rec.metadata["unix_offset_ns"] == 1654608257581000000
    assert abs(int(a.t_ns[1] - a.t_ns[0]) - round(1e9 / rate)) <= 1
    gps = rec.streams["gps"]
    assert len(gps) == k  # the two cached fixes dropped, and said so
    assert any("cached last location" in r and "dropped 2 fix" in r for r in rec.repairs)
    assert np.allclose(gps.values[:, 0], [back(v) for v in lat], rtol=0, atol=1e-12)
    assert math.isnan(gps.values[0, 4]) and math.isnan(gps.values[0, 5])  # -1: no velocity, no direction
    assert np.allclose(gps.values[1:, 4], 1.2) and np.allclose(gps.values[1:, 5], 74.3)


def test_cached_fix_window_after_each_start():
    from core.importers.phyphox import _cached_fixes

    t = np.array([0.0, 0.02, 0.49, 0.5, 3.1, 30.6, 30.9, 31.2])
    # a second run starting at experiment time 30.5: its first 0.5 s are cached fixes too
    assert _cached_fixes(t, [0.0, 30.5]).tolist() == [True, True, True, False, False, True, True, False]
    assert CACHED_FIX_WINDOW_S == 0.5


def test_android_10_hz_export_without_meta(tmp_path):
    """kim66003-style: 10 Hz, Android headers, ``Linear Acceleration.csv`` beside the accelerometer, a cached fix
    at 0.000 s followed by an 11.8 s gap, speed and direction 0 without a bearing."""
    root = tmp_path / "Walking_2020-06-03_15-13-20"
    root.mkdir()
    n = 600
    t = np.arange(n) * 0.1
    step = np.sin(2 * np.pi * 1.9 * t)

    def csv(heads, cols):
        head = ",".join(f'"{h}"' for h in heads)
        return head + "\n" + "".join(",".join(f"{v:.9E}" for v in r) + "\n" for r in zip(*cols))

    (root / "Accelerometer.csv").write_text(csv(["Time (s)", "Acceleration x (m/s^2)", "Acceleration y (m/s^2)",
                                                 "Acceleration z (m/s^2)"], [t, 0.4 + 0 * t, 4.1 + 0 * t, 9.0 + step]))
    (root / "Linear Acceleration.csv").write_text(csv(["Time (s)", "Linear Acceleration x (m/s^2)",
                                                       "Linear Acceleration y (m/s^2)", "Linear Acceleration z (m/s^2)"],
                                                      [t, 0 * t, 0 * t, step]))
    (root / "Gyroscope.csv").write_text(csv(["Time (s)", "Gyroscope x (rad/s)", "Gyroscope y (rad/s)",
                                             "Gyroscope z (rad/s)"], [t + 0.27, 0 * t, 0 * t, 0 * t]))
    ft = np.array([0.0, 11.78, 12.78, 13.78, 14.78])
    (root / "Location.csv").write_text(csv(["Time (s)", "Latitude (°)", "Longitude (°)", "Height (m)",
                                            "Velocity (m/s)", "Direction (°)", "Horizontal Accuracy (m)",
                                            "Vertical Accuracy (m)"],
                                           [ft, 52.3843 + 1e-5 * ft, 5.2102 + 0 * ft, 0 * ft,
                                            np.array([0.0, 0.82, 1.15, 1.2, 1.3]),
                                            np.array([0.0, 68.3, 56.9, 60.0, 61.0]),
                                            np.array([27.1, 48.0, 32.0, 16.0, 8.0]), 0 * ft]))
    rec = load_recording(str(root))
    assert abs(np.median(np.diff(rec.streams["acc"].t_ns)) - 1e8) < 1
    assert np.allclose(rec.streams["acc"].values[:, 2], 9.0 + step, atol=1e-6)  # with g
    gps = rec.streams["gps"]
    assert list(gps.t_ns) == [11_780_000_000, 12_780_000_000, 13_780_000_000, 14_780_000_000]
    assert rec.metadata["pauses"] == 0 and "unix_offset_ns" not in rec.metadata
