"""Files on Android 11+ (issue #28, 4): the system picker (Storage Access Framework) and the Downloads export.

The fake ``jnius`` of test_app_android_source resolves every Java call as pyjnius 1.7 does; here it gets a
``ContentResolver`` that serves ``content://`` documents from real files (``openFileDescriptor`` returns a
real descriptor, as Android's does) and a ``MediaStore.Downloads`` that writes into a folder, and p4a's
``android.activity`` is a fake that delivers the picker's result.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import _pyjnius_fake as pj
from app.android_files import EXPORT_SUBDIR, REQUEST_OPEN_DOCUMENT, RESULT_OK, AndroidFiles, safe_name
from test_app_android_source import FakeSensorManager, called_signatures, make_fake_jnius

ROOT = Path(__file__).resolve().parents[1]


class FakeUri:
    __javaclass__ = "android/net/Uri"

    def __init__(self, s):
        self.s = s

    def getLastPathSegment(self):
        return self.s.rsplit("/", 1)[-1]

    def toString(self):
        return self.s


class FakeIntent:
    ACTION_OPEN_DOCUMENT = "android.intent.action.OPEN_DOCUMENT"
    CATEGORY_OPENABLE = "android.intent.category.OPENABLE"

    def __init__(self, action=None):
        self.action, self.categories, self.type, self.data = action, [], None, None

    def addCategory(self, c):
        self.categories.append(c)
        return self

    def setType(self, t):
        self.type = t
        return self

    def getData(self):
        return self.data


class FakeCursor:
    def __init__(self, projection, row):
        self.projection, self.row, self.closed = projection, row, False

    def moveToFirst(self):
        return self.row is not None

    def getColumnIndex(self, name):
        return self.projection.index(name) if name in self.projection else -1

    def getString(self, i):
        return self.row[self.projection[i]]

    def close(self):
        self.closed = True


class FakePfd:
    def __init__(self, fd):
        self.fd = fd

    def detachFd(self):
        return self.fd


class FakeContentValues:
    def __init__(self):
        self.d = {}

    def put(self, k, v):
        self.d[k] = v


class FakeDownloads:
    EXTERNAL_CONTENT_URI = FakeUri("content://media/external/downloads")


class FakeResolver:
    """Documents of other apps (``content://`` -> a file we can read) and MediaStore's Downloads (a folder)."""

    __javaclass__ = "android/content/ContentResolver"

    def __init__(self, media_root, names_refused=False):
        self.docs, self.media, self.media_root, self.names_refused = {}, {}, Path(media_root), names_refused
        self.cursors = []

    def add_document(self, uri, name, path):
        self.docs[uri] = (name, str(path))
        return FakeUri(uri)

    def query(self, uri, projection, selection, args, order):
        if self.names_refused:
            raise pj.JavaException("java.lang.SecurityException: no query")
        name = self.docs.get(uri.s, (None,))[0]
        cur = FakeCursor(projection, None if name is None else {"_display_name": name})
        self.cursors.append(cur)
        return cur

    def openFileDescriptor(self, uri, mode):
        if mode == "r":
            return FakePfd(os.open(self.docs[uri.s][1], os.O_RDONLY))
        values, path = self.media[uri.s]
        path.parent.mkdir(parents=True, exist_ok=True)
        return FakePfd(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC))

    def insert(self, collection, values):
        assert collection.s == FakeDownloads.EXTERNAL_CONTENT_URI.s
        uri = f"{collection.s}/{len(self.media) + 1}"
        self.media[uri] = (dict(values.d), self.media_root / values.d["relative_path"] / values.d["_display_name"])
        return FakeUri(uri)


class FakeActivityModule:
    """p4a's ``android.activity``: bind/unbind, and what Android does when the picker closes."""

    def __init__(self):
        self.callbacks = []

    def bind(self, on_activity_result):
        self.callbacks.append(on_activity_result)

    def unbind(self, on_activity_result):
        self.callbacks = [c for c in self.callbacks if c != on_activity_result]

    def result(self, code, result, intent):
        for cb in list(self.callbacks):
            cb(code, result, intent)


def files_jnius(tmp_path, sdk=34, **resolver_kw):
    jn = make_fake_jnius(FakeSensorManager(), sdk=sdk)
    jn.resolver = FakeResolver(tmp_path / "media", **resolver_kw)
    jn.classes.update({"android.content.Intent": FakeIntent, "android.content.ContentValues": FakeContentValues,
                       "android.provider.MediaStore$Downloads": FakeDownloads})
    return jn


