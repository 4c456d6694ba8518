"""What pyjnius 1.7.0 does with a Python call on a Java object, for the fake ``jnius`` of the app tests.

pyjnius (``jnius/jnius_export_class.pxi``, ``JavaMultipleMethod.__call__``, and ``jnius/jnius_utils.pxi``,
``calculate_score``, at tag 1.7.0 -- the version p4a's recipe pins) picks an overload like this:

* a method with one signature (``JavaMethod``) is called with it: no scoring (a wrong number of arguments
  is a ``JavaException``, an argument it cannot convert an error);
* with several, every signature is scored against the arguments; a score <= 0 drops it; the scores are
  sorted as ``(score, signature)`` tuples and the **last** one is called, so a tie goes to the signature
  that sorts highest as a string;
* the score: -1 when the number of arguments differs; else +10, and per argument: ``None`` +10 for any
  object or array; ``str`` +10 for ``String`` (not for ``CharSequence``: -1 there, unless the method has
  a single signature); ``java/lang/Object`` +10 for a Java or PythonJavaClass object, +5 for str, list,
  int or float; an autoclass object +10 when its class *is* the parameter's class, else **+5 whatever
  the class** (no assignability check); a ``PythonJavaClass`` (a Python listener) **+1 for any object
  parameter**; a callable +1; ints +10 for ``I``/``J``/``S``/``B`` (+5 for a float), floats +10 for
  ``F``/``D`` (+5 for an int); ``bool`` +10 for ``Z`` only; a list for an array +10 when its items score.

So ``SensorManager.unregisterListener(listener)`` with a Python listener scores 11 for both
``(SensorEventListener)`` and the deprecated ``(SensorListener)``; ``"...SensorListener;)V"`` sorts after
``"...SensorEventListener;)V"`` and wins.

A debuggable build runs with CheckJNI, which aborts the process when a Java method gets an argument of the
wrong type: :class:`CheckJNIAbort` (a ``BaseException``, so the app's ``except Exception`` does not hide it,
as nothing hides an abort).  Returned objects are wrapped as pyjnius wraps them: as the *declared* return
type, except ``java/lang/Object``, which becomes the object's own class.

:data:`SDK` holds the overloads (from the Android API reference, API 36) of every Java method the app calls;
a call to a method missing from it fails, so the table is complete for what the tests run.
"""

from __future__ import annotations

import functools

#: ``class: (superclasses and interfaces, {method: [signature, ...]}, {object field: type})``; ``<init>`` are
#: the constructors; a signature with a leading ``static `` is a static method.
SDK: dict = {}


def _cls(name, supers=(), fields=None, **methods):
    SDK[name] = (tuple(supers), {("<init>" if k == "init" else k): v for k, v in methods.items()}, fields or {})


S, CS, O = "Ljava/lang/String;", "Ljava/lang/CharSequence;", "Ljava/lang/Object;"
CTX, INTENT, URI, HANDLER, LOOPER = ("Landroid/content/Context;", "Landroid/content/Intent;", "Landroid/net/Uri;",
                                     "Landroid/os/Handler;", "Landroid/os/Looper;")
SEL, SL, SENSOR = "Landroid/hardware/SensorEventListener;", "Landroid/hardware/SensorListener;", "Landroid/hardware/Sensor;"
LL, PI, EXE = "Landroid/location/LocationListener;", "Landroid/app/PendingIntent;", "Ljava/util/concurrent/Executor;"
NMEA, GNMEA = "Landroid/location/OnNmeaMessageListener;", "Landroid/location/GpsStatus$NmeaListener;"
BUNDLE = "Landroid/os/Bundle;"

_cls("java/lang/Object")
_cls("java/io/File", getAbsolutePath=["()Ljava/lang/String;"])
_cls("java/lang/String", ["java/lang/CharSequence"], init=["()V", f"({S})V", "([B)V", "([C)V"])
_cls("android/content/Context", getSystemService=[f"({S}){O}", f"(Ljava/lang/Class;){O}"],
     checkSelfPermission=[f"({S})I"], getPackageName=[f"(){S}"],
     getPackageManager=["()Landroid/content/pm/PackageManager;"],
     getApplicationInfo=["()Landroid/content/pm/ApplicationInfo;"], getFilesDir=["()Ljava/io/File;"],
     getExternalFilesDir=[f"({S})Ljava/io/File;"], getContentResolver=["()Landroid/content/ContentResolver;"],
     startActivity=[f"({INTENT})V", f"({INTENT}{BUNDLE})V"])
