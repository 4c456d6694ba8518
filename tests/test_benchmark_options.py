"""Every benchmark module takes --data, --only and --no-write the same way (issue #29, benchmarks.options)."""

from __future__ import annotations

import argparse
import importlib
import math

import pytest

from benchmarks import options as O

#: the benchmark modules with a command line (python -m benchmarks.<name>)
MODULES = ("run", "indoor", "carry", "walkdir", "gnss_eval", "gnss_faults", "ablation", "floors", "velocity_eval",
           "throughput", "foot", "real_walks")


@pytest.mark.parametrize("name", MODULES)
def test_every_benchmark_takes_data_only_and_no_write(name, capsys):
    mod = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit) as e:
        mod.main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for opt in ("--data", "--only", "--no-write"):
        assert opt in text, f"benchmarks.{name} has no {opt}"


def _args(argv):
    ap = argparse.ArgumentParser()
    O.add_common(ap)
    return ap.parse_args(argv)


def test_only_is_comma_separated_and_repeatable_and_implies_no_write(tmp_path):
    a = _args(["--only", "T05r01,1-1", "--only", "babur"])
    assert O.only_keys(a) == ["T05r01", "1-1", "babur"]
    assert O.selected(O.only_keys(a), "ipin2023_track3", "IPIN2023_T3_T05r01") and \
        not O.selected(O.only_keys(a), "oxford", "Pixel_Jamie")
    assert not O.writes_committed(a)
    committed = O.HERE / "INDOOR_RESULTS.md"
    assert O.result_path(a, committed, "indoor") == O.REPO / "out" / "benchmarks" / "indoor" / committed.name
    full = _args([])
    assert O.writes_committed(full) and O.result_path(full, committed, "indoor") == committed
    assert not O.writes_committed(_args(["--no-write"]))
    assert O.data_root(_args(["--data", str(tmp_path)])) == tmp_path


def test_a_missing_data_root_is_said(tmp_path, capsys):
    """A run from a checkout without ../shared/data beside it read nothing and said nothing before."""
    O.data_root(_args(["--data", str(tmp_path)]))
    assert capsys.readouterr().err == ""
    O.data_root(_args(["--data", str(tmp_path / "nowhere")]))
    assert "does not exist" in capsys.readouterr().err


def test_a_failed_recording_counts_as_inf_never_dropped():
    assert O.median_inf([1.0, None, 3.0]) == 3.0  # [1, 3, inf]: dropping the failure would give 2.0
    assert O.median_inf([None]) == math.inf and math.isnan(O.median_inf([]))

    def boom(task):
        raise ValueError("bad file")

    row = O.Guarded(boom, "report")(("ipin2023", "/data/x/T05r01.txt"))
    assert row["failed"].startswith("ValueError: bad file") and row["split"] == "report"
    bad, ok = O.split_failed([row, {"name": "a"}])
    assert bad == [row] and ok == [{"name": "a"}]
    assert "1 failed" in O.failures_line(bad) and "x/T05r01.txt" in O.failures_line(bad)
    assert any("bad file" in ln for ln in O.failures_markdown(bad))


def test_shared_result_helpers():
    # one place for what real_walks, truth_walks, carry and foot used privately (before: ImportError)
    import numpy as np

    from benchmarks.metrics import median_present
    from benchmarks.options import git_rev, jsonable

    assert jsonable({1: [np.float64(1.234567), math.nan, np.int64(3), (math.inf, "a", None)]}) == {
        "1": [1.2346, "nan", 3, ["inf", "a", None]]}
    # walkdir's own markdown reads None for a non-finite value (its private copy of this function, before)
    assert jsonable([np.float32(0.5), math.nan, -math.inf], digits=None, nonfinite_as_null=True) == [0.5, None, None]
    assert median_present([None, math.nan, 1.0, math.inf, 2.0]) == 2.0 and median_present([None, math.nan]) is None
    assert isinstance(git_rev(), str)


def test_results_json_keeps_a_failure_apart_from_not_measured(tmp_path):
    # before, a counted failure (+inf) and "not measured" were both written as null
    import json

    from benchmarks.options import read_json, write_json

    path = tmp_path / "r.json"
    write_json(path, {"median": math.inf, "low": -math.inf, "unscored": math.nan, "absent": None, "x": 1.23456},
               digits=None)
    json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(f"not standard JSON: {c}"))
    back = read_json(path)
    assert back["median"] == math.inf and back["low"] == -math.inf and math.isnan(back["unscored"])
    assert back["absent"] is None and back["x"] == 1.23456
