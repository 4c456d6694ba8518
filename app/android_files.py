"""Files the user can reach on Android 11+: open through the system picker, export into Downloads.

Scoped storage (Android 11+) hides from the app every shared file it did not create itself, so Kivy's file
chooser, which browses paths, shows a recording copied to the phone over USB as nothing at all.  Instead:

Open (recordings, floor plans)
    ``Intent.ACTION_OPEN_DOCUMENT`` with ``CATEGORY_OPENABLE`` (the Storage Access Framework): the system
    picker shows every provider (Downloads, Documents, a USB stick, Drive...).  The result comes to the
    activity (p4a's ``android.activity.bind(on_activity_result=...)``, on Android's UI thread) with a
    ``content://`` URI; its display name is asked of the ``ContentResolver`` (``OpenableColumns``), its
    bytes are copied into the app's storage through ``openFileDescriptor(uri, "r").detachFd()`` (one JNI
    call, then plain ``os`` reads: no per-byte Java calls) and the copy is opened as any file.  The copy
    runs off the UI thread; ``on_done(path, error)`` is called when it is there.
Export
    Android 10+ (API 29): every exported file is also written into ``Download/PDR`` through
    ``MediaStore.Downloads`` (``ContentResolver.insert`` with the display name, MIME type and relative
    path, then ``openFileDescriptor(uri, "w")``).  No permission is needed, and the files are the user's:
    the Files app shows them, other apps open them, they stay after the app is uninstalled.  Before
    Android 10 the export folder (``Documents/PDR`` with the storage permission, app.storage) already is
    shared storage.

Every Java call is one whose overload pyjnius 1.7 resolves to the intended signature (the tests' fake jnius
checks it): no ``Intent.putExtra`` (a ``Uri`` would go to ``putExtra(String, String)``), no
``ContentValues.put`` with a Python int (no overload takes one), only ``put(String, String)``.
``jnius`` and p4a's ``android.activity`` are passed in (the phone's, or fakes).
"""

from __future__ import annotations

import os
import re
import shutil
import threading
from typing import Callable

REQUEST_OPEN_DOCUMENT = 0x5044  #: our request code for startActivityForResult
RESULT_OK = -1  #: Activity.RESULT_OK
DISPLAY_NAME = "_display_name"  #: OpenableColumns.DISPLAY_NAME == MediaStore.MediaColumns.DISPLAY_NAME
MIME_TYPE = "mime_type"  #: MediaStore.MediaColumns.MIME_TYPE
RELATIVE_PATH = "relative_path"  #: MediaStore.MediaColumns.RELATIVE_PATH (API 29+)
DOWNLOADS_SDK = 29  #: MediaStore.Downloads exists from API 29
EXPORT_SUBDIR = "Download/PDR"
MIME_TYPES = {".csv": "text/csv", ".txt": "text/plain", ".gpx": "application/gpx+xml",
              ".geojson": "application/geo+json", ".json": "application/json", ".gz": "application/gzip",
              ".zip": "application/zip", ".png": "image/png"}


def safe_name(name: str | None, default: str = "document") -> str:
    """A file name from a provider's display name: no folders, no characters a file system refuses."""
    name = os.path.basename(str(name or "").replace("\\", "/")).strip()
    name = re.sub(r"[\x00-\x1f<>:\"|?*]", "_", name).lstrip(".")
    return name[:120] or default