_cls("android/app/Activity", ["android/content/Context"], getWindow=["()Landroid/view/Window;"],
     getOnBackInvokedDispatcher=["()Landroid/window/OnBackInvokedDispatcher;"],
     startActivityForResult=[f"({INTENT}I)V", f"({INTENT}I{BUNDLE})V"])
_cls("android/app/Service", ["android/content/Context"], stopSelf=["()V", "(I)V"])
_cls("org/kivy/android/PythonActivity", ["android/app/Activity"],
     fields={"mActivity": "org/kivy/android/PythonActivity"})
_cls("org/kivy/android/PythonService", ["android/app/Service"], setAutoRestartService=["(Z)V"],
     fields={"mService": "org/kivy/android/PythonService"})
# p4a's Service.tmpl.java (services = Tracker:...)
_cls("org/pdrproject/pdrtracker/ServiceTracker", ["org/kivy/android/PythonService"],
     start=[f"static ({CTX}{S})V", f"static ({CTX}{S}{S}{S}{S})V"], stop=[f"static ({CTX})V"])
_cls("android/hardware/SensorManager",
     getDefaultSensor=[f"(I){SENSOR}", f"(IZ){SENSOR}"],
     registerListener=[f"({SL}I)Z", f"({SL}II)Z", f"({SEL}{SENSOR}I)Z", f"({SEL}{SENSOR}I{HANDLER})Z",
                       f"({SEL}{SENSOR}II)Z", f"({SEL}{SENSOR}II{HANDLER})Z"],
     unregisterListener=[f"({SL})V", f"({SL}I)V", f"({SEL}{SENSOR})V", f"({SEL})V"])
_cls("android/hardware/Sensor", getType=["()I"], getName=[f"(){S}"], getVendor=[f"(){S}"],
     getMinDelay=["()I"], getResolution=["()F"], getMaximumRange=["()F"])
_cls("android/os/HandlerThread", ["java/lang/Thread"], init=[f"({S})V", f"({S}I)V"], start=["()V"],
     getLooper=[f"(){LOOPER}"], quitSafely=["()Z"], quit=["()Z"])
_cls("java/lang/Thread")
_cls("android/os/Looper")
_cls("android/os/Handler", init=["()V", "(Landroid/os/Handler$Callback;)V", f"({LOOPER})V",
                                 f"({LOOPER}Landroid/os/Handler$Callback;)V"])
_cls("android/os/SystemClock", elapsedRealtimeNanos=["static ()J"])
_cls("android/os/Build")
_cls("android/os/Build$VERSION")
_cls("android/location/LocationManager",
     requestLocationUpdates=[f"({S}JF{LL})V", f"({S}JF{LL}{LOOPER})V", f"({S}JF{EXE}{LL})V",
                             f"(JFLandroid/location/Criteria;{LL}{LOOPER})V",
                             f"(JFLandroid/location/Criteria;{EXE}{LL})V", f"({S}JF{PI})V",
                             f"(JFLandroid/location/Criteria;{PI})V",
                             f"({S}Landroid/location/LocationRequest;{EXE}{LL})V",
                             f"({S}Landroid/location/LocationRequest;{PI})V"],
     removeUpdates=[f"({LL})V", f"({PI})V"], hasProvider=[f"({S})Z"],
     addNmeaListener=[f"({GNMEA})Z", f"({NMEA})Z", f"({NMEA}{HANDLER})Z", f"({EXE}{NMEA})Z"],
     removeNmeaListener=[f"({GNMEA})V", f"({NMEA})V"])
_cls("android/os/PowerManager", newWakeLock=[f"(I{S})Landroid/os/PowerManager$WakeLock;"])
_cls("android/os/PowerManager$WakeLock", setReferenceCounted=["(Z)V"], acquire=["()V", "(J)V"],
     release=["()V", "(I)V"], isHeld=["()Z"])
