"""Shared by the foot tests: a navigator fed event by event (the streaming path)."""

from core.foot.navigator import FootNavigator


def run_streaming(settings, recording, names=("gyro", "acc", "mag"), **kwargs):
    """``FootNavigator(settings).update`` on every event of ``names`` in time order, then ``finish()``."""
    nav = FootNavigator(settings, **kwargs)
    for name, t, v in recording.events(list(names)):
        nav.update(name, t, v)
    return nav.finish()
