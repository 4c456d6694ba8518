"""The carry mode where users see it (issue #17): the pdr summary, the exports' per-step column, the app's
strip and health panel.  The detector itself is tested in tests/test_carry.py."""

import csv
import json
import pytest

from app.session import export_session
from core.conventions import CARRY_MODES, CARRY_POCKET, CARRY_STILL, CARRY_WORDS
from core.pdr.pipeline import Pipeline
from core.recording import write_recording
from desktop.cli import carry_lines, main
from desktop.simulator import simulate_walk
from tests._session_helpers import replay_session


@pytest.fixture(autouse=True)
def _no_stored_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("PDR_APP_DATA", str(tmp_path / "app"))


@pytest.fixture(scope="module")
def pocket_walk():
    # 60 m out and back: about 45 s of walking with the phone in a trouser pocket (seed of the tuning split)
    return simulate_walk([(0.0, 0.0), (30.0, 0.0), (30.0, 2.0), (0.0, 2.0)], placement=CARRY_POCKET, seed=3, rate_hz=50.0)


def test_pdr_replay_says_how_the_phone_was_carried_and_exports_it_per_step(pocket_walk, tmp_path, capsys):
    path = tmp_path / "pocket.csv"
    write_recording(str(path), pocket_walk.recording)
    out = tmp_path / "track.csv"
    assert main(["replay", str(path), "--csv", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["carry"]["time_s"][CARRY_POCKET] > 0.7 * sum(s["carry"]["time_s"].values())
    rows = list(csv.DictReader(out.open()))
    # every step is in a walking mode: a counted step is never labelled "not walking", even while the
    # detector's hysteresis still says so at the start of the walk
    assert rows and all(r["carry"] in CARRY_MODES and r["carry"] != CARRY_STILL for r in rows)
    assert sum(r["carry"] == CARRY_POCKET for r in rows) > 0.8 * len(rows)
    # the summary's line names the mode of most of the time first
    (line,) = carry_lines(s["carry"], pocket_walk.recording.t0_ns)
    assert line.startswith("carried") and line.split(None, 1)[1].startswith(CARRY_WORDS[CARRY_POCKET]), line


def test_the_app_strip_health_panel_and_export_carry_the_mode(pocket_walk, tmp_path):
    ses = replay_session(pocket_walk.recording, Pipeline)
    s = ses.summary()
    assert s["carry"] == CARRY_POCKET and 0.0 < s["carry_confidence"] <= 1.0
    assert f"carried: {CARRY_WORDS[CARRY_POCKET]}" in ses.health_text()
    out = export_session(ses, str(tmp_path), "walk")
    assert not out["errors"]
    rows = list(csv.DictReader(open(out["csv"])))
    assert len(rows) == len(ses.steps) and rows[-1]["carry"] == CARRY_POCKET
    gj = json.loads(open(out["geojson"]).read())
    assert gj["features"][-1]["properties"]["carry"] == CARRY_POCKET


def test_without_a_detector_nothing_is_claimed(pocket_walk):
    ses = replay_session(pocket_walk.recording, lambda: Pipeline(carry=False))
    assert ses.summary()["carry"] is None
    assert "carried" not in ses.health_text()
