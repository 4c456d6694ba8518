"""No walk is ever lost (issue #12): the live recorder under kill -9, write errors and a slow disk.

The recorder is :class:`app.recorder.BackgroundRecorder` as :class:`app.session.Session` uses it.
The timing of the fsyncs is checked with an injected clock (no wall-clock asserts); the kill test
kills a recording process at seeded random moments and compares the file event by event with
what was sent.
"""

import errno
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.recorder import BackgroundRecorder
from app.session import Session, load_any_recording
from core.recording import RecordingError, read_recording
from tests._recorder_helpers import STREAMS, FakeSource, NullPipeline, event

ROOT = Path(__file__).resolve().parents[1]


def events_in(rec):
    out = []
    for name, s in rec.streams.items():
        out += [(name, int(t), tuple(float(v) for v in row)) for t, row in zip(s.t_ns, s.values)]
    return sorted(out, key=lambda e: (e[1], e[0]))


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


class CountingFile:
    """An :class:`app.recorder.AppendFile` stand-in that keeps the bytes and counts syncs; ``fail_at``
    makes the n-th write (0-based) raise ``OSError`` like a full disk, ``fail_sync`` the syncs."""

    def __init__(self, path, fail_at=None, fail_sync=False):
        self.path, self.fail_at, self.fail_sync = path, fail_at, fail_sync
        self.writes, self.syncs, self.closed = [], 0, False

    def write(self, data):
        if self.fail_at is not None and len(self.writes) >= self.fail_at:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.writes.append(data)
        with open(self.path, "ab") as f:
            f.write(data)

    def sync(self):
        if self.fail_sync:
            raise OSError(errno.EIO, "Input/output error")
        self.syncs += 1

    def close(self):
        self.closed = True


def recorder(tmp_path, clock, files, **kw):
    def opener(path):
        f = CountingFile(path, **kw)
        files.append(f)
        return f
    return BackgroundRecorder(str(tmp_path / "r.csv"), STREAMS, {"model": "test"}, {}, flush_interval_s=0.5,
                              opener=opener, clock=clock, threaded=False)


def test_fsync_at_least_every_flush_interval_by_the_writers_clock(tmp_path):
    clock, files = FakeClock(), []
    r = recorder(tmp_path, clock, files)
    k = 0
    for tick in range(60):  # 2 s of 30 Hz ticks, 6 events each
        clock.t = tick / 30.0
        for _ in range(6):
            r.add(*event(k))
            k += 1
        r.push()
        r.pump()
        # nothing written stays unsynced longer than the interval
        assert r.events_written == k
        assert r._unsynced_since is None or clock.t - r._unsynced_since < 0.5
    f, = files
    assert 3 <= f.syncs <= 5  # about every 0.5 s over 2 s, not on every tick
    assert len(f.writes) == 60  # one write per tick's batch
    r.close()
    assert f.closed and r.events_synced == k == 360
    assert events_in(read_recording(f.path, warn=False)) == [event(i) for i in range(360)]


def test_no_file_before_the_first_event_and_never_a_header_only_file(tmp_path):
    clock, files = FakeClock(), []
    r = recorder(tmp_path, clock, files)
    r.push()
    r.flush()
    r.close()
    assert files == [] and not (tmp_path / "r.csv").exists()
    # the first write carries the header and the first events: the file reads back from its first byte on
    r = recorder(tmp_path, clock, files)
    r.add(*event(0))
    r.push()
    r.pump()
    f, = files
    assert len(f.writes) == 1 and f.writes[0].startswith(b"# pdr-recording")
    assert events_in(read_recording(f.path, warn=False)) == [event(0)]


@pytest.mark.parametrize("fail_at", [0, 3])
def test_a_write_error_stops_the_recording_and_keeps_what_was_written(tmp_path, fail_at):
    clock, files = FakeClock(), []
    r = recorder(tmp_path, clock, files, fail_at=fail_at)
    for tick in range(6):
        for j in range(4):
            r.add(*event(tick * 4 + j))
        r.push()
        r.pump()
    assert "No space left on device" in r.error and str(tmp_path / "r.csv") in r.error
    assert r.events_written == 4 * fail_at
    r.add(*event(99))  # ignored from now on
    r.close()  # no exception
    if fail_at:
        assert events_in(read_recording(files[0].path, warn=False)) == [event(i) for i in range(4 * fail_at)]
    else:
        assert not (tmp_path / "r.csv").exists()


