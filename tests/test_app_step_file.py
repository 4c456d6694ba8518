"""The app's steps go to disk as they come (issue #30): memory held by the step list does not grow with the walk.

Before: the session kept every :class:`core.pdr.pipeline.Step` in a list (and the pipeline a second one),
about 700 bytes a step: 4.6 MB an hour of walking, 155 MB a day.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.long_walk import deep_bytes
from core.export import StepFile
from core.pdr.pipeline import Pipeline, Step, Track
from core.pdr.stride import StepFeatures


def _steps(n: int, start: int = 0):
    rng = np.random.default_rng(start)
    e = n_ = 0.0
    for k in range(start, start + n):
        length, heading = 0.6 + 0.2 * rng.random(), math.pi * (2 * rng.random() - 1)
        e += length * math.cos(heading)
        n_ += length * math.sin(heading)
        yield Step(k, 10**12 + k * 550_000_000, length, heading, e, n_,
                   StepFeatures(10**12 + k * 550_000_000, 0.55, 11.0, 8.5, 1.2), k % 3 != 0, "handheld", k % 7 == 0)


def test_the_step_file_reads_back_every_step_exactly(tmp_path):
    want = list(_steps(300))
    f = StepFile(directory=str(tmp_path))
    for s in want[:200]:
        f.append(s)
    it = iter(f)
    first = [next(it) for _ in range(10)]
    for s in want[200:]:  # appends while a reader is part-way through do not disturb either
        f.append(s)
    got = first + list(it)
    assert len(got) == 200 and len(f) == 300 and f.distance_m == pytest.approx(sum(s.length_m for s in want))
    got = list(f)
    assert [(g.index, g.t_ns, g.length_m, g.heading_rad, g.east_m, g.north_m, g.mag_trusted, g.estimated, g.carry_mode)
            for g in got] == [(s.index, s.t_ns, s.length_m, s.heading_rad, s.east_m, s.north_m, s.mag_trusted,
                               s.estimated, s.carry_mode) for s in want]
    tr, ref = f.track(), Track.from_steps(want)
    for name in ("t_ns", "length_m", "heading_rad", "east_m", "north_m", "estimated"):
        np.testing.assert_array_equal(getattr(tr, name), getattr(ref, name))
    f.close()


def test_memory_held_by_the_step_file_does_not_grow_with_the_walk(tmp_path):
    """Bytes of the objects the step store holds, after 1 000 and after 10 000 steps (about an hour and a half; it
    was 20 000, for CI's time: measuring the plain list of 20 000 steps cost about 1 s)."""
    f, kept = StepFile(directory=str(tmp_path)), []
    for s in _steps(1000):
        f.append(s)
        kept.append(s)
    short_file, short_list = deep_bytes(f), deep_bytes(kept)
    for s in _steps(9000, 1000):
        f.append(s)
        kept.append(s)
    assert deep_bytes(f) <= short_file + 2048  # flat: the count, the distance, the last 64 steps
    assert deep_bytes(kept) > 7.5 * short_list  # what the list did (about 600 bytes a step: 10.0 times)
    assert len(f) == 10000 and sum(1 for _ in f) == 10000
    f.close()


def test_a_step_file_that_cannot_be_written_keeps_the_steps_in_memory(tmp_path):
    f = StepFile(directory=str(tmp_path))
    want = list(_steps(20))
    for s in want[:5]:
        f.append(s)

    def full(_):
        raise OSError(28, "No space left on device")
    f._f.write = full
    for s in want[5:]:
        f.append(s)
    assert "No space left" in f.error and [g.t_ns for g in f] == [s.t_ns for s in want]


def test_the_session_keeps_its_steps_on_disk_and_exports_all_of_them(tmp_path):
    from app.session import export_session
    from desktop.simulator import simulate_walk
    from tests._session_helpers import replay_session

    rec = simulate_walk([(0, 0), (25, 0), (25, 10)], seed=2, rate_hz=50.0).recording  # the rate is not the subject
    batch = Pipeline().run(rec)
    ses = replay_session(rec, lambda: Pipeline(keep_steps=False))
    assert isinstance(ses.steps, StepFile) and len(ses.steps) == len(batch.steps) > 40
    assert len(ses.steps.last) <= 64 and len(ses.pipeline.steps) == 0  # neither keeps the walk in memory
    out = export_session(ses, str(tmp_path), "walk")
    assert not out["errors"]
    rows = (tmp_path / "walk.track.csv").read_text().splitlines()
    assert len(rows) == len(batch.steps) + 1
    assert float(rows[-1].split(",")[5]) == pytest.approx(batch.track.east_m[-1], abs=1e-3)
    assert ses.summary()["distance_m"] == pytest.approx(float(np.sum(batch.track.length_m)), abs=1e-9)


def test_the_app_pipeline_keeps_no_steps():
    from app.settings import Settings

    assert Settings().pipeline_factory()().keep_steps is False
