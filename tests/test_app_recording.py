"""Live recording survives an abrupt stop: a recording session is SIGKILLed mid-stream, then read back."""

import inspect
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from app.session import Session
from core.recording import read_recording
from desktop.simulator import simulate_walk

ROOT = Path(__file__).resolve().parents[1]
WAYPOINTS = ((0.0, 0.0), (30.0, 0.0), (30.0, 20.0))
SEED = 2

CHILD = r"""
import sys, time
from desktop.simulator import simulate_walk
from core.pdr.pipeline import Pipeline
from app.sources import ReplaySource
from app.session import Session

rec = simulate_walk(%r, seed=%d).recording

class Reporting(Session):
    def flush(self):
        super().flush()
        if self.writer is not None:
            print("FLUSHED", self.writer.count, flush=True)

ses = Reporting(ReplaySource(rec, speed=10.0), pipeline_factory=Pipeline, record_path=sys.argv[1])
ses.start()
print("READY", flush=True)
while True:
    ses.tick()
    time.sleep(0.003)
"""


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL")
def test_recording_survives_sigkill_mid_stream(tmp_path):
    path = tmp_path / "live.csv"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-c", CHILD % (WAYPOINTS, SEED), str(path)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    flushed, times = [], []
    try:
        for line in proc.stdout:
            if line.startswith("FLUSHED"):
                flushed.append(int(line.split()[1]))
                times.append(time.monotonic())
                if len(flushed) == 3:
                    time.sleep(0.25)  # between two flushes: some events written since the last one
                    os.kill(proc.pid, signal.SIGKILL)  # no close(), no atexit, no finally
                    break
    finally:
        proc.kill()
        proc.wait(timeout=10)
    assert len(flushed) == 3, proc.stderr.read()
    assert proc.returncode == -signal.SIGKILL
    # flushed at least once a second while events came in
    assert max(np.diff(times)) < 1.0

    rec = read_recording(str(path), warn=False)  # tolerates a cut-off last line
    expected = simulate_walk(WAYPOINTS, seed=SEED).recording
    n_file = sum(len(s) for s in rec.streams.values())
    n_total = sum(len(s) for s in expected.streams.values())
    assert n_total > n_file >= flushed[-1] > 1000  # killed mid-stream; everything flushed is there
    for name in ("acc", "gyro", "mag"):
        got, want = rec.streams[name], expected.streams[name]
        assert len(got) > 100
        # timestamps and values preserved exactly, and no event missing before the last one written
        np.testing.assert_array_equal(got.t_ns, want.t_ns[:len(got)])
        np.testing.assert_array_equal(got.values, want.values[:len(got)])
    assert all("cut off" in r for r in rec.repairs)


def test_sessions_flush_at_least_once_a_second_by_default():
    default = inspect.signature(Session.__init__).parameters["flush_interval_s"].default
    assert 0 < default <= 1.0 and not math.isnan(default)
