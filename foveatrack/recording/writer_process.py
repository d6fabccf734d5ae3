"""A recording written by a child process: :class:`RecordingProcess` takes a
:class:`foveatrack.recording.writer.RecordingWriter`'s calls and hands them to a child interpreter
(:func:`child_main`), which makes the same calls on a RecordingWriter of its own.  The file is the
same to the byte (tests/recording/test_writer_process.py).

Why a process: the Foxglove SDK holds the interpreter lock while it encodes, compresses and writes
(0.4-0.5 ms of a 10 k-point frame), so a writer *thread* only takes turns with the loop
(docs/recordings.md).  Here the caller's thread copies a frame's arrays into a ring of shared
memory (a 16 MiB memfd both processes map) and pickles its calls into a 1 MiB pipe: about 0.1 ms a
frame with the building of the records.  It pays only where a second core is free: ``simulate``
uses it then (``--one-thread`` never, ``--second-core`` always).

What the caller sees:

- the arrays handed over may be changed as soon as a call returns (they were copied);
- a call waits only when the child is ~50 frames behind (the ring is full; nothing is dropped);
- an error in the child (disk full, ...) is raised by the next frame, :meth:`flush` or :meth:`close`,
  and the file is still completed with what was written;
- the child ignores SIGINT and SIGTERM (a Ctrl-C at the terminal reaches the whole process group):
  it ends when the caller closes the pipe, by :meth:`close` or by dying, even by ``kill -9``, and
  completes the file then, so nothing already handed over is lost.

The child's start (an interpreter, numpy, the SDK, numba and the packing kernel: 0.7-1.9 s, 0.7 s of
CPU) runs beside the caller's own set-up: ``simulate`` starts it first, and the first frames wait
in the ring.
"""

from __future__ import annotations

import os
import pickle
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.recording.format import imu_columns
from foveatrack.recording.foxglove_view import log_clock
from foveatrack.recording.writer import RecordCalls, check_options

_HEAD = struct.Struct("<QI")        # pickle bytes, number of arrays; then a <Q per array (its bytes)
_ARRAY = "foveatrack.recording.writer_process.array"   # marks an argument sent as raw bytes on the pipe
_IN_RING = "foveatrack.recording.writer_process.ring"  # marks an argument copied into the ring
_RING_BYTES = 16 << 20              # ~50 frames of 10 k points: how far the child may fall behind
_PIPE_BYTES = 1 << 20               # the pipe's capacity asked for (Linux F_SETPIPE_SZ; unprivileged maximum)


# The child's program: the signals first (a Ctrl-C at the terminal reaches the whole process group,
# also while the child still imports), then the writer; the caller decides when to stop.
# os._exit: the file is complete once the writer is closed; the interpreter's teardown (numba's and
# the SDK's) would cost the caller another 0.1-0.2 s of waiting.
_CHILD = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
          "signal.signal(signal.SIGTERM, signal.SIG_IGN); "
          "from foveatrack.recording.writer_process import background_priority; background_priority(); "
          "from foveatrack.recording.writer_process import child_main; "
          "rc = child_main(*map(int, sys.argv[1:])); sys.stderr.flush(); os._exit(rc)")


def background_priority() -> None:
    """Make the calling process yield to the loop: SCHED_BATCH (Linux: a write into its pipe does not
    let it preempt the writer on the writer's core) and nice 5.  Where neither exists, nothing."""
    try:
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    except (AttributeError, OSError):
        pass
    try:
        os.nice(5)
    except (AttributeError, OSError):
        pass


