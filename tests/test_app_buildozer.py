"""buildozer.spec: what can be checked without building an APK (no SDK/NDK/network here).

Parsed with buildozer's own ``SpecParser`` when buildozer is installed (a
ConfigParser with the same list rules otherwise); the packaged file list
comes from buildozer's own ``_copy_application_sources``.
"""

import ast
import configparser
import importlib.metadata
import os
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = ROOT / "buildozer.spec"

#: python-for-android recipes the spec may use (checked against p4a v2026.05.09's recipe list)
P4A_RECIPES = {"python3", "hostpython3", "kivy", "pyjnius", "numpy", "sdl2", "android", "setuptools", "libffi",
               "openssl", "sqlite3"}
#: pure-Python packages the spec may list (installed by p4a with pip --no-deps)
PURE_PYTHON = {"plyer", "gpxpy", "pygeomag", "pymap3d"}  # pygeomag: WMM in pure Python, its WMM.COF inside the wheel;
# pymap3d: WGS-84 <-> ENU, no dependencies
#: modules the phone provides without a requirement (p4a's own ``android`` module)
PROVIDED = {"android"}
#: import name -> requirement name
IMPORT_TO_REQ = {"jnius": "pyjnius"}
NEVER_ON_PHONE = {"scipy", "matplotlib", "pandas", "pytest", "hypothesis"}


def _spec():
    try:
        from buildozer.specparser import SpecParser
    except ImportError:  # same semantics for what is read here
        class SpecParser(configparser.ConfigParser):
            def __init__(self):
                super().__init__(allow_no_value=True, interpolation=configparser.BasicInterpolation())
                self.optionxform = str

            def getlist(self, section, token, default=None):
                if not self.has_option(section, token):
                    return default or []
                return [x.strip() for x in self.get(section, token).split(",") if x.strip()]

            def getdefault(self, section, token, default=None):
                return self.get(section, token) if self.has_option(section, token) else default
    c = SpecParser()
    c.read(str(SPEC))
    return c


@pytest.fixture(scope="module")
def spec():
    return _spec()


def _req_name(r):
    return re.split(r"[=<>!~ ]", r, maxsplit=1)[0].strip().lower()


def test_buildozer_token_checks(spec):
    """buildozer's own check_configuration_tokens, re-stated (constructing Buildozer creates directories)."""
    get = spec.getdefault
    assert get("app", "title", "") and get("app", "source.dir", "") == "."
    name = get("app", "package.name", "")
    assert name and not name[0].isdigit() and re.fullmatch(r"[a-z][a-z0-9_]*", name)
    assert re.fullmatch(r"[a-z][a-z0-9_]*(\.[a-z][a-z0-9_]*)+", get("app", "package.domain", ""))
    assert all(o in ("landscape", "portrait", "landscape-reverse", "portrait-reverse", "all")
               for o in spec.getlist("app", "orientation", ["landscape"]))
    assert (ROOT / "main.py").exists()


def test_version_is_single_sourced_from_core(spec):
    import core

    assert not spec.has_option("app", "version"), "use version.regex, not a second copy of the version"
    fn = spec.get("app", "version.filename")  # buildozer interpolates %(source.dir)s
    path = (ROOT / fn).resolve()
    assert path == (ROOT / "core" / "__init__.py").resolve()
    m = re.search(spec.get("app", "version.regex"), path.read_text())
    assert m and m.group(1) == core.__version__


def test_requirements_are_recipes_or_pure_python(spec):
    reqs = spec.getlist("app", "requirements")
    names = {_req_name(r) for r in reqs}
    assert {"python3", "kivy", "numpy", "plyer", "pyjnius"} <= names
    assert not names & NEVER_ON_PHONE
    unknown = names - P4A_RECIPES - PURE_PYTHON
    assert not unknown, f"neither a p4a recipe nor a known pure-Python package: {unknown}"
    assert not any(_req_name(r) == "numpy" and "==" in r for r in reqs), "numpy's recipe version is a git tag"


