"""The pdr command as a user runs it: demo replay, exports, clear one-line errors, never a traceback."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from desktop.cli import main
from tests._demo_helpers import demo_replay_json

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))  # never the user's own profile (subprocesses too)


def _pdr(capsys, *args) -> subprocess.CompletedProcess:
    """``pdr ARGS`` in this process (``python -m desktop`` is ``sys.exit(main())``): its exit code, stdout and
    stderr as ``subprocess.run`` would give them, without a Python start and the imports (about 0.3 s a call); a
    closed pipe (below) keeps its own process."""
    capsys.readouterr()
    try:
        code = main(list(args))
    except SystemExit as e:  # argparse: --help, usage errors
        code = e.code
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["pdr", *args], code, out.out, out.err)


def test_demo_replay_prints_the_summary_and_writes_every_output(tmp_path, capsys):
    # in this process: CI runs the README's `pdr replay` itself before the tests, and the closed-pipe test below
    # runs `python -m desktop`
    out = {k: tmp_path / f"t.{k}" for k in ("csv", "geojson", "gpx", "png")}
    r = _pdr(capsys, "replay", "--csv", str(out["csv"]), "--geojson", str(out["geojson"]), "--gpx", str(out["gpx"]),
             "--plot", str(out["png"]))
    assert r.returncode == 0, r.stderr
    assert "steps         227" in r.stdout  # the demo's truth: 227 steps
    assert "truth         227 steps" in r.stdout
    for p in out.values():
        assert p.stat().st_size > 500
    assert out["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    gj = json.loads(out["geojson"].read_text())
    assert len(gj["features"]) == 1 + 227
    # how the phone was carried (issue #17): in the summary, and per step, where a counted step is never
    # "not walking" (the demo starts standing: the detector's hysteresis says "still" over its first steps)
    assert "carried       in the hand" in r.stdout
    carry = [ln.rsplit(",", 1)[1] for ln in out["csv"].read_text().splitlines()[1:]]
    assert len(carry) == 227 and set(carry) == {"handheld"}


def test_demo_loop_closes():
    s = json.loads(demo_replay_json())  # pdr replay --json
    assert s["n_steps"] == 227
    assert s["start_to_end_m"] < 0.02 * s["distance_m"]


@pytest.mark.parametrize("content,needle", [
    ("", "empty file"),
    ("# pdr-recording 1\n# {\"streams\": {\"acc\": {\"columns\": [\"x\", \"y\", \"z\"]}}}\nacc,1,2,x,4\n",
     ":3: value 'x' of column 'y' is not a number"),
    ("# pdr-recording 1\n# {\"streams\": {\"acc\": {\"columns\": [\"x\", \"y\", \"z\"]}}}\nacc,1,2\nacc,2,1,1,1\n",
     ":3: missing columns"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, content, needle):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    r = _pdr(capsys, "replay", str(p))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("pdr: error: ") and str(p) in lines[0] and needle in lines[0]


def test_missing_file_and_missing_sensor_are_clear(tmp_path, capsys):
    r = _pdr(capsys, "replay", str(tmp_path / "nope.csv"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "nope.csv" in r.stderr
    p = tmp_path / "gyro_only.csv"
    p.write_text('# pdr-recording 1\n# {"streams": {"gyro": {"columns": ["x", "y", "z"]}}}\ngyro,1,0,0,0\n')
    r = _pdr(capsys, "replay", str(p))
    assert r.returncode == 2 and "no 'acc' stream" in r.stderr and "Traceback" not in r.stderr


def test_repaired_timestamps_are_reported_as_a_warning(tmp_path, capsys):
    p = tmp_path / "w.csv"
    rows = "".join(f"acc,{t},0.0,0.0,9.81\n" for t in (1000, 3000, 2000, 3000, 4000))
    p.write_text('# pdr-recording 1\n# {"streams": {"acc": {"columns": ["x", "y", "z"]}}}\n' + rows)
    r = _pdr(capsys, "replay", str(p))
    assert r.returncode == 0, r.stderr
    assert "pdr: warning:" in r.stderr and "1 timestamp(s) went backwards and 1 repeated" in r.stderr


def test_help_explains_every_option(capsys):
    r = _pdr(capsys, "replay", "--help")
    assert r.returncode == 0
    for opt in ("--csv", "--geojson", "--gpx", "--plot", "--origin", "--height", "--stride-c", "--declination",
                "--no-mag", "--json", "--progress", "--no-progress", "--gps", "--gps-outage", "--profile", "--mode",
                "--aid", "--detector", "--foot-device", "--waist-device", "--gyro-delay-ms", "--out-dir", "--export",
                "--jobs", "--no-profile"):
        assert opt in r.stdout
    from core.importers import FORMATS
    flat = " ".join(r.stdout.split()).replace("- ", "-")  # argparse wraps at a hyphen
    missing = [name for name in FORMATS if name not in flat]
    assert not missing, missing  # every format replay detects is named (the help named four of twenty)


def test_simulate_then_replay_round_trip(tmp_path, capsys):
    p = tmp_path / "out" / "sq.csv.gz"  # a folder that does not exist yet, as out/ on a fresh clone (#29)
    r = _pdr(capsys, "simulate", str(p), "--shape", "square", "--rate", "50", "--seed", "4")
    assert r.returncode == 0, r.stderr
    info = _pdr(capsys, "info", str(p)).stdout.splitlines()
    head = next(k for k, ln in enumerate(info) if ln.startswith("stream"))
    table = info[head:head + 4]
    assert [ln.split()[0] for ln in table[1:]] == ["acc", "gyro", "mag"]
    for col in ("events", "rate Hz", "jitter ms", "gaps"):  # every number ends under the end of its header
        end = table[0].index(col) + len(col)
        assert all(ln[end - 1] != " " and ln[end] == " " for ln in table[1:]), (col, table)
    r = _pdr(capsys, "replay", str(p), "--json")
    s = json.loads(r.stdout)
    assert s["start_to_end_m"] < 0.03 * s["distance_m"]


def test_progress_shows_after_two_seconds_tty_or_not(capsys):
    from desktop.cli import _Progress

    now = [0.0]
    log = _Progress("replay", tty=False, clock=lambda: now[0])
    for k in range(0, 101):
        now[0] = 0.05 * k  # 5 s in all
        log(k / 100)
    err = capsys.readouterr().err.splitlines()
    assert err and all(line.startswith("replay:") for line in err)
    assert float(err[0].split()[1]) >= 40.0  # nothing before 2 s (40 %)
    assert len(err) <= 8 and err[-1].split()[1] == "100.0"  # a line per 10 % in a log, and the end
    quick = _Progress("replay", tty=True, clock=lambda: 0.5)
    quick(0.5)
    quick(1.0)
    assert capsys.readouterr().err == ""  # done in half a second: nothing shown
    off = _Progress("replay", enabled=False, clock=lambda: 100.0)
    off(0.5)
    assert capsys.readouterr().err == ""


def test_a_fifo_is_refused_in_one_line(tmp_path, capsys):
    import os

    from desktop.cli import main

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert main(["replay", str(fifo)]) == 2
    err = capsys.readouterr().err
    assert "not a regular file" in err and str(fifo) in err


def test_info_help_describes_every_column(capsys):
    r = _pdr(capsys, "info", "--help")
    for col in ("stream", "events", "rate Hz", "jitter ms", "gaps", "rate chg", "columns [unit]"):
        assert f"  {col} " in r.stdout


@pytest.fixture(scope="module")
def _square_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("square") / "sq.csv"
    assert main(["simulate", str(p), "--shape", "square", "--rate", "50", "--seed", "4"]) == 0
    return p


@pytest.fixture
def square(_square_file, capsys):
    capsys.readouterr()
    return _square_file


def test_json_stays_json_with_exports_and_csv_dash_is_stdout_with_lat_lon(square, tmp_path, capsys):
    import csv
    import io

    from core.geodesy import geodetic_to_enu

    p = square
    assert main(["replay", str(p), "--json", "--geojson", str(tmp_path / "o" / "t.geojson"), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["n_steps"] > 100  # the whole of stdout is one JSON document
    assert "wrote" in err and (tmp_path / "o" / "t.geojson").exists()
    assert main(["replay", str(p), "--csv", "-", "--origin", "47.3769,8.5417", "--no-progress"]) == 0
    out, err = capsys.readouterr()
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) > 100 and float(rows[-1]["distance_m"]) > 50
    assert "steps " in err  # the summary went to stderr
    lat = [float(r["lat_deg"]) for r in rows]
    lon = [float(r["lon_deg"]) for r in rows]
    e, n = geodetic_to_enu(lat, lon, (47.3769, 8.5417))  # placed where the local metres say
    assert max(abs(e - [float(r["east_m"]) for r in rows])) < 0.01
    assert max(abs(n - [float(r["north_m"]) for r in rows])) < 0.01
    assert main(["replay", str(p), "--json", "--csv", "-"]) == 2
    assert "both want stdout" in capsys.readouterr().err


def test_a_track_not_placed_has_no_lat_lon(tmp_path):
    import numpy as np

    from core.pdr.pipeline import Track
    from desktop.cli import _write_track_csv

    tr = Track(np.array([1, 2], dtype=np.int64), np.ones(2), np.zeros(2), np.array([1.0, 2.0]), np.zeros(2))
    _write_track_csv(str(tmp_path / "t.csv"), tr, None)
    assert "lat_deg" not in (tmp_path / "t.csv").read_text().splitlines()[0]
    _write_track_csv(str(tmp_path / "t.csv"), tr, (10.0, 20.0))
    assert (tmp_path / "t.csv").read_text().splitlines()[0].endswith(",lat_deg,lon_deg")


@pytest.mark.parametrize("where,needle", [
    ("{f}/x.csv", "is a file, not a folder"),  # a parent that is a file
    ("{d}", "is a folder"),
    ("/proc/pdr-no-such-folder/x.gpx", "cannot write there"),  # a folder that cannot be made
])
def test_a_bad_output_path_exits_2_before_the_run(square, tmp_path, capsys, monkeypatch, where, needle):
    p = square
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    capsys.readouterr()

    def no_run(*a, **k):
        raise AssertionError("the pipeline ran before the output path was checked")

    monkeypatch.setattr("core.pdr.pipeline.Pipeline.run", no_run)
    bad = where.format(f=tmp_path / "afile", d=tmp_path / "adir")
    assert main(["replay", str(p), "--gpx", bad]) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert out == "" and len(lines) == 1 and lines[0].startswith("pdr: error: --gpx ") and needle in lines[0]


def test_calibrate_stores_the_profile_and_replay_uses_it(square, tmp_path, capsys):
    from core.pdr.calibration import UserProfile
    from core.recording import read_recording

    p = square
    true_m = read_recording(str(p)).metadata["truth"]["path_length_m"]  # the square's walked length
    capsys.readouterr()
    assert main(["calibrate", str(p), "--distance", f"{true_m}", "--height", "1.8", "--json", "--no-progress"]) == 0
    doc = json.loads(capsys.readouterr().out)
    stored = tmp_path / "app" / "profile.json"
    prof = UserProfile.load(stored)
    assert doc["profile_path"] == str(stored) and prof.height_m == 1.8
    assert prof.c_scale == pytest.approx(true_m / doc["model_distance_m"], rel=1e-9) == doc["c_scale"]
    assert main(["replay", str(p), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert f"profile       {stored}: stride x{prof.c_scale:.3f} on model default (1 calibration walk)" in out
    assert "distance +0.0 %" in out  # the walk it was calibrated on: exact
    from desktop.cli import choose_profile, make_parser

    assert choose_profile(make_parser().parse_args(["replay", str(p), "--no-profile"])) == (None, None, False)
    assert choose_profile(make_parser().parse_args(["replay"]), demo=True)[0] is None  # the demo is nobody's walk


def test_an_accelerometer_only_recording_gets_steps_and_distance_not_a_made_up_track(tmp_path, capsys):
    from core.recording import Recording, write_recording
    from desktop.simulator import simulate_walk

    w = simulate_walk(((0.0, 0.0), (15.0, 0.0), (15.0, 10.0)), seed=8, rate_hz=50.0, still_start_s=1.0, still_end_s=1.0)
    path = tmp_path / "acc-only.csv"
    write_recording(str(path), Recording({"acc": w.recording.streams["acc"]}, device=w.recording.device,
                                         metadata=w.recording.metadata))
    png, out_csv = tmp_path / "steps.png", tmp_path / "steps.csv"
    assert main(["replay", str(path), "--plot", str(png), "--csv", str(out_csv)]) == 0
    out = capsys.readouterr().out
    assert "heading       none" in out and "final pos" not in out and "degraded" not in out
    assert png.stat().st_size > 1000
    rows = out_csv.read_text().strip().splitlines()
    assert len(rows) > 10 and all(r.split(",")[5] == "nan" for r in rows[1:])  # east_m: no position invented
    assert main(["replay", str(path), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["heading"] == "none" and s["final_east_m"] is None and s["n_steps"] > 10
    assert main(["replay", str(path), "--geojson", str(tmp_path / "x.geojson")]) == 2  # refused, nothing written
    assert not (tmp_path / "x.geojson").exists()


@pytest.mark.parametrize("height, says", [("175", "centimetres"), ("0.4", "plausible"), ("tall", "number")])
def test_height_is_metres_and_range_checked(height, says, capsys):
    with pytest.raises(SystemExit) as e:
        main(["replay", "--height", height])
    assert e.value.code == 2 and says in capsys.readouterr().err


def test_an_accelerometer_too_slow_for_steps_is_said_not_scored(tmp_path, capsys):
    from core.recording import Recording, make_stream, write_recording
    from desktop.simulator import simulate_walk

    w = simulate_walk(((0.0, 0.0), (15.0, 0.0)), seed=9, still_start_s=1.0, still_end_s=1.0)
    acc = w.recording.streams["acc"]
    slow = make_stream("acc", acc.t_ns[::50], acc.values[::50])  # 100 Hz -> 2 Hz
    path = tmp_path / "slow.csv"
    write_recording(str(path), Recording({"acc": slow}, device=w.recording.device, metadata=w.recording.metadata))
    assert main(["replay", str(path), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "not measured: the accelerometer is sampled at 2.0 Hz" in out and "truth error" not in out


@pytest.mark.parametrize("rate_hz, measured", [(9.96, True), (9.0, False)])
def test_a_nominal_10_hz_export_counts_its_steps(tmp_path, capsys, rate_hz, measured):
    """A 10 Hz phone export measures a little under 10 Hz from its timestamps (9.99 Hz on a real phyphox walk
    that counts its steps): within 5 % of MIN_STEP_RATE_HZ the steps are measured; 9 Hz is refused."""
    from core.recording import write_recording
    from desktop.simulator import simulate_walk

    walk = simulate_walk([(0, 0), (0, 20)], rate_hz=rate_hz, seed=3)
    path = tmp_path / "walk.csv"
    write_recording(str(path), walk.recording)
    assert main(["replay", str(path), "--json", "--no-progress", "--gps", "off"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s.get("steps_measured", True) is measured


def test_a_closed_pipe_is_not_an_error():
    """`pdr info X | head -1` (issue #29): the reader closed the pipe before pdr wrote; exit 0, nothing on stderr."""
    demo = ROOT / "desktop" / "data" / "demo_walk.csv.gz"
    proc = subprocess.Popen([sys.executable, "-m", "desktop", "info", str(demo)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # before the child has imported anything: its first write meets a closed pipe
    err = proc.stderr.read()
    proc.wait(timeout=60)
    assert proc.returncode == 0 and err == "", (proc.returncode, err)
