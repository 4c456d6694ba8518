"""Live recording: the default fsync interval (the kill -9 tests are in tests/test_no_walk_lost.py)."""

import inspect
import math

from app.session import Session


def test_sessions_flush_at_least_once_a_second_by_default():
    default = inspect.signature(Session.__init__).parameters["flush_interval_s"].default
    assert 0 < default <= 1.0 and not math.isnan(default)
