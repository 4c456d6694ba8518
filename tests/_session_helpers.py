"""A replay session run to its end, as the app runs one (shared by the app, floor and carry-mode tests)."""

import math

from app.session import Session
from app.sources import ReplaySource


def replay_session(rec, pipeline_factory, chunk: int = 500) -> Session:
    """A session that replayed ``rec`` to the end, as fast as it goes."""
    ses = Session(ReplaySource(rec, speed=math.inf, max_chunk=chunk), pipeline_factory=pipeline_factory)
    ses.start()
    for _ in range(100000):
        ses.tick(budget_s=0.01)
        if ses.finished:
            break
    assert ses.finished
    return ses
