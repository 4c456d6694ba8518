"""What the app does through pyjnius besides the sensors: permissions, the tracking service's start, wake
lock and notification, the system-bar insets, predictive back.  No Kivy here; ``jnius`` is always passed
in (the phone's module, or the fake one of the tests), never imported at module level.

Everything in this module is exercised against a fake ``jnius`` only (tests/test_app_android_source.py);
docs/app.md lists what only a phone can show.
"""

from __future__ import annotations

import json
import os

from app.service import CONFIG_FILE, NOTIFICATION_CHANNEL, NOTIFICATION_ID, SERVICE_NAME

FINE_LOCATION = "android.permission.ACCESS_FINE_LOCATION"
COARSE_LOCATION = "android.permission.ACCESS_COARSE_LOCATION"
POST_NOTIFICATIONS = "android.permission.POST_NOTIFICATIONS"
WRITE_EXTERNAL_STORAGE = "android.permission.WRITE_EXTERNAL_STORAGE"
PERMISSION_GRANTED = 0  #: PackageManager.PERMISSION_GRANTED
PARTIAL_WAKE_LOCK = 1  #: PowerManager.PARTIAL_WAKE_LOCK
WAKE_LOCK_TAG = "pdrtracker:tracking"
#: edge-to-edge is enforced for apps targeting API 35+ from Android 15 (API 35) on; before, the window
#: is laid out inside the system bars and no padding is needed
EDGE_TO_EDGE_SDK = 35
BACK_CALLBACK_SDK = 33  #: OnBackInvokedDispatcher exists from API 33
PRIORITY_DEFAULT = 0  #: OnBackInvokedDispatcher.PRIORITY_DEFAULT


def sdk_int(jnius) -> int:
    return int(jnius.autoclass("android.os.Build$VERSION").SDK_INT)


def activity(jnius):
    return jnius.autoclass("org.kivy.android.PythonActivity").mActivity


def permissions_to_request(sdk: int) -> list[str]:
    """Run-time permissions to ask for at start: location (GPS; also the location-type service's
    prerequisite), notifications on Android 13+ (the service's notification), storage up to Android 10
    (Documents/PDR by path; Android 10 with ``requestLegacyExternalStorage``)."""
    perms = [FINE_LOCATION, COARSE_LOCATION]
    if sdk >= 33:
        perms.append(POST_NOTIFICATIONS)
    if sdk <= 29:
        perms.append(WRITE_EXTERNAL_STORAGE)
    return perms


def location_grant(context) -> str | None:
    """``"fine"``, ``"coarse"`` (Android 12+ lets the user grant only the approximate one) or None."""
    try:
        if context.checkSelfPermission(FINE_LOCATION) == PERMISSION_GRANTED:
            return "fine"
        if context.checkSelfPermission(COARSE_LOCATION) == PERMISSION_GRANTED:
            return "coarse"
    except Exception:  # noqa: BLE001 - before API 23 every permission is granted at install
        return "fine"
    return None


# -- the tracking service (UI side: start / stop; service side: hooks, entry point) --------------------


def start_service(jnius, config: dict) -> None:
    """Start the p4a service ``Tracker`` (``services = Tracker:app/service_main.py:foreground:...``)
    with ``config`` as its argument (``PYTHON_SERVICE_ARGUMENT``)."""
    act = activity(jnius)
    cls = jnius.autoclass(f"{act.getPackageName()}.Service{SERVICE_NAME}")
    # (context, small icon: the app's, notification title, text, argument)
    cls.start(act, "", "PDR Tracker", "starting...", json.dumps(config))


def stop_service(jnius) -> None:
    """Stop the service by Android (the UI's ``stop`` request is the clean way; this is the fallback)."""
    act = activity(jnius)
    jnius.autoclass(f"{act.getPackageName()}.Service{SERVICE_NAME}").stop(act)


