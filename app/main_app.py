"""The Kivy app: thin UI over :class:`app.session.Session`.

State shown on screen lives in Kivy properties of :class:`PDRApp` bound in
``layout.kv``; all processing happens in the session (plain Python).  The
Kivy clock calls :meth:`PDRApp._tick` 30 times a second: it drains the
source and runs the pipeline (bounded time per tick), and updates the
widgets at most 10 times a second, or when a step completes.

Live tracking runs in the tracking service (:mod:`app.service`): a p4a foreground
service on the phone, a thread of this process on the desktop; the UI holds a
:class:`app.service.ServiceSession` that polls it.  Replays run in a
:class:`app.session.Session` of the UI itself.

Lifecycle (Android): ``on_pause`` pauses a replay (or the sensors of a live
session that could not use the service: no location permission), flushes the
recording and saves the settings; live tracking in the service goes on.
``on_resume`` restarts what was paused.  ``on_stop`` leaves the service
recording (the next start of the UI attaches to it); a replay is finished.

Floor plan (issue #16, :mod:`app.indoor`)
    Settings > Floor plan > Choose picks our GeoJSON file or a Microsoft floor folder (remembered in
    ``settings.json``); its walls are drawn under the track.  **Here** (the track screen's button, enabled
    with a plan) arms one tap: the first places the user (the particle filter starts there), every later one
    is a fix of about 2 m.  A replay whose recording has landmarks in plan metres starts at the first one.
    Live, the filter runs in the tracking service (it reads the plan from the settings); in a replay, in the
    UI's session.

Android 15/16 (target API 36): the layout is padded by the system-bar and
cutout insets (edge-to-edge is enforced), and back comes through an
``OnBackInvokedCallback`` registered while Settings or Health is shown
(:mod:`app.android_platform`).
"""

from __future__ import annotations

import functools
import json
import math
import os
import tempfile
import time

from kivy.app import App
from kivy.base import ExceptionHandler, ExceptionManager
from kivy.clock import Clock, mainthread
from kivy.logger import Logger
from kivy.core.window import Window
from kivy.lang import Builder
from kivy.properties import BooleanProperty, ListProperty, NumericProperty, StringProperty
from kivy.uix.boxlayout import BoxLayout
from kivy.uix.button import Button
from kivy.uix.filechooser import FileChooserListView
from kivy.uix.popup import Popup

from core.conventions import CARRY_BAG, CARRY_EAR, CARRY_HANDHELD, CARRY_POCKET, CARRY_STILL, CARRY_SWINGING
from core.pdr.calibration import CalibrationError
from core.pdr.stride_models import StrideModelError

import app.track_view  # noqa: F401 - registers TrackView for the kv file
from app import android_platform as droid
from app.indoor import PLAN_PATTERNS
from app.service import (InProcessService, ServiceClient, ServiceSession, ServiceUnavailable, service_answers,
                         socket_path)
from app.session import Session, load_any_recording, reading_notes
from app.settings import RATE_CHOICES, SETTINGS_FILE, STRIDE_MODEL_CHOICES, TRACKING_MODES, Settings
from app.sources import REPLAY_SPEEDS, SensorStartError, make_live_source, replay_source_for
from app.storage import is_android, new_recording_path, output_dir

KV_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "layout.kv")
RECORDING_PATTERNS = ["*.csv", "*.txt", "*.gz", "*.out", "*.dat"]  #: without core.importers' list


def recording_formats() -> tuple[list, list]:
    """``(file patterns, format names)`` of what ``core.importers`` reads: the extensions its format
    descriptions name (``.csv``, ``.txt``, ``.gz``, ``.zip``, ...), the project's own first."""
    try:
        from core.importers import FORMATS  # noqa: PLC0415
    except ImportError:
        return list(RECORDING_PATTERNS), ["pdr-recording"]
    import re  # noqa: PLC0415

    exts = {m.lower() for text in FORMATS.values() for m in re.findall(r"(?<![\w.])\.([A-Za-z]{2,4})\b", text)}
    if any(re.search(r"\bzip\b", text) for text in FORMATS.values()):
        exts.add("zip")  # "a zip or folder of ..."
    exts = [e for e in ("csv", "txt", "gz") if e in exts] + sorted(exts - {"csv", "txt", "gz"})
    return ["*." + e for e in exts], list(FORMATS)
UI_INTERVAL_S = 0.1
#: a button whose request the tracking service did not answer is tried again after this long, this often
#: (only where sending it twice does no harm: play/pause as the wanted state, export)
RETRY_S = 1.5
MAX_RETRIES = 2
#: what the message calls a callback
ACTION_NAMES = {"toggle_play": "play/pause", "set_playing": "play/pause", "toggle_recording": "recording",
                "export": "export", "new_track": "new track", "toggle_calibration": "calibration walk",
                "save_calibration": "calibration", "stop_live": "stop", "go_live": "live", "choose_plan": "floor plan",
                "here": "here", "open_recording": "open", "seek_start": "back to the start"}


def ui_callback(retry: bool = False):
    """A UI callback that cannot close the app: the tracking service not answering (it is starting Python and
    numpy, or busy with a long export) is a message, and with ``retry`` the callback runs again after
    :data:`RETRY_S` (at most :data:`MAX_RETRIES` times); any other exception is logged and shown."""
    def deco(fn):
        name = fn.__name__

        @functools.wraps(fn)
        def wrapper(self, *args, _attempt=0, **kwargs):
            try:
                return fn(self, *args, **kwargs)
            except ServiceUnavailable as e:
                again = None
                if retry and _attempt < MAX_RETRIES:
                    def again(dt=None):
                        wrapper(self, *args, _attempt=_attempt + 1, **kwargs)
                self._service_unavailable(name, e, again)
            except Exception as e:  # noqa: BLE001 - a button must never close the app
                self._callback_failed(name, e)
            return None
        return wrapper
    return deco