FILE_SIGNATURES = {
    ("android/content/Intent", "<init>"): "(Ljava/lang/String;)V",
    ("android/content/Intent", "addCategory"): "(Ljava/lang/String;)Landroid/content/Intent;",
    ("android/content/Intent", "setType"): "(Ljava/lang/String;)Landroid/content/Intent;",
    ("android/content/Intent", "getData"): "()Landroid/net/Uri;",
    ("android/app/Activity", "startActivityForResult"): "(Landroid/content/Intent;I)V",
    ("android/content/Context", "getContentResolver"): "()Landroid/content/ContentResolver;",
    ("android/content/ContentResolver", "query"):
        "(Landroid/net/Uri;[Ljava/lang/String;Ljava/lang/String;[Ljava/lang/String;Ljava/lang/String;)"
        "Landroid/database/Cursor;",
    ("android/database/Cursor", "moveToFirst"): "()Z",
    ("android/database/Cursor", "getColumnIndex"): "(Ljava/lang/String;)I",
    ("android/database/Cursor", "getString"): "(I)Ljava/lang/String;",
    ("android/database/Cursor", "close"): "()V",
    ("android/content/ContentResolver", "openFileDescriptor"):
        "(Landroid/net/Uri;Ljava/lang/String;)Landroid/os/ParcelFileDescriptor;",
    ("android/os/ParcelFileDescriptor", "detachFd"): "()I",
    ("android/content/ContentValues", "<init>"): "()V",
    ("android/content/ContentValues", "put"): "(Ljava/lang/String;Ljava/lang/String;)V",
    ("android/content/ContentResolver", "insert"):
        "(Landroid/net/Uri;Landroid/content/ContentValues;)Landroid/net/Uri;",
}


def test_the_system_picker_copies_the_chosen_document_into_the_app(tmp_path):
    jn = files_jnius(tmp_path)
    am = FakeActivityModule()
    data = os.urandom(300_000)  # bytes, not text: the copy is byte for byte
    (tmp_path / "theirs.csv").write_bytes(data)
    uri = jn.resolver.add_document("content://com.android.providers.downloads.documents/document/msf%3A31",
                                   "walk in the park.csv", tmp_path / "theirs.csv")
    files = AndroidFiles(jn, am, run=lambda fn: fn())
    got = []
    files.pick(str(tmp_path / "app" / "imported"), lambda path, err: got.append((path, err)))
    (intent, code), = jn.activity_requests
    assert code == REQUEST_OPEN_DOCUMENT and intent.action == FakeIntent.ACTION_OPEN_DOCUMENT
    assert intent.categories == [FakeIntent.CATEGORY_OPENABLE] and intent.type == "*/*"
    result = FakeIntent()
    result.data = uri
    am.result(12, RESULT_OK, jn.wrap(result, "Landroid/content/Intent;"))  # another request's result: not ours
    assert got == []
    am.result(REQUEST_OPEN_DOCUMENT, RESULT_OK, jn.wrap(result, "Landroid/content/Intent;"))
    (path, err), = got
    assert err == "" and path == str(tmp_path / "app" / "imported" / "walk in the park.csv")
    assert Path(path).read_bytes() == data and not Path(path + ".part").exists()
    assert am.callbacks == [] and all(c.closed for c in jn.resolver.cursors)
    called = called_signatures(jn)
    assert set(called) <= set(FILE_SIGNATURES)
    for key, sigs in called.items():
        assert sigs == {FILE_SIGNATURES[key]}, key


def test_a_cancelled_picker_a_refused_query_and_a_provider_that_fails(tmp_path):
    jn = files_jnius(tmp_path, names_refused=True)
    am = FakeActivityModule()
    files = AndroidFiles(jn, am, run=lambda fn: fn())
    got = []
    files.pick(str(tmp_path / "in"), lambda path, err: got.append((path, err)))
    am.result(REQUEST_OPEN_DOCUMENT, 0, None)  # RESULT_CANCELED, no intent
    assert got == [(None, "cancelled")] and am.callbacks == []
    (tmp_path / "x.gz").write_bytes(b"\x1f\x8b")
    uri = jn.resolver.add_document("content://p/document/primary%3ADownload%2Fx.gz", "x.gz", tmp_path / "x.gz")
    res = FakeIntent()
    res.data = uri
    files.pick(str(tmp_path / "in"), lambda path, err: got.append((path, err)))
    am.result(REQUEST_OPEN_DOCUMENT, RESULT_OK, jn.wrap(res, "Landroid/content/Intent;"))
    # no display name (the query refused): the URI's last segment, made a file name
    assert got[-1] == (str(tmp_path / "in" / "primary%3ADownload%2Fx.gz"), "")
    res.data = FakeUri("content://p/document/gone")  # the provider has no such document any more
    files.pick(str(tmp_path / "in"), lambda path, err: got.append((path, err)))
    am.result(REQUEST_OPEN_DOCUMENT, RESULT_OK, jn.wrap(res, "Landroid/content/Intent;"))
    assert got[-1][0] is None and got[-1][1].startswith("could not copy the document")


