"""The fake live source, null pipeline and numbered events of tests/test_no_walk_lost.py, in a module of their own:
its kill -9 test starts fourteen recording processes that import them, and importing them from here (not from the
test file, which imports pytest) saves each about 0.15 s of CPU."""

from app.sources import SensorSource
from core.recording import STREAM_SPECS

STREAMS = {n: STREAM_SPECS[n] for n in ("acc", "gyro")}


def event(k: int, t0_ns: int = 0, dt_ns: int = 5_000_000):
    """Event k of the fake source: alternating acc/gyro, values that name k (exact in the file)."""
    if k % 2 == 0:  # plausible values (the reader checks the units), none with a short repr
        return "acc", t0_ns + k * dt_ns, (0.1 + (k % 97) / 3e3, -0.2 - k / 7e7, 9.81 + (k % 7) * 1e-5)
    return "gyro", t0_ns + k * dt_ns, ((k % 101) / 3e3, 0.01 + k / 7e7, -0.02)


class FakeSource(SensorSource):
    """Events from a list, delivered on drain (a live source's interface)."""

    def __init__(self, events=()):
        super().__init__()
        self.pending = list(events)
        self.device = {"model": "fake"}

    def start(self):
        self.running = True

    def stop(self):
        self.running = False

    def drain(self, max_events=None):
        n = len(self.pending) if max_events is None else max_events
        out, self.pending = self.pending[:n], self.pending[n:]
        return out

    @property
    def finished(self):
        return False


class NullPipeline:
    """Enough of a pipeline for the recorder's tests."""

    def update(self, name, t, vals):
        return []

    def finish(self):
        return []