class KeepAlive(ExceptionHandler):
    """Kivy's last resort: an exception nothing caught in the event loop (a touch handler, a clock callback)
    is logged and shown, and the app goes on (``ExceptionManager.PASS``); Ctrl-C and ``SystemExit`` still end it."""

    MAX_LOGGED = 20  #: tracebacks logged in full (a callback raising every frame is then only counted)

    def __init__(self, app):
        super().__init__()
        self.app = app
        self.count = 0

    def handle_exception(self, inst):
        if not isinstance(inst, Exception):
            return ExceptionManager.RAISE
        self.count += 1
        if self.count <= self.MAX_LOGGED:
            Logger.error(f"PDR: uncaught {type(inst).__name__}: {inst}", exc_info=(type(inst), inst, inst.__traceback__))
        try:
            self.app.warning = f"internal error ({self.count}x, logged; the app goes on): {type(inst).__name__}: {inst}"
        except Exception:  # noqa: BLE001
            pass
        return ExceptionManager.PASS


#: the carry modes in a word, for the status strip's narrow column (the health panel says them in full)
CARRY_SHORT = {CARRY_HANDHELD: "hand", CARRY_SWINGING: "swing", CARRY_POCKET: "pocket", CARRY_BAG: "bag",
               CARRY_EAR: "ear", CARRY_STILL: "still"}