def test_a_full_queue_is_an_error_not_a_blocked_ui(tmp_path):
    clock, files = FakeClock(), []
    r = BackgroundRecorder(str(tmp_path / "q.csv"), STREAMS, flush_interval_s=0.5, clock=clock, threaded=False,
                           max_batches=3)
    for k in range(5):  # the writer never runs: the storage does not keep up
        r.add(*event(k))
        r.push()
    assert r.error.startswith("storage does not keep up")


def test_a_write_error_in_a_session_is_shown_and_stops_recording_cleanly(tmp_path):
    files = []

    def factory(path, streams, device, metadata, flush_interval_s):
        def opener(p):
            f = CountingFile(p, fail_at=2)
            files.append(f)
            return f
        return BackgroundRecorder(path, streams, device, metadata, flush_interval_s=flush_interval_s,
                                  opener=opener, threaded=False)

    src = FakeSource()
    ses = Session(src, pipeline_factory=NullPipeline, record_path=str(tmp_path / "s.csv"),
                  record_streams=STREAMS, recorder_factory=factory)
    ses.start()
    for tick in range(5):
        src.pending = [event(tick * 10 + j) for j in range(10)]
        ses.tick()  # never raises
        ses.writer and ses.writer.pump()
    assert ses.writer is None  # recording stopped
    assert ses.record_error.startswith("recording stopped: cannot write") and "20 events kept" in ses.record_error
    assert ses.events_in == 50  # tracking goes on
    ses.flush()
    ses.close()
    assert events_in(read_recording(str(tmp_path / "s.csv"), warn=False)) == [event(i) for i in range(20)]


