"""Importers: GetSensorData, Sensor Logger, phyphox, format detection.

Synthetic fixtures are written by the tests into ``tmp_path`` from a known
phone attitude, so every unit, axis and sign conversion is checked against
ground truth.  Tests on real recordings read ``../shared/data`` beside the
checkout and are skipped when it is absent.
"""

from __future__ import annotations

import csv
import functools
import gzip
import json
import math
import time
import zipfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import quaternion
from core.conventions import STANDARD_GRAVITY_M_S2 as G
from core.importers import FORMATS, detect_format, load_recording
from core.importers.getsensordata import parse_getsensordata, read_getsensordata
from core.importers.phyphox import read_phyphox
from core.importers.sensorlogger import read_sensorlogger
from core.recording import (
    Recording,
    RecordingError,
    TimestampRepairWarning,
    make_stream,
    read_recording,
    write_recording,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
IPIN = DATA / "ipin2023_track3" / "logfiles"
ETH = DATA / "sensorlogger_gps_walk_ethz" / "2023-03-17_15-50-47"
needs_ipin = pytest.mark.skipif(not IPIN.is_dir(), reason="../shared/data/ipin2023_track3 not present")
needs_eth = pytest.mark.skipif(not ETH.is_dir(), reason="../shared/data/sensorlogger_gps_walk_ethz not present")


# ---------------------------------------------------------------------------
# attitude helpers (independent of the code under test)


def quat(axis, deg):
    a = math.radians(deg) / 2
    q = [math.cos(a), 0.0, 0.0, 0.0]
    q["xyz".index(axis) + 1] = math.sin(a)
    return np.array(q)


def qmul(p, q):
    return np.array(quaternion.multiply(p, q))


def rot(q):
    return np.array(quaternion.to_matrix(q))


def same_rotation(q1, q2, tol=1e-6):
    return abs(abs(float(np.dot(q1, q2))) - 1.0) < tol


#: a hand-held phone: heading 30 deg east of north (device y), top tilted up 40 deg, rolled 10 deg
Q_TRUE = qmul(qmul(quat("z", -30.0), quat("x", 40.0)), quat("y", 10.0))
H_N = np.array([0.0, 20.0, -40.0])  # Earth field in ENU, uT (northern hemisphere: points down)
ACC_B = rot(Q_TRUE).T @ np.array([0.0, 0.0, G])  # Android accelerometer at rest: +g up, in the device frame
MAG_B = rot(Q_TRUE).T @ H_N


def bearing_deg(R):
    return math.degrees(math.atan2(R[0, 1], R[1, 1]))


# ---------------------------------------------------------------------------
# GetSensorData


def gsd_header(model="SM-TEST"):
    return (
        "% LogFile created by the 'GetSensorData' App for Android.\n"
        "% Date of creation: Wed Jun 14 10:00:58 GMT+02:00 2023\n"
        "% Version 2.21 July 2021\n"
        "% Manufacturer:            \tsamsung\n"
        f"% Model:                   \t{model}\n"
        "% API Android version:     \t26\n"
        "% Android version Release: \t8.0.0\n"
        "% Accelerometer data: \t'ACCE;AppTimestamp(s);SensorTimestamp(s);Acc_X(m/s^2);Acc_Y(m/s^2);Acc_Z(m/s^2);"
        "Accuracy(integer)'\n"
        "% \n\n"
    )


def ahrs_fields(q):
    """GetSensorData's AHRS fields for an ENU<-device quaternion: PitchX, RollY, YawZ (deg), x, y, z."""
    q = q if q[0] >= 0 else -q
    R = rot(q)
    pitch = math.degrees(math.asin(R[2, 1]))
    roll = math.degrees(math.atan2(-R[2, 0], R[2, 2]))
    yaw = math.degrees(math.atan2(-R[0, 1], R[1, 1]))  # minus the Android azimuth
    return [pitch, roll, yaw, q[1], q[2], q[3]]


def make_gsd(n=200, sensor0=5000.0, app0=0.05, offset=None, extra_lines=()):
    """A still phone at Q_TRUE for n samples at 50 Hz; SensorTimestamp = AppTimestamp + 4999.95 - latency."""
    lines = [gsd_header()]
    for i in range(n):
        ts = sensor0 + 0.02 * i
        app = ts - (sensor0 - app0) + 0.002  # 2 ms delivery latency
        lines.append(f"ACCE;{app:.4f};{ts:.4f};{ACC_B[0]:.5f};{ACC_B[1]:.5f};{ACC_B[2]:.5f};3\n")
        lines.append(f"GYRO;{app:.4f};{ts:.4f};0.00100;-0.00200;0.00300;3\n")
        lines.append(f"MAGN;{app + 0.001:.4f};{ts + 0.001:.4f};{MAG_B[0]:.5f};{MAG_B[1]:.5f};{MAG_B[2]:.5f};3\n")
        f = ahrs_fields(Q_TRUE)
        lines.append(f"AHRS;{app:.4f};{ts:.4f};{f[0]:.6f};{f[1]:.6f};{f[2]:.6f};{f[3]:.8f};{f[4]:.8f};{f[5]:.8f};3\n")
        if i % 10 == 0:
            lines.append(f"PRES;{app:.4f};{ts:.4f};976.2273;3\n")
            lines.append(f"WIFI;{app:.3f};{ts:.2f};SSID;20:23:00:00:00:01;2437;-60\n")
        if i % 50 == 25:
            # each fix twice (as the app does), Unix fix time 1686729678 + k
            k = i // 50
            # fix 1 has no bearing: Android's getBearing() is then 0.0, and GetSensorData logs it as such
            bearing, speed = ("0.000", "0.0") if k == 1 else ("79.500", "0.1")
            for d in (0.0, 0.01):
                lines.append(f"GNSS;{app + d:.4f};{1686729678 + k:.4f};49.461269;11.111049;346.000;{bearing};9.0;"
                             f"{speed};22;19\n")
    lines.append("POSI;1.0500;1;49.461316433032;11.110964442580;0;100\n")
    lines.append("POSI;3.0500;2;49.461275602490;11.110988346746;0;100\n")
    lines.extend(extra_lines)
    return "".join(lines)


def test_getsensordata_synthetic_units_time_and_attitude():
    rec = parse_getsensordata(make_gsd(), "synthetic.txt")
    assert set(rec.streams) == {"acc", "gyro", "mag", "rotvec", "pressure", "gps", "gnss_status", "posi"}
    acc = rec.streams["acc"]
    assert acc.t_ns.dtype == np.int64
    assert acc.t_ns[0] == 5_000_000_000_000 and acc.t_ns[1] - acc.t_ns[0] == 20_000_000  # sensor clock, exact ns
    assert np.allclose(acc.values[0], ACC_B, atol=1e-5)
    assert np.allclose(rec.streams["mag"].values[0], MAG_B, atol=1e-5)
    assert np.allclose(rec.streams["gyro"].values[0], [0.001, -0.002, 0.003])
    # rotvec: the ENU<-device quaternion, w restored from the vector part
    q = rec.streams["rotvec"].values[0]
    assert same_rotation(q, Q_TRUE, 1e-7)
    assert np.allclose(rot(q) @ ACC_B, [0, 0, G], atol=1e-3)
    assert rec.metadata["rotvec_check"]["tilt_err_deg"] < 0.1
    assert rec.metadata["rotvec_check"]["heading_diff_deg"] < 0.1
    assert rec.metadata["ahrs_angles_vs_quaternion_deg"]["max"] < 1e-3
    # AppTimestamp -> sensor clock: offset sensor - app without the 2 ms latency
    off = rec.metadata["app_to_sensor_offset_ns"]
    assert abs(off - int(round((5000.0 - 0.05 - 0.002) * 1e9))) < 200_000
    posi = rec.streams["posi"]
    assert posi.columns == ("lat_deg", "lon_deg", "floor", "building_id", "counter")
    assert posi.t_ns[0] == int(round(1.05e9)) + off
    assert posi.values[1, 4] == 2 and posi.values[0, 3] == 100
    # GNSS: repeats dropped, hacc from Accuracy(m), speed from Speed(m/s), course from Bearing(deg), Unix time
    # from the fix times
    gps = rec.streams["gps"]
    assert len(gps) == 4 and rec.metadata["gnss_repeats_dropped"] == 4
    assert gps.columns == ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg")
    assert np.allclose(gps.values[0], [49.461269, 11.111049, 346.0, 9.0, 0.1, 79.5], rtol=0, atol=1e-9)
    assert gps.values[1, 4] == pytest.approx(0.0, abs=1e-12) and np.isnan(gps.values[1, 5])  # no bearing
    assert abs(rec.metadata["unix_offset_ns"] + gps.t_ns[0] - 1686729678 * 10**9) < 2 * 10**9
    assert rec.metadata["t0_unix_ns"] == rec.t0_ns + rec.metadata["unix_offset_ns"]
    assert rec.streams["pressure"].values[0, 0] == pytest.approx(976.2273)
    assert rec.metadata["ignored_line_types"] == {"WIFI": 20}
    assert rec.metadata["line_counts"]["ACCE"] == 200
    assert rec.device["model"] == "SM-TEST" and rec.device["android_api"] == 26
    assert rec.metadata["app_version"] == "2.21" and rec.metadata["source_format"] == "getsensordata"
    assert rec.repairs == []


def test_getsensordata_satellites_become_gnss_status_and_survive_a_round_trip(tmp_path):
    """SatInView / SatInUse of each kept fix -> gnss_status (n_used, cn0 nan, n_view) at the fix's time; a fix line
    without them reads nan; written as a pdr-recording and read back, the same numbers."""
    lines = [f"GNSS;{0.6 + k:.4f};{1686729700 + k:.4f};49.4613;11.1111;346.0;0.0;12.0;0.0;{v};{u}\n"
             for k, (v, u) in enumerate([(9, 8), (9, 0), (13, 11)])]
    lines.append("GNSS;3.6000;1686729703.0000;49.4613;11.1111;346.0;0.0;12.0;0.0\n")  # an older app: no satellites
    rec = parse_getsensordata(make_gsd(n=10) + "".join(lines), "sats.txt")
    st, gps = rec.streams["gnss_status"], rec.streams["gps"]
    assert st.columns == ("n_used", "cn0_4th_dbhz", "n_view")
    assert np.array_equal(st.t_ns, gps.t_ns)
    assert np.array_equal(st.values[:, 0], [8, 0, 11, np.nan], equal_nan=True)
    assert np.array_equal(st.values[:, 2], [9, 9, 13, np.nan], equal_nan=True)
    assert np.isnan(st.values[:, 1]).all()
    write_recording(str(tmp_path / "sats.pdr.gz"), rec)
    back = read_recording(str(tmp_path / "sats.pdr.gz"), warn=False).streams["gnss_status"]
    assert back.columns == st.columns and np.array_equal(back.t_ns, st.t_ns)
    assert np.array_equal(back.values, st.values, equal_nan=True)


def test_getsensordata_gnss_without_speed_field_reads_speed_as_nan():
    text = make_gsd(n=10) + "GNSS;0.5000;1686729690.0000;49.4613;11.1111;346.0;123.4;7.0\n"
    gps = parse_getsensordata(text, "old.txt").streams["gps"]
    assert np.isnan(gps.values[-1, 4])
    assert gps.values[-1, 5] == pytest.approx(123.4, abs=1e-9) and gps.values[-1, 3] == pytest.approx(7.0, abs=1e-9)


def test_getsensordata_ahrs_without_quaternion_uses_angles():
    f = ahrs_fields(Q_TRUE)
    text = gsd_header() + "".join(
        f"ACCE;{i * 0.02:.4f};{100 + i * 0.02:.4f};{ACC_B[0]:.5f};{ACC_B[1]:.5f};{ACC_B[2]:.5f};3\n"
        f"AHRS;{i * 0.02:.4f};{100 + i * 0.02:.4f};{f[0]:.6f};{f[1]:.6f};{f[2]:.6f}\n" for i in range(20))
    rec = parse_getsensordata(text, "angles.txt")
    assert rec.metadata["ahrs_from_angles"] == 20
    assert same_rotation(rec.streams["rotvec"].values[5], Q_TRUE, 1e-9)


@pytest.mark.parametrize("bad, match, line", [
    ("ACCE;1.0;5001.0;0.1;abc;9.8;3\n", r"field 5 \(Acc_Y\) is not a number: 'abc'", None),
    ("GYRO;1.0;5001.0;0.1;0.2\n", r"missing fields: GYRO needs 5 fields", None),
    ("POSI;3.1;3;49.46\n", r"missing fields: POSI", None),
    ("MAGN;1.0;;1;2;3;3\n", r"field 3 \(SensorTimestamp\) is not a number: ''", None),
])
def test_getsensordata_malformed_lines_name_file_and_line(bad, match, line):
    text = make_gsd(n=20)
    lines = text.split("\n")
    lines.insert(30, bad.rstrip("\n"))
    with pytest.raises(RecordingError, match=match) as e:
        parse_getsensordata("\n".join(lines), "bad.txt")
    assert e.value.path == "bad.txt" and e.value.line == 31
    assert str(e.value).startswith("bad.txt:31: ") and "\n" not in str(e.value)


def test_getsensordata_cut_off_last_line_is_dropped_and_noted():
    text = make_gsd(n=20) + "ACCE;9.9;5009.9;0.12"  # no newline: the logger was killed mid-line
    rec = parse_getsensordata(text, "cut.txt")
    assert len(rec.streams["acc"]) == 20
    assert any("incomplete last line" in r for r in rec.repairs)


def test_getsensordata_unknown_types_are_counted_not_errors():
    text = make_gsd(n=10, extra_lines=["XYZW;1;2;3\n", "BLE4;2.8;iBeacon;BE:AC;-90;0;1;1;UUID\n", "garbage\n"])
    rec = parse_getsensordata(text, "u.txt")
    ign = rec.metadata["ignored_line_types"]
    assert ign["XYZW"] == 1 and ign["BLE4"] == 1 and ign["garbage"] == 1


def test_getsensordata_without_sensor_records_is_an_error():
    with pytest.raises(RecordingError, match="no ACCE, GYRO, MAGN or AHRS records"):
        parse_getsensordata(gsd_header() + "WIFI;0.6;1.0;SSID;20:23;2437;-60\n", "empty.txt")


def test_getsensordata_backwards_timestamps_are_repaired_with_a_warning():
    text = gsd_header() + "".join(f"ACCE;{i * 0.02:.4f};{100 + t:.4f};0;0;9.8;3\n"
                                  for i, t in enumerate([0.0, 0.02, 0.01, 0.03, 0.03]))
    with pytest.warns(TimestampRepairWarning):
        rec = parse_getsensordata(text, "back.txt")
    assert np.all(np.diff(rec.streams["acc"].t_ns) > 0) and len(rec.streams["acc"]) == 4
    assert rec.repairs


def test_getsensordata_non_finite_values_pass_without_warnings_but_times_must_be_finite(recwarn):
    text = (gsd_header() + "ACCE;0.1;5.00;inf;nan;1e400;3\nAHRS;0.1;5.00;1e400;nan;-inf;nan;0.1;0.2;3\n"
            "MAGN;0.1;5.00;1;2;3;0\nACCE;0.12;5.02;0;0;9.8;3\n")
    rec = parse_getsensordata(text, "inf.txt")
    assert np.isinf(rec.streams["acc"].values[0, 0]) and not [w for w in recwarn if w.category is RuntimeWarning]
    with pytest.raises(RecordingError, match=r"inf.txt:14: ACCE SensorTimestamp is not a usable time: nan"):
        parse_getsensordata(text.replace("ACCE;0.12;5.02", "ACCE;0.12;nan"), "inf.txt")


_finite = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    rows=st.lists(st.tuples(st.floats(1e-6, 5.0), _finite, _finite, _finite), min_size=1, max_size=40),
    t0=st.floats(0.0, 1e6),
    tag=st.sampled_from(["ACCE", "GYRO", "MAGN"]),
    fmt=st.sampled_from(["repr", "app"]),
)
def test_getsensordata_line_parser_round_trip(rows, t0, tag, fmt):
    """Lines written from random values read back within float precision (exactly, for repr)."""
    def f(x, nd):
        return repr(float(x)) if fmt == "repr" else f"{x:.{nd}f}"

    ts, vals, out = [], [], [gsd_header()]
    t = t0
    for dt, x, y, z in rows:
        t += dt
        st_s, v = f(t, 4), [f(x, 5), f(y, 5), f(z, 5)]
        ts.append(float(st_s))
        vals.append([float(s) for s in v])
        out.append(f"{tag};{f(t - t0, 4)};{st_s};{v[0]};{v[1]};{v[2]};3\n")
    name = {"ACCE": "acc", "GYRO": "gyro", "MAGN": "mag"}[tag]
    ts = np.array(ts)
    if np.any(np.diff(np.rint(ts * 1e9)) <= 0):
        return  # rounding to 0.1 ms merged two timestamps: not a parser question
    rec = parse_getsensordata("".join(out), "prop.txt", warn=False)
    s = rec.streams[name]
    assert np.array_equal(s.t_ns, np.rint(ts * 1e9).astype(np.int64))
    assert np.array_equal(s.values, np.array(vals))


