"""The live recorder: append-only, flushed and fsync'ed off the UI thread, never a header-only file.

Why a thread
    ``fsync`` on a phone's flash can take tens to hundreds of milliseconds (longer on a full or
    failing card); done in the Kivy clock callback it would freeze the track.  The UI thread only
    appends events to a list; each tick hands that list, as one batch, to a bounded queue
    (:data:`MAX_BATCHES`, about 20 s of ticks).  One writer thread formats the rows, writes them
    with a single ``os.write`` per batch (so the file only ever ends with a whole line, unless a
    kill lands inside that one system call) and fsyncs once the oldest unsynced row is
    ``flush_interval_s`` old.  A kill -9 keeps everything the kernel was given; at most the
    rows of the last ``flush_interval_s`` plus one tick are not yet written.

Never a header-only file
    The file is created at the first write that has events in it: header and first rows go in
    one ``os.write`` (to ``NAME.part``, renamed to ``NAME`` at once, so ``NAME`` never exists
    empty).  A kill before that leaves no recording at all (nothing is lost but less than
    a second of events), instead of a header the reader rejects ("the file has a header but no
    sensor events").  A recording stopped before any event leaves no file either
    (:attr:`BackgroundRecorder.events_written` is 0).

Errors
    An ``OSError`` (disk full, storage removed, a short write) stops the recorder: the rows
    already in the file stay (a partial last batch is cut back to the last whole batch), the
    error is kept in :attr:`BackgroundRecorder.error` for the UI, and further events are
    ignored.  A queue that stays full (storage that no longer keeps up) is an error too: the
    UI thread never blocks and never drops events silently.
"""

from __future__ import annotations

import json
import os
import queue
import threading
import time
from collections.abc import Callable

import numpy as np

from core.recording import FORMAT_VERSION, MAGIC, Recording, Stream, format_row

MAX_BATCHES = 600  #: batches (one per UI tick, 30 a second) waiting for the writer thread

_FLUSH, _CLOSE = object(), object()