class AndroidFiles:
    """The system picker and the Downloads export for the app (see the module docstring).

    Parameters
    ----------
    jnius : module
        The phone's ``jnius`` (or the tests' fake).
    activity_module : module
        p4a's ``android.activity`` (``bind`` / ``unbind``), or a fake.
    run : callable, optional
        ``run(fn)`` runs the copy; default a daemon thread (the picker's result comes on Android's UI
        thread, which must not copy megabytes); tests run it inline.
    """

    def __init__(self, jnius, activity_module, *, run: Callable | None = None):
        self.jnius = jnius
        self.activity_module = activity_module
        self._run = run or (lambda fn: threading.Thread(target=fn, name="pdr-import", daemon=True).start())
        self._pending = None

    def _activity(self):
        return self.jnius.autoclass("org.kivy.android.PythonActivity").mActivity

    def sdk(self) -> int:
        return int(self.jnius.autoclass("android.os.Build$VERSION").SDK_INT)

    # -- open ----------------------------------------------------------------------------------------------

    def pick(self, dest_dir: str, on_done: Callable, mime: str = "*/*") -> None:
        """Show the system picker; the chosen document is copied into ``dest_dir`` and ``on_done(path, "")``
        is called (``on_done(None, reason)`` when the user cancelled or the copy failed)."""
        Intent = self.jnius.autoclass("android.content.Intent")
        intent = Intent(Intent.ACTION_OPEN_DOCUMENT)
        intent.addCategory(Intent.CATEGORY_OPENABLE)
        intent.setType(mime)  # "*/*": a recording may be .csv, .txt, .gz, .zip...; the reader decides
        if self._pending is not None:
            self.activity_module.unbind(on_activity_result=self._on_result)
        self._pending = (dest_dir, on_done)
        self.activity_module.bind(on_activity_result=self._on_result)
        self._activity().startActivityForResult(intent, REQUEST_OPEN_DOCUMENT)

    def _on_result(self, request_code, result_code, intent) -> None:
        if request_code != REQUEST_OPEN_DOCUMENT or self._pending is None:
            return
        dest_dir, on_done = self._pending
        self._pending = None
        try:
            self.activity_module.unbind(on_activity_result=self._on_result)
        except Exception:  # noqa: BLE001 - already unbound
            pass
        uri = intent.getData() if intent is not None and result_code == RESULT_OK else None
        if uri is None:
            on_done(None, "cancelled")
            return

        def copy():
            try:
                path = self.copy_document(uri, dest_dir)
            except Exception as e:  # noqa: BLE001 - a provider gone, no space: a message, not a crash
                on_done(None, f"could not copy the document: {e}")
                return
            on_done(path, "")

        self._run(copy)

    def display_name(self, uri) -> str:
        """The document's name as its provider shows it (``OpenableColumns.DISPLAY_NAME``), "" if unknown."""
        resolver = self._activity().getContentResolver()
        cursor = resolver.query(uri, [DISPLAY_NAME], None, None, None)
        if cursor is None:
            return ""
        try:
            if cursor.moveToFirst():
                i = cursor.getColumnIndex(DISPLAY_NAME)
                if i >= 0:
                    return str(cursor.getString(i) or "")
        finally:
            cursor.close()
        return ""

    def copy_document(self, uri, dest_dir: str) -> str:
        """Copy the ``content://`` document into ``dest_dir`` under its display name; returns the path."""
        try:
            name = self.display_name(uri)
        except Exception:  # noqa: BLE001 - some providers refuse queries: the URI's last segment then
            name = ""
        name = safe_name(name or uri.getLastPathSegment())
        os.makedirs(dest_dir, exist_ok=True)
        path = os.path.join(dest_dir, name)
        tmp = path + ".part"
        pfd = self._activity().getContentResolver().openFileDescriptor(uri, "r")
        if pfd is None:
            raise OSError("the provider gave no file descriptor")
        fd = pfd.detachFd()  # the descriptor is ours now: os.fdopen closes it
        try:
            with os.fdopen(fd, "rb") as src, open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return path

    # -- export --------------------------------------------------------------------------------------------

    def export_to_downloads(self, paths) -> list[str]:
        """Write each file into ``Download/PDR`` through ``MediaStore.Downloads`` (API 29+); returns where
        they are as the user sees them (``Download/PDR/<name>``).  [] before API 29 (see the module)."""
        if self.sdk() < DOWNLOADS_SDK:
            return []
        jn = self.jnius
        resolver = self._activity().getContentResolver()
        collection = jn.autoclass("android.provider.MediaStore$Downloads").EXTERNAL_CONTENT_URI
        ContentValues = jn.autoclass("android.content.ContentValues")
        out = []
        for path in paths:
            name = os.path.basename(path)
            values = ContentValues()
            values.put(DISPLAY_NAME, name)
            values.put(MIME_TYPE, MIME_TYPES.get(os.path.splitext(name)[1].lower(), "application/octet-stream"))
            values.put(RELATIVE_PATH, EXPORT_SUBDIR)
            uri = resolver.insert(collection, values)
            if uri is None:
                raise OSError(f"MediaStore refused {name}")
            pfd = resolver.openFileDescriptor(uri, "w")
            if pfd is None:
                raise OSError(f"MediaStore gave no file for {name}")
            with os.fdopen(pfd.detachFd(), "wb") as dst, open(path, "rb") as src:
                shutil.copyfileobj(src, dst, 1 << 20)
            out.append(f"{EXPORT_SUBDIR}/{name}")
        return out