_token = st.one_of(st.sampled_from(["", "nan", "1.5", "-0.0", "1e400", "abc", " 2 ", "3;", "%"]),
                   st.floats(allow_nan=True).map(repr), st.text(alphabet="0123456789.-eE;x ", max_size=8))
_tag = st.sampled_from(["ACCE", "GYRO", "MAGN", "AHRS", "PRES", "GNSS", "POSI", "WIFI", "XXXX", "", "%"])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lines=st.lists(st.tuples(_tag, st.lists(_token, max_size=11)), max_size=25), newline=st.booleans())
def test_getsensordata_any_input_gives_a_recording_or_a_recording_error(lines, newline):
    text = "\n".join(";".join([tag] + toks) for tag, toks in lines) + ("\n" if newline else "")
    try:
        rec = parse_getsensordata(text, "fuzz.txt", warn=False)
    except RecordingError as e:
        assert str(e).startswith("fuzz.txt") and "\n" not in str(e)
    else:
        for s in rec.streams.values():
            assert s.t_ns.dtype == np.int64 and len(s.values) == len(s.t_ns)


# ---------------------------------------------------------------------------
# Sensor Logger


def sl_csv(header, rows):
    return header + "\n" + "".join(",".join(repr(float(v)) if isinstance(v, float) else str(v) for v in r) + "\n"
                                   for r in rows)