_cls("android/app/NotificationManager", createNotificationChannel=["(Landroid/app/NotificationChannel;)V"],
     notify=["(ILandroid/app/Notification;)V", f"({S}ILandroid/app/Notification;)V"],
     cancel=["(I)V", f"({S}I)V"])
_cls("android/app/NotificationChannel", init=[f"({S}{CS}I)V"], setShowBadge=["(Z)V"])
_cls("android/app/Notification")
_cls("android/app/PendingIntent", getActivity=[f"static ({CTX}I{INTENT}I){PI}", f"static ({CTX}I{INTENT}I{BUNDLE}){PI}"])
_B = "Landroid/app/Notification$Builder;"
_cls("android/app/Notification$Builder", init=[f"({CTX}{S})V", f"({CTX})V"],
     setContentTitle=[f"({CS}){_B}"], setContentText=[f"({CS}){_B}"],
     setSmallIcon=[f"(I){_B}", f"(Landroid/graphics/drawable/Icon;){_B}"], setOngoing=[f"(Z){_B}"],
     setOnlyAlertOnce=[f"(Z){_B}"], setContentIntent=[f"({PI}){_B}"], build=["()Landroid/app/Notification;"])
_cls("android/content/pm/PackageManager", getLaunchIntentForPackage=[f"({S}){INTENT}"])
_cls("android/content/pm/ApplicationInfo")
_cls("android/view/Window", getDecorView=["()Landroid/view/View;"])
_cls("android/view/View", getRootWindowInsets=["()Landroid/view/WindowInsets;"])
_cls("android/view/WindowInsets", getInsets=["(I)Landroid/graphics/Insets;"])
_cls("android/graphics/Insets")
_cls("android/view/WindowInsets$Type", systemBars=["static ()I"], displayCutout=["static ()I"])
_cls("android/window/OnBackInvokedDispatcher",
     registerOnBackInvokedCallback=["(ILandroid/window/OnBackInvokedCallback;)V"],
     unregisterOnBackInvokedCallback=["(Landroid/window/OnBackInvokedCallback;)V"])
# the system picker and MediaStore (app/android_files.py)
_I = INTENT
_cls("android/content/Intent", init=["()V", f"({_I})V", f"({S})V", f"({S}{URI})V", f"({CTX}Ljava/lang/Class;)V",
                                     f"({S}{URI}{CTX}Ljava/lang/Class;)V"],
     addCategory=[f"({S}){_I}"], setType=[f"({S}){_I}"], getData=[f"(){URI}"], addFlags=[f"(I){_I}"],
     putExtra=[f"({S}{t}){_I}" for t in ("Z", "B", "C", "S", "I", "J", "F", "D", S, CS, "Landroid/os/Parcelable;",
                                         "[Landroid/os/Parcelable;", "Ljava/io/Serializable;", "[Z", "[B", "[S",
                                         "[C", "[I", "[J", "[F", "[D", f"[{S}", f"[{CS}", BUNDLE)])
_cls("android/net/Uri", ["android/os/Parcelable"], getLastPathSegment=[f"(){S}"], toString=[f"(){S}"])
_cls("android/os/Parcelable")
_cls("android/content/ContentResolver",
     openFileDescriptor=[f"({URI}{S})Landroid/os/ParcelFileDescriptor;",
                         f"({URI}{S}Landroid/os/CancellationSignal;)Landroid/os/ParcelFileDescriptor;"],
     query=[f"({URI}[{S}{S}[{S}{S})Landroid/database/Cursor;",
            f"({URI}[{S}{S}[{S}{S}Landroid/os/CancellationSignal;)Landroid/database/Cursor;",
            f"({URI}[{S}{BUNDLE}Landroid/os/CancellationSignal;)Landroid/database/Cursor;"],
     insert=[f"({URI}Landroid/content/ContentValues;){URI}", f"({URI}Landroid/content/ContentValues;{BUNDLE}){URI}"],
     delete=[f"({URI}{S}[{S})I", f"({URI}{BUNDLE})I"])