class ServiceHooks:
    """The service process's phone side: partial wake lock and the notification with steps and distance.

    p4a's own foreground notification sits on a channel of importance NONE (not shown); this one posts
    the same id (:data:`app.service.NOTIFICATION_ID`) on a channel of low importance (shown, silent), so
    it replaces it.
    """

    def __init__(self, jnius, service):
        self.jnius = jnius
        self.service = service
        self.wake_lock = None
        self._manager = None
        self._intent = None

    def acquire(self) -> None:
        Context = self.jnius.autoclass("android.content.Context")
        pm = self.service.getSystemService(Context.POWER_SERVICE)
        wl = pm.newWakeLock(PARTIAL_WAKE_LOCK, WAKE_LOCK_TAG)
        wl.setReferenceCounted(False)
        wl.acquire()
        self.wake_lock = wl

    def release(self) -> None:
        """The walk is over: wake lock released, the notification removed (the service ends next)."""
        wl, self.wake_lock = self.wake_lock, None
        if wl is not None and wl.isHeld():
            wl.release()
        if self._manager is not None:
            self._manager.cancel(NOTIFICATION_ID)

    def _setup(self):
        jn = self.jnius
        Context = jn.autoclass("android.content.Context")
        self._manager = self.service.getSystemService(Context.NOTIFICATION_SERVICE)
        if sdk_int(jn) >= 26:
            Channel = jn.autoclass("android.app.NotificationChannel")
            Manager = jn.autoclass("android.app.NotificationManager")
            ch = Channel(NOTIFICATION_CHANNEL, "Tracking", Manager.IMPORTANCE_LOW)
            ch.setShowBadge(False)
            self._manager.createNotificationChannel(ch)
        # a tap opens the app: the launcher's intent of our own package (no Java class object needed)
        PendingIntent = jn.autoclass("android.app.PendingIntent")
        launch = self.service.getPackageManager().getLaunchIntentForPackage(self.service.getPackageName())
        self._intent = PendingIntent.getActivity(self.service, 0, launch,
                                                 PendingIntent.FLAG_IMMUTABLE | PendingIntent.FLAG_UPDATE_CURRENT)

    def notify(self, title: str, text: str) -> None:
        jn = self.jnius
        if self._manager is None:
            self._setup()
        Builder = jn.autoclass("android.app.Notification$Builder")
        b = Builder(self.service, NOTIFICATION_CHANNEL) if sdk_int(jn) >= 26 else Builder(self.service)
        b.setContentTitle(title)
        b.setContentText(text)
        b.setSmallIcon(self.service.getApplicationInfo().icon)
        b.setOngoing(True)
        b.setOnlyAlertOnce(True)
        b.setContentIntent(self._intent)
        self._manager.notify(NOTIFICATION_ID, b.build())


def service_config(environ=os.environ) -> dict | None:
    """The service's configuration: its start argument (``PYTHON_SERVICE_ARGUMENT``), None without one.

    p4a's ``PythonService`` passes an empty argument when Android restarts the service with a null intent
    (what ``START_STICKY`` does after a kill; buildozer.spec no longer declares ``sticky``, so p4a returns
    ``START_NOT_STICKY`` and Android should not).  Such a restart does not track: a walk the user did not
    start would go into a new file, and ``startForeground`` from the background throws on Android 12+
    anyway.  What the killed walk left is told by the next UI (:func:`take_interrupted_walk`)."""
    arg = environ.get("PYTHON_SERVICE_ARGUMENT", "")
    return json.loads(arg) if arg else None


def save_service_config(config: dict, active: bool, private_dir: str) -> None:
    """``service.json``: the running walk's configuration, ``active`` while it tracks (cleared when it stops:
    still set at the next start of the UI means the process died while tracking)."""
    data = {k: v for k, v in config.items() if k != "pipeline_factory"}
    data["active"] = active
    try:
        with open(os.path.join(private_dir, CONFIG_FILE), "w", encoding="utf-8") as f:
            json.dump(data, f)
    except OSError:
        pass


def take_interrupted_walk(private_dir: str | None) -> str:
    """What the UI tells at its start when no service answers but ``service.json`` still says ``active``:
    the service's process died while it tracked (Android stopped it, the app was swiped from the recents,
    a crash).  The file is marked done, so it is told once; "" when there is nothing to tell."""
    if not private_dir:
        return ""
    path = os.path.join(private_dir, CONFIG_FILE)
    try:
        with open(path, encoding="utf-8") as f:
            saved = json.load(f)
    except (OSError, ValueError):
        return ""
    if not isinstance(saved, dict) or not saved.get("active"):
        return ""
    save_service_config(saved, False, private_dir)
    rec = saved.get("record_path")
    import time  # noqa: PLC0415

    if rec and os.path.exists(rec):
        when = time.strftime("%H:%M", time.localtime(os.path.getmtime(rec)))
        return (f"the last walk ended without Stop at about {when} (Android stopped the tracking service, or the "
                f"app was swiped away): {os.path.basename(rec)} keeps it up to then")
    return ("the last walk ended without Stop (Android stopped the tracking service, or the app was swiped "
            "away)")