def test_the_real_file_survives_a_failing_disk(tmp_path, monkeypatch):
    """AppendFile: a short write (disk full) is cut back, so the file still ends with a whole line."""
    import app.recorder as recmod

    r = BackgroundRecorder(str(tmp_path / "d.csv"), STREAMS, flush_interval_s=0.5, threaded=False)
    r.add(*event(0))
    r.flush()
    real_write = os.write
    monkeypatch.setattr(recmod.os, "write", lambda fd, data: real_write(fd, data[: len(data) // 2]))
    r.add(*event(1))
    r.add(*event(2))
    r.flush()
    monkeypatch.setattr(recmod.os, "write", real_write)
    assert "short write" in r.error
    r.close()
    rec = read_recording(str(tmp_path / "d.csv"), warn=False)
    assert events_in(rec) == [event(0)] and rec.repairs == []


def test_the_recording_never_exists_empty(tmp_path):
    from app.recorder import AppendFile

    path = tmp_path / "e.csv"
    f = AppendFile(str(path))
    assert not path.exists()  # a kill now leaves no recording (an empty e.csv.part at most)
    f.write(b"abc\n")
    assert path.read_bytes() == b"abc\n" and not (tmp_path / "e.csv.part").exists()
    f.write(b"def\n")
    f.close()
    assert path.read_bytes() == b"abc\ndef\n"
    g = AppendFile(str(tmp_path / "never.csv"))
    g.close()
    assert list(tmp_path.iterdir()) == [path]  # closed before any write: nothing left
    with pytest.raises(FileExistsError):
        AppendFile(str(path))


def test_a_header_only_file_from_an_older_recorder_gets_a_clear_message(tmp_path):
    path = tmp_path / "old.csv"
    from app.recorder import header_text

    path.write_text(header_text(STREAMS, {}, {}))
    with pytest.raises(RecordingError, match="no sensor events"):
        load_any_recording(str(path))


# -- kill -9 at random moments -----------------------------------------------------------------

#: the recording processes' parent: it imports the session once, then forks one recording process per file (a fork
#: costs next to nothing, a fresh interpreter importing numpy and the session about 0.2 s of CPU each, 14 of them);
#: each child records as the app's clock does and never returns: it is killed.  The parent reports every child's
#: start ("start I PID T0") and how it ended ("exit I WAIT_STATUS") on its stdout, one short line each (atomic).
ZYGOTE = r"""
import os, sys, time
sys.path.insert(0, sys.argv[1])
from tests._recorder_helpers import FakeSource, NullPipeline, STREAMS, event
from app.session import Session


def record(i, path):
    src = FakeSource()
    ses = Session(src, pipeline_factory=NullPipeline, record_path=path, record_streams=STREAMS)
    ses.start()
    t0 = time.monotonic_ns()
    os.write(1, f"start {i} {os.getpid()} {t0}\n".encode())
    k = 0
    while True:  # a 200 Hz sensor, delivered in 30 Hz ticks like the app's clock
        now = time.monotonic_ns()
        while event(k, t0)[1] <= now:
            src.pending.append(event(k, t0))
            k += 1
        ses.tick()
        time.sleep(1 / 30)


children = {}
for i, path in enumerate(sys.argv[2:]):
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        try:
            record(i, path)
        except BaseException:
            import traceback
            traceback.print_exc()
            sys.stderr.flush()
        os._exit(3)  # not killed: an error (its traceback on stderr)
    children[pid] = i
while children:
    pid, status = os.wait()
    os.write(1, f"exit {children.pop(pid)} {status}\n".encode())
"""


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL, fork")
def test_kill_9_at_random_moments_loses_at_most_the_last_second(tmp_path):
    """Fourteen recording processes killed at seeded random moments after their start. They run side by
    side (each killed at its own moment on the shared monotonic clock), so the test takes the longest
    delay, not their sum.  They are forked from one parent that imported the session (not fourteen fresh
    interpreters): each is a process of its own, opens its file after the fork and dies by SIGKILL."""
    import selectors

    rnd = random.Random(12)
    delays = [rnd.uniform(0.0, 0.4) for _ in range(4)] + [rnd.uniform(0.4, 2.0) for _ in range(10)]
    rnd.shuffle(delays)
    paths = [tmp_path / f"kill{i}.csv" for i in range(len(delays))]
    # its own session: the finally below ends the parent and every recording process (its group) whatever happened
    zygote = subprocess.Popen([sys.executable, "-c", ZYGOTE, str(ROOT), *map(str, paths)], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    pids, t0s, kills, statuses = {}, {}, {}, {}
    failure = None
    sel = selectors.DefaultSelector()
    sel.register(zygote.stdout, selectors.EVENT_READ)
    fd, buf = zygote.stdout.fileno(), b""
    try:
        due = {}  # process -> monotonic ns of its kill
        while len(statuses) < len(delays) and failure is None:
            now = time.monotonic_ns()
            for i in [i for i, t in due.items() if t <= now]:
                kills[i] = time.monotonic_ns()
                os.kill(pids[i], signal.SIGKILL)  # no close(), no atexit, no finally
                del due[i]
            timeout = max(0.0, (min(due.values()) - time.monotonic_ns()) * 1e-9) if due else 30.0
            if not sel.select(timeout):
                if not due:
                    failure = "no recording process started (or ended) within 30 s"
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                failure = "the recording processes' parent ended early"
                break
            *lines, buf = (buf + chunk).split(b"\n")
            for line in lines:
                what, i, a, *b = line.decode().split()
                i = int(i)
                if what == "start":
                    pids[i], t0s[i] = int(a), int(b[0])
                    due[i] = t0s[i] + int(delays[i] * 1e9)
                else:
                    statuses[i] = int(a)
                    if i not in kills:
                        failure = f"recording process {i} ended by itself (wait status {a})"
        if failure is None:
            zygote.wait(timeout=10)
    finally:
        try:
            os.killpg(zygote.pid, signal.SIGKILL)  # the parent and any recording process left (none when passed)
        except ProcessLookupError:
            pass
        zygote.wait(timeout=10)
        sel.close()
    assert failure is None, (failure, zygote.stderr.read().decode(errors="replace")[-3000:])
    results = []
    for i, delay in enumerate(delays):
        assert os.WIFSIGNALED(statuses[i]) and os.WTERMSIG(statuses[i]) == signal.SIGKILL, statuses[i]
        path, t0 = tmp_path / f"kill{i}.csv", t0s[i]
        if path.exists():
            got = events_in(read_recording(str(path), warn=False))  # reads back without error
        else:
            got = []  # killed before the first write: no file, not a header-only one
        n = len(got)
        assert got == [event(k, t0) for k in range(n)]  # exactly the prefix of what was sent
        # every event sampled more than a second before the kill is in the file
        must = max(0, (kills[i] - 1_000_000_000 - t0) // 5_000_000 + 1)
        assert n >= must, (i, delay, n, must)
        results.append((delay, n, path.exists()))
    print(results)
    assert sum(n < 100 for _, n, _ in results) >= 3  # kills within the first half second (before the first fsync)
    assert sum(n > 200 for _, n, _ in results) >= 5  # and kills mid-walk