def _child_env() -> dict:
    """The caller's environment, with the directory this foveatrack comes from first on the path (a
    checkout run without installing it finds the same code)."""
    import foveatrack

    env = dict(os.environ)
    root = str(Path(foveatrack.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    return env


def available() -> bool:
    """Whether this platform can run the writer process (POSIX pipes handed to a child)."""
    return os.name == "posix"


class _Ring:
    """Shared memory both processes map (a memfd) through which the arrays go: the caller copies an
    array in (0.02 ms for a frame's 330 kB, against 0.04-0.05 ms through the pipe), the child reads
    it in place and publishes, in the first 8 bytes, how far it has read; the caller waits for that
    before it writes over bytes not yet read.  Positions count bytes since the start, never wrapping."""

    HEAD = 64

    def __init__(self, fd: int, size: int):
        import mmap

        self.fd = fd
        # MAP_POPULATE: the pages are allocated and mapped now (~5 ms for 16 MiB), not one fault at a
        # time in the loop's copies (0.1 ms a frame while the ring fills for the first time)
        flags = mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0)
        self.mm = mmap.mmap(fd, size, flags=flags)
        self.size = size - self.HEAD
        self.written = 0

    @classmethod
    def create(cls, size: int = _RING_BYTES) -> "_Ring | None":
        """A new ring, or None where there is no memfd (the arrays then all go through the pipe)."""
        try:
            fd = os.memfd_create("foveatrack-recording", 0)
        except (AttributeError, OSError):
            return None
        os.ftruncate(fd, size)
        return cls(fd, size)

    def read_up_to(self) -> int:
        return struct.unpack_from("<Q", self.mm, 0)[0]

    def set_read_up_to(self, pos: int) -> None:
        struct.pack_into("<Q", self.mm, 0, pos)

    def reports(self) -> int:
        """How many reports the child has written to its report pipe (bytes 8-16 of the header): the
        caller reads that pipe only when this changed, not with a system call every frame."""
        return struct.unpack_from("<Q", self.mm, 8)[0]

    def count_report(self) -> None:
        struct.pack_into("<Q", self.mm, 8, self.reports() + 1)

    def put(self, a: np.ndarray, wait) -> int | None:
        """Copy ``a`` (C-contiguous) in; its position, or None if it is too large for the ring.
        ``wait()`` is called while the child has not yet read the bytes the copy needs."""
        need = (a.nbytes + 63) & ~63                # 64-byte aligned: every dtype reads in place
        if need > self.size // 2:
            return None
        pos = self.written
        if pos % self.size + need > self.size:      # not in the tail: start again at the front
            pos += self.size - pos % self.size
        while pos + need - self.read_up_to() > self.size:
            wait()
        start = self.HEAD + pos % self.size
        if a.nbytes:
            self.mm[start:start + a.nbytes] = a.reshape(-1).view(np.uint8)
        self.written = pos + need
        return pos

    def view(self, pos: int, dtype: str, shape: tuple) -> np.ndarray:
        dt = np.dtype(dtype)
        count = int(np.prod(shape, dtype=np.int64))
        return np.frombuffer(self.mm, dt, count, self.HEAD + pos % self.size).reshape(shape)


class RecordingProcess(RecordCalls):
    """A :class:`RecordingWriter` in a child process: same options (checked here, so a wrong one is
    an error at once), same calls, same file.  ``RecordingProcess()`` starts the child;
    :meth:`open` gives it the file.  Use as a context manager, or call :meth:`close`.

    Start it early (before the caller's own set-up) and open it when the recording's meta is known:
    the child's start then costs nothing.  The calls of a frame are sent together when its points
    come (:meth:`write_points`), at :meth:`flush` and at :meth:`close`: one system call a frame.
    """

    def __init__(self):
        self.path: Path | None = None
        self.frames_written = self.messages_written = 0
        self._pending: list = []
        self._arrays: list = []
        self._back = b""
        self._ready = False
        self._child_gone = False    # the end of its report pipe was read: the child has exited
        self._error: BaseException | None = None
        self._closed = False
        self._torn = False          # a message is (or may be) only partly in the pipe: see _send
        self._reports_seen = -1     # the child's report count when its pipe was last read (_Ring.reports)
        self._ring = _Ring.create()
        data_r, self._data = os.pipe()
        self._back_fd, back_w = os.pipe()
        ring_args = [] if self._ring is None else [str(self._ring.fd), str(self._ring.mm.size())]
        try:
            try:
                import fcntl

                fcntl.fcntl(self._data, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
            except (ImportError, AttributeError, OSError):
                pass        # the default 64 KiB pipe: the caller waits on the child more often
            self._proc = subprocess.Popen(
                # -P: the working directory is not on the child's path (a signal.py there ran in it)
                [sys.executable, "-P", "-c", _CHILD, str(data_r), str(back_w), *ring_args],
                pass_fds=(data_r, back_w, *([] if self._ring is None else [self._ring.fd])),
                stdin=subprocess.DEVNULL, env=_child_env())
        except BaseException:
            for fd in (data_r, back_w, self._data, self._back_fd):
                os.close(fd)
            raise
        os.close(data_r)
        os.close(back_w)
        if self._ring is not None:
            os.close(self._ring.fd)     # the mapping stays
        os.set_blocking(self._back_fd, False)

    def open(self, path, meta: dict | None = None, flush_every_frames: int = 1, compression: str = "zstd",
             compression_level: int | None = None, points_dtype: str = "float64", fsync: bool = False,
             overwrite: bool = False, created_utc: str | None = None,
             log_time: int | str = 0) -> "RecordingProcess":
        """Give the child the file to write, with :class:`RecordingWriter`'s options; returns self."""
        if self.path is not None:
            raise ValueError(f"this writer process already writes {self.path}")
        if path is None:
            raise ValueError("a writer process writes a file: give a path (a live view needs RecordingWriter)")
        path, _, _ = check_options(path, meta, flush_every_frames, compression, compression_level,
                                   points_dtype, overwrite)
        log_clock(log_time)         # a wrong one named here, not in the child
        self.path = path.absolute()
        self._call("open", str(self.path), meta, flush_every_frames, compression, compression_level,
                   points_dtype, fsync, True, created_utc, log_time)
        self._send()
        return self

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        """Wait until the child has started (its imports and kernels loaded): for benchmarks that
        time the calls alone."""
        import select

        while not self._ready:
            if not select.select([self._back_fd], [], [], timeout_s)[0]:
                raise TimeoutError(f"the recording process did not start within {timeout_s:g} s")
            self._read_back()
            if self._child_gone and not self._ready:
                raise RuntimeError(f"the recording process exited with code {self._proc.wait()} at its start")

    # ------------------------------------------------------------------ the calls

    def write(self, channel: str, t_ns: int, record: dict) -> None:
        self._call("write", channel, t_ns, record)

    def write_points(self, t_ns, frame_id, xyz, t_ns_points, reflectivity=None) -> None:
        # the arrays go as raw buffers after the message (a pickled array costs ~10 us more)
        self._call("write_points", t_ns, frame_id, *(None if a is None else self._array(a)
                                                     for a in (xyz, t_ns_points, reflectivity)))
        self.frames_written += 1
        self._send()

    def write_imu(self, t_ns, frame_id, t_s, gyro_rad_s, accel_g=None) -> None:
        # checked here (a wrong shape is the caller's error, raised at once); sent with the next frame
        t, g, a = imu_columns(t_s, gyro_rad_s, accel_g)
        self._call("write_imu", t_ns, frame_id, *(None if x is None else self._array(x) for x in (t, g, a)))

    def _array(self, a) -> tuple:
        a = np.ascontiguousarray(a)
        pos = None if self._ring is None else self._ring.put(a, self._wait_for_child)
        if pos is not None:
            return _IN_RING, pos, a.dtype.str, a.shape
        self._arrays.append(a)
        return _ARRAY, len(self._arrays) - 1, a.dtype.str, a.shape

    def _wait_for_child(self) -> None:
        """The ring is full: wait for the child to read on (or say why it cannot).

        Whether the child still runs is read from its report pipe (its end: the child has exited),
        not asked of ``Popen.poll()``: a Ctrl-C lands here more than anywhere when the child is
        behind, and ``poll()`` takes the Popen's lock with a bare ``acquire()`` before its ``try``.
        A KeyboardInterrupt just after that acquire left the lock taken, and :meth:`close`'s wait
        for the child then blocked on it for ever (docs/interrupts.md)."""
        import time

        self._read_back()
        self._raise_reported()
        if self._child_gone:
            raise self._ended_early()
        time.sleep(0.0005)

    def flush(self) -> None:
        if self._closed:
            return
        self._call("flush")
        self._send()

    def close(self) -> None:
        """Send what is pending, let the child complete the file, and wait for it.  Raises the
        child's error, if one is still unreported."""
        if self._closed:
            return
        self._closed = True
        if self.path is None:       # never opened: no file to complete, so no need to wait for its start
            self._proc.kill()
            self._release()
            return
        try:
            # After a message cut short (a Ctrl-C in the middle of its write), nothing more is sent:
            # the child would read it as the rest of that message.  The end of the pipe alone has
            # it drop the cut message and complete the file with every message before it.
            if not self._torn:
                self._pending.append(("close", ()))
                self._send()
        except (OSError, RuntimeError, UserError):
            pass        # the child's report or its exit code (below) says what went wrong
        finally:
            os.close(self._data)    # the end of the pipe: the child completes the file and exits
            self._data = -1
        os.set_blocking(self._back_fd, True)
        while chunk := os.read(self._back_fd, 1 << 16):
            self._back += chunk
        rc = self._release()
        self._read_back()
        self._raise_reported()
        if rc != 0:
            raise RuntimeError(f"the recording process exited with code {rc}; {self.path} holds what it "
                               f"wrote up to then")

    def _release(self) -> int:
        """Wait for the child to end, close what is left open; its exit code."""
        rc = self._proc.wait()
        for fd in (self._data, self._back_fd):
            if fd >= 0:
                os.close(fd)
        self._data = self._back_fd = -1
        if self._ring is not None:
            self._ring.mm.close()
        return rc

    def __enter__(self) -> "RecordingProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ the pipe

    def _call(self, name: str, *args) -> None:
        if self._closed and name != "close":
            raise ValueError("recording is closed")
        if self.path is None and name != "open":
            raise ValueError("open() the writer process before writing to it")
        self._raise_reported()
        self._pending.append((name, args))
        self.messages_written += name in ("write", "write_points", "write_imu")

    def _send(self) -> None:
        """One message: the pending calls pickled, then the bytes of the arrays they refer to.

        A KeyboardInterrupt can land between two writes of a message (a signal cuts a write to a full
        pipe short): the message is then marked torn, and only :meth:`close` may follow."""
        if self._torn:
            raise RuntimeError(f"a message to the recording process was cut short (interrupted); "
                               f"close() completes {self.path} with what came before it")
        calls, self._pending = self._pending, []
        raws, self._arrays = self._arrays, []
        # the ring's end after this message's arrays: the child may say it has read that far once done
        body = pickle.dumps((calls, 0 if self._ring is None else self._ring.written), protocol=pickle.HIGHEST_PROTOCOL)
        parts = [_HEAD.pack(len(body), len(raws)) + b"".join(struct.pack("<Q", r.nbytes) for r in raws) + body,
                 *raws]
        self._torn = True           # until the last byte is in the pipe
        try:
            _write_all(self._data, parts)
        except BrokenPipeError:
            self._torn = False      # the child is gone: nothing to keep whole
            self._read_back()
            self._raise_reported()
            raise self._ended_early() from None
        self._torn = False
        if self._ring is None or self._ring.reports() != self._reports_seen:
            self._read_back()

    def _raise_reported(self) -> None:
        """Raise the error the child reported, once."""
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def _ended_early(self) -> RuntimeError:
        """The error for a child that stopped reading: it has exited, or exits now (it stops reading
        only at its end), so its exit code is waited for (``wait()``, unlike ``poll()``, takes the
        Popen's lock in a ``with``: a Ctrl-C cannot leave it taken)."""
        return RuntimeError(f"the recording process ended early (exit code {self._proc.wait()}); "
                            f"{self.path} holds what it wrote up to then")

    def _read_back(self) -> None:
        """Take the child's reports (ready, an error) without waiting; after :meth:`close`, only
        parse what it has read."""
        # the count is taken before the pipe is read (the child counts each report after writing it):
        # every report counted so far is in the pipe now; one counted later is read at the next frame
        seen = None if self._ring is None or self._closed else self._ring.reports()
        if not self._closed:
            try:
                while chunk := os.read(self._back_fd, 1 << 16):
                    self._back += chunk
                self._child_gone = True     # the pipe's end: only the child held its other end
            except BlockingIOError:
                pass
        while len(self._back) >= 8:
            n = int.from_bytes(self._back[:8], "little")
            if len(self._back) < 8 + n:
                break
            kind, value = pickle.loads(self._back[8:8 + n])
            self._back = self._back[8 + n:]
            if kind == "error" and self._error is None:
                self._error = _rebuilt(*value, self.path)
            elif kind == "ready":
                self._ready = True
        # (a report only partly read: the pipe is read again at the next frame)
        self._reports_seen = -1 if self._back or seen is None else seen


def _write_all(fd: int, parts: list) -> None:
    """``writev`` until every byte is in the pipe (a signal can cut a write short)."""
    # (an empty array, a frame without points, has no bytes to send and cannot be cast)
    views = [memoryview(p).cast("B") for p in parts if (p.nbytes if isinstance(p, np.ndarray) else len(p))]
    while views:
        n = os.writev(fd, views)
        while views and n >= views[0].nbytes:
            n -= views[0].nbytes
            views.pop(0)
        if views and n:
            views[0] = views[0][n:]


def _rebuilt(kind: str, text: str, user: bool, path) -> BaseException:
    """The child's error as the caller raises it: a user's mistake (disk full, no permission) stays a
    :class:`UserError`; anything else names the process it came from."""
    if user:
        return UserError(text)
    return RuntimeError(f"the recording process failed writing {path}: {kind}: {text}")


# ====================================================================================== the child


def _rebuilt_array(arg, bufs, ring):
    """An argument as the caller gave it: an array sent as raw bytes or copied into the ring is
    rebuilt in place (no copy)."""
    if type(arg) is tuple and len(arg) == 4:
        if arg[0] == _ARRAY:
            _, i, dtype, shape = arg
            return np.frombuffer(bufs[i], dtype=dtype).reshape(shape)
        if arg[0] == _IN_RING:
            _, pos, dtype, shape = arg
            return ring.view(pos, dtype, shape)
    return arg


class _PolledPipe:
    """The child's end of the caller's pipe, read without ever waiting in ``read()``: a reader asleep
    in ``read()`` must be woken by the caller's write, and that wake-up is paid on the caller's thread,
    the loop's (34 us of a 0.15 ms hand-over per frame here, against 3-4 us for a write that wakes
    nobody).  When the pipe is empty the child sleeps ``POLL_S`` instead: at most that much later to
    the file, ~500 wake-ups a second of its own while idle."""

    POLL_S = 0.002

    def __init__(self, fd: int):
        self.fd = fd
        os.set_blocking(fd, False)
        self._buf = bytearray()
        self._pos = 0
        self._eof = False

    def read_exact(self, n: int) -> bytearray | None:
        """``n`` bytes, or None at the end of the pipe before them."""
        while len(self._buf) - self._pos < n:
            if self._eof:
                return None
            try:
                chunk = os.read(self.fd, max(_PIPE_BYTES, n))
            except BlockingIOError:
                time.sleep(self.POLL_S)
                continue
            if not chunk:
                self._eof = True
                continue
            if self._pos:
                del self._buf[:self._pos]
                self._pos = 0
            self._buf += chunk
        out = self._buf[self._pos:self._pos + n]
        self._pos += n
        return out


def _report(fd: int, kind: str, value, ring: "_Ring | None" = None) -> None:
    body = pickle.dumps((kind, value))
    try:
        os.write(fd, len(body).to_bytes(8, "little") + body)
    except BrokenPipeError:
        pass        # the caller is gone: the file is still completed
    if ring is not None:
        ring.count_report()     # after the write: the caller reads the pipe when the count moves


def _report_error(fd: int, exc: Exception, ring: "_Ring | None" = None) -> None:
    """An error for the caller to raise (:func:`_rebuilt` there): its type, text, and whether it is a
    user's mistake."""
    _report(fd, "error", (type(exc).__name__, str(exc), isinstance(exc, UserError)), ring)


def child_main(data_fd: int, back_fd: int, ring_fd: int | None = None, ring_bytes: int = 0) -> int:
    """Read calls until ``close`` or the end of the pipe, make them on a RecordingWriter, and report
    the first error (then the calls that follow are read and dropped; the file is still closed)."""
    from foveatrack.recording.pack_kernels import pack_points
    from foveatrack.recording.writer import RecordingWriter

    # load the packing kernels now, while the caller still sets up (0.5 s the first time in a process)
    pack_points(np.zeros((1, 3)), 0, np.zeros(1, np.int64), np.zeros(1, np.uint8))
    ring = None if ring_fd is None else _Ring(ring_fd, ring_bytes)
    _report(back_fd, "ready", None, ring)
    writer = None
    failed = False
    f = _PolledPipe(data_fd)
    try:
        while True:
            head = f.read_exact(_HEAD.size)
            if head is None:
                break           # the caller is gone (closed without "close", or died): complete the file
            n_body, n_bufs = _HEAD.unpack(head)
            raw_lens = f.read_exact(8 * n_bufs) if n_bufs else b""
            if raw_lens is None:
                break           # a message cut short by the caller's Ctrl-C: dropped, the file completed
            lens = struct.unpack(f"<{n_bufs}Q", raw_lens)
            body = f.read_exact(n_body)
            bufs = [f.read_exact(k) for k in lens]
            if body is None or any(b is None for b in bufs):
                break
            calls, ring_end = pickle.loads(body)
            closing = False
            for name, args in calls:
                if name == "close":
                    closing = True
                    break
                if failed:
                    continue
                try:
                    if name == "open":
                        path, meta, flush_every, comp, level, dtype, fsync, overwrite, created, log_time = args
                        writer = RecordingWriter(Path(path), meta, flush_every, comp, level, dtype, fsync,
                                                 overwrite, created, log_time=log_time)
                    else:
                        getattr(writer, name)(*(_rebuilt_array(a, bufs, ring) for a in args))
                except Exception as exc:  # noqa: BLE001 - reported to the caller, which raises it
                    failed = True
                    _report_error(back_fd, exc, ring)
            if ring is not None:
                ring.set_read_up_to(ring_end)   # the writer keeps no view of the ring past its calls
            if closing:
                break
    finally:
        os.close(data_fd)
    if writer is not None:
        try:
            writer.close()
        except Exception as exc:  # noqa: BLE001
            if not failed:
                _report_error(back_fd, exc, ring)
            return 1
    return 0