class AppendFile:
    """The file the recorder writes: append-only, raw file descriptor (no buffering).

    It is created as ``path + ".part"`` and renamed to ``path`` right after its first write (the
    header and the first rows), so ``path`` never exists empty: a kill between the creation and
    the first write leaves at most an empty ``.part`` file, not an empty recording.
    """

    def __init__(self, path: str):
        self.path = path
        self.part = path + ".part"
        if os.path.exists(path):
            raise FileExistsError(17, "the recording exists already", path)
        self.fd = os.open(self.part, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        self.size = 0

    def write(self, data: bytes) -> None:
        """Write all of ``data`` or raise ``OSError`` (a short write is cut back and raised)."""
        n = os.write(self.fd, data)
        if n != len(data):
            os.ftruncate(self.fd, self.size)
            raise OSError(28, f"short write ({n} of {len(data)} bytes): storage full?")
        if self.size == 0:
            os.rename(self.part, self.path)  # the recording appears with its header and first rows
            self._sync_dir()
        self.size += n

    def _sync_dir(self) -> None:
        try:  # the new name survives a power cut too (a kill -9 does not need this)
            dfd = os.open(os.path.dirname(os.path.abspath(self.path)), os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass

    def sync(self) -> None:
        os.fsync(self.fd)

    def close(self) -> None:
        os.close(self.fd)
        if self.size == 0:  # nothing was ever written: no file
            try:
                os.unlink(self.part)
            except OSError:
                pass


def header_text(streams: dict, device: dict | None, metadata: dict | None) -> str:
    """The magic line and the JSON header line, as :class:`core.recording.RecordingWriter` writes them."""
    rec = Recording({n: Stream(n, [], np.zeros((0, len(s["columns"]))), s["columns"], s.get("unit", ""),
                               s.get("note", "")) for n, s in streams.items()},
                    device=dict(device or {}), metadata=dict(metadata or {}))
    return f"{MAGIC} {FORMAT_VERSION}\n# " + json.dumps(rec.header(), sort_keys=True) + "\n"


class BackgroundRecorder:
    """Records events to ``path`` from a writer thread (see the module docstring).

    UI thread: :meth:`add` per event, :meth:`push` once per tick, :meth:`flush`, :meth:`close`,
    :attr:`error`.  ``opener(path)`` returns the file (default :class:`AppendFile`; tests inject
    one that fails).  ``clock`` is the writer thread's clock for the fsync interval;
    ``threaded=False`` runs no thread: :meth:`pump` then does the thread's work (tests).
    """

    def __init__(self, path: str, streams: dict, device: dict | None = None, metadata: dict | None = None, *,
                 flush_interval_s: float = 0.5, opener: Callable = AppendFile,
                 clock: Callable[[], float] = time.monotonic, threaded: bool = True,
                 max_batches: int = MAX_BATCHES):
        if str(path).endswith(".gz"):
            raise ValueError("live recordings are written as plain text; compress them after the session")
        self.path = str(path)
        self.flush_interval_s = float(flush_interval_s)
        self._header = header_text(streams, device, metadata).encode("utf-8")
        self._opener = opener
        self._clock = clock
        self._q: queue.Queue = queue.Queue(max_batches)
        self._batch: list = []
        self.count = 0  #: events accepted from the UI thread
        self.events_written = 0  #: events handed to the OS (survive a kill of the app)
        self.events_synced = 0  #: events fsync'ed (survive a power cut)
        self.syncs = 0
        self.error: str | None = None
        self._file = None
        self._unsynced_since: float | None = None
        self._closed = False
        self._thread = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="pdr-recorder", daemon=True)
            self._thread.start()

    # -- UI thread --------------------------------------------------------------------------

    def add(self, name: str, t_ns: int, values) -> None:
        if self.error is None and not self._closed:
            self._batch.append((name, t_ns, values))
            self.count += 1

    def push(self) -> None:
        """Hand the events added since the last push to the writer thread (never blocks)."""
        if self._batch and self.error is None and not self._closed:
            batch, self._batch = self._batch, []
            self._put(batch)

    def flush(self, wait_s: float = 0.0) -> bool:
        """Push, then ask for a write and fsync now; wait up to ``wait_s`` for it. True when done."""
        self.push()
        if self.error is not None or self._closed:
            return False
        done = threading.Event()
        self._put((_FLUSH, done))
        if self._thread is None:
            self.pump()
        return done.wait(wait_s) if wait_s > 0 or self._thread is None else False

    def close(self, wait_s: float = 5.0) -> None:
        """Write and fsync what is left, close the file and end the thread (waits up to ``wait_s``)."""
        if self._closed:
            return
        self.push()
        self._closed = True
        try:
            self._q.put((_CLOSE, None), timeout=wait_s)
        except queue.Full:  # the thread closes the file when it sees the error
            self.error = self.error or f"storage does not keep up: {self._q.qsize()} batches still waiting at the stop"
        if self._thread is None:
            self.pump()
        else:
            self._thread.join(wait_s)

    def _put(self, item) -> None:
        try:
            self._q.put_nowait(item)
        except queue.Full:  # the thread closes the file when it sees the error
            self.error = self.error or f"storage does not keep up: {self._q.qsize()} batches waiting to be written"
            self._batch = []

    # -- writer thread ------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._handle_one(block=True):
            pass

    def pump(self) -> None:
        """Do the writer thread's work on what is queued now (``threaded=False``)."""
        while not self._q.empty():
            if self._handle_one(block=False):
                return
        self._sync_if_due()

    def _handle_one(self, block: bool) -> bool:
        """Write one queued item (waiting for one until a sync is due); True when the recorder is done."""
        timeout = None
        if self._unsynced_since is not None:
            timeout = max(0.0, self._unsynced_since + self.flush_interval_s - self._clock())
        try:
            item = self._q.get(block=block, timeout=timeout if block else None)
        except queue.Empty:
            self._sync_if_due()
            return False
        if isinstance(item, tuple) and item and item[0] is _FLUSH:
            self._sync(force=True)
            item[1].set()
            return False
        if isinstance(item, tuple) and item and item[0] is _CLOSE:
            self._sync(force=True)
            self._close_file()
            return True
        if self.error is None:
            self._write(item)
        else:
            self._close_file()
        self._sync_if_due()
        return False

    def _write(self, batch: list) -> None:
        data = "".join(format_row(n, t, v) for n, t, v in batch).encode("utf-8")
        try:
            if self._file is None:
                f = self._opener(self.path)
                f.write(self._header + data)
                self._file = f
            else:
                self._file.write(data)
        except OSError as e:
            self._fail(f"cannot write {self.path}: {e.strerror or e}")
            return
        self.events_written += len(batch)
        if self._unsynced_since is None:
            self._unsynced_since = self._clock()

    def _sync_if_due(self) -> None:
        if self._unsynced_since is not None and self._clock() - self._unsynced_since >= self.flush_interval_s:
            self._sync()

    def _sync(self, force: bool = False) -> None:
        if self._file is None or self.error is not None or (self._unsynced_since is None and not force):
            return
        try:
            self._file.sync()
        except OSError as e:
            self._fail(f"cannot save {self.path}: {e.strerror or e}")
            return
        self.syncs += 1
        self.events_synced = self.events_written
        self._unsynced_since = None

    def _fail(self, message: str) -> None:
        if self.error is None:
            self.error = message
        self._batch = []
        self._close_file()

    def _close_file(self) -> None:
        f, self._file = self._file, None
        if f is not None:
            try:
                f.close()
            except OSError:
                pass

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()
