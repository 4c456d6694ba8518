"""Where the app keeps settings, recordings and exports.

Desktop
    settings in the Kivy ``user_data_dir``; recordings and exports in
    ``<user_data_dir>/recordings`` unless ``PDR_APP_OUT`` (or ``--out``) names
    a directory.
Android
    recordings and exports must be reachable by the user (USB, file manager),
    so in order of preference: ``Documents/PDR`` on shared storage (plyer's
    storage path; writable without permission on Android 11+, with
    ``WRITE_EXTERNAL_STORAGE`` up to Android 10, which also needs the manifest's
    ``requestLegacyExternalStorage``), then the app's external files
    directory ``Android/data/<package>/files`` (always writable, reachable over
    USB), then the private data directory.  Every candidate is checked by
    actually creating a file.
"""

from __future__ import annotations

import os
import time

SUBDIR = "PDR"


def is_android() -> bool:
    return "ANDROID_ARGUMENT" in os.environ or "ANDROID_PRIVATE" in os.environ


def writable_dir(path: str | None) -> bool:
    """Create ``path`` if needed and check a file can be written there."""
    if not path:
        return False
    try:
        os.makedirs(path, exist_ok=True)
        probe = os.path.join(path, ".pdr-write-test")
        with open(probe, "w") as f:
            f.write("ok")
        os.unlink(probe)
        return True
    except OSError:
        return False


def _android_candidates() -> list[str]:
    out = []
    try:
        from plyer import storagepath  # noqa: PLC0415 - Android only

        out.append(os.path.join(storagepath.get_documents_dir(), SUBDIR))
    except Exception:  # noqa: BLE001 - facade missing, permission, old plyer
        pass
    try:
        from jnius import autoclass  # noqa: PLC0415 - Android only

        activity = autoclass("org.kivy.android.PythonActivity").mActivity
        ext = activity.getExternalFilesDir(None)
        if ext is not None:
            out.append(ext.getAbsolutePath())
    except Exception:  # noqa: BLE001
        pass
    return out


def output_dir(user_data_dir: str, override: str | None = None) -> str:
    """The directory for recordings and exports (created)."""
    candidates = []
    if override or os.environ.get("PDR_APP_OUT"):
        candidates.append(override or os.environ["PDR_APP_OUT"])
    if is_android():
        candidates += _android_candidates()
    candidates.append(os.path.join(user_data_dir, "recordings"))
    for c in candidates:
        if writable_dir(c):
            return c
    raise OSError(f"no writable directory among {candidates}")


def new_recording_path(directory: str, when: float | None = None) -> str:
    """``<directory>/pdr-YYYYmmdd-HHMMSS.csv`` (a suffix is added if it exists)."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(when if when is not None else time.time()))
    path = os.path.join(directory, f"pdr-{stamp}.csv")
    k = 1
    while os.path.exists(path):
        path = os.path.join(directory, f"pdr-{stamp}-{k}.csv")
        k += 1
    return path