@pytest.mark.parametrize("dist", sorted(PURE_PYTHON))
def test_pure_python_requirements_are_pure_and_bring_their_dependencies(spec, dist):
    try:
        d = importlib.metadata.distribution(dist)
    except importlib.metadata.PackageNotFoundError:
        pytest.skip(f"{dist} not installed here")
    wheel = d.read_text("WHEEL") or ""
    assert "Root-Is-Purelib: true" in wheel and "py3-none-any" in wheel.replace("py2.py3", "py3")
    listed = {_req_name(r) for r in spec.getlist("app", "requirements")}
    needed = {_req_name(r) for r in (d.requires or []) if "extra ==" not in r}
    assert needed <= listed, f"p4a installs {dist} with --no-deps: also list {needed - listed}"


def _packaged_files():
    """Files buildozer would put in the APK, from buildozer's own copy routine when available."""
    try:
        from buildozer import Buildozer
    except ImportError:
        return None

    import tempfile

    class _B(Buildozer):
        app_dir = property(lambda self: self._tmp_app)

    b = _B.__new__(_B)
    b.config = _spec()
    b._tmp_app = tempfile.mkdtemp(prefix="apk-app-")
    b.logger = type("L", (), {"debug": lambda *a: None, "info": lambda *a: None, "error": lambda *a: None})()
    cwd = os.getcwd()
    os.chdir(ROOT)  # buildozer resolves source.dir from the working directory
    try:
        b._copy_application_sources()
    finally:
        os.chdir(cwd)
    out = []
    for root, _dirs, files in os.walk(b._tmp_app):
        out += [os.path.relpath(os.path.join(root, f), b._tmp_app).replace(os.sep, "/") for f in files]
    return sorted(out)


@pytest.fixture(scope="module")
def packaged():
    files = _packaged_files()
    if files is None:
        pytest.skip("buildozer not installed (pip install buildozer)")
    return files


def test_tests_and_desktop_material_are_not_packaged(packaged):
    for must in ("main.py", "app/main_app.py", "app/layout.kv", "app/sources.py", "core/pdr/pipeline.py",
                 "core/recording.py"):
        assert must in packaged
    for f in packaged:
        assert not f.startswith(("tests/", "docs/", "benchmarks/", "tools/", ".")), f
        assert not f.endswith((".pyc", ".png")) or f.startswith(("app/", "core/"))


