"""The pdr command as a user runs it: demo replay, exports, clear one-line errors, never a traceback."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from desktop.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _run(*args):
    return subprocess.run([sys.executable, "-m", "desktop", *args], capture_output=True, text=True, cwd=ROOT)


def test_demo_replay_prints_the_summary_and_writes_every_output(tmp_path):
    out = {k: tmp_path / f"t.{k}" for k in ("csv", "geojson", "gpx", "png")}
    r = _run("replay", "--csv", str(out["csv"]), "--geojson", str(out["geojson"]), "--gpx", str(out["gpx"]),
             "--plot", str(out["png"]))
    assert r.returncode == 0, r.stderr
    assert "steps         227" in r.stdout  # the demo's truth: 227 steps
    assert "truth         227 steps" in r.stdout
    for p in out.values():
        assert p.stat().st_size > 500
    assert out["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    gj = json.loads(out["geojson"].read_text())
    assert len(gj["features"]) == 1 + 227


def test_demo_loop_closes(capsys):
    assert main(["replay", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["n_steps"] == 227
    assert s["start_to_end_m"] < 0.02 * s["distance_m"]


@pytest.mark.parametrize("content,needle", [
    ("", "empty file"),
    ("# pdr-recording 1\n# {\"streams\": {\"acc\": {\"columns\": [\"x\", \"y\", \"z\"]}}}\nacc,1,2,x,4\n",
     ":3: value 'x' of column 'y' is not a number"),
    ("# pdr-recording 1\n# {\"streams\": {\"acc\": {\"columns\": [\"x\", \"y\", \"z\"]}}}\nacc,1,2\nacc,2,1,1,1\n",
     ":3: missing columns"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, content, needle):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    r = _run("replay", str(p))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("pdr: error: ") and str(p) in lines[0] and needle in lines[0]


def test_missing_file_and_missing_sensor_are_clear(tmp_path):
    r = _run("replay", str(tmp_path / "nope.csv"))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "nope.csv" in r.stderr
    p = tmp_path / "gyro_only.csv"
    p.write_text('# pdr-recording 1\n# {"streams": {"gyro": {"columns": ["x", "y", "z"]}}}\ngyro,1,0,0,0\n')
    r = _run("replay", str(p))
    assert r.returncode == 2 and "no 'acc' stream" in r.stderr and "Traceback" not in r.stderr


def test_repaired_timestamps_are_reported_as_a_warning(tmp_path):
    p = tmp_path / "w.csv"
    rows = "".join(f"acc,{t},0.0,0.0,9.81\n" for t in (1000, 3000, 2000, 3000, 4000))
    p.write_text('# pdr-recording 1\n# {"streams": {"acc": {"columns": ["x", "y", "z"]}}}\n' + rows)
    r = _run("replay", str(p))
    assert r.returncode == 0, r.stderr
    assert "pdr: warning:" in r.stderr and "1 timestamp(s) went backwards and 1 repeated" in r.stderr


def test_help_explains_every_option():
    r = _run("replay", "--help")
    assert r.returncode == 0
    for opt in ("--csv", "--geojson", "--gpx", "--plot", "--origin", "--height", "--stride-c", "--declination",
                "--no-mag", "--json", "--progress", "--no-progress", "--gps", "--gps-outage", "--profile", "--mode",
                "--aid", "--detector", "--foot-device", "--waist-device", "--gyro-delay-ms"):
        assert opt in r.stdout


def test_simulate_then_replay_round_trip(tmp_path):
    p = tmp_path / "sq.csv.gz"
    r = _run("simulate", str(p), "--shape", "square", "--rate", "50", "--seed", "4")
    assert r.returncode == 0, r.stderr
    assert _run("info", str(p)).stdout.count("Hz") == 3
    r = _run("replay", str(p), "--json")
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
