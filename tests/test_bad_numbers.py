"""One NaN or inf in any sensor: skipped, counted, reported, and the demo's track barely moves (issue #8 target).

The attitude filter's own guards are tested in tests/test_attitude_filter.py;
here the whole pipeline and the CLI summary on the bundled demo.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from core.pdr.pipeline import Pipeline
from core.recording import Recording, make_stream, read_recording, write_recording

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "desktop" / "data" / "demo_walk.csv.gz"


@pytest.fixture(scope="module")
def demo():
    rec = read_recording(str(DEMO))
    return rec, Pipeline().run(rec).summary()


def _with_bad_value(rec: Recording, stream: str, bad: float, where: float = 0.5, column: int = 1) -> Recording:
    streams = dict(rec.streams)
    s = streams[stream]
    v = np.array(s.values, dtype=float)
    v[int(where * len(v)), column] = bad
    streams[stream] = make_stream(stream, s.t_ns, v)
    return Recording(streams, source=rec.source, metadata=dict(rec.metadata))


def test_bad_values_in_every_sensor_change_the_demo_closure_by_less_than_10_cm(demo):
    """NaN, +inf and -inf in each of the three sensors, at 30, 50 and 70 % of the walk (the three sensors at
    slightly different moments; one run for all nine values instead of one per sensor, for CI's time): each is
    skipped and counted per sensor, and the closure moves by less than 10 cm with all nine together."""
    rec, clean = demo
    bad = rec
    for k, stream in enumerate(("acc", "gyro", "mag")):
        for where, value in ((0.3, math.nan), (0.5, math.inf), (0.7, -math.inf)):
            bad = _with_bad_value(bad, stream, value, where=where + 0.01 * k)
    s = Pipeline().run(bad).summary()
    assert s["nonfinite_skipped"] == {"acc": 3, "gyro": 3, "mag": 3}
    assert s["n_steps"] == clean["n_steps"]
    moved = math.hypot(s["final_east_m"] - clean["final_east_m"], s["final_north_m"] - clean["final_north_m"])
    assert moved < 0.1
    assert abs(s["start_to_end_m"] - clean["start_to_end_m"]) < 0.1
    assert any("non-finite" in lab for lab in s["labels"])


def test_the_cli_summary_reports_the_skipped_values(tmp_path, demo, capsys):
    # ``pdr replay`` in this process (``python -m desktop`` is ``sys.exit(main())``): no Python start and imports
    from desktop.cli import main

    rec, _ = demo
    path = tmp_path / "bad.csv"
    # the demo's first 20 s, the NaN at their middle: the summary line is the subject, not the walk (the whole demo
    # written, read and replayed cost about 1.5 s more)
    part = rec.slice_time(rec.t0_ns, rec.t0_ns + 20_000_000_000)
    write_recording(str(path), _with_bad_value(part, "gyro", math.nan))
    capsys.readouterr()
    code = main(["replay", str(path)])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "1 non-finite gyro value(s)" in out.out


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e300])
def test_the_papers_quaternion_ekf_skips_bad_numbers_too(bad):
    from core.pdr.attitude_qekf import QuaternionEKF

    f = QuaternionEKF()
    t = 0
    for k in range(300):
        t += 10_000_000
        f.predict(t, 0.01, bad if k == 150 else 0.0, 0.0)
        f.update_acc(t, 0.0, bad if k == 160 else 0.3, 9.8)
        if k % 2 == 0:
            f.update_mag(t, 0.0, 20.0 if k != 170 else bad, -40.0)
    assert all(math.isfinite(v) for v in f.q) and f.n_skipped_nonfinite == 3