def test_every_import_of_the_packaged_code_is_available_on_the_phone(spec, packaged):
    listed = {_req_name(r) for r in spec.getlist("app", "requirements")}
    missing = []
    for f in packaged:
        if not f.endswith(".py"):
            continue
        tree = ast.parse((ROOT / f).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                mods = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                mods = [node.module]
            else:
                continue
            for m in mods:
                top = m.split(".")[0]
                if top in sys.stdlib_module_names or top in ("app", "core") or top in PROVIDED:
                    continue
                if IMPORT_TO_REQ.get(top, top).lower() not in listed:
                    missing.append(f"{f}: {m}")
    assert not missing, "imported but not in requirements: " + ", ".join(missing)


def test_android_api_levels_and_archs(spec):
    assert int(spec.get("app", "android.api")) >= 35  # Google Play's floor since 2025-08-31
    assert int(spec.get("app", "android.minapi")) == 24  # numpy recipe needs >= 24
    assert int(spec.get("app", "android.ndk_api")) == 24
    # phones, and x86_64 for the usual emulators (no scipy, whose recipe builds 64-bit archs only)
    assert set(spec.getlist("app", "android.archs")) == {"arm64-v8a", "armeabi-v7a", "x86_64"}
    # p4a pinned as buildozer can keep it: a tag as the branch is re-cloned on every build (buildozer compares
    # "git branch -vv" with the branch), so the branch is master and the release is its commit
    assert spec.get("app", "p4a.branch") == "master"
    assert re.fullmatch(r"[0-9a-f]{40}", spec.get("app", "p4a.commit"))
    assert spec.get("app", "p4a.bootstrap") == "sdl2"
    assert spec.getdefault("buildozer", "warn_on_root", "1") == "0"  # CI builds as root in a container


def test_manifest_application_attributes(spec):
    """The file buildozer pastes into <application>: attributes only (no tag, no comment), each known."""
    path = ROOT / spec.get("app", "android.extra_manifest_application_arguments")
    text = path.read_text().strip()
    attrs = dict(re.findall(r'android:(\w+)="([^"]*)"', text))
    assert re.fullmatch(r'(android:\w+="[^"]*"\s*)+', text), text
    assert attrs == {"enableOnBackInvokedCallback": "true", "requestLegacyExternalStorage": "true",
                     "hasFragileUserData": "true"}
    assert not path.suffix == ".py" and "xml" not in spec.getlist("app", "source.include_exts")  # not packaged


def test_permissions_are_the_ones_the_app_uses(spec):
    perms = spec.getlist("app", "android.permissions")
    names = {re.sub(r"^\(name=([^;)]*).*\)$", r"\1", p) for p in perms}
    assert all(n.startswith("android.permission.") for n in names), perms
    assert names == {"android.permission.ACCESS_FINE_LOCATION", "android.permission.ACCESS_COARSE_LOCATION",
                     "android.permission.WAKE_LOCK", "android.permission.WRITE_EXTERNAL_STORAGE",
                     "android.permission.FOREGROUND_SERVICE", "android.permission.FOREGROUND_SERVICE_LOCATION",
                     "android.permission.POST_NOTIFICATIONS"}
    # storage permission only where Android still needs it for Documents/ (Android 10: legacy storage)
    assert "(name=android.permission.WRITE_EXTERNAL_STORAGE;maxSdkVersion=29)" in perms
    # the location permissions serve the LocationListener; WAKE_LOCK serves android.wakelock
    src = (ROOT / "app" / "sources.py").read_text()
    assert "LOCATION_SERVICE" in src and "requestLocationUpdates" in src
    assert spec.get("app", "android.wakelock").lower() in ("true", "1")
    # no HIGH_SAMPLING_RATE_SENSORS: the app never asks for more than 200 Hz
    from app.settings import RANGES, RATE_CHOICES
    from app.sources import MAX_RATE_HZ

    assert MAX_RATE_HZ <= 200 and max(RATE_CHOICES) <= 200 and RANGES["rate_hz"][1] <= 200


def test_the_tracking_service_is_declared_as_the_app_starts_it(spec):
    """``services = Tracker:app/service_main.py:foreground:foregroundServiceType=location``, parsed as
    p4a's build.py parses it; the name is the one app.android_platform starts (``<package>.ServiceTracker``),
    the entry point exists and is packaged, the type's permission is declared, and the run-time permissions
    the app asks for are declared too."""
    from app import android_platform as droid
    from app.service import SERVICE_NAME

    services = spec.getlist("app", "services")
    assert len(services) == 1
    name, entry, *options = services[0].split(":")
    assert name == SERVICE_NAME and (ROOT / entry).is_file() and entry.endswith(".py")
    # not sticky: p4a's PythonService.startType() is then START_NOT_STICKY (a sticky restart after a kill comes
    # with a null intent from the background: startForeground throws on Android 12+)
    assert "foreground" in options and "sticky" not in options
    types_ = [o.split("=", 1)[1] for o in options if o.startswith("foregroundServiceType=")]
    assert types_ == ["location"]
    perms = {re.sub(r"^\(name=([^;)]*).*\)$", r"\1", p) for p in spec.getlist("app", "android.permissions")}
    assert {"android.permission.FOREGROUND_SERVICE", "android.permission.FOREGROUND_SERVICE_LOCATION"} <= perms
    for sdk in (24, 28, 33, 36):  # every run-time permission asked for is in the manifest
        assert set(droid.permissions_to_request(sdk)) <= perms
    assert droid.POST_NOTIFICATIONS in droid.permissions_to_request(33)
    assert droid.POST_NOTIFICATIONS not in droid.permissions_to_request(32)
    assert "android.permission.ACCESS_BACKGROUND_LOCATION" not in perms  # the service is started in the foreground


def test_the_java_listener_is_compiled_into_the_apk(spec):
    """``android.add_src`` names a Java source root (p4a adds it as a gradle ``srcDir``) holding the class
    app.sources autoclasses, in the folder of its package; .java files are not packaged as app files."""
    from app.sources import BUFFER_CLASS

    roots = spec.getlist("app", "android.add_src")
    assert len(roots) == 1
    java = ROOT / roots[0] / (BUFFER_CLASS.replace(".", "/") + ".java")
    assert java.is_file()
    text = java.read_text()
    assert f"package {BUFFER_CLASS.rsplit('.', 1)[0]};" in text and "implements SensorEventListener" in text
    assert "java" not in spec.getlist("app", "source.include_exts")