def sl_files(platform="android", n=150, start_ns=1_700_000_000_123_000_000, with_total=True, with_gravity=True,
             orientation="native", metadata=True):
    """Sensor Logger CSVs of a still phone at Q_TRUE, written as the app would on `platform`."""
    files = {}
    t = [start_ns + 20_000_000 * i + 7 for i in range(n)]
    el = [(ti - start_ns) / 1e9 for ti in t]
    sign = -1.0 if platform == "ios" else 1.0  # iOS default: inertial-force sign on acc and gravity
    lin = np.array([0.01, -0.02, 0.03])  # a small user acceleration
    grav = ACC_B - lin
    rows = lambda v: [(t[i], el[i], v[2], v[1], v[0]) for i in range(n)]  # noqa: E731  (z, y, x order)
    files["Accelerometer.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(sign * lin))
    if with_gravity:
        files["Gravity.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(sign * grav))
    if with_total and platform == "android":
        files["TotalAcceleration.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(ACC_B))
    files["Gyroscope.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(np.array([0.001, 0.002, -0.003])))
    files["Magnetometer.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(MAG_B))
    files["MagnetometerUncalibrated.csv"] = sl_csv("time,seconds_elapsed,z,y,x", rows(MAG_B + 30.0))
    if orientation:
        if orientation == "native" and platform == "ios":
            q = qmul(quat("z", -90.0), Q_TRUE)  # CoreMotion: North-West-Up <- device
        elif orientation == "conjugate":
            q = Q_TRUE * np.array([1, -1, -1, -1])
        else:
            q = Q_TRUE
        files["Orientation.csv"] = sl_csv("time,seconds_elapsed,qz,qy,qx,qw,roll,pitch,yaw",
                                          [(t[i], el[i], q[3], q[2], q[1], q[0], 0.1, 0.2, 0.3) for i in range(n)])
    files["Location.csv"] = sl_csv(
        "time,seconds_elapsed,bearingAccuracy,speedAccuracy,verticalAccuracy,horizontalAccuracy,speed,bearing,"
        "altitude,longitude,latitude",
        [(start_ns + 1_000_000_000 * k, float(k), "", 0.5, 3.0, 4.7 if k else -1.0, 1.0, 90.0, 500.0, 8.51, 47.41)
         for k in range(3)])
    files["Barometer.csv"] = sl_csv("time,seconds_elapsed,relativeAltitude,pressure",
                                    [(t[i], el[i], 0.0, 947.77) for i in range(0, n, 10)])
    files["Annotation.csv"] = ""
    if metadata:
        files["Metadata.csv"] = ("version,device name,recording time,platform,appVersion,device id,sensors,"
                                 "sampleRateMs\n"
                                 f"3,TestPhone,2023-11-14_22-13-20,{platform},1.30.0,abc,Accelerometer|Gravity,20|20\n")
    return files


def write_folder(root: Path, files: dict, gz=()):
    root.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        if name in gz:
            with gzip.open(root / (name + ".gz"), "wt") as f:
                f.write(text)
        else:
            (root / name).write_text(text)
    return root


def write_zip(path: Path, files: dict, prefix=""):
    with zipfile.ZipFile(path, "w") as z:
        for name, text in files.items():
            z.writestr(prefix + name, text)
    return path


def check_still_phone(rec, tol_deg=1e-3):
    acc = rec.streams["acc"].values
    assert np.allclose(acc, ACC_B, atol=1e-9)
    assert np.allclose(rec.streams["mag"].values, MAG_B, atol=1e-9)
    q = rec.streams["rotvec"].values[0]
    assert same_rotation(q, Q_TRUE, 1e-9)


def test_sensorlogger_android_folder(tmp_path):
    root = write_folder(tmp_path / "rec", sl_files("android"), gz=("Gyroscope.csv",))
    rec = read_sensorlogger(root)
    check_still_phone(rec)
    assert rec.metadata["acc_from"] == "TotalAcceleration.csv"
    assert rec.metadata["unix_offset_ns"] == 1_700_000_000_123_000_000
    assert rec.streams["acc"].t_ns[0] == 7 and rec.streams["acc"].t_ns[1] == 20_000_007
    assert rec.metadata["t0_unix_ns"] == 1_700_000_000_123_000_000
    assert rec.device == {"platform": "android", "app": "Sensor Logger", "model": "TestPhone"}
    assert rec.metadata["rotvec_north"] == "magnetic north"
    assert rec.metadata["rotvec_check"]["tilt_err_deg"] < 0.01
    gps = rec.streams["gps"]
    assert np.isnan(gps.values[0, 3]) and gps.values[1, 3] == pytest.approx(4.7)  # negative accuracy = invalid
    assert np.allclose(gps.values[1, :3], [47.41, 8.51, 500.0])
    assert np.allclose(gps.values[:, 4:], [[1.0, 90.0]] * 3, rtol=0, atol=1e-12)  # speed, bearing
    assert rec.metadata["gps_speedAccuracy_median"] == pytest.approx(0.5, abs=1e-12)
    assert np.allclose(rec.streams["mag_uncal"].values, MAG_B + 30.0)
    assert rec.streams["pressure"].values[0, 0] == pytest.approx(947.77)
    assert "Annotation.csv" in rec.metadata["ignored_files"]
    assert rec.metadata["mag_dip_deg"] == pytest.approx(math.degrees(math.atan2(40, 20)), abs=0.01)
    # a CSV inside the folder reads the whole folder
    assert set(read_sensorlogger(root / "Accelerometer.csv").streams) == set(rec.streams)


@pytest.mark.parametrize("platform", ["android", "ios"])
def test_sensorlogger_location_invalid_values_and_cached_fixes(tmp_path, platform):
    files = sl_files(platform)
    start = 1_700_000_000_123_000_000
    #          seconds_elapsed, speedAccuracy, horizontalAccuracy, speed, bearing, bearingAccuracy
    fixes = [(-20.0, 0.5, 4.0, 0.8, 190.0, 10.0),  # cached before the start: dropped
             (1.0, 0.5, 4.0, -1.0, -1.0, -1.0),  # iOS: invalid speed and course
             (2.0, -1.0, 4.0, 1.2, 45.0, 10.0),  # invalid speed accuracy: speed unknown
             (3.0, 0.5, 0.0, 0.0, 0.0, 0.0),  # Android without hasBearing(): bearing 0.0
             (4.0, 0.4, 3.0, 1.4, 359.5, 8.0)]
    files["Location.csv"] = sl_csv(
        "time,seconds_elapsed,altitude,speedAccuracy,bearingAccuracy,latitude,bearing,horizontalAccuracy,longitude,"
        "speed",
        [(start + int(el * 1e9), el, 500.0, sa, ba, 47.41, b, h, 8.51, sp) for el, sa, h, sp, b, ba in fixes])
    rec = read_sensorlogger(write_folder(tmp_path / platform, files))
    gps = rec.streams["gps"]
    assert list(gps.t_ns) == [1_000_000_000, 2_000_000_000, 3_000_000_000, 4_000_000_000]
    assert any("dropped 1 fix(es) stamped before the recording started" in r for r in rec.repairs)
    expect = [[np.nan, np.nan], [np.nan, 45.0], [0.0, np.nan], [1.4, 359.5]]
    assert np.allclose(gps.values[:, 4:], expect, rtol=0, atol=1e-12, equal_nan=True)
    assert np.isnan(gps.values[2, 3]) and gps.values[3, 3] == pytest.approx(3.0, abs=1e-12)  # hacc 0: unknown
    assert rec.metadata["gps_bearingAccuracy_median"] == pytest.approx(9.0, abs=1e-12)  # of 10, 10, 0, 8
    assert "bearingAccuracy are not in the stream" in gps.note
    assert rec.t0_ns >= 0


def test_sensorlogger_android_without_total_acceleration_adds_gravity(tmp_path):
    rec = read_sensorlogger(write_folder(tmp_path / "r", sl_files("android", with_total=False)))
    assert rec.metadata["acc_from"] == "Accelerometer.csv + Gravity.csv"
    assert np.allclose(rec.streams["acc"].values, ACC_B, atol=1e-9)


def test_sensorlogger_ios_zip_is_converted_to_android_convention(tmp_path):
    z = write_zip(tmp_path / "ios.zip", sl_files("ios"), prefix="2023-11-14_22-13-20/")
    assert detect_format(z) == "sensorlogger"
    rec = load_recording(z)
    check_still_phone(rec)  # acc sign flipped and gravity added; NWU quaternion turned into ENU
    assert rec.device["platform"] == "ios"
    assert rec.metadata["acc_from"] == "Accelerometer.csv + Gravity.csv"
    assert rec.metadata["rotvec_north"] == "true north"
    assert "NWU" in rec.metadata["rotvec_convention"]
    assert rec.metadata["rotvec_check"]["heading_diff_deg"] < 0.01


def test_sensorlogger_orientation_that_fits_no_documented_convention_is_detected(tmp_path):
    rec = read_sensorlogger(write_folder(tmp_path / "r", sl_files("android", orientation="conjugate")))
    assert same_rotation(rec.streams["rotvec"].values[0], Q_TRUE, 1e-9)
    assert rec.metadata["rotvec_convention"].startswith("conjugate")
    assert any("does not fit the documented android convention" in r for r in rec.repairs)


def test_sensorlogger_errors(tmp_path):
    # no platform information and no Android-only file: the acceleration sign is unknown
    root = write_folder(tmp_path / "a", sl_files("android", with_total=False, metadata=False))
    with pytest.raises(RecordingError, match="cannot tell whether this was recorded on iOS or Android"):
        read_sensorlogger(root)
    assert read_sensorlogger(root, platform="android").device["platform"] == "android"
    # linear acceleration only: cannot restore gravity
    files = sl_files("android", with_total=False, with_gravity=False)
    with pytest.raises(RecordingError, match="without gravity"):
        read_sensorlogger(write_folder(tmp_path / "b", files))
    # non-numeric values (more than one bad line and 1 %, issue #12): file and the first line
    files = sl_files("android")
    lines = files["Gyroscope.csv"].split("\n")
    for k in (5, 50):
        lines[k] = lines[k].replace("0.002", "oops")
    files["Gyroscope.csv"] = "\n".join(lines)
    with pytest.raises(RecordingError, match=r"Gyroscope.csv:6: column 'y' is not a number: 'oops' \(2 bad lines of "
                                             r"150: too many to skip"):
        read_sensorlogger(write_folder(tmp_path / "c", files))
    # missing fields
    files = sl_files("android")
    lines = files["Magnetometer.csv"].split("\n")
    for k in (3, 30):
        lines[k] = ",".join(lines[k].split(",")[:3])
    files["Magnetometer.csv"] = "\n".join(lines)
    with pytest.raises(RecordingError, match=r"Magnetometer.csv:4: missing fields"):
        read_sensorlogger(write_folder(tmp_path / "d", files))
    # missing column
    files = sl_files("android")
    files["Gyroscope.csv"] = files["Gyroscope.csv"].replace("time,seconds_elapsed,z,y,x", "time,seconds_elapsed,z,y,w")
    with pytest.raises(RecordingError, match=r"Gyroscope.csv:1: .*missing column 'x'"):
        read_sensorlogger(write_folder(tmp_path / "e", files))
    # an acceleration that is neither ~g nor ~1
    files = sl_files("android")
    files["TotalAcceleration.csv"] = sl_csv("time,seconds_elapsed,z,y,x",
                                            [(i + 1, i * 0.02, 100.0, 0.0, 0.0) for i in range(5)])
    with pytest.raises(RecordingError, match="cannot establish its unit"):
        read_sensorlogger(write_folder(tmp_path / "f", files))


def test_sensorlogger_platform_message_names_something_a_user_can_set(tmp_path, monkeypatch):
    # issue #12 class 6: the message named only a Python keyword, which the command line does not have
    from core.importers.sensorlogger import PLATFORM_ENV
    root = write_folder(tmp_path / "a", sl_files("android", with_total=False, metadata=False))
    monkeypatch.delenv(PLATFORM_ENV, raising=False)
    with pytest.raises(RecordingError, match=f"set the environment variable {PLATFORM_ENV}=android or "
                                             f"{PLATFORM_ENV}=ios"):
        load_recording(root)
    monkeypatch.setenv(PLATFORM_ENV, "android")
    assert load_recording(root).device["platform"] == "android"
    monkeypatch.setenv(PLATFORM_ENV, "windows")
    with pytest.raises(RecordingError, match=f"unknown platform 'windows' in {PLATFORM_ENV}"):
        load_recording(root)
    # it stands in for a missing Metadata.csv, never overrides one
    monkeypatch.setenv(PLATFORM_ENV, "ios")
    assert load_recording(write_folder(tmp_path / "b", sl_files("android"))).device["platform"] == "android"


def test_sensorlogger_missing_gyroscope_uses_the_uncalibrated_one_and_says_so(tmp_path):
    from core.recording import SensorSubstitutedWarning
    files = sl_files("android")
    files["GyroscopeUncalibrated.csv"] = files.pop("Gyroscope.csv")
    with pytest.warns(SensorSubstitutedWarning, match="no calibrated Gyroscope.csv.*GyroscopeUncalibrated.csv"):
        rec = read_sensorlogger(write_folder(tmp_path / "r", files))
    assert len(rec.streams["gyro"]) == 150
    assert any("'gyro' stream is GyroscopeUncalibrated.csv instead (the OS gyro bias is not removed)" in r
               for r in rec.repairs)
    # with the calibrated file present nothing is said
    rec = read_sensorlogger(write_folder(tmp_path / "s", sl_files("android")))
    assert not any("no calibrated" in r for r in rec.repairs)


def test_sensorlogger_gzip_member_cut_part_way_keeps_its_complete_lines(tmp_path):
    # issue #12 class 4: a cut gzip keeps what came before the damage
    from core.recording import DamagedFileWarning
    files = sl_files("android", n=3000)
    root = write_folder(tmp_path / "rec", files, gz=("Gyroscope.csv",))
    gz = root / "Gyroscope.csv.gz"
    data = gz.read_bytes()
    gz.write_bytes(data[: len(data) // 2])
    with pytest.warns(DamagedFileWarning, match="Gyroscope.csv.gz: the gzip stream is truncated"):
        rec = read_sensorlogger(root)
    n = len(rec.streams["gyro"])
    assert 100 < n < 3000 and len(rec.streams["acc"]) == 3000
    np.testing.assert_allclose(rec.streams["gyro"].values, [[0.001, 0.002, -0.003]] * n)


def test_sensorlogger_acceleration_in_g_is_converted(tmp_path):
    files = sl_files("android")
    files["TotalAcceleration.csv"] = sl_csv("time,seconds_elapsed,z,y,x",
                                            [(i + 1, i * 0.02, *(ACC_B[::-1] / G)) for i in range(5)])
    rec = read_sensorlogger(write_folder(tmp_path / "g", files))
    assert np.allclose(rec.streams["acc"].values, ACC_B)
    assert any("in g" in r for r in rec.repairs)


def test_sensorlogger_acceleration_of_a_swinging_phone_is_accepted_linear_acceleration_is_not(tmp_path):
    T0_NS = 1_700_000_000_000_000_000  # Sensor Logger's 'time': Unix nanoseconds
    n = 400
    t = np.arange(n) * 0.01
    files = sl_files("android")
    # gravity plus an arm's centripetal acceleration of 6-12 m/s^2 towards the shoulder: median |a| ~ 1.5 g
    swing = np.column_stack([6.0 + 6.0 * np.abs(np.sin(2 * np.pi * t)), np.zeros(n), np.full(n, G)])
    files["TotalAcceleration.csv"] = sl_csv("time,seconds_elapsed,z,y,x",
                                            [(T0_NS + i * 10_000_000, t[i], *swing[i, ::-1]) for i in range(n)])
    rec = read_sensorlogger(write_folder(tmp_path / "swing", files))
    med = float(np.median(np.linalg.norm(swing, axis=1)))
    assert 1.4 * G < med < 2.5 * G
    assert np.allclose(rec.streams["acc"].values, swing, rtol=0, atol=1e-9)  # unchanged: already m/s^2
    assert "swinging" in rec.metadata["acc_unit_check"]
    # the same magnitude without gravity passes through zero: not a unit that can be established
    lin = np.column_stack([20.0 * np.sin(2 * np.pi * t), np.zeros(n), np.zeros(n)])
    files["TotalAcceleration.csv"] = sl_csv("time,seconds_elapsed,z,y,x",
                                            [(T0_NS + i * 10_000_000, t[i], *lin[i, ::-1]) for i in range(n)])
    assert 1.4 * G < np.median(np.linalg.norm(lin, axis=1)) < 2.5 * G
    with pytest.raises(RecordingError, match="cannot establish its unit"):
        read_sensorlogger(write_folder(tmp_path / "lin", files))


# ---------------------------------------------------------------------------
# phyphox


def phyphox_csv(heads, rows, delim=",", decimal_comma=False):
    def num(v):
        if v != v:
            return "NaN"  # phyphox's missing value (GPS velocity before the first fix)
        mantissa, exp = f"{v:.9E}".split("E")
        s = f"{mantissa}E{int(exp)}"  # phyphox (Java) writes 9.364549000E-3
        return s.replace(".", ",") if decimal_comma else s
    out = delim.join(f'"{h}"' for h in heads) + "\n"
    for r in rows:
        out += delim.join("" if v is None else num(v) for v in r) + "\n"
    return out


PHY_TIME = ('"event","experiment time","system time","system time text"\n'
            '"START",0.000000000E0,1700000000.000,"2023-11-14 23:13:20.000 UTC+01:00"\n'
            '"PAUSE",2.000000000E0,1700000002.000,"2023-11-14 23:13:22.000 UTC+01:00"\n'
            '"START",2.000000000E0,1700000012.500,"2023-11-14 23:13:32.500 UTC+01:00"\n'
            '"PAUSE",4.000000000E0,1700000014.500,"2023-11-14 23:13:34.500 UTC+01:00"\n')
PHY_DEVICE = ('"property","value"\n"version","1.1.15"\n"build","1011501"\n"deviceModel","Pixel 7"\n'
              '"deviceBrand","google"\n"deviceManufacturer","Google"\n"deviceRelease","14"\n')


def phyphox_files(delim=",", decimal_comma=False, device=PHY_DEVICE):
    ts = [0.01 * i for i in range(400)]  # 4 s of experiment time: 2 s, pause (10.5 s), 2 s
    acc = phyphox_csv(["Time (s)", "Acceleration x (m/s^2)", "Acceleration y (m/s^2)", "Acceleration z (m/s^2)",
                       "Absolute acceleration (m/s^2)"],
                      [(t, *ACC_B, G) for t in ts], delim, decimal_comma)
    gyr = phyphox_csv(["Time (s)", "Gyroscope x (rad/s)", "Gyroscope y (rad/s)", "Gyroscope z (rad/s)",
                       "Absolute (rad/s)"], [(t, 0.001, 0.002, 0.003, 0.0037) for t in ts[::2]], delim, decimal_comma)
    # magnetometer buffer shorter than the time buffer: empty fields at the end
    mag = phyphox_csv(["Time (s)", "Magnetic field x (µT)", "Magnetic field y (µT)", "Magnetic field z (µT)",
                       "Absolute field (µT)"],
                      [(t, *MAG_B, 44.7) for t in ts[::4]] + [(5.0, None, None, None, None)], delim, decimal_comma)
    time_csv, dev = PHY_TIME, device
    if delim != ",":
        time_csv = time_csv.replace(",", delim)
        dev = dev.replace(",", delim)
    if decimal_comma:
        time_csv = "\n".join(ln if i == 0 else ln.replace(".", ",") for i, ln in enumerate(time_csv.split("\n")))
    return {"Raw Data.csv": acc, "Gyroscope.csv": gyr, "Magnetometer.csv": mag,
            "meta/time.csv": time_csv, "meta/device.csv": dev}


def test_phyphox_zip_units_axes_and_pauses(tmp_path):
    z = write_zip(tmp_path / "Acceleration with g 2023-11-14.zip", phyphox_files())
    assert detect_format(z) == "phyphox"
    rec = load_recording(z)
    assert set(rec.streams) == {"acc", "gyro", "mag"}
    assert np.allclose(rec.streams["acc"].values, ACC_B, atol=1e-8)
    assert np.allclose(rec.streams["mag"].values, MAG_B, atol=1e-7)
    assert len(rec.streams["mag"]) == 100 and rec.metadata["rows_dropped_empty"] == 1
    t = rec.streams["acc"].t_ns
    # experiment time 0..1.99 s, then the second run starts 12.5 s after the first START
    assert t[0] == 0 and t[199] == 1_990_000_000
    assert t[200] == 12_500_000_000 and t[399] == 14_490_000_000
    assert rec.metadata["pauses"] == 1
    assert rec.metadata["unix_offset_ns"] == 1_700_000_000_000_000_000
    assert rec.device["platform"] == "android" and rec.device["model"] == "Pixel 7"
    assert rec.metadata["app_version"] == "1.1.15"


def test_phyphox_semicolon_decimal_comma_folder(tmp_path):
    root = write_folder(tmp_path / "phy", {k: v for k, v in phyphox_files(";", True).items() if "/" not in k})
    write_folder(tmp_path / "phy" / "meta", {k.split("/")[1]: v for k, v in phyphox_files(";", True).items()
                                             if "/" in k})
    assert detect_format(root) == "phyphox"
    rec = read_phyphox(root)
    assert np.allclose(rec.streams["acc"].values, ACC_B, atol=1e-8)
    assert rec.streams["acc"].t_ns[200] == 12_500_000_000


def test_phyphox_single_csv_and_ios_device(tmp_path):
    f = tmp_path / "Accelerometer.csv"
    f.write_text(phyphox_files()["Raw Data.csv"])
    assert detect_format(f) == "phyphox"
    rec = load_recording(f)
    assert rec.streams["acc"].t_ns[399] == 3_990_000_000  # no time.csv: experiment time
    assert "unix_offset_ns" not in rec.metadata
    ios = PHY_DEVICE.replace('"google"', '"Apple"').replace("Pixel 7", "iPhone14,5")
    rec = read_phyphox(write_zip(tmp_path / "i.zip", phyphox_files(device=ios)))
    assert rec.device["platform"] == "ios"
    assert np.allclose(rec.streams["acc"].values, ACC_B, atol=1e-8)  # phyphox iOS already uses Android's sign


def test_phyphox_location_speed_and_direction(tmp_path):
    files = phyphox_files()
    # the iOS header of phyphox 1.1.16 (vertical accuracy with a degree sign, as phyphox writes it)
    heads = ["Time (s)", "Latitude (°)", "Longitude (°)", "Height (m)", "Velocity (m/s)", "Direction (°)",
             "Horizontal Accuracy (m)", "Vertical Accuracy (°)"]
    nan = float("nan")
    rows = [(0.5, 52.36, 4.92, 1.0, nan, nan, 35.0, 20.0),  # before the first fix with a velocity
            (1.5, 52.36001, 4.92001, 1.1, 0.27, nan, 12.0, 20.0),
            (2.5, 52.36002, 4.92002, 1.2, 1.31, 241.5, 5.0, 10.0),
            (3.5, 52.36003, 4.92003, 1.3, 1.25, 359.9, 4.9, 10.0)]
    files["Location.csv"] = phyphox_csv(heads, rows)
    rec = read_phyphox(write_zip(tmp_path / "loc.zip", files))
    gps = rec.streams["gps"]
    assert rec.metadata["files_used"]["gps"] == "Location.csv"
    assert np.allclose(gps.values[:, 4:], [[nan, nan], [0.27, nan], [1.31, 241.5], [1.25, 359.9]],
                       rtol=0, atol=1e-6, equal_nan=True)
    assert np.allclose(gps.values[:, 3], [35.0, 12.0, 5.0, 4.9], rtol=0, atol=1e-6)
    # the second run (after the pause at experiment time 2 s) starts 12.5 s after the first START
    assert list(gps.t_ns) == [500_000_000, 1_500_000_000, 13_000_000_000, 14_000_000_000]
    assert "mean sea level" in gps.note


def test_phyphox_errors(tmp_path):
    files = phyphox_files()
    files["Raw Data.csv"] = files["Raw Data.csv"].replace("Acceleration", "Linear Acceleration")
    with pytest.raises(RecordingError, match="only linear acceleration"):
        read_phyphox(write_zip(tmp_path / "lin.zip", files))
    # more bad lines than are skipped (over 1 %, issue #12): the first is named
    files = phyphox_files()
    lines = files["Gyroscope.csv"].split("\n")
    for k in (7, 70, 170):
        lines[k] = lines[k].replace("E-3", "E-3x", 1)
    files["Gyroscope.csv"] = "\n".join(lines)
    with pytest.raises(RecordingError, match=r"lin2.zip/Gyroscope.csv:8: column 'Gyroscope x \(rad/s\)' is not a "
                                             r"number.*\(3 bad lines of 200: too many to skip"):
        read_phyphox(write_zip(tmp_path / "lin2.zip", files))
    files = phyphox_files()
    lines = files["Raw Data.csv"].split("\n")
    for k in (4, 44, 144, 244, 344):
        lines[k] = ",".join(lines[k].split(",")[:2])  # time and x only
    files["Raw Data.csv"] = "\n".join(lines)
    with pytest.raises(RecordingError, match=r"short.zip/Raw Data.csv:5: missing fields: no value for "
                                             r"Acceleration y \(m/s\^2\), Acceleration z"):
        read_phyphox(write_zip(tmp_path / "short.zip", files))
    files = phyphox_files()
    files["meta/time.csv"] = '"event","experiment time"\n"START",0\n'
    with pytest.raises(RecordingError, match="meta/time.csv"):
        read_phyphox(write_zip(tmp_path / "t.zip", files))
    f = tmp_path / "other.csv"
    f.write_text('"Time (s)","Temperature (°C)"\n0.0,21.5\n')
    with pytest.raises(RecordingError, match="no phyphox sensor columns"):
        read_phyphox(f)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(_token, min_size=0, max_size=5), max_size=12))
def test_phyphox_any_rows_give_a_recording_or_a_recording_error(tmp_path, rows):
    f = tmp_path / "fuzz.csv"
    f.write_text('"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"\n'
                 + "".join(",".join(r) + "\n" for r in rows))
    try:
        read_phyphox(f, warn=False)
    except RecordingError as e:
        assert "fuzz.csv" in str(e) and "\n" not in str(e)


def test_gps_check_compares_reported_speed_and_course_with_the_track():
    from core.importers._common import gps_check, gps_values

    n = 120
    t_ns = np.arange(n, dtype=np.int64) * 1_000_000_000
    dist = 1.3 * np.arange(n)  # 1.3 m/s towards bearing 60 deg
    lat0, lon0 = 52.0, 4.9
    lat = lat0 + dist * math.cos(math.radians(60)) / 111_320.0
    lon = lon0 + dist * math.sin(math.radians(60)) / (111_320.0 * math.cos(math.radians(lat0)))
    speed = np.full(n, 1.3)
    speed[:10] = 0.0  # a receiver that reports 0 while the fixes move
    vals = gps_values(lat, lon, None, np.full(n, 4.0), speed, np.full(n, 60.0))
    chk = gps_check(t_ns, vals)
    assert chk["n"] == n and chk["speed_median_m_s"] == pytest.approx(1.3, abs=1e-9)
    assert chk["track_speed_median_m_s"] == pytest.approx(1.3, rel=0.01)
    assert chk["course_vs_track_deg"] < 1.0
    assert chk["zero_speed_while_moving"] == 10
    flipped = gps_values(lat, lon, None, None, speed, np.full(n, 240.0))  # a course 180 deg off
    assert gps_check(t_ns, flipped)["course_vs_track_deg"] > 179.0
    assert math.isnan(gps_check(t_ns[:3], vals[:3])["course_vs_track_deg"])  # 2 s of fixes: no 5 s baseline
    # markers of unknown values: hacc <= 0, negative speed/course, a course of exactly 0; 360 wraps to 0
    v = gps_values([1.0] * 4, [2.0] * 4, None, [0.0, -1.0, 3.0, 5.0], [-1.0, 0.0, 1.0, 2.0], [0.0, -1.0, 360.0, 90.0])
    assert np.allclose(v[:, 3:], [[np.nan, np.nan, np.nan], [np.nan, 0.0, np.nan], [3.0, 1.0, 0.0], [5.0, 2.0, 90.0]],
                       rtol=0, atol=1e-12, equal_nan=True)
    assert np.isnan(v[:, 2]).all()


# ---------------------------------------------------------------------------
# detection and dispatch


def small_recording():
    t = np.arange(5, dtype=np.int64) * 20_000_000
    return Recording({"acc": make_stream("acc", t, np.tile([0.0, 0.0, 9.81], (5, 1)))}, device={"model": "x"})


@pytest.mark.parametrize("name", ["rec.txt", "rec.txt.gz", "rec_gz_without_suffix"])
def test_detect_and_load_pdr_recording(tmp_path, name):
    p = tmp_path / name
    if name.endswith("suffix"):
        write_recording(str(tmp_path / "tmp.gz"), small_recording())
        p.write_bytes((tmp_path / "tmp.gz").read_bytes())
    else:
        write_recording(str(p), small_recording())
    assert detect_format(p) == "pdr-recording"
    rec = load_recording(p)
    assert len(rec.streams["acc"]) == 5 and rec.metadata["source_format"] == "pdr-recording"


@pytest.mark.parametrize("gz", [False, True])
def test_detect_getsensordata_by_content_not_name(tmp_path, gz):
    p = tmp_path / "logfile.dat"  # no telling extension
    data = make_gsd(n=10).encode()
    p.write_bytes(gzip.compress(data) if gz else data)
    assert detect_format(p) == "getsensordata"
    assert len(load_recording(p).streams["acc"]) == 10


def test_unknown_formats_name_the_file_and_the_supported_formats(tmp_path):
    p = tmp_path / "notes.txt"
    p.write_text("hello\nworld\n")
    with pytest.raises(RecordingError) as e:
        load_recording(p)
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg
    for fmt in FORMATS:
        assert fmt in msg
    for content, why in ((b"", "empty file"), (b"\x00\x01\x02binary", "binary")):
        p.write_bytes(content)
        with pytest.raises(RecordingError, match=why):
            detect_format(p)
    with pytest.raises(RecordingError, match="no such file"):
        detect_format(tmp_path / "missing.txt")
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "a.csv").write_text("a,b\n1,2\n")
    with pytest.raises(RecordingError, match="unrecognised recording format"):
        load_recording(tmp_path / "folder")
    write_zip(tmp_path / "x.zip", {"readme.txt": "nothing"})
    with pytest.raises(RecordingError, match="zip archive"):
        load_recording(tmp_path / "x.zip")


def test_imported_recordings_round_trip_through_the_project_format(tmp_path):
    recs = [parse_getsensordata(make_gsd(n=30), "g.txt"),
            read_sensorlogger(write_folder(tmp_path / "sl", sl_files("ios"))),
            read_phyphox(write_zip(tmp_path / "p.zip", phyphox_files()))]
    for i, rec in enumerate(recs):
        out = tmp_path / f"r{i}.txt.gz"
        write_recording(str(out), rec)
        back = read_recording(str(out))
        assert back.metadata == json.loads(json.dumps(rec.metadata))
        for name, s in rec.streams.items():
            assert np.array_equal(back.streams[name].t_ns, s.t_ns)
            assert np.array_equal(back.streams[name].values, s.values, equal_nan=True)


# ---------------------------------------------------------------------------
# real recordings (../shared/data)


def still_windows(acc, gyro, win_s=2.0):
    """Mask of acc samples in 2 s windows where the hand-held phone is nearly still (standing).

    A phone held in front of the face is never quite still: hand tremor gives
    ~0.1 rad/s and ~0.2-0.3 m/s^2 of |acc| spread in the IPIN standing phases.
    """
    t = acc.t_ns
    gi = np.clip(np.searchsorted(gyro.t_ns, t), 0, len(gyro) - 1)
    w = np.linalg.norm(gyro.values[gi], axis=1)
    an = np.linalg.norm(acc.values, axis=1)
    n = max(1, int(round(win_s * acc.rate_hz)))
    k = np.ones(n) / n
    w_avg = np.convolve(w, k, mode="same")
    a_std = np.sqrt(np.maximum(np.convolve(an ** 2, k, mode="same") - np.convolve(an, k, mode="same") ** 2, 0))
    return (w_avg < 0.15) & (a_std < 0.4)


def heading_agreement_deg(rec):
    """Median |rotvec bearing - tilt-compensated magnetometer bearing| over still samples (deg)."""
    acc, gyro, mag, rv = (rec.streams[n] for n in ("acc", "gyro", "mag", "rotvec"))
    still = still_windows(acc, gyro)
    t = acc.t_ns[still]
    a = acc.values[still]
    m = np.stack([np.interp(t, mag.t_ns, mag.values[:, j]) for j in range(3)], axis=1)
    q = rv.values[np.clip(np.searchsorted(rv.t_ns, t), 0, len(rv) - 1)]
    up = a / np.linalg.norm(a, axis=1, keepdims=True)
    east = np.cross(m, up)
    east /= np.linalg.norm(east, axis=1, keepdims=True)
    north = np.cross(up, east)
    mag_bearing = np.degrees(np.arctan2(east[:, 1], north[:, 1]))
    rv_bearing = np.array([bearing_deg(rot(qi)) for qi in q])
    d = (rv_bearing - mag_bearing + 180) % 360 - 180
    return float(np.median(np.abs(d))), int(still.sum())


@needs_ipin
def test_ipin_logfile_loads_fast_with_sane_values():
    path = IPIN / "IPIN2023_T3_TrainingTrial01_repetition01.txt.gz"
    assert detect_format(path) == "getsensordata"
    t0 = time.perf_counter()
    rec = load_recording(path)
    dt = time.perf_counter() - t0
    print(f"\nIPIN logfile load: {dt * 1000:.0f} ms for {sum(rec.metadata['line_counts'].values())} records")
    assert dt < 3.0  # ~0.1-0.2 s on a laptop
    assert rec.repairs == []  # sensor timestamps strictly increasing
    acc, gyro, mag = rec.streams["acc"], rec.streams["gyro"], rec.streams["mag"]
    assert 1 / acc.interval_stats_s()["median_s"] == pytest.approx(50, abs=1)
    assert 1 / gyro.interval_stats_s()["median_s"] == pytest.approx(100, abs=2)  # SM-A520F: gyro at 100 Hz
    still = still_windows(acc, gyro)
    assert still.sum() > 200
    assert np.median(np.linalg.norm(acc.values[still], axis=1)) == pytest.approx(9.8, abs=0.3)
    assert 20 < np.median(np.linalg.norm(mag.values, axis=1)) < 70
    agree, n = heading_agreement_deg(rec)
    assert agree < 20.0, (agree, n)
    assert rec.metadata["ahrs_angles_vs_quaternion_deg"]["max"] < 0.5
    posi = rec.streams["posi"]
    assert len(posi) == 14 and acc.t_ns[0] < posi.t_ns[0] < posi.t_ns[-1] < acc.t_ns[-1]
    assert (posi.t_ns[0] - acc.t_ns[0]) * 1e-9 == pytest.approx(61.4, abs=0.5)  # first landmark at ~61 s
    assert np.array_equal(posi.values[0, :2], posi.values[-1, :2])  # closed loop
    day = datetime.fromtimestamp(rec.metadata["t0_unix_ns"] * 1e-9, tz=timezone.utc)
    assert (day.year, day.month, day.day) == (2023, 6, 14)


@needs_ipin
def test_all_ipin_logfiles_pass_the_loaders_own_checks():
    """The first and the last logfile here; every logfile in the CI guard (benchmarks.guard's
    ipin_loader_checks, for CI's test time: issue #29), whose check is the same."""
    files = sorted(IPIN.glob("*.txt.gz"))
    assert len(files) > 2
    files = [files[0], files[-1]]
    for f in files:
        rec = read_getsensordata(f)
        assert rec.repairs == [], f
        chk = rec.metadata["rotvec_check"]
        assert chk["tilt_err_deg"] < 10 and chk["heading_diff_deg"] < 15, (f.name, chk)
        assert rec.metadata["ahrs_angles_vs_quaternion_deg"]["max"] < 0.5, f.name
        assert rec.metadata["mag_dip_deg"] > 30, f.name  # Nuremberg: field points down
        assert 48 < rec.streams["acc"].rate_hz < 51, f.name


@needs_eth
def test_eth_sensorlogger_walk_loads_with_sane_values():
    assert detect_format(ETH) == "sensorlogger"
    t0 = time.perf_counter()
    rec = load_recording(ETH)
    print(f"\nETH Sensor Logger load: {(time.perf_counter() - t0) * 1000:.0f} ms")
    assert rec.device["platform"] == "android" and rec.device["model"] == "SM-A520F"
    assert rec.metadata["acc_from"] == "TotalAcceleration.csv"
    assert rec.repairs == []
    acc, gyro, mag = rec.streams["acc"], rec.streams["gyro"], rec.streams["mag"]
    assert 1 / acc.interval_stats_s()["median_s"] == pytest.approx(50, abs=1)
    assert 1 / gyro.interval_stats_s()["median_s"] == pytest.approx(50, abs=1)
    first_100s = acc.t_ns < acc.t_ns[0] + 100 * 10**9  # the first ~100 s are still
    assert np.median(np.linalg.norm(acc.values[first_100s], axis=1)) == pytest.approx(9.8, abs=0.4)
    assert 20 < np.median(np.linalg.norm(mag.values, axis=1)) < 70
    assert 60 < np.median(np.linalg.norm(rec.streams["mag_uncal"].values, axis=1)) < 90
    gps = rec.streams["gps"]
    assert 1.0 < gps.rate_hz < 3.0 and np.nanmedian(gps.values[:, 3]) == pytest.approx(4.7, abs=1.0)
    assert np.all(np.abs(gps.values[:, 0] - 47.4) < 0.1)
    assert (rec.t1_ns - rec.t0_ns) * 1e-9 == pytest.approx(702, abs=5)
    # Metadata.csv's "recording time" 2023-03-17_15-50-47 is the start in UTC (Zurich was UTC+1)
    start = datetime.fromtimestamp(rec.metadata["unix_offset_ns"] * 1e-9, tz=timezone.utc)
    assert start.strftime("%Y-%m-%d_%H-%M-%S") == rec.metadata["recording_time"] == "2023-03-17_15-50-47"


# ---------------------------------------------------------------------------
# real outdoor walks with GPS (../shared/data/gps_walks_phone and the ETH walk)

GPS_WALKS = DATA / "gps_walks_phone"
needs_gps_walks = pytest.mark.skipif(not GPS_WALKS.is_dir(), reason="../shared/data/gps_walks_phone not present")

PHY_LOC = ("Time (s)", "Latitude (°)", "Longitude (°)", "Velocity (m/s)", "Direction (°)")
SL_LOC = ("seconds_elapsed", "latitude", "longitude", "speed", "bearing")
#: walk -> (folder, format, location columns (time, lat, lon, speed, course), has a magnetometer, |acc| median range)
WALKS = {
    "bahramib_walk_stan1": (GPS_WALKS / "bahramib_walk_stan1", "phyphox", PHY_LOC, True, (9.5, 11.6)),
    "babur_walking": (GPS_WALKS / "babur_walking", "phyphox", PHY_LOC, True, (9.5, 11.6)),
    # Android, swinging in the hand: the arm's centripetal acceleration lifts the median to ~15 m/s^2
    "liatoutou_walk2": (GPS_WALKS / "liatoutou_walk2", "phyphox", PHY_LOC, False, (14.0, 16.5)),
    "bahramib_walk_beni1": (GPS_WALKS / "bahramib_walk_beni1", "phyphox", PHY_LOC, False, (9.5, 11.6)),
    "siberiawolfp_walking2": (GPS_WALKS / "siberiawolfp_walking2", "sensorlogger", SL_LOC, True, (9.5, 11.6)),
    "eth": (ETH, "sensorlogger", SL_LOC, True, (9.5, 11.6)),
}


def read_csv_columns(folder: Path, name: str) -> dict:
    """``name`` (or ``name.gz``) in ``folder`` as {header: float array}, read with the csv module."""
    path = folder / name if (folder / name).exists() else folder / (name + ".gz")
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8", newline="") as f:
        rows = [r for r in csv.reader(f) if r]
    return {h.strip(): np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}


def csv_fixes(walk: str) -> dict:
    """The walk's Location.csv by the apps' documented rules: time, lat, lon, valid speed and course (nan else)."""
    folder, _fmt, (tc, la, lo, sp, co), _mag, _acc = WALKS[walk]
    c = read_csv_columns(folder, "Location.csv")
    keep = c[tc] >= 0  # Sensor Logger: fixes cached before the start have negative seconds_elapsed
    if _fmt == "phyphox":  # phyphox: the cached last location comes within 0.5 s of each START (issue #25)
        from core.importers.phyphox import _cached_fixes, _read_events

        tf = Path(folder) / "meta" / "time.csv"
        ev = _read_events(tf.read_text(encoding="utf-8-sig"), str(tf)) if tf.exists() else []
        keep = ~_cached_fixes(c[tc], [e for k, e, _ in ev if k == "START"] or [0.0])
    speed, course = c[sp].copy(), c[co].copy()
    speed[~(speed >= 0) | (c.get("speedAccuracy", speed * 0) < 0)] = np.nan
    course[~(course > 0) | (c.get("bearingAccuracy", course * 0) < 0)] = np.nan  # 0.0 = Android's no bearing
    return {"t": c[tc][keep], "lat": c[la][keep], "lon": c[lo][keep], "speed": speed[keep], "course": course[keep]}


def course_vs_track_deg(f: dict, baseline_s=5.0, moving_m_s=0.7) -> float:
    """Median |reported course - bearing of the track to the fix >= baseline_s later| while moving (sphere)."""
    diffs = []
    r = 6_371_000.0
    for i in range(len(f["t"])):
        j = int(np.searchsorted(f["t"], f["t"][i] + baseline_s))
        if j >= len(f["t"]) or not np.isfinite(f["course"][i]):
            continue
        north = math.radians(f["lat"][j] - f["lat"][i]) * r
        east = math.radians(f["lon"][j] - f["lon"][i]) * r * math.cos(math.radians(f["lat"][i]))
        if math.hypot(east, north) / (f["t"][j] - f["t"][i]) > moving_m_s:
            track = math.degrees(math.atan2(east, north))
            diffs.append(abs((f["course"][i] - track + 180.0) % 360.0 - 180.0))
    return float(np.median(diffs))


def gyro_explains_mag(rec, smooth_s=0.1) -> tuple[float, float]:
    """Slope and correlation of dm/dt against -w x m (a rotating phone sees the field turn the other way).

    Holds for a magnetometer and a gyroscope in the same axes, the gyroscope
    in rad/s; not affected by the walker's accelerations.
    """
    m, g = rec.streams["mag"], rec.streams["gyro"]
    n = max(3, int(round(smooth_s * m.rate_hz)))
    k = np.ones(n) / n

    def smooth(x):
        return np.column_stack([np.convolve(x[:, j], k, mode="same") for j in range(3)])[n:-n]

    w = smooth(np.column_stack([np.interp(m.t_ns, g.t_ns, g.values[:, j]) for j in range(3)]))
    mm = smooth(m.values)
    t = m.t_ns[n:-n] * 1e-9
    x = -np.cross(w, mm)[1:-1].ravel()
    y = ((mm[2:] - mm[:-2]) / (t[2:] - t[:-2])[:, None]).ravel()
    return float(x @ y / (x @ x)), float(np.corrcoef(x, y)[0, 1])


@functools.cache
def _walk_recording(folder) -> Recording:
    """``load_recording(folder, warn=False)`` once per process: the tests below check several things of the same
    real walk's load (``warn`` only says whether repaired timestamps also warn; they are in ``repairs`` either way).
    Shared: read it, never change it."""
    return load_recording(folder, warn=False)


@needs_gps_walks
@pytest.mark.parametrize("walk", list(WALKS))
def test_real_walk_units_signs_and_gps_speed_course(walk):
    folder, fmt, _cols, has_mag, (acc_lo, acc_hi) = WALKS[walk]
    assert detect_format(folder) == fmt
    rec = _walk_recording(folder)  # babur, liatoutou: repeated timestamps (listed in rec.repairs)
    acc, gyro = rec.streams["acc"], rec.streams["gyro"]
    an = np.linalg.norm(acc.values, axis=1)
    assert acc_lo < np.median(an) < acc_hi
    # Android sign: the phone faces up while the walker taps start and stop, so +z reads most of +g
    first, last = acc.t_ns < acc.t_ns[0] + 500_000_000, acc.t_ns > acc.t_ns[-1] - 1_000_000_000
    assert np.median(acc.values[first, 2]) > 5.0 and np.median(acc.values[last, 2]) > 5.0
    assert 0.1 < np.median(np.linalg.norm(gyro.values, axis=1)) < 6.0  # rad/s (deg/s would be 57 times more)
    if has_mag and walk != "eth":  # the ETH walk: calibrated field of 22 uT, phone hardly turns (see its test)
        mag = rec.streams["mag"]
        assert 40.0 < np.median(np.linalg.norm(mag.values, axis=1)) < 60.0  # the Netherlands: ~49 uT
        assert rec.metadata["mag_dip_deg"] > 30.0  # the field points down: acc and mag signs agree
        slope, corr = gyro_explains_mag(rec)
        assert 0.85 < slope < 1.1 and corr > 0.8, (slope, corr)
    # GPS: six columns; speed and course as the app reported them, times on the sensors' clock
    gps = rec.streams["gps"]
    assert gps.columns == ("lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg")
    f = csv_fixes(walk)
    speed_median = float(np.nanmedian(f["speed"]))
    assert 0.9 < speed_median < 1.6  # walking
    assert np.nanmedian(gps.values[:, 4]) == pytest.approx(speed_median, abs=0.005)
    assert np.isfinite(gps.values[:, 4]).sum() == np.isfinite(f["speed"]).sum()
    assert np.isfinite(gps.values[:, 5]).sum() == np.isfinite(f["course"]).sum()
    assert np.nanmedian(gps.values[:, 5]) == pytest.approx(np.nanmedian(f["course"]), abs=0.01)
    disagreement = course_vs_track_deg(f)
    assert disagreement < 20.0  # clockwise from north, like the track (a sign or origin error gives ~90-180)
    assert rec.metadata["gps_check"]["course_vs_track_deg"] == pytest.approx(disagreement, abs=3.0)
    assert acc.t_ns[0] - 1_000_000_000 < gps.t_ns[0] and gps.t_ns[-1] < acc.t_ns[-1] + 1_000_000_000


@needs_gps_walks
def test_real_walk_fix_times_are_the_files_times_on_the_sensor_clock():
    # phyphox without a pause: t_ns is the experiment time
    f = csv_fixes("bahramib_walk_stan1")
    gps = _walk_recording(WALKS["bahramib_walk_stan1"][0]).streams["gps"]
    assert np.array_equal(gps.t_ns, np.rint(f["t"] * 1e9).astype(np.int64))
    # Sensor Logger: t_ns + unix_offset_ns is the file's 'time' (Unix ns), the cached fixes left out
    folder = WALKS["siberiawolfp_walking2"][0]
    c = read_csv_columns(folder, "Location.csv")
    with open(folder / "Location.csv", encoding="utf-8", newline="") as fh:
        unix_ns = np.array([int(r[0]) for r in list(csv.reader(fh))[1:] if r])
    rec = _walk_recording(folder)
    gps = rec.streams["gps"]
    kept = c["seconds_elapsed"] >= 0
    assert (~kept).sum() == 2 and len(gps) == kept.sum() == 265
    assert np.array_equal(gps.t_ns + rec.metadata["unix_offset_ns"], unix_ns[kept])
    assert any("before the recording started" in r for r in rec.repairs)
    assert rec.t0_ns >= 0 and gps.t_ns[0] == pytest.approx(0.131e9, abs=1e6)


@needs_gps_walks
def test_real_ios_sensorlogger_acceleration_matches_the_raw_accelerometer():
    """iOS 1.15: Accelerometer.csv (no gravity) + Gravity.csv, both with the iOS sign, against the raw sensor in g."""
    folder = WALKS["siberiawolfp_walking2"][0]
    rec = _walk_recording(folder)
    acc = rec.streams["acc"]
    assert rec.device["platform"] == "ios" and rec.metadata["acc_from"] == "Accelerometer.csv + Gravity.csv"
    raw = read_csv_columns(folder, "AccelerometerUncalibrated.csv")
    t_raw = (raw["seconds_elapsed"] * 1e9).astype(np.int64)
    raw_ms2 = np.column_stack([np.interp(acc.t_ns, t_raw, -G * raw[a]) for a in "xyz"])  # iOS: -g units
    assert np.median(np.linalg.norm(acc.values - raw_ms2, axis=1)) < 0.3
    assert np.median(np.linalg.norm(acc.values + raw_ms2, axis=1)) > 15.0  # the other sign would not fit


@needs_gps_walks
def test_real_android_phyphox_walk_with_a_pause_and_a_swinging_phone():
    folder = WALKS["liatoutou_walk2"][0]
    rec = _walk_recording(folder)
    assert rec.device["platform"] == "android" and rec.metadata["pauses"] == 1
    assert "swinging" in rec.metadata["acc_unit_check"]
    # phyphox wrote some samples twice (same time, same values) and three 10 ms steps back: repaired
    assert any("stream 'acc': 3 timestamp(s) went backwards and 61 repeated" in r for r in rec.repairs)
    # the pause: real time between PAUSE and the next START, in meta/time.csv
    with open(folder / "meta" / "time.csv", encoding="utf-8", newline="") as fh:
        events = [r for r in csv.reader(fh)][1:]
    pause_s = float(events[2][2]) - float(events[1][2])
    assert pause_s == pytest.approx(228.9, abs=0.1)
    acc, gps = rec.streams["acc"], rec.streams["gps"]
    dt = np.diff(acc.t_ns) * 1e-9
    i = int(np.argmax(dt))
    assert dt[i] == pytest.approx(pause_s, abs=0.1)  # one gap in the acceleration, the length of the pause
    j = int(np.searchsorted(gps.t_ns, acc.t_ns[i]))  # and the fixes around it: 155.3 s and 163.9 s experiment time
    assert gps.t_ns[j - 1] <= acc.t_ns[i] and gps.t_ns[j] >= acc.t_ns[i + 1]
    assert (gps.t_ns[j] - gps.t_ns[j - 1]) * 1e-9 == pytest.approx(pause_s + 163.87 - 155.29, abs=0.2)
    # this receiver reports a speed of 0 for minutes of walking: kept as reported, counted in the metadata
    assert rec.metadata["gps_check"]["zero_speed_while_moving"] > 100


def test_the_guards_ipin_loader_checks_report_a_file_that_fails(tmp_path):
    """benchmarks.guard.ipin_loader_checks names a logfile that does not pass (here: one that does not load)."""
    from benchmarks.guard import ipin_loader_checks

    logs = tmp_path / "ipin2023_track3" / "logfiles"
    logs.mkdir(parents=True)
    (logs / "broken.txt.gz").write_bytes(b"not gzip")
    assert ipin_loader_checks(tmp_path / "nowhere") == []
    failures = ipin_loader_checks(tmp_path)
    assert len(failures) == 1 and failures[0].startswith("broken.txt.gz: ")