def test_display_names_become_safe_file_names():
    assert safe_name("../../etc/passwd") == "passwd"
    assert safe_name("a:b?.csv") == "a_b_.csv" and safe_name(".hidden") == "hidden"
    assert safe_name("") == "document" and safe_name(None) == "document" and len(safe_name("x" * 500)) == 120


def test_export_writes_into_download_pdr_through_mediastore(tmp_path):
    jn = files_jnius(tmp_path, sdk=30)
    files = AndroidFiles(jn, FakeActivityModule())
    src = []
    for name, body in (("walk.gpx", b"<gpx/>"), ("walk.csv", b"t,e,n\n"), ("walk.geojson", b"{}"), ("walk.bin", b"\0")):
        (tmp_path / name).write_bytes(body)
        src.append(str(tmp_path / name))
    shared = files.export_to_downloads(src)
    assert shared == [f"{EXPORT_SUBDIR}/{os.path.basename(p)}" for p in src]
    mimes = {}
    for values, path in jn.resolver.media.values():
        assert values["relative_path"] == "Download/PDR"
        assert path.read_bytes() == (tmp_path / values["_display_name"]).read_bytes()
        mimes[values["_display_name"]] = values["mime_type"]
    assert mimes == {"walk.gpx": "application/gpx+xml", "walk.csv": "text/csv", "walk.geojson": "application/geo+json",
                     "walk.bin": "application/octet-stream"}
    for key, sigs in called_signatures(jn).items():
        assert sigs == {FILE_SIGNATURES[key]}, key
    old = files_jnius(tmp_path / "old", sdk=28)  # before Android 10: Documents/PDR is shared storage already
    assert AndroidFiles(old, FakeActivityModule()).export_to_downloads(src) == [] and old.resolver.media == {}


APP = r"""
import json, sys
sys.path.insert(0, sys.argv[5])
from test_app_files import FakeActivityModule, FakeIntent, files_jnius
from pathlib import Path
from app import kivy_env
kivy_env.prepare(headless=True)
from kivy.clock import Clock
from app.android_files import AndroidFiles, REQUEST_OPEN_DOCUMENT, RESULT_OK
from app.main_app import PDRApp

out, data, report, walk = sys.argv[1:5]
tmp = Path(report).parent
jn = files_jnius(tmp)
am = FakeActivityModule()
uri = jn.resolver.add_document("content://com.android.externalstorage.documents/document/primary%3Awalk",
                               "their walk.csv", walk)
app = PDRApp(out_dir=out, data_dir=data, files=AndroidFiles(jn, am, run=lambda fn: fn()), speed="max")
log = {}

def choose(dt):
    app.show_file_chooser()  # the system picker, not Kivy's chooser
    log["popup"] = hasattr(app, "chooser")
    log["picker_message"] = app.message
    res = FakeIntent()
    res.data = uri
    am.result(REQUEST_OPEN_DOCUMENT, RESULT_OK, jn.wrap(res, "Landroid/content/Intent;"))
    Clock.schedule_interval(wait_end, 0)

def wait_end(dt):
    if app.session is None or not app.session.finished:
        return True
    log["mode"], log["raw_path"] = app.mode, app.raw_path
    out = app.export()
    log["export"] = out
    log["message"] = app.message
    log["media"] = [[v, str(p)] for v, p in jn.resolver.media.values()]
    with open(report, "w") as f:
        json.dump(log, f)
    app.stop()
    return False

Clock.schedule_once(choose, 0)
app.run()
"""


def test_the_app_opens_through_the_picker_and_exports_into_downloads(tmp_path):
    """The phone's path through the app: Open shows the system picker (no Kivy chooser), the chosen
    document is copied into the app's storage and replayed, Export also writes Download/PDR."""
    from core.recording import write_recording
    from desktop.simulator import simulate_walk

    # 50 Hz: the rate is not the subject
    w = simulate_walk(((0.0, 0.0), (20.0, 0.0)), seed=3, rate_hz=50.0, still_start_s=1.0, still_end_s=1.0)
    walk = tmp_path / "walk.csv"
    write_recording(str(walk), w.recording)
    report = tmp_path / "files.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-c", APP, str(tmp_path / "out"), str(tmp_path / "data"), str(report),
                        str(walk), str(ROOT / "tests")], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    log = json.loads(report.read_text())
    assert not log["popup"] and "system picker" in log["picker_message"]
    assert log["mode"] == "replay" and log["raw_path"] == str(tmp_path / "data" / "imported" / "their walk.csv")
    assert Path(log["raw_path"]).read_bytes() == walk.read_bytes()
    exp = log["export"]
    assert not exp["errors"] and "Download/PDR/their walk.gpx" in exp["downloads"]
    assert log["message"].startswith("exported to Download/PDR: ")
    media = {Path(p).name: Path(p) for _v, p in log["media"]}
    for key, path in exp.items():
        if key not in ("errors", "downloads"):
            assert media[Path(path).name].read_bytes() == Path(path).read_bytes()
