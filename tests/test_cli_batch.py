"""`pdr replay` on several recordings and folders: all cores, one table or one JSON document, exports per file."""

import json

import pytest

from desktop.cli import collect_recordings, is_folder_of_recordings, main, unique_stems


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))


@pytest.fixture(scope="module")
def walks(tmp_path_factory):
    """A folder with two short simulated walks (one in a subfolder), a README and a Sensor Logger export folder."""
    root = tmp_path_factory.mktemp("batch")
    (root / "sub").mkdir()
    assert main(["simulate", str(root / "line.csv.gz"), "--shape", "line", "--rate", "50", "--seed", "1"]) == 0
    assert main(["simulate", str(root / "sub" / "turn.csv.gz"), "--shape", "turn", "--rate", "50", "--seed", "2"]) == 0
    (root / "README.md").write_text("# walks\n")
    sl = root / "sensorlogger_export"
    sl.mkdir()
    for name in ("Accelerometer.csv", "Gyroscope.csv", "Magnetometer.csv"):
        (sl / name).write_text("time,seconds_elapsed,z,y,x\n" + "".join(
            f"{1_700_000_000_000_000_000 + k * 10_000_000},{k * 0.01},9.8,0.1,0.0\n" for k in range(50)))
    return root


def test_a_folder_is_searched_and_an_export_folder_is_one_recording(walks):
    assert is_folder_of_recordings(str(walks))
    assert not is_folder_of_recordings(str(walks / "sensorlogger_export"))  # a Sensor Logger folder is a recording
    found, skipped = collect_recordings([str(walks)])
    assert sorted(found) == sorted([str(walks / "line.csv.gz"), str(walks / "sub" / "turn.csv.gz"),
                                    str(walks / "sensorlogger_export")])
    assert skipped == [str(walks / "README.md")]


@pytest.fixture(scope="module")
def batch_json(walks, tmp_path_factory):
    """One batch run in this process (--jobs 1: the same rows as on all cores) with a recording that is bad."""
    tmp = tmp_path_factory.mktemp("batch_out")
    bad = tmp / "bad.csv"
    bad.write_text("# pdr-recording 1\nnot a header\n")
    out_dir = tmp / "out"
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        mp.setenv("PDR_APP_DATA", str(tmp / "app"))
        code = main(["replay", str(walks / "line.csv.gz"), str(walks / "sub"), str(bad), "--json", "--out-dir",
                     str(out_dir), "--jobs", "1", "--progress"])
    return code, out.getvalue(), err.getvalue(), bad, out_dir


def test_batch_json_has_one_row_per_recording_and_exports_go_to_out_dir(walks, batch_json):
    code, out, err, bad, out_dir = batch_json
    doc = json.loads(out)  # the whole of stdout
    assert code == 2  # one recording could not be read
    assert [r["path"] for r in doc["recordings"]] == [str(walks / "line.csv.gz"), str(walks / "sub" / "turn.csv.gz"),
                                                      str(bad)]
    ok = [r for r in doc["recordings"] if r["ok"]]
    assert len(ok) == 2 and doc["n_failed"] == 1 and str(bad) in doc["recordings"][2]["error"]
    for r in ok:
        assert r["summary"]["n_steps"] > 20 and r["summary"]["truth"]["simulator"]["path_m"] > 30
    assert sorted(p.name for p in out_dir.iterdir()) == ["line.csv", "line.geojson", "turn.csv", "turn.geojson"]
    assert "replay: 100.0 %  3/3" in err and "wrote" in err


def test_batch_table_on_all_cores_has_the_rows_of_the_json(walks, batch_json, capsys):
    assert main(["replay", str(walks / "line.csv.gz"), str(walks / "sub" / "turn.csv.gz"), "--jobs", "2"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:3] == ["recording", "tracker", "carried"] and len(table) == 2 + 2 + 2
    for r in json.loads(batch_json[1])["recordings"][:2]:
        s = r["summary"]
        row = next(ln for ln in table if ln.startswith(r["path"]))
        assert f"{s['n_steps']:d}" in row.split() and f"{s['distance_m']:.1f}" in row.split()
        # the carry mode of most of the walking time (the simulated walks are hand-held)
        assert row.split()[1:4] == ["phone", "PDR", "handheld"], row


def test_batch_refuses_single_file_exports(walks, capsys):
    assert main(["replay", str(walks), "--csv", "x.csv"]) == 2
    assert "--out-dir" in capsys.readouterr().err


def test_unique_stems():
    assert unique_stems(["a/walk.txt.gz", "b/walk.csv", "c/other.zip"]) == ["a__walk", "b__walk", "other"]
    assert unique_stems(["x/a/w.csv", "y/a/w.csv"]) == ["x__a__w", "y__a__w"]
