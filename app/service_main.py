"""Entry point of the tracking service on the phone (``services = Tracker:app/service_main.py:...`` in
buildozer.spec): p4a runs this file in the service's own process, with the app's folder on the path.
See :mod:`app.service` and :func:`app.android_platform.service_main`."""

from app.android_platform import service_main

if __name__ == "__main__":
    service_main()