_cls("android/os/ParcelFileDescriptor", detachFd=["()I"], close=["()V"])
_cls("android/database/Cursor", moveToFirst=["()Z"], getColumnIndex=[f"({S})I"], getString=[f"(I){S}"],
     close=["()V"])
_cls("android/content/ContentValues", init=["()V", "(I)V", "(Landroid/content/ContentValues;)V"],
     put=[f"({S}{t})V" for t in (S, "Ljava/lang/Byte;", "Ljava/lang/Short;", "Ljava/lang/Integer;", "Ljava/lang/Long;",
                                 "Ljava/lang/Float;", "Ljava/lang/Double;", "Ljava/lang/Boolean;", "[B")])
_cls("android/provider/MediaStore$Downloads", fields={"EXTERNAL_CONTENT_URI": "android/net/Uri"})
_cls("android/provider/MediaStore$MediaColumns")
_cls("android/provider/OpenableColumns")
_cls("android/os/Environment")
_cls("android/app/Activity$Result")

# the app's own Java listener (app/java/org/pdrproject/sensors/EventBuffer.java)
_cls("org/pdrproject/sensors/EventBuffer", ["android/hardware/SensorEventListener"], init=["(II)V"], take=["()I"],
     takenTimes=["()[J"], takenValues=["()[F"], dropped=["()J"], accuracy=["()I"], width=["()I"])
_cls("android/hardware/SensorEventListener")

#: methods of the Android SDK the app must not use (deprecated overloads picked by mistake show up here)
DEPRECATED = {("android/hardware/SensorManager", "unregisterListener", f"({SL})V"),
              ("android/hardware/SensorManager", "unregisterListener", f"({SL}I)V"),
              ("android/hardware/SensorManager", "registerListener", f"({SL}I)Z"),
              ("android/hardware/SensorManager", "registerListener", f"({SL}II)Z"),
              ("android/location/LocationManager", "addNmeaListener", f"({GNMEA})Z"),
              ("android/location/LocationManager", "addNmeaListener", f"({NMEA})Z"),
              ("android/location/LocationManager", "removeNmeaListener", f"({GNMEA})V"),
              ("android/os/Handler", "<init>", "()V"),
              ("android/app/Notification$Builder", "<init>", f"({CTX})V")}


class JavaException(Exception):
    """``jnius.JavaException``: no overload matches, or the Java side threw."""


class CheckJNIAbort(BaseException):
    """CheckJNI's ``JNI DETECTED ERROR IN APPLICATION``: the process aborts (nothing catches it)."""


class PythonJavaClass:
    """``jnius.PythonJavaClass``: a Python object implementing Java interfaces (``__javainterfaces__``)."""

    def __init__(self, *args, **kwargs):
        pass


def java_method(signature, name=None):
    def deco(f):
        f.__javasignature__ = signature
        f.__javaname__ = name or f.__name__
        return f
    return deco


# -- signatures and scores ---------------------------------------------------------------------------------


def parse_args(signature: str) -> tuple[list, str]:
    """``"(ILjava/lang/String;[B)V"`` -> ``(["I", "Ljava/lang/String;", "[B"], "V")``."""
    body, ret = signature[1:].split(")", 1)
    out, i = [], 0
    while i < len(body):
        j = i
        while body[j] == "[":
            j += 1
        j = body.index(";", j) + 1 if body[j] == "L" else j + 1
        out.append(body[i:j])
        i = j
    return out, ret