def service_main(jnius=None, environ=os.environ) -> None:
    """The p4a service's entry point (``app/service_main.py``): runs until the UI says ``stop``."""
    from app.service import run_service  # noqa: PLC0415
    from app.sources import make_live_source  # noqa: PLC0415

    if jnius is None:
        import jnius  # noqa: PLC0415 - the phone's
    service = jnius.autoclass("org.kivy.android.PythonService").mService
    private = environ.get("ANDROID_PRIVATE") or service.getFilesDir().getAbsolutePath()
    config = service_config(environ)
    if config is None:
        return  # restarted by Android with a null intent: no walk without the user; p4a then stops the service
    service.setAutoRestartService(False)
    save_service_config(config, True, private)
    try:
        # ``active`` is cleared as the stop begins, before the sensors go: a crash while stopping leaves no
        # walk to resume
        run_service(config, lambda rate: make_live_source(rate_hz=rate, context=service, jnius=jnius),
                    hooks=ServiceHooks(jnius, service), on_stopping=lambda: save_service_config(config, False, private))
    finally:
        save_service_config(config, False, private)


# -- the UI: insets and back ----------------------------------------------------------------------


def system_bar_insets(jnius) -> tuple[int, int, int, int]:
    """``(left, top, right, bottom)`` pixels of the system bars and the display cutout over the window, on
    Android 15+ (edge-to-edge); zeros before (the window is laid out inside the bars) or when unknown."""
    try:
        if sdk_int(jnius) < EDGE_TO_EDGE_SDK:
            return (0, 0, 0, 0)
        wi = activity(jnius).getWindow().getDecorView().getRootWindowInsets()
        if wi is None:  # not attached yet
            return (0, 0, 0, 0)
        Type = jnius.autoclass("android.view.WindowInsets$Type")
        ins = wi.getInsets(Type.systemBars() | Type.displayCutout())
        return (int(ins.left), int(ins.top), int(ins.right), int(ins.bottom))
    except Exception:  # noqa: BLE001 - no padding rather than no app
        return (0, 0, 0, 0)


_BACK_CLASSES: dict = {}


def _back_callback_class(jnius):
    key = id(jnius)
    if key not in _BACK_CLASSES:
        class BackCallback(jnius.PythonJavaClass):
            """``android.window.OnBackInvokedCallback``: Android 13+ delivers back here, not as a key."""

            __javainterfaces__ = ["android/window/OnBackInvokedCallback"]
            __javacontext__ = "app"

            def __init__(self, on_back):
                super().__init__()
                self._on_back = on_back

            @jnius.java_method("()V")
            def onBackInvoked(self):
                try:
                    self._on_back()
                except Exception:  # noqa: BLE001 - never into Java
                    pass

        _BACK_CLASSES[key] = BackCallback
    return _BACK_CLASSES[key]


class BackHandler:
    """Back on Android 13+ (predictive back; at target API 36 no key 27 reaches Kivy): a callback is
    registered while the app has somewhere to go back to (Settings, Health -> Track) and unregistered on
    the track, so that back there leaves the app as Android does it.

    ``on_back`` runs on Android's UI thread (the app hands it to the Kivy clock); ``run_on_ui_thread``
    wraps the (un)registration (p4a's ``android.runnable.run_on_ui_thread``; direct in tests).
    """

    def __init__(self, jnius, on_back, run_on_ui_thread=None):
        self.jnius = jnius
        self.enabled = sdk_int(jnius) >= BACK_CALLBACK_SDK
        self.registered = False
        self._run = run_on_ui_thread or (lambda f: f)
        self.callback = _back_callback_class(jnius)(on_back) if self.enabled else None

    def want(self, wanted: bool) -> None:
        if not self.enabled or wanted == self.registered:
            return
        self.registered = wanted
        cb = self.callback
        jn = self.jnius

        def apply():
            dispatcher = activity(jn).getOnBackInvokedDispatcher()
            if wanted:
                dispatcher.registerOnBackInvokedCallback(PRIORITY_DEFAULT, cb)
            else:
                dispatcher.unregisterOnBackInvokedCallback(cb)

        self._run(apply)()
