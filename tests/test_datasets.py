"""Benchmark dataset readers: on small files made here, and on the real data when ../shared/data is present."""

import csv
import gzip
import math

import numpy as np
import pytest

from benchmarks.datasets import brajdic_harle, ipin2023, ms_indoor, oxford
from benchmarks.datasets.base import Trial, default_data_root
from benchmarks.metrics import polyline_length

ROOT = default_data_root()


def needs(module):
    return pytest.mark.skipif(not (ROOT.is_dir() and module.available(ROOT)),
                              reason=f"{module.NAME} not in {ROOT}")


# ---------------------------------------------------------------------------
# readers on files made here


def test_foot_switch_steps_are_rising_edges(tmp_path):
    p = tmp_path / "stepcounter.csv"
    p.write_text("100,0,1\n200,1,1\n300,1,0\n400,1,1\n500,0,1\n600,0,0\n700,1,0\n")
    np.testing.assert_array_equal(oxford.foot_switch_steps(p), [200, 400, 700])


def test_oxford_validation_file(tmp_path):
    d = tmp_path / oxford.NAME / "validation"
    d.mkdir(parents=True)
    rows = [[1_000_000_000 + 10_000_000 * i, 0.1, 0.2, 9.8, i // 50, i // 40, 0] for i in range(200)]
    with open(d / "user1_frontpocket.csv", "w") as f:
        f.write("\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    (trial,) = oxford.trials(tmp_path)
    assert trial.placement == "front_pocket"
    assert trial.step_count == 4 and len(trial.step_t_ns) == 4
    assert trial.peer_step_counts == {"app": 3}  # the hardware counter stays 0: not a peer
    rec = trial.open()
    assert rec.streams["acc"].values.shape == (200, 3)


def test_brajdic_harle_binary_and_text_agree(tmp_path):
    n = 30
    t = 5_000_000_000 + np.repeat(np.arange(n), 3) * 10_000_000
    typ = np.tile([1, 2, 3], n)
    v = np.arange(3 * n * 3, dtype=np.float32).reshape(-1, 3)
    rec = np.zeros(3 * n, dtype=brajdic_harle.RECORD)
    rec["t"], rec["type"], rec["v"] = t, typ, v
    name = "p1.1_Female_20-29_170-179cm_Hand_held"
    rec.tofile(tmp_path / f"{name}.out")
    with gzip.open(tmp_path / f"{name}.dat.gz", "wt") as f:
        for row in rec:
            f.write(f"{row['t']} {row['type']} {row['v'][0]} {row['v'][1]} {row['v'][2]}\n")
    a = brajdic_harle.read_trace(tmp_path / f"{name}.out")
    b = brajdic_harle.read_trace(tmp_path / f"{name}.dat.gz")
    for s in ("acc", "gyro", "mag"):
        np.testing.assert_array_equal(a.streams[s].t_ns, b.streams[s].t_ns)
        np.testing.assert_allclose(a.streams[s].values, b.streams[s].values)
    np.testing.assert_allclose(a.streams["gyro"].values[0], [3, 4, 5])
    assert brajdic_harle.walk_window_t_ns(a, (2, 10)) == (5_020_000_000, 5_100_000_000)


def test_ms_trace_parser(tmp_path):
    lines = ["#\tstartTime:1000", "#\tBrand:X\tModel:Y", "1000\tTYPE_WAYPOINT\t10.0\t20.0"]
    for k in range(5):
        t = 1000 + 20 * k
        lines += [f"{t}\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3", f"{t}\tTYPE_GYROSCOPE\t0.0\t0.0\t0.1\t3",
                  f"{t}\tTYPE_MAGNETIC_FIELD\t0.0\t20.0\t-40.0\t3", f"{t}\tTYPE_ROTATION_VECTOR\t0.0\t0.0\t0.6\t3"]
    lines.append("1060\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.81061\tTYPE_GYROSCOPE\t0\t0\t0\t3")  # a line without newline
    lines.append("1100\tTYPE_WAYPOINT\t13.0\t24.0")
    p = tmp_path / "trace.txt"
    p.write_text("\n".join(lines) + "\n")
    rec, lm, header = ms_indoor.parse_trace(p)
    assert header["Model"] == "Y" and rec.device["Model"] == "Y"
    assert len(rec.streams["acc"]) == 5 and rec.streams["acc"].t_ns[1] == 1_020_000_000
    np.testing.assert_allclose(rec.streams["rotvec"].values[0], [0.8, 0.0, 0.0, 0.6])
    np.testing.assert_array_equal(lm.t_ns, [1_000_000_000, 1_100_000_000])
    assert polyline_length(lm.east_m, lm.north_m) == pytest.approx(5.0)
    assert any("malformed" in r for r in rec.repairs)


def test_trial_open_resolves_ground_truth():
    calls = []
    t = Trial(dataset="d", name="n", load=lambda: "rec", info={"a": 1},
              resolve=lambda rec: calls.append(rec) or {"step_count": 7, "info": {"b": 2}})
    assert t.open() == "rec" and calls == ["rec"]
    assert t.step_count == 7 and t.info == {"a": 1, "b": 2}


# ---------------------------------------------------------------------------
# the real data


@needs(oxford)
def test_oxford_real_counts_match_the_authors_stats():
    trials = {t.name: t for t in oxford.trials(ROOT)}
    assert len(trials) == 48 and not any(n.startswith("_Patient") for n in trials)
    with open(ROOT / oxford.NAME / "optimisation" / "stats.csv") as f:
        stats = {row[0].strip(): int(row[-1]) for row in csv.reader(f) if row and not row[0].startswith("#")}
    for name, t in trials.items():
        assert t.step_count == stats[name], name
    assert {t.placement for t in trials.values()} == {"hand", "front_pocket", "back_pocket", "armband",
                                                      "neck_pouch", "bag", "swinging_hand"}
    assert trials["Samsung_Carmelo_Hard_FrontPocket_1"].peer_step_counts == {"notes": 271}
    rec = trials["Nexus_Jamie_Hard_InHand_1"].open()
    acc = rec.streams["acc"]
    assert 190 < acc.rate_hz < 210
    assert 9.0 < np.mean(np.linalg.norm(acc.values, axis=1)) < 10.5
    st = trials["Nexus_Jamie_Hard_InHand_1"].step_t_ns
    assert acc.t_ns[0] <= st[0] and st[-1] <= acc.t_ns[-1]  # one clock


@needs(brajdic_harle)
def test_brajdic_harle_real():
    trials = {t.name: t for t in brajdic_harle.trials(ROOT)}
    assert len(trials) == 14
    t = trials["p1.1"]
    assert t.step_count == 70 and t.subject["height_m"] == pytest.approx(1.75) and t.placement == "hand"
    assert trials["p19.1"].step_count is None
    rec = t.open()
    acc = rec.streams["acc"]
    assert t.walk_t_ns == (int(acc.t_ns[1607]), int(acc.t_ns[5393]))
    for s in ("acc", "gyro", "mag"):
        assert 95 < rec.streams[s].rate_hz < 105
    assert 9.0 < np.mean(np.linalg.norm(acc.values, axis=1)) < 10.0
    assert len(trials["p27.1"].open().streams["acc"]) == 12083  # the gzip text trace


@needs(ipin2023)
def test_ipin_real_landmarks_are_closed_loops_on_the_sensor_clock():
    pytest.importorskip("core.importers.getsensordata")
    trials = ipin2023.trials(ROOT)
    assert len(trials) == 32
    with open(ROOT / ipin2023.NAME / "my_summary.csv") as f:
        summary = {row["file"].split(".")[0]: row for row in csv.DictReader(f)}
    for t in trials[::7]:
        rec = t.open()
        lm = t.landmarks
        row = summary[[k for k in summary if f"Trial{t.info['route']}_repetition{t.info['repetition']}" in k][0]]
        assert len(lm.t_ns) == int(row["n_posi"])
        # the summary used a spherical Earth; WGS-84 radii at 49.5 N are up to 0.3 % longer
        assert polyline_length(lm.east_m, lm.north_m) == pytest.approx(float(row["posi_polyline_m"]), rel=0.005)
        assert math.hypot(lm.east_m[-1] - lm.east_m[0], lm.north_m[-1] - lm.north_m[0]) < 0.01
        first_s = (lm.t_ns[0] - rec.streams["acc"].t_ns[0]) * 1e-9
        assert abs(first_s - float(row["first_posi_s"])) < 1.0
        assert rec.has("rotvec") and rec.has("gyro") and rec.has("mag")
        assert t.info["phone"] == row["phone"]
        assert math.degrees(t.declination_rad) == pytest.approx(4.01, abs=0.01) and t.site is ipin2023.SITE


@needs(ms_indoor)
def test_ms_real_traces():
    trials = ms_indoor.trials(ROOT)
    assert len(trials) >= 30
    info = ROOT / ms_indoor.NAME / "site2" / "F3" / "floor_info.json"
    import json

    size = json.loads(info.read_text())["map_info"]
    for t in trials[::6]:
        lm = t.landmarks
        assert len(lm.t_ns) >= 3 and np.all(np.diff(lm.t_ns) >= 0)
        assert np.all((lm.east_m >= 0) & (lm.east_m <= size["width"]))
        assert np.all((lm.north_m >= 0) & (lm.north_m <= size["height"]))
        rec = t.open()
        for s in ("acc", "gyro", "mag", "rotvec"):
            assert 45 < rec.streams[s].rate_hz < 55, s
        np.testing.assert_allclose(np.linalg.norm(rec.streams["rotvec"].values, axis=1), 1.0, atol=1e-6)
        assert rec.t0_ns - 1_000_000_000 <= lm.t_ns[0] <= rec.t1_ns


# ---------------------------------------------------------------------------
# splits


def test_split_declarations():
    from benchmarks import splits as S

    assert [S.split_of("ipin2023_track3", {"route": r}) for r in ("01", "02", "21", "22")] == ["tuning"] * 4
    assert [S.split_of("ipin2023_track3", {"route": r}) for r in ("04", "05", "23", "24")] == ["report"] * 4
    # an undeclared route was never tuned on: report, and not declared
    assert S.split_of("ipin2023_track3", {"route": "03"}) == "report"
    assert not S.declared("ipin2023_track3", {"route": "03"}) and S.declared("ipin2023_track3", {"route": "21"})
    assert [S.split_of("ms_indoor_location_2020", {"file_no": k}) for k in (1, 2, 3, 4)] == \
        ["tuning", "report", "tuning", "report"]
    for ds in ("oxford_step_counter", "brajdic_harle_handheld", "trundlewheel_distance", "sensorlogger_gps_walk_ethz"):
        assert S.split_of(ds) == "report"
    assert S.split_of("ipol_healthy_gait_xsens") == "tuning"
    assert S.split_of("some_new_dataset") == "report" and not S.declared("some_new_dataset")
    # issue #25: the real corpus by repository, a third tuning
    assert S.split_of("phone_walks_more", {"walk": "thomasdingemanse_lopen"}) == "tuning"
    assert [S.split_of("phone_walks_more", {"walk": w}) for w in ("kim66003_walking_2020-06-03_15-13-20", "aymdi_data")] \
        == ["report"] * 2
    assert S.split_of("anything", {"repository": "thomasdingemanse/ML4QS"}) == "tuning"
    assert S.split_of("anything", {"repository": "someone/else"}) == "report"
    # the extra corpus (declared 2026-12-06 before any number): fif911 tuning, mikamartinb report
    assert S.repo_split("fif911/ML4QS") == "tuning" and S.repo_split("mikamartinb/ML4QS") == "report"
    # the second search's clip (declared 2026-12-06, the rule's 4th extra repository): tuning
    assert S.repo_split("psy901/SensorActivity") == "tuning"
    assert S.repo_split("parabiomech/25.GPS-TRACKING") == "report"
    # the fourth search (declared 2026-12-07, the rule's 7th repository): tuning; sgrzegorz, Omer1Eryilmaz report
    assert S.repo_split("yh570/sensibility_testbed") == "tuning"
    assert S.repo_split("zDrakon/SensorDataExplorer") == "report"  # the 8th, declared the same day
    assert S.repo_split("sgrzegorz/StepApp") == S.repo_split("Omer1Eryilmaz/SignalProcessing") == "report"
    # the fifth search (declared 2026-12-07, in order of addition): the 9th report, the 10th tuning
    assert S.repo_split("NIghtwing1914/Assignment2-Ubicomp") == "report"
    assert S.repo_split("Tclack88/MatlabSucks") == "tuning"
    # the seventh search (OxIOD truth walks, declared 2026-12-07 by sequence): every third per placement from the first
    ox = S.OXIOD_TRUTH_DATASET
    tun = [("handheld", "data1", 2), ("handheld", "data1", 7), ("pocket", "data1", 5), ("running", "data1", 6),
           ("trolley", "data1", 7), ("trolley", "data2", 3), ("trolley", "data2", 6)]
    rep = [("handheld", "data1", 3), ("handheld", "data1", 4), ("running", "data1", 7)] + \
        [("trolley", "data2", k) for k in (1, 2, 4, 5)]
    for (pl, d, k), want in [(t, "tuning") for t in tun] + [(r, "report") for r in rep]:
        info = {"placement": pl, "data_folder": d, "sequence": k}
        assert S.split_of(ox, info) == want and S.declared(ox, info), (pl, d, k)
    other = {"placement": "handbag", "data_folder": "data1", "sequence": 1}
    assert S.split_of(ox, other) == "report" and not S.declared(ox, other)
    # the same search's RIDI copies (declared 2026-12-07 by sequence, the same rule): 11 of 28 tuning
    rd = S.RIDI_TRUTH_DATASET
    assert len(S.RIDI_DECLARED_SEQUENCES) == 28 and len(S.RIDI_TUNING_SEQUENCES) == 11
    assert S.split_of(rd, {"sequence": "dan_leg1"}) == "tuning" and S.split_of(rd, {"sequence": "hao_leg2"}) == "report"
    assert S.split_of(rd, {"sequence": "hang_bag_side1"}) == "report" and S.declared(rd, {"sequence": "hang_bag_side1"})
    assert S.split_of(rd, {"sequence": "tang_bag1"}) == "report" and not S.declared(rd, {"sequence": "tang_bag1"})
    from benchmarks.run import DATASET_MODULES
    import importlib

    for mod in DATASET_MODULES:  # every dataset the benchmark runs has a declaration
        name = importlib.import_module(f"benchmarks.datasets.{mod}").NAME
        assert name in S.WHOLE_DATASET or name in ("ipin2023_track3", "ms_indoor_location_2020"), name


def test_ms_split_numbers_files_in_the_sorted_folder(tmp_path):
    folder = tmp_path / ms_indoor.NAME / "site9" / "F1" / "path_data_files"
    folder.mkdir(parents=True)
    wp = "".join(f"{1000 + 100 * k}\tTYPE_WAYPOINT\t{k}.0\t0.0\n" for k in range(3))
    for name, text in (("b.txt", wp), ("a.txt", "1000\tTYPE_WAYPOINT\t0.0\t0.0\n"), ("c.txt", wp)):
        (folder / name).write_text(text)
    trials = ms_indoor.trials(tmp_path)
    # a.txt (file 1) has too few waypoints and is skipped, but still counts for the numbering
    assert [(t.name.split("/")[-1], t.info["file_no"]) for t in trials] == [("b", 2), ("c", 3)]
    from benchmarks.splits import trial_split

    assert [trial_split(t) for t in trials] == ["report", "tuning"]


def test_site_declinations_come_from_the_world_magnetic_model():
    pytest.importorskip("pygeomag")
    # WMM2020 at Nuremberg 2023-06 and WMM2015v2 at Hangzhou 2019-11 (NOAA's calculator: +4.0 and -5.7 deg)
    assert math.degrees(ipin2023.SITE.magnetic_field()[0]) == pytest.approx(4.01, abs=0.01)
    assert math.degrees(ms_indoor.SITE.magnetic_field()[0]) == pytest.approx(-5.68, abs=0.01)


def test_eth_reader_takes_the_gps_out_of_the_recording():
    from benchmarks.datasets import eth_walk
    from core.recording import Recording, make_stream

    t = np.array([0, 1, 2, 3], dtype=np.int64) * 1_000_000_000 + 500_000_000
    gps = np.array([[47.0, 8.0, 500.0, 24.0],  # a coarse first fix: not reference
                    [47.0, 8.0, 500.0, 5.0], [47.0001, 8.0, 500.0, 4.0], [47.0002, 8.0, 500.0, np.nan]])
    acc = make_stream("acc", t, np.tile([0.0, 0.0, 9.81], (4, 1)))
    rec = Recording({"acc": acc, "gps": make_stream("gps", t, gps)}, metadata={"unix_offset_ns": 1679068247199000000})
    fields = eth_walk.split_off_gps(rec)
    assert not rec.has("gps") and rec.has("acc")
    ref = fields["reference_track"]
    np.testing.assert_array_equal(ref.t_ns, t[1:])
    np.testing.assert_allclose(ref.north_m, [0.0, 11.12, 22.24], atol=0.01)
    np.testing.assert_allclose(ref.east_m, 0.0, atol=1e-9)
    assert fields["site"].lat_deg == 47.0 and fields["site"].alt_m == 500.0
    assert fields["site"].when.year == 2023
    assert math.degrees(fields["declination_rad"]) == pytest.approx(3.2, abs=0.3)  # WMM2020 near Zurich
    assert fields["info"]["gps_fixes_dropped"] == 1
    with pytest.raises(ValueError, match="no GPS"):
        eth_walk.split_off_gps(rec)


@needs(__import__("benchmarks.datasets.eth_walk", fromlist=["NAME"]))
def test_eth_real_walk():
    from benchmarks.datasets import eth_walk

    trials = eth_walk.trials(ROOT)
    assert len(trials) == 1
    t = trials[0]
    rec = t.open()
    assert not rec.has("gps") and rec.has("acc") and rec.has("gyro") and rec.has("mag")
    ref = t.reference_track
    assert len(ref.t_ns) > 1000 and np.all(np.diff(ref.t_ns) > 0)
    assert np.nanmax(ref.hacc_m) <= eth_walk.MAX_HACC_M
    # README: GPS path about 694 m, of which ~65 m is the jump from the dropped coarse first fixes
    assert 600 < polyline_length(ref.east_m, ref.north_m) < 700
    assert rec.t0_ns <= ref.t_ns[0] and ref.t_ns[-1] <= rec.t1_ns + 1_000_000_000
    assert math.degrees(t.declination_rad) == pytest.approx(3.26, abs=0.02)
    assert t.placement == "hand_flat"


@needs(ipin2023)
def test_ipin_real_splits_by_route():
    from benchmarks.splits import trial_split

    trials = ipin2023.trials(ROOT)
    by = {}
    for t in trials:
        by.setdefault(trial_split(t), set()).add(t.info["route"])
    assert by == {"tuning": {"01", "02", "21", "22"}, "report": {"04", "05", "23", "24"}}


@needs(ms_indoor)
def test_ms_real_splits_alternate_over_the_sorted_files():
    from benchmarks.splits import trial_split

    trials = ms_indoor.trials(ROOT)
    folder = ROOT / ms_indoor.NAME / "site2" / "F3" / "path_data_files"
    files = sorted(p.name.split(".")[0] for p in folder.glob("*.txt*"))
    for t in trials:
        k = files.index(t.name.split("/")[-1]) + 1
        assert t.info["file_no"] == k and trial_split(t) == ("tuning" if k % 2 else "report")
    n = {s: sum(trial_split(t) == s for t in trials) for s in ("tuning", "report")}
    assert n["tuning"] >= 15 and n["report"] >= 15