def score(sign_args: list, args: tuple) -> int:
    """pyjnius 1.7.0 ``calculate_score`` (no varargs: the app calls none)."""
    if len(args) != len(sign_args):
        return -1
    total = 10
    for r, arg in zip(sign_args, args):
        if r == "Z":
            if not isinstance(arg, bool):
                return -1
            total += 10
        elif r in ("B", "C"):
            ok = isinstance(arg, int) if r == "B" else isinstance(arg, str) and len(arg) == 1
            if not ok:
                return -1
            total += 10
        elif r in ("S", "I", "J"):
            lim = {"S": 32767, "I": 2147483647, "J": None}[r]
            if isinstance(arg, int) and (lim is None or -lim - 1 <= arg <= lim):
                total += 10
            elif isinstance(arg, float):
                total += 5
            else:
                return -1
        elif r in ("F", "D"):
            if isinstance(arg, int):
                total += 5
            elif isinstance(arg, float):
                total += 10
            else:
                return -1
        elif r[0] == "L":
            cls = r[1:-1]
            if arg is None or (cls == "java/lang/String" and isinstance(arg, str)):
                total += 10
            elif cls == "java/lang/Object":
                if isinstance(arg, (PythonJavaClass, JavaObject)):
                    total += 10
                elif isinstance(arg, (str, list, tuple, int, float)):
                    total += 5
                else:
                    return -1
            elif hasattr(arg, "__javaclass__") and cls == "java/lang/Class":
                total += 10
            elif isinstance(arg, JavaObject):
                total += 10 if arg.__javaclass__ == cls else 5
            elif isinstance(arg, PythonJavaClass) or callable(arg):
                total += 1
            else:
                return -1
        elif r[0] == "[":
            if arg is None or (r == "[B" and isinstance(arg, (bytes, bytearray))) or (r == "[C" and isinstance(arg, str)):
                total += 10
            elif not isinstance(arg, (list, tuple)):
                return -1
            elif arg:
                if score([r[1:]] * len(arg), tuple(arg)) == -1:
                    return -1
                total += 10
    return total


def choose(signatures: list, args: tuple, where: str) -> str:
    """The signature pyjnius 1.7.0 calls (see the module docstring)."""
    if len(signatures) == 1:
        sig = signatures[0]
        if len(parse_args(sig)[0]) != len(args):
            raise JavaException(f"{where}: invalid call, number of argument mismatch, available: {signatures}")
        return sig
    scores = []
    for sig in signatures:
        s = score(parse_args(sig)[0], args)
        if s > 0:
            scores.append((s, sig))
    if not scores:
        raise JavaException(f"No methods called {where} matching your arguments, requested: {args}, "
                            f"available: {signatures}")
    scores.sort()
    return scores[-1][1]


# -- Java types (for CheckJNI) -----------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def supertypes(cls: str) -> frozenset:
    out, todo = set(), [cls]
    while todo:
        c = todo.pop()
        if c in out:
            continue
        out.add(c)
        todo += list(SDK.get(c, ((),))[0])
    return frozenset(out | {"java/lang/Object"})


def assignable(r: str, arg) -> bool:
    """Would Java accept ``arg`` for a parameter of JNI type ``r``?  (What CheckJNI checks.)"""
    if r in ("Z",):
        return isinstance(arg, bool)
    if r in ("B", "C", "S", "I", "J"):
        return isinstance(arg, int) and not isinstance(arg, bool) or (r == "C" and isinstance(arg, str))
    if r in ("F", "D"):
        return isinstance(arg, (int, float)) and not isinstance(arg, bool)
    if arg is None:
        return True
    if r[0] == "[":
        return isinstance(arg, (list, tuple, bytes, bytearray))
    cls = r[1:-1]
    if isinstance(arg, str):
        return cls in ("java/lang/String", "java/lang/CharSequence", "java/lang/Object")
    if isinstance(arg, PythonJavaClass):
        return cls == "java/lang/Object" or cls in {i.replace(".", "/") for i in arg.__javainterfaces__}
    if isinstance(arg, JavaObject):
        return cls in supertypes(arg.__javaclass__)
    return False


# -- wrapped objects ---------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _members(cls: str, name: str) -> tuple:
    sigs = []
    for c in [cls] + sorted(supertypes(cls) - {cls}):
        for sig in SDK.get(c, ((), {}, {}))[1].get(name, []):
            if sig not in sigs:
                sigs.append(sig)
    return tuple(sigs)


def _field_type(cls: str, name: str):
    for c in [cls] + sorted(supertypes(cls) - {cls}):
        t = SDK.get(c, ((), {}, {}))[2].get(name)
        if t:
            return t
    return None


