"""The benchmark as a user reads it: it leaves tracked files alone unless asked, and the report starts with
what to expect in plain words."""

import re
from pathlib import Path

import numpy as np

from benchmarks import report
from benchmarks.run import main, parse_args

ROOT = Path(__file__).resolve().parents[1]


def test_default_outputs_are_untracked_and_write_results_targets_the_committed_report(tmp_path, monkeypatch):
    # parse_args leaves the defaults to main(); main() resolves them before it looks for data
    monkeypatch.setattr("benchmarks.run.default_data_root", lambda: tmp_path / "no-data")
    for argv, want_out in (([], ROOT / "out" / "benchmarks" / "RESULTS.md"),
                           (["--write-results"], ROOT / "benchmarks" / "RESULTS.md")):
        args = parse_args(argv)
        assert args.out is None and args.plots is None
        assert main(argv) == 2  # no data folder: nothing written anywhere
    seen = {}

    def fake_parse(argv=None):
        a = parse_args(argv)
        seen["args"] = a
        return a

    monkeypatch.setattr("benchmarks.run.parse_args", fake_parse)
    main([])
    assert seen["args"].out == ROOT / "out" / "benchmarks" / "RESULTS.md"
    assert seen["args"].plots == ROOT / "out" / "benchmarks" / "plots"
    main(["--write-results"])
    assert seen["args"].out == ROOT / "benchmarks" / "RESULTS.md"
    assert seen["args"].plots == ROOT / "benchmarks" / "plots"


def test_what_to_expect_speaks_plainly_from_the_report_split():
    lm = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 40.0]])
    results = [{"dataset": "ipin2023_track3", "split": "report", "plot": {"landmarks": lm}},
               {"dataset": "ipin2023_track3", "split": "tuning", "plot": {"landmarks": lm * 10}}]
    h = {"handheld_report_step_mae_pct": 1.52, "oxford_report_all_step_mae_pct": 1.93,
         "ipin2023_report_landmark_median_m": 2.48, "ipin2023_report_distance_median_abs_pct": 4.6,
         "ipin2023_report_loop_closure_median_pct": 4.49, "ipin2023_tuning_landmark_median_m": 99.0}
    text = "\n".join(report.what_to_expect(results, h))
    assert "1.5 % of the true count" in text and "about 2.5 m" in text and "loops of about 70 m" in text
    assert "99" not in text  # tuning numbers are not what a user should expect
    assert not re.search(r"issue\s*#", text, re.I)
    assert "about 5 %" in text  # the distance, rounded as a person would say it


def test_landmarks_at_one_place_share_one_label():
    from desktop.plot import label_groups

    lm = [[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.1, -0.2], [5.0, 0.3]]
    assert label_groups(lm) == [(0.0, 0.0, "0,3"), (5.0, 0.0, "1,4"), (5.0, 5.0, "2")]
    assert len(label_groups(lm, radius_m=0.05)) == 5


def test_a_subset_that_matches_nothing_is_an_error_not_an_empty_report(tmp_path, capsys):
    # an empty data folder: no dataset is available, so `--only ipin` (a near miss of `ipin2023`) runs nothing
    out = tmp_path / "r.md"
    assert main(["--data", str(tmp_path), "--only", "ipin", "--jobs", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "matched no recording" in err and "ipin2023" in err
    assert not out.exists()


def test_what_to_expect_counts_a_failed_truth_walk_as_the_worst(tmp_path):
    # the real truth walks' walking-direction error in "What to expect": a report walk that failed is counted
    from benchmarks.options import write_json
    from benchmarks.report import _truth_walk_offsets

    def walk(place, err, split="report", failed=None):
        w = {"split": split, "placement": place, "offset_truth": {"abs_err_deg_median": err}}
        return {**w, "failed": failed} if failed else w

    write_json(tmp_path / "t.json", {"walks": [walk("leg", 10.0), walk("backpocket", 30.0), walk("pocket", None,
                                                                                                   failed="no steps"),
                                               walk("bag", 50.0), walk("bag", 5.0, split="tuning")]})
    text = _truth_walk_offsets(tmp_path / "t.json")
    assert "in a trouser pocket 30 deg (3 walks)" in text  # median of 10, 30 and the failure (inf)
    assert "in a bag 50 deg (1 walk)" in text and "swinging" not in text  # tuning walks left out
