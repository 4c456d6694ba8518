"""The Kivy app: live sensors on Android, desktop replay, live track, recording.

Layout (thin UI over :mod:`core`; only the modules marked *kivy* import Kivy,
``jnius``/``android`` are imported only lazily, by :mod:`app.sources`,
:mod:`app.android_platform`, :mod:`app.storage` and :mod:`app.main_app`):

``app.sources``     SensorSource interface, ReplaySource, AndroidSource, PlyerFallbackSource
``app.session``     one tracking session: source -> reorder -> Pipeline, RecordingWriter, health
``app.service``     the tracking service (foreground service on the phone, a thread on the desktop) and the
                    UI's side of its socket
``app.android_platform``  permissions, the service's start / wake lock / notification, insets, back (jnius
                    injected)
``app.health``      per-sensor rate / jitter / dropped-event statistics
``app.viewport``    metres <-> pixels, pan, zoom, follow, scale bar
``app.settings``    persisted user settings and the user's stride profile (height, model, calibration)
``app.storage``     where settings, recordings and exports go (desktop and Android)
``app.kivy_env``    environment for Kivy (no argv parsing, headless tests) -- no Kivy import
``app.track_view``  *kivy* the track widget
``app.main_app``    *kivy* the App, screens and lifecycle

Desktop: ``python -m app RECORDING --speed 10`` or ``python main.py RECORDING``.
"""