class Bridge:
    """Calls from the app go through here: resolved, logged in :attr:`calls`, checked, then run on the fake."""

    def __init__(self):
        #: ``(class, method, signature)`` of every Java call the app made, in order
        self.calls: list = []

    def call(self, cls: str, name: str, target, args: tuple, static: bool):
        sigs = [s for s in _members(cls, name) if s.startswith("static ") == static]
        if not sigs:
            raise AttributeError(f"the fake SDK table has no {'static ' if static else ''}method {cls}.{name}")
        plain = [s.replace("static ", "") for s in sigs]
        sig = choose(plain, args, f"{name} in {cls}")
        self.calls.append((cls, name, sig))
        params, ret = parse_args(sig)
        for r, a in zip(params, args):
            if not assignable(r, a):
                raise CheckJNIAbort(f"JNI DETECTED ERROR IN APPLICATION: bad arguments passed to {cls}.{name}{sig}: "
                                    f"{type(a).__name__} is not a {r}")
        fn = getattr(target, name)
        result = fn(*[unwrap(a) for a in args])
        return self.wrap(result, ret)

    def wrap(self, value, ret: str):
        if value is None or ret[0] != "L" or isinstance(value, (str, JavaObject)):
            return value
        cls = ret[1:-1]
        if cls in ("java/lang/String", "java/lang/CharSequence"):
            return value
        if cls == "java/lang/Object":
            cls = getattr(value, "__javaclass__", None) or getattr(type(value), "__javaclass__", None)
            if cls is None:
                return value
        return JavaObject(self, cls, value)


def unwrap(value):
    return value._target if isinstance(value, JavaObject) else value


class JavaObject:
    """An autoclass'd Java object (pyjnius ``JavaClass`` instance) in front of a Python fake."""

    def __init__(self, bridge: Bridge, cls: str, target):
        object.__setattr__(self, "_bridge", bridge)
        object.__setattr__(self, "__javaclass__", cls)
        object.__setattr__(self, "_target", target)

    def __getattr__(self, name):
        cls = self.__javaclass__
        if _members(cls, name):
            return lambda *args: self._bridge.call(cls, name, self._target, args, static=False)
        value = getattr(self._target, name)
        if callable(value):
            raise AttributeError(f"the fake SDK table has no method {cls}.{name}")
        t = _field_type(cls, name)
        return self._bridge.wrap(value, f"L{t};") if t else value

    def __setattr__(self, name, value):
        setattr(self._target, name, value)

    def __eq__(self, other):
        return unwrap(other) is self._target

    def __hash__(self):
        return id(self._target)

    def __repr__(self):
        return f"<{self.__javaclass__} {self._target!r}>"


class JavaClassProxy:
    """What ``autoclass(name)`` returns: static methods, fields and the constructors of a Python fake class."""

    def __init__(self, bridge: Bridge, name: str, pycls):
        self._bridge, self._pycls = bridge, pycls
        self.__javaclass__ = name.replace(".", "/")

    def __getattr__(self, name):
        cls = self.__javaclass__
        if any(s.startswith("static ") for s in _members(cls, name)):
            return lambda *args: self._bridge.call(cls, name, self._pycls, args, static=True)
        value = getattr(self._pycls, name)
        t = _field_type(cls, name)
        if t:
            return self._bridge.wrap(value, f"L{t};")
        if callable(value) and not isinstance(value, type):
            raise AttributeError(f"the fake SDK table has no static method {cls}.{name}")
        return value

    def __call__(self, *args):
        cls = self.__javaclass__
        sigs = SDK.get(cls, ((), {}, {}))[1].get("<init>") or ["()V"]
        sig = choose(sigs, args, f"constructor of {cls}")
        self._bridge.calls.append((cls, "<init>", sig))
        for r, a in zip(parse_args(sig)[0], args):
            if not assignable(r, a):
                raise CheckJNIAbort(f"JNI DETECTED ERROR IN APPLICATION: bad arguments to new {cls}{sig}")
        return JavaObject(self._bridge, cls, self._pycls(*[unwrap(a) for a in args]))


def cast(name: str, obj):
    """``jnius.cast``: the same object seen as class ``name``."""
    target = obj if isinstance(obj, JavaObject) else None
    if target is None:
        raise JavaException(f"cannot cast {obj!r}")
    return JavaObject(target._bridge, name.replace(".", "/"), target._target)