def _fmt_time(s: float) -> str:
    s = int(s)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class PDRApp(App):
    """PDR Tracker.

    Parameters (desktop / tests)
    ----------------------------
    recording : str, optional
        Replay this file at start.
    speed : str
        Replay speed label ("1x", "10x", "max"); default from the settings.
    out_dir : str, optional
        Where recordings and exports go (default: see :mod:`app.storage`).
    data_dir : str, optional
        Where the settings live (default: Kivy's ``user_data_dir``; env ``PDR_APP_DATA``).
    exit_at_end : bool
        Quit when the replay has finished (after ``screenshot`` / ``report``).
    screenshot, report : str, optional
        At the end of the replay, save a PNG of the window / a JSON report.
    """

    title = "PDR Tracker"

    steps_text = StringProperty("0")
    distance_text = StringProperty("0.0 m")
    heading_text = StringProperty("–")
    time_text = StringProperty("0:00")
    #: the name under the heading in the status strip: "heading", with the carry mode when one is detected
    heading_name = StringProperty("heading")
    warning = StringProperty("")
    message = StringProperty("")
    health_text = StringProperty("")
    source_text = StringProperty("no source")
    mode = StringProperty("idle")  # idle | replay | live
    playing = BooleanProperty(False)
    speed_label = StringProperty("10x")
    recording_label = StringProperty("")
    progress = NumericProperty(0.0)
    # settings screen
    height_text = StringProperty("")
    rate_text = StringProperty("100")
    rate_choices = ListProperty([str(r) for r in RATE_CHOICES])
    record_live = BooleanProperty(True)
    use_gps = BooleanProperty(True)
    gps_fusion_text = StringProperty("auto")
    gps_fusion_choices = ListProperty(["auto", "chen", "kubrak"])
    tracking_mode_text = StringProperty("auto")  # the setting: auto | handheld | foot
    tracking_mode_choices = ListProperty(list(TRACKING_MODES))
    tracking = StringProperty("handheld")  # what the session runs: handheld | foot
    tracking_reason = StringProperty("")
    steps_name = StringProperty("steps")  # "strides" in foot mode (one per stance of the foot)
    _replay_recording = None  # the recording being replayed (a new track of it needs its tracking mode)
    stride_model_text = StringProperty("default")
    stride_model_choices = ListProperty(list(STRIDE_MODEL_CHOICES))
    c_text = StringProperty("")
    settings_message = StringProperty("")
    calibrating = BooleanProperty(False)
    calib_text = StringProperty("")
    calib_message = StringProperty("")
    plan_text = StringProperty("none")  # the floor plan chosen (Settings)
    has_plan = BooleanProperty(False)

    def __init__(self, *, recording: str | None = None, speed: str | None = None, out_dir: str | None = None,
                 data_dir: str | None = None, exit_at_end: bool = False, screenshot: str | None = None,
                 report: str | None = None, jnius=None, files=None, **kwargs):
        super().__init__(**kwargs)
        self._files = files  # app.android_files.AndroidFiles: the system picker and Downloads (None: decided)
        self._jnius = jnius  # the phone's (imported on Android), or a fake one (tests): insets, back, grants
        self.back_handler = None
        self.insets = (0, 0, 0, 0)
        self.initial_recording = recording
        self._speed_arg = speed
        self._out_dir_arg = out_dir
        self._data_dir_arg = data_dir
        self.exit_at_end = exit_at_end
        self.screenshot_path = screenshot
        self.report_path = report
        self.session: Session | None = None
        self.raw_path: str | None = None
        self._last_ui = 0.0
        self._was_running = False
        self._end_handled = False
        self.frames = 0
        self.exit_code = 0  #: non-zero when the file given on the command line could not be replayed
        self.error = ""
        self._data_dir: str | None = None
        self.data_dir_problem = ""
        self.paused_count = 0
        self.resumed_count = 0
        self.pending_notice = ""  #: told with the next message (the last walk was interrupted)
        self.schedule_retry = Clock.schedule_once  #: how a retry is scheduled (tests collect them)
        self.exception_handler = KeepAlive(self)
        self.plan = None  # the floor plan (core.indoor.FloorPlan) of the settings, None: none
        self.plan_name = ""

    # -- build / settings ------------------------------------------------------------

    @property
    def data_dir(self) -> str:
        """The settings folder (created); if it cannot be created, a temporary one for this run (and
        :attr:`data_dir_problem` says why: the app starts with default settings instead of crashing)."""
        if self._data_dir is None:
            d = self._data_dir_arg or os.environ.get("PDR_APP_DATA") or self.user_data_dir
            try:
                os.makedirs(d, exist_ok=True)
            except OSError as e:
                tmp = tempfile.mkdtemp(prefix="pdr-app-settings-")
                self.data_dir_problem = (f"settings folder {d} cannot be created ({e.strerror or e}): "
                                         f"settings are kept for this run only")
                d = tmp
            self._data_dir = d
        return self._data_dir

    @property
    def settings_path(self) -> str:
        return os.path.join(self.data_dir, SETTINGS_FILE)

    def out_dir(self) -> str:
        return output_dir(self.data_dir, self._out_dir_arg)

    def build(self):
        if self.exception_handler not in ExceptionManager.handlers:
            ExceptionManager.add_handler(self.exception_handler)
        self.settings = Settings.load(self.settings_path)
        problems = ([self.data_dir_problem] if self.data_dir_problem else []) + list(self.settings.problems)
        if problems:
            self.warning = "; ".join(problems)
        self.settings_message = "; ".join(([self.data_dir_problem] if self.data_dir_problem else []) +
                                          list(self.settings.notes))  # the settings screen keeps saying it
        self.speed_label = self._speed_arg or self.settings.replay_speed
        self._settings_to_ui()
        Builder.load_file(KV_FILE)
        from kivy.factory import Factory  # noqa: PLC0415

        root = Factory.PDRRoot()
        problem = self._load_plan()
        if problem:
            self.warning = "; ".join(x for x in (self.warning, problem) if x)
        root.ids.track.set_plan(self.plan)
        root.ids.track.bind(on_here=lambda tv, e, n: self.here(e, n))
        Window.bind(on_keyboard=self._on_key, on_flip=self._on_flip, on_resize=self._on_resize)
        root.ids.screens.bind(current=self._screen_changed)
        jn = self.jnius
        if jn is not None:
            run_on_ui_thread = None
            if self._jnius is None:  # the phone: (un)register on Android's UI thread
                try:
                    from android.runnable import run_on_ui_thread  # noqa: PLC0415 - p4a module
                except ImportError:
                    pass
            try:
                self.back_handler = droid.BackHandler(jn, self._back_from_android, run_on_ui_thread)
            except Exception as e:  # noqa: BLE001 - back then comes as key 27 (or not at all)
                self.warning = f"back button: {e}"
        self.apply_insets(root)
        return root

    # -- Android UI: jnius, insets, back ----------------------------------------------------------

    @property
    def jnius(self):
        """The ``jnius`` module on the phone (or the one given), None on the desktop."""
        if self._jnius is None and is_android():
            try:
                import jnius  # noqa: PLC0415 - the phone's

                return jnius
            except ImportError:
                return None
        return self._jnius

    @property
    def files(self):
        """:class:`app.android_files.AndroidFiles` on the phone (the system picker, Downloads), None on the
        desktop (Kivy's file chooser and the export folder)."""
        if self._files is None and is_android() and self.jnius is not None:
            try:
                import android.activity as activity_module  # noqa: PLC0415 - p4a module

                from app.android_files import AndroidFiles  # noqa: PLC0415

                self._files = AndroidFiles(self.jnius, activity_module)
            except Exception as e:  # noqa: BLE001 - then Kivy's chooser, which shows only the app's files
                Logger.warning(f"PDR: no system picker: {e}")
                self._files = False
        return self._files or None

    def _import_dir(self, kind: str) -> str:
        """Where a document chosen in the system picker is copied (the app's own storage)."""
        return os.path.join(self.data_dir, kind)

    def _pick(self, kind: str, then) -> None:
        """The system picker; ``then(path)`` on the Kivy thread once the chosen document is copied."""
        def done(path, error):  # Android's UI thread or the copy's thread
            Clock.schedule_once(lambda dt: self._picked(path, error, then), 0)

        self.files.pick(self._import_dir(kind), done)
        self.message = "choose a file in the system picker"

    @ui_callback()
    def _picked(self, path, error, then) -> None:
        if path is None:
            self.message = "nothing opened" + ("" if error == "cancelled" else f": {error}")
            return
        then(path)

    def apply_insets(self, root=None) -> None:
        """Pad the layout by the system bars and the cutout (Android 15+ draws the app under them)."""
        root = root or self.root
        jn = self.jnius
        if jn is None or root is None:
            return
        left, top, right, bottom = self.insets = droid.system_bar_insets(jn)
        root.padding = [left, top, right, bottom]

    def _on_resize(self, *_):
        Clock.schedule_once(lambda dt: self.apply_insets(), 0)  # rotation, a new cutout, the bars shown

    def _screen_changed(self, screens, current):
        if self.back_handler is not None:
            self.back_handler.want(current != "track")

    def _back_from_android(self):
        """OnBackInvokedCallback (Android's UI thread): go back on the Kivy thread."""
        Clock.schedule_once(lambda dt: self.go_back(), 0)

    def go_back(self) -> bool:
        """Back: from Settings or Health to the track (True), else nothing to do here (False)."""
        screens = self.root.ids.screens
        if screens.current != "track":
            screens.current = "track"
            return True
        return False

    def _service_unavailable(self, name: str, e: Exception, again) -> None:
        what = ACTION_NAMES.get(name, name.replace("_", " "))
        Logger.warning(f"PDR: {name}: tracking service not answering: {e}")
        if again is not None:
            self.message = f"{what}: the tracking service is not answering ({e}); trying again in {RETRY_S:g} s"
            self.schedule_retry(again, RETRY_S)
        else:
            self.message = (f"{what}: the tracking service is not answering ({e}); it may still be starting or "
                            "busy with an export -- try again in a moment")

    def _callback_failed(self, name: str, e: Exception) -> None:
        Logger.exception(f"PDR: {name} failed")
        self.message = (f"{ACTION_NAMES.get(name, name.replace('_', ' '))} failed: {type(e).__name__}: {e} "
                        "(logged; the app goes on)")

    def _settings_to_ui(self):
        s = self.settings
        self.height_text = f"{s.height_m * 100:.0f}" if s.height_m else ""
        self.rate_text = f"{s.rate_hz:g}"
        self.record_live = s.record_live
        self.use_gps = s.use_gps
        self.gps_fusion_text = s.gps_fusion
        self.tracking_mode_text = s.tracking_mode
        self.stride_model_text = s.stride_model_name
        walks = s.calibration_walks()
        scale = s.profile.c_scale
        n = len(walks)
        self.c_text = (f"step length x {scale:.3f} ({n} walk{'s' if n > 1 else ''})" if walks else
                       f"step length x {scale:.3f} (older version)" if scale != 1.0 else "not calibrated")

    @ui_callback()
    def save_settings(self, height_cm: str, rate: str, record_live: bool, stride_model: str | None = None,
                      use_gps: bool | None = None, gps_fusion: str | None = None,
                      tracking_mode: str | None = None) -> None:
        s = self.settings
        try:
            height_m = float(height_cm) / 100.0 if height_cm.strip() else None
            rate_hz = float(rate)
        except ValueError as e:
            self.settings_message = f"not saved: {e}"
            return
        try:
            s.height_m = height_m
        except CalibrationError:
            self.settings_message = f"not saved: {height_cm.strip()} cm is not a plausible body height"
            return
        problems = []
        try:
            if stride_model:
                s.set_stride_model(stride_model)
        except StrideModelError as e:
            problems.append(f"stride model not changed: {e}")
        s.rate_hz = rate_hz
        s.record_live = bool(record_live)
        if use_gps is not None:
            s.use_gps = bool(use_gps)
        if gps_fusion is not None:
            s.gps_fusion = str(gps_fusion)
        if tracking_mode is not None:
            s.tracking_mode = str(tracking_mode)
        problems += s.validate()
        s.save(self.settings_path)
        self._settings_to_ui()
        self.settings_message = ("; ".join(problems) if problems else "saved") + \
            (" – applies to the next track" if self.session else "")

    def _pipeline_factory(self, recording=None):
        """The factory of the session's tracker, and the tracking mode shown (foot or hand-held, and why)."""
        mode, why = self.settings.choose_tracking_mode(recording)
        self.tracking, self.tracking_reason = mode, why
        self.steps_name = "strides" if mode == "foot" else "steps"
        return self.settings.pipeline_factory(recording)

    # -- the floor plan -------------------------------------------------------------------

    def _load_plan(self) -> str:
        """Read the plan the settings name (app.indoor.load_plan); returns why it could not ("" when it could)."""
        self.plan, self.plan_name, problem = self.settings.load_floor_plan()
        self.has_plan = self.plan is not None
        self.plan_text = self.plan_name or ("none" if not self.settings.floor_plan else "not readable")
        return problem

    @ui_callback()
    def choose_plan(self, path: str) -> bool:
        """Use the floor plan at ``path`` ("" for none): remembered in the settings, drawn, and given to the
        running session (placed anew).  False, with the reason in the settings message, if it cannot be read."""
        old = self.settings.floor_plan
        self.settings.floor_plan = str(path or "")
        problem = self._load_plan()
        if problem:
            self.settings.floor_plan = old
            self._load_plan()
            self.settings_message = problem
            return False
        self._save_settings_quietly()
        self.track_view.set_plan(self.plan)
        ses = self.session
        if ses is not None:
            ses.set_plan(self.plan, self.plan_name)
        self.settings_message = (f"floor plan: {self.plan_name}" + (" – press Here on the track, then tap where "
                                 "you are" if self.plan is not None else "") if path else "no floor plan")
        self._update_ui(force=True)
        return True

    @ui_callback()
    def here(self, east_m: float, north_m: float) -> None:
        """The user's tap in Here mode (plan metres): the start of the map matching, later a fix."""
        ses = self.session
        if ses is None:
            self.message = "start tracking (Live) or a replay first, then place yourself"
            return
        try:
            ses.here(east_m, north_m)
        except (ValueError, OSError) as e:
            self.message = f"not placed: {e}"
            return
        self.track_view.follow = True
        self.message = f"you are at {east_m:.1f}, {north_m:.1f} m on {self.plan_name}"
        self._update_ui(force=True)

    @ui_callback()
    def show_plan_chooser(self):
        """Choose a floor plan: our GeoJSON file, or a Microsoft floor folder (select the folder).  On the
        phone, the system picker (a GeoJSON file, copied into the app's storage)."""
        from kivy.uix.label import Label  # noqa: PLC0415

        if self.files is not None:
            self._pick("plans", self.choose_plan)
            return None

        start = os.path.dirname(self.settings.floor_plan) if self.settings.floor_plan else self.out_dir()
        chooser = FileChooserListView(path=start if os.path.isdir(start) else self.out_dir(),
                                      filters=PLAN_PATTERNS, dirselect=True)
        box = BoxLayout(orientation="vertical")
        box.add_widget(Label(text="a floor-plan GeoJSON, or a Microsoft floor folder (floor_info.json)",
                             size_hint_y=None, height="22dp", font_size="11sp", color=(0.7, 0.7, 0.7, 1),
                             shorten=True))
        box.add_widget(chooser)
        buttons = BoxLayout(size_hint_y=None, height="44dp")
        popup = Popup(title="Floor plan", content=box, size_hint=(0.95, 0.9))

        def _use(path):
            popup.dismiss()
            self.choose_plan(path)

        for text, fn in (("Use", lambda *_: chooser.selection and _use(chooser.selection[0])),
                         ("No plan", lambda *_: _use("")), ("Cancel", popup.dismiss)):
            b = Button(text=text)
            b.bind(on_release=fn)
            buttons.add_widget(b)
        box.add_widget(buttons)
        popup.open()
        self.plan_chooser = chooser  # for tests and scripts
        return popup

    @property
    def track_view(self):
        return self.root.ids.track

    # -- lifecycle ---------------------------------------------------------------------

    def on_start(self):
        Clock.schedule_interval(self._tick, 1 / 30.0)
        if self.initial_recording:
            if not self.open_recording(self.initial_recording):
                self._initial_recording_failed()
        elif is_android():
            if not self.attach_service():
                # the service's process died while it tracked: say so (once); the walk is not resumed
                self.pending_notice = droid.take_interrupted_walk(os.environ.get("ANDROID_PRIVATE"))
                self._request_android_permissions()
        else:
            self.message = "Open a recording to replay it"

    def _initial_recording_failed(self):
        """The file of the command line cannot be replayed: the error is shown, and with --exit-at-end (or
        --report) it goes into the report and the app exits with status 2 instead of waiting forever."""
        self.exit_code = 2
        self.error = self.warning
        self.message = self.warning
        if self.screenshot_path or self.report_path or self.exit_at_end:
            self._end_frames = self.frames
            Clock.schedule_interval(self._wait_frames_then_finish, 0)

    def on_pause(self):
        """Android is pausing the app: a replay pauses, live tracking in the service goes on (the sensors of
        a live session in the UI stop: Android sends them nothing in the background anyway); settings saved."""
        self.paused_count += 1
        self._save_settings_quietly()
        if isinstance(self.session, ServiceSession):
            self._was_running = False
            return True
        self._was_running = bool(self.session and self.session.running)
        if self.session:
            self.session.pause()
        self.playing = False
        return True

    def on_resume(self):
        self.resumed_count += 1
        self.apply_insets()
        if isinstance(self.session, ServiceSession):
            self.session.tick()
            return
        if self.session and self._was_running:
            try:
                self.session.resume()
            except SensorStartError as e:
                self.warning = f"sensors did not restart: {e}"
            self.playing = self.session.running

    def on_stop(self):
        if self.exception_handler in ExceptionManager.handlers:
            ExceptionManager.remove_handler(self.exception_handler)
        ses = self.session
        if isinstance(ses, ServiceSession) and ses.host is None:
            ses.detach()  # the phone: the service goes on recording; the next start attaches to it
        elif ses:
            self._close_session(ses)
        self._save_settings_quietly()

    def _close_session(self, ses) -> None:
        """Finish a session: the service's is stopped (it keeps what GPS taught in the profile itself, so the
        settings are read again), the UI's own closed here."""
        if isinstance(ses, ServiceSession):
            ses.close()
            self.settings = Settings.load(self.settings_path)
            return
        self._learn_from(ses)
        ses.close()

    def _learn_from(self, session) -> None:
        """A live walk's GPS training goes into the profile (a replayed file is someone else's walk: not kept)."""
        if self.mode == "live" and self.settings.learn_from_gps(session.pipeline):
            self._save_settings_quietly()

    def _save_settings_quietly(self):
        try:
            self.settings.save(self.settings_path)
        except OSError as e:
            self.warning = f"settings not saved: {e}"

    def _on_key(self, window, key, *args):
        if key == 27:  # back before Android 13 (and Escape on the desktop): to the track first
            return self.go_back()
        return False

    def _on_flip(self, *_):
        self.frames += 1

    # -- sessions ------------------------------------------------------------------------

    def _replace_session(self, session, mode: str, raw_path: str | None):
        if self.session:
            self._close_session(self.session)
        self.session = session
        self.mode = mode
        self.raw_path = raw_path
        self._end_handled = False
        self.track_view.follow = True
        self.track_view.set_track([0.0], [0.0])
        self.track_view.set_heading(math.nan)
        self.source_text = session.source.describe()
        self.warning = session.source.warning
        self._update_ui(force=True)

    @ui_callback()
    def open_recording(self, path: str) -> bool:
        try:  # the tracker first (foot or hand-held): a foot INS may read other devices' streams too
            rec = load_any_recording(path)
            factory = self._pipeline_factory(rec)
            source = replay_source_for(rec, factory, speed=REPLAY_SPEEDS[self.speed_label])
        except Exception as e:  # noqa: BLE001 - RecordingError, ValueError, OSError: show, don't crash
            self.warning = f"cannot replay {os.path.basename(path)}: {e}"
            return False
        self._replay_recording = rec  # a new track of this replay needs it for the tracking mode
        self._replace_session(Session(source, pipeline_factory=factory, plan=self.plan, plan_name=self.plan_name),
                              "replay", path)
        self._start_at_landmark(rec)
        notes = reading_notes(rec)
        if notes:
            self.warning = notes
        self.message = (f"replaying {os.path.basename(path)} ({rec.duration_s:.0f} s)"
                        + (f", foot-mounted INS ({self.tracking_reason})" if self.tracking == "foot" else ""))
        self.session.start()
        self.playing = True
        return True

    def _start_at_landmark(self, rec) -> None:
        """A replay on a plan starts the map matching at the recording's first landmark in plan metres (as
        ``pdr replay --map``); without one the user places it (Here)."""
        if self.plan is None:
            return
        from core.metrics import truth_of  # noqa: PLC0415

        lm = truth_of(rec).landmarks
        if lm is not None and lm.origin_lat_lon is None and len(lm.t_ns):
            self.session.start_map_at(int(lm.t_ns[0]), float(lm.east_m[0]), float(lm.north_m[0]))

    def start_live(self) -> bool:
        """Live tracking: in the tracking service (the phone's foreground service, a thread on the desktop);
        on a phone without a location grant, in the UI's own session (screen on only, and the warning says so)."""
        path = None
        if self.settings.record_live:
            try:
                path = new_recording_path(self.out_dir())
            except OSError as e:
                self.warning = f"not recording: {e}"
        self._replay_recording = None
        factory = self._pipeline_factory()
        meta = self._recording_metadata()
        jn = self.jnius
        grant = droid.location_grant(droid.activity(jn)) if jn is not None and is_android() else "desktop"
        try:
            if grant is not None:
                session = self._start_service_session(path, meta)
            else:
                source = make_live_source(rate_hz=self.settings.live_rate_hz())
                session = Session(source, pipeline_factory=factory, record_path=path, metadata=meta, plan=self.plan,
                                  plan_name=self.plan_name)
        except Exception as e:  # noqa: BLE001 - no sensors, no jnius, the service could not start
            self.warning = f"no sensors: {e}"
            return False
        self._replace_session(session, "live", path)
        session.start() if isinstance(session, Session) else session.tick()
        if grant is None:
            self.warning = ("no location permission: tracking runs in the app and stops when the screen is off "
                            "(grant location to track in the background)")
        self.recording_label = os.path.basename(path) if path else ""
        self.message = f"recording to {path}" if path else "live (not recording)"
        if self.pending_notice:
            self.message = f"{self.pending_notice}; {self.message}"
            self.pending_notice = ""
        self.playing = True
        return True

    def _service_config(self, path, meta) -> dict:
        return {"data_dir": self.data_dir, "socket": socket_path(self.data_dir), "record_path": path,
                "metadata": meta, "out_dir": self.out_dir()}

    def _start_service_session(self, path, meta) -> ServiceSession:
        config = self._service_config(path, meta)
        if is_android():
            droid.start_service(self.jnius, config)  # its own process; the first polls wait for it
            return ServiceSession(ServiceClient(config["socket"], timeout_s=2.0))
        host = InProcessService(config, lambda rate: make_live_source(rate_hz=rate))
        host.start()
        return ServiceSession(ServiceClient(config["socket"]), host=host)

    def attach_service(self) -> bool:
        """A new UI (the app was closed while the service recorded): take over the running service's
        session; the first poll brings the whole track.  False when no service answers."""
        sock = socket_path(self.data_dir)
        if not service_answers(sock):
            return False
        ses = ServiceSession(ServiceClient(sock, timeout_s=2.0))
        try:
            ses.poll()
        except (OSError, ValueError, KeyError):  # it answered a ping, then not: as if none answered
            ses.client.close()
            return False
        self._replace_session(ses, "live", ses.record_path)
        self.recording_label = os.path.basename(ses.record_path) if ses.recording and ses.record_path else ""
        self.message = "tracking goes on" + (f", recording to {ses.record_path}" if ses.recording else "")
        self.playing = ses.running
        self._update_ui(force=True)
        return True

    @ui_callback()
    def stop_live(self) -> None:
        """The Stop button: end live tracking (the service finishes the track, closes the recording, keeps
        what GPS taught, releases the wake lock, removes its notification and ends); the track stays shown."""
        ses = self.session
        if ses is None or self.mode != "live":
            return
        ses.tick()  # the last steps
        self._update_ui(force=True)
        summ = ses.summary()
        path = ses.record_path if ses.recording else None
        self._close_session(ses)
        self.session = None
        self.mode = "idle"
        self.playing = False
        self.recording_label = ""
        self.message = (f"tracking stopped: {summ['steps']} {self.steps_name}, {summ['distance_m']:.1f} m"
                        + (f"; saved {path}" if path else ""))

    @ui_callback()
    def go_live(self) -> None:
        """The Live button: live tracking (after a replay too), asking for the permissions first on a phone."""
        if self.mode == "live" and self.session is not None:
            return
        if is_android():
            self._request_android_permissions()
        else:
            self.start_live()

    def _recording_metadata(self) -> dict:
        s = self.settings
        from core import __version__  # noqa: PLC0415

        return {"app": f"pdr-app {__version__}", "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "height_m": s.height_m, "stride_model": s.stride_model_name, "c_scale": s.profile.c_scale,
                "rate_hz": s.live_rate_hz(), "use_gps": s.use_gps, "gps_fusion": s.gps_fusion_name(),
                "tracking_mode": s.choose_tracking_mode(None)[0]}

    @ui_callback()
    def toggle_recording(self):
        """Live: stop the running recording, or start a new one."""
        ses = self.session
        if not ses or self.mode != "live":
            return
        if ses.recording:
            n = ses.stop_recording()
            self.message = (ses.record_error or f"saved {ses.record_path} ({n} events)") if n else \
                "nothing recorded (no sensor event yet): no file written"
            self.recording_label = ""
        else:
            ses.start_recording(new_recording_path(self.out_dir()), self._recording_metadata())
            self.raw_path = ses.record_path
            self.recording_label = os.path.basename(ses.record_path)
            self.message = f"recording to {ses.record_path}"

    @mainthread
    def _request_android_permissions(self):
        try:
            from android.permissions import request_permissions  # noqa: PLC0415 - p4a module
        except ImportError:
            self.start_live()
            return
        try:
            perms = droid.permissions_to_request(droid.sdk_int(self.jnius))
        except Exception:  # noqa: BLE001
            perms = droid.permissions_to_request(0)

        def done(permissions, grants):  # called on the Android UI thread
            Clock.schedule_once(lambda dt: self.start_live(), 0)

        request_permissions(perms, done)

    # -- replay controls -----------------------------------------------------------------

    @ui_callback()
    def toggle_play(self):
        ses = self.session
        if not ses:
            return
        self.set_playing(not ses.running)

    @ui_callback(retry=True)
    def set_playing(self, want: bool):
        """Play (resume) or pause; sent again by a retry as the wanted state, so twice is no harm."""
        ses = self.session
        if not ses or ses.running == want:
            self.playing = bool(ses and ses.running)
            return
        if want:
            if self.mode == "replay" and ses.finished:
                self.seek_start()
            try:
                ses.resume()
            except SensorStartError as e:
                self.warning = f"sensors did not restart: {e}"
        else:
            ses.pause()
        self.playing = ses.running

    @ui_callback()
    def seek_start(self):
        ses = self.session
        if not ses or self.mode != "replay":
            return
        ses.source.seek_start()
        ses.reset_track()
        self._end_handled = False
        self.track_view.follow = True
        self.track_view.set_track([0.0], [0.0])
        self._update_ui(force=True)

    @ui_callback()
    def set_speed(self, label: str):
        if label not in REPLAY_SPEEDS:
            return
        self.speed_label = label
        self.settings.replay_speed = label
        if self.session and self.mode == "replay":
            self.session.source.set_speed(REPLAY_SPEEDS[label])

    @ui_callback()
    def new_track(self):
        """Start a new track with the current settings (live: the recording goes on)."""
        ses = self.session
        if not ses:
            return
        if self.mode == "replay":
            ses.pipeline_factory = self._pipeline_factory(self._replay_recording)
            self.seek_start()
            return
        factory = self._pipeline_factory()
        if isinstance(ses, ServiceSession):
            ses.new_track()  # the service reads the saved settings: new pipeline, sensors at the saved rate
        else:
            rate = self.settings.live_rate_hz()
            if getattr(ses.source, "rate_hz", rate) != rate:
                try:
                    ses.replace_source(make_live_source(rate_hz=rate))
                except Exception as e:  # noqa: BLE001
                    self.warning = f"sensors not restarted at {rate:g} Hz: {e}"
            ses.pipeline_factory = factory
            ses.reset_track()
        self.track_view.set_track([0.0], [0.0])
        self._update_ui(force=True)

    # -- calibration ---------------------------------------------------------------------

    @ui_callback()
    def toggle_calibration(self):
        ses = self.session
        if not ses:
            self.calib_message = "start a live session (or a replay) first"
            return
        if self.tracking == "foot":
            self.calib_message = ("foot mode measures each stride directly (zero-velocity updates): there is no "
                                  "step length to calibrate")
            return
        if not ses.calibrating:
            ses.start_calibration()
            self.calibrating = True
            self.calib_message = "walk the known distance, then stop"
        else:
            walked = ses.stop_calibration()
            self.calibrating = False
            self.calib_text = f"measured {walked:.1f} m"
            self.calib_message = "enter the known distance and save"

    @ui_callback()
    def save_calibration(self, known_text: str):
        """Calibrate the profile with the calibration walk's steps (core.pdr.calibration) and save it."""
        ses = self.session
        if not ses or ses.calibration_range_ns is None or ses.calibrating:
            self.calib_message = "do a calibration walk first (start, walk, stop)"
            return
        if isinstance(ses, ServiceSession):  # the steps are in the service: it calibrates and saves the profile
            resp = ses.calibrate(known_text.strip())
            if not resp.get("ok"):
                self.calib_message = resp.get("error", "calibration failed")
                return
            self.settings = Settings.load(self.settings_path)
            self._settings_to_ui()
            self.calib_message = "; ".join([f"saved: step length x {resp['scale']:.3f} ({resp['n_steps']} steps, "
                                            f"the model said {resp['model_distance_m']:.1f} m); press 'New track' "
                                            "to use it", *resp["warnings"]])
            return
        try:
            res = self.settings.calibrate(ses.calibration_steps(), known_text.strip())
        except CalibrationError as e:
            self.calib_message = str(e)
            return
        self.settings.save(self.settings_path)
        self._settings_to_ui()
        saved = (f"saved: step length x {res.scale:.3f} ({res.n_steps} steps, the model said "
                 f"{res.model_distance_m:.1f} m); press 'New track' to use it")
        self.calib_message = "; ".join([saved, *res.warnings])

    # -- export ----------------------------------------------------------------------------

    @ui_callback(retry=True)
    def export(self):
        ses = self.session
        if not ses:
            return None
        base = os.path.splitext(os.path.basename(self.raw_path or "track"))[0]
        if base.endswith((".csv", ".txt")):
            base = os.path.splitext(base)[0]
        out = ses.export(self.out_dir(), base, raw_path=self.raw_path)
        written = [os.path.basename(v) for k, v in out.items() if k != "errors"]
        where = self.out_dir()
        errors = list(out["errors"])
        if self.files is not None and written:  # the phone: also into Download/PDR, the user's own files
            try:
                shared = self.files.export_to_downloads([v for k, v in out.items() if k != "errors"])
            except Exception as e:  # noqa: BLE001 - the files are still in the export folder
                errors.append(f"not copied to Download/PDR: {e}")
                shared = []
            if shared:
                out["downloads"] = shared
                where = os.path.dirname(shared[0])
        self.message = f"exported to {where}: " + ", ".join(written)
        if errors:
            self.warning = "export: " + "; ".join(errors)
        return out

    @ui_callback()
    def show_file_chooser(self):
        """Open a recording: the chooser starts in the recordings folder, shows where it is, and lists the
        files of the formats ``core.importers`` reads (``*.csv``, ``*.gz``, ``*.zip``, ...)."""
        from kivy.uix.label import Label  # noqa: PLC0415

        if self.files is not None:  # the phone: the system picker sees what scoped storage hides from paths
            self._pick("imported", self.open_recording)
            return None
        patterns, names = recording_formats()
        start = self.out_dir()
        chooser = FileChooserListView(path=start, filters=patterns)
        box = BoxLayout(orientation="vertical")
        where = Label(text=chooser.path, size_hint_y=None, height="28dp", font_size="12sp", shorten=True,
                      shorten_from="left", halign="left", valign="middle")
        where.bind(size=lambda w, *_: setattr(w, "text_size", w.size))
        chooser.bind(path=lambda c, path: setattr(where, "text", path))
        box.add_widget(where)
        box.add_widget(Label(text="reads: " + ", ".join(names), size_hint_y=None, height="22dp", font_size="11sp",
                             color=(0.7, 0.7, 0.7, 1), shorten=True))
        box.add_widget(chooser)
        buttons = BoxLayout(size_hint_y=None, height="44dp")
        popup = Popup(title="Open a recording", content=box, size_hint=(0.95, 0.9))

        def _open(*_):
            if chooser.selection:
                popup.dismiss()
                self.open_recording(chooser.selection[0])

        ok = Button(text="Replay")
        ok.bind(on_release=_open)
        home = Button(text="Recordings")
        home.bind(on_release=lambda *_: setattr(chooser, "path", start))
        cancel = Button(text="Cancel")
        cancel.bind(on_release=popup.dismiss)
        for b in (ok, home, cancel):
            buttons.add_widget(b)
        box.add_widget(buttons)
        chooser.bind(on_submit=lambda *a: _open())
        popup.open()
        self.chooser = chooser  # for tests and scripts
        self.chooser_path_label = where
        return popup

    # -- the clock ---------------------------------------------------------------------------

    def _tick(self, dt):
        ses = self.session
        if ses is None:
            return
        try:
            new = ses.tick()
        except Exception as e:  # noqa: BLE001 - an error in a clock callback would close the app
            ses.source.stop()
            self.playing = False
            self.warning = f"stopped: {type(e).__name__}: {e}"
            return
        if ses.record_error and self.recording_label:
            self.recording_label = ""
            self.warning = ses.record_error
            self.message = ses.record_error
        now = time.monotonic()
        if new or now - self._last_ui >= UI_INTERVAL_S:
            self._update_ui(track_changed=bool(new))
        if self.mode == "replay" and ses.finished and not self._end_handled:
            self._end_handled = True
            self._on_replay_end()

    def _update_ui(self, force: bool = False, track_changed: bool = True):
        ses = self.session
        self._last_ui = time.monotonic()
        if ses is None:
            return
        tv = self.track_view
        if track_changed or force:
            tv.set_track(ses.track_east, ses.track_north)
        tv.set_gps(ses.gps_overlay())  # copies only what is new
        tv.set_map(ses.map_overlay())
        summ = ses.summary()
        tv.set_heading(summ["heading_rad"])
        held = summ.get("steps_held", 0)  # a walk's first steps, held while the carry mode settles
        self.steps_text = f"{summ['steps']} +{held}" if held else str(summ["steps"])
        self.distance_text = f"{summ['distance_m']:.1f} m"
        h = summ["heading_deg"]
        self.heading_text = f"{h:.0f}°" if h == h else "–"
        self.time_text = _fmt_time(summ["elapsed_s"])
        carry = summ.get("carry")
        self.heading_name = f"heading · {CARRY_SHORT.get(carry, carry)}" if carry else "heading"
        if self.root.ids.screens.current == "health" or force:
            self.health_text = ses.health_text()
        self.calibrating = ses.calibrating  # a new track ends a calibration walk
        if self.calibrating:
            self.calib_text = f"walking: {ses.calibration_distance_m():.1f} m"
        if self.mode == "replay":
            self.progress = ses.source.progress
        labels = summ["labels"]
        if ses.errors:
            self.warning = f"{ses.errors} pipeline error(s), last: {ses.last_error}"
        elif labels and not ses.source.warning:
            self.warning = "; ".join(labels)
        if ses.record_error and not self.warning.startswith(ses.record_error):
            self.warning = ses.record_error + ("; " + self.warning if self.warning else "")  # stays on screen
        self.playing = ses.running and not (self.mode == "replay" and ses.finished)

    def _on_replay_end(self):
        ses = self.session
        self.playing = False
        self._update_ui(force=True)
        self.track_view.fit()
        s = ses.summary()
        self.message = f"replay finished: {s['steps']} steps, {s['distance_m']:.1f} m"
        if self.screenshot_path or self.report_path or self.exit_at_end:
            self._end_frames = self.frames
            Clock.schedule_interval(self._wait_frames_then_finish, 0)

    def _wait_frames_then_finish(self, dt):
        # take the screenshot after a few rendered frames, not at a wall-clock time; a window with nothing new
        # to draw does not flip (e.g. the file could not be opened): ask for redraws, and go on after 300 calls
        self._end_waits = getattr(self, "_end_waits", 0) + 1
        if self.frames - self._end_frames < 6 and self._end_waits < 300:
            Window.canvas.ask_update()
            return True
        if self.screenshot_path:
            self.save_screenshot(self.screenshot_path)
        if self.report_path:
            self.write_report(self.report_path)
        if self.exit_at_end:
            self.stop()
        return False

    def save_screenshot(self, path: str) -> str:
        """Window screenshot to exactly ``path`` (Kivy adds a counter to the name it is given)."""
        base, ext = os.path.splitext(os.path.abspath(path))
        written = Window.screenshot(name=base + "-tmp" + (ext or ".png"))
        os.replace(written, path)
        return path

    def report(self) -> dict:
        """What is on screen, for tests and scripts."""
        ses = self.session
        tv = self.track_view
        vp = tv.vp
        wx, wy = tv.to_window(tv.x, tv.y)  # the track screen is a RelativeLayout
        out = {"mode": self.mode, "window_size": list(Window.size), "frames": self.frames,
               "paused": self.paused_count, "resumed": self.resumed_count,
               # the view rectangle in window pixels (y up), metres -> pixels by scale and center
               "view": {"x": wx, "y": wy, "width": tv.width, "height": tv.height, "scale": vp.scale,
                        "center": list(vp.center), "follow": tv.follow},
               "tracking": {"mode": self.tracking, "reason": self.tracking_reason, "steps_name": self.steps_name},
               "status": {"steps": self.steps_text, "distance": self.distance_text,
                          "heading": self.heading_text, "time": self.time_text,
                          "heading_name": self.heading_name},
               "warning": self.warning, "message": self.message, "exit_code": self.exit_code,
               "error": self.error, "settings_problem": self.data_dir_problem,
               "service": isinstance(ses, ServiceSession), "screen": self.root.ids.screens.current,
               "insets": list(self.insets), "padding": list(self.root.padding),
               "back_registered": bool(self.back_handler and self.back_handler.registered)}
        out["plan"] = {"path": self.settings.floor_plan, "name": self.plan_name,
                       "walls": int(sum(len(m.indices) for m in tv.wall_meshes) // 2)}
        if ses:
            m = ses.map_overlay()
            if m is not None:
                out["map"] = {"east": list(m.east), "north": list(m.north), "position": m.position, "cov": m.cov,
                              "raw_offset": m.raw_offset, "placed": m.placed, "text": m.text,
                              "shows_map": tv.shows_map}
            out.update(summary={k: v for k, v in ses.summary().items() if k != "labels"},
                       track_east=ses.track_east, track_north=ses.track_north, events=ses.events_in,
                       errors=ses.errors, health=ses.health_text(), finished=ses.finished)
            gps = ses.gps_overlay()
            if gps is not None:
                out["gps"] = {"fused_east": gps.fused_east, "fused_north": gps.fused_north,
                              "fused_source": gps.fused_source, "fix_east": gps.fix_east,
                              "fix_north": gps.fix_north, "fix_hacc": gps.fix_hacc,
                              "fix_accepted": gps.fix_accepted, "n_fixes": gps.n_fixes, "n_used": gps.n_used,
                              "cov_en_m2": gps.cov_en_m2, "anchored": gps.anchored, "fusion": gps.fusion,
                              "last_verdict": gps.last_verdict,
                              "legend": tv._legend.text, "shows_fused": tv.shows_fused}
        return out

    def write_report(self, path: str) -> None:
        with open(path, "w", encoding="utf-8") as f:
            json.dump(self.report(), f, indent=1, default=float)
