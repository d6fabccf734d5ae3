"""Work the closed loop will need, done ahead on the second core while it works on the current frame.

Two things a frame needs do not depend on anything the loop decides:

* the scan: the rosette pattern moves with the prisms, not with the head (the head turns the beams
  afterwards), so the points of the coming frames can be traced early (:class:`ScanAhead`);
* the effects' random draws: each effect owns a stream and takes the next ``n`` values of one kind
  (uniforms or standard normals) per frame, so those values can be drawn early in blocks
  (:class:`DrawsAhead`).

Both run on one worker thread (:class:`Ahead`), in numba kernels that release the GIL (the scan
kernel :func:`sim.scan.kernels.scan_exact_kernel`, the fills of :mod:`sim.random_kernels`), so the
worker runs beside the loop's Python.  The loop's critical path loses the scan and the draws (measured by
``scripts/bench_closed_loop.py``: the loop thread's CPU per frame with and without).

Same bits as without, by construction:

* a point's direction, time and channel do not depend on where a chunk starts (the kernels are
  compiled without fast-math; ``tests/scan/test_scan_fused.py`` checks chunking), and the worker is the
  only caller of the scan model while it runs, in frame order, so motor-noise draws come in the same
  order;
* numpy's ``Generator.random(n)`` and ``standard_normal(n)`` give the same values however a run of
  draws is split into calls, ``normal(0, s, n)`` is ``0 + s * standard_normal(n)`` value for value,
  and numba's kernels draw what numpy draws (``tests/world/test_ahead.py`` checks all three against
  the installed numpy and numba, and whole runs).

What differs: a stream drawn ahead ends the run further along than one drawn frame by frame (the
unused rest of its last block); nothing reads a stream after its effect.
"""

from __future__ import annotations

import queue
import threading
import weakref

import numpy as np

from foveatrack.detection import frozen_maker
from sim import random_kernels as rk
from sim.scan.model import ScanChunk, ScanModel

BLOCK = 65_536      # values per block drawn ahead (the worker fills one block ahead of the loop)
_make_chunk = frozen_maker(ScanChunk)   # a frame's slice of a batch, once per frame: without the
                                        # frozen dataclass's per-field __setattr__


class Job:
    """One piece of work handed to the worker, and its outcome (:meth:`result`).

    Why not ``concurrent.futures``: a Future keeps its state under a ``threading.Condition`` that
    the waiting thread and the worker both enter, and entering it (``Condition.__enter__``, Python
    code around the lock) is not safe against a Ctrl-C.  A KeyboardInterrupt that lands just after
    the loop's thread took the lock, before its ``with`` block began, left the lock taken for good:
    the worker then blocked in ``set_result`` for ever, and with it the pool's ``shutdown(wait=True)``
    and the interpreter's exit (``concurrent.futures`` joins its workers there), while the writer
    process waited for a ``close`` that never came (docs/interrupts.md).  Here the waiting thread
    waits on a bare lock that only the worker releases, once, and the worker takes no lock the
    waiting thread could hold: a KeyboardInterrupt at any bytecode of the wait leaves the worker free.
    """

    __slots__ = ("_fn", "_args", "_done", "_finished", "_value", "_error")

    def __init__(self, fn, args: tuple):
        self._fn, self._args = fn, args
        self._done = threading.Lock()
        self._done.acquire()         # released by the worker when the outcome is in
        self._finished = False
        self._value = self._error = None

    @classmethod
    def done_now(cls, fn, args: tuple) -> "Job":
        """Done at once on the caller's thread (an error raised here, as the call itself would)."""
        job = cls(None, ())
        job._value = fn(*args)
        job._finished = True
        job._done.release()
        return job

    def run(self) -> None:
        """On the worker: do the work, keep its outcome, and let the waiting thread go on."""
        try:
            self._value = self._fn(*self._args)
        except BaseException as exc:  # noqa: BLE001 - raised by result() on the thread that asks
            self._error = exc
        self._fn = self._args = None
        self._finished = True        # before the release: a wait cut short after the lock was taken
        self._done.release()         # (by a Ctrl-C) leaves it taken, and later calls must not wait on it

    def result(self):
        """The work's return value (waiting for it), or its exception raised here."""
        if not self._finished:
            self._done.acquire()
            self._done.release()
        if self._error is not None:
            raise self._error
        return self._value


def _work(jobs: queue.SimpleQueue) -> None:
    """The worker's loop: the jobs in the order handed over, until None."""
    while (job := jobs.get()) is not None:
        job.run()
        job = None      # the outcome belongs to the waiting thread: not kept alive until the next job


class Ahead:
    """The worker thread.  After :meth:`close`, everything that used it works synchronously.

    Safe against a Ctrl-C on the thread that uses it (docs/interrupts.md): the worker is a daemon
    thread (an interpreter that exits never waits for it) and blocks on nothing but its queue, and
    :meth:`close` may be called again after an interrupted one."""

    def __init__(self):
        self._closed = False
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        # an Ahead dropped without close(): its worker ends too, after the jobs handed over
        weakref.finalize(self, self._jobs.put, None)
        thread = threading.Thread(target=_work, args=(self._jobs,), name="sim-ahead", daemon=True)
        thread.start()
        self._thread = thread

    def submit(self, fn, *args) -> Job:
        if self._closed:                 # closed: do it now, on the caller's thread
            return Job.done_now(fn, args)
        job = Job(fn, args)
        self._jobs.put(job)
        return job

    def close(self) -> None:
        """Let the worker do every job handed over (their results stay to be taken), then end it and
        wait for it: from then on the scan model and the streams are the caller's alone."""
        self._closed = True
        if self._thread is not None:
            self._jobs.put(None)         # one more None if an interrupted close() put one: harmless
            self._thread.join()
            self._thread = None


class ScanAhead:
    """``scan_time`` of ``model`` for consecutive frames of ``period_s``, traced ``batch_frames`` at a
    time one batch ahead on ``ahead``'s worker.  Any other request is traced at once (after the
    batch in flight, so the model is only ever used by one thread at a time)."""

    def __init__(self, model: ScanModel, period_s: float, ahead: Ahead, batch_frames: int = 10):
        if not period_s > 0:
            raise ValueError(f"period_s = {period_s!r} must be > 0")
        if batch_frames < 1:
            raise ValueError(f"batch_frames = {batch_frames!r} must be >= 1")
        self.model = model
        self.period_s = period_s
        self.batch_frames = batch_frames
        self._ahead = ahead
        self._next: tuple[int, Job] | None = None             # (first frame, its batch in flight)
        self._batch: tuple[int, ScanChunk] | None = None         # (first frame, its points)
        self._cuts: list[int] = []                               # frame starts in the batch's points

    def _frame_k(self, f: int) -> int:
        return self.model.index_at_time(f * self.period_s)

    def _submit(self, f0: int) -> tuple[int, Job]:
        k0, k1 = self._frame_k(f0), self._frame_k(f0 + self.batch_frames)
        return f0, self._ahead.submit(self.model.scan, k0, k1 - k0)

    def scan_time(self, t0_s: float, t1_s: float) -> ScanChunk:
        """The points fired in ``[t0_s, t1_s)``, as :meth:`ScanModel.scan_time`."""
        f = round(t0_s / self.period_s)
        if not (f >= 0 and f * self.period_s == t0_s and (f + 1) * self.period_s == t1_s):
            self._drain()                 # not a frame of the grid: traced here and now
            return self.model.scan_time(t0_s, t1_s)
        if self._batch is None or not self._batch[0] <= f < self._batch[0] + self.batch_frames:
            if self._next is None or self._next[0] != f:
                self._drain()
                self._next = self._submit(f)
            f0, fut = self._next
            self._batch = (f0, fut.result())
            # where each frame of the batch starts in it, worked out once per batch
            self._cuts = [self._frame_k(f0 + i) - self._batch[1].k0 for i in range(self.batch_frames + 1)]
            self._next = self._submit(f0 + self.batch_frames)    # the next batch starts now
        f0, chunk = self._batch
        a = self._cuts[f - f0]
        b = self._cuts[f - f0 + 1]
        return _make_chunk(chunk.k0 + a, chunk.t_ns[a:b], chunk.direction[a:b], chunk.channel[a:b],
                           chunk.status[a:b])

    def _drain(self) -> None:
        """Wait for the batch in flight and forget it (the model is then the caller's alone)."""
        if self._next is not None:
            self._next[1].result()
            self._next = None
        self._batch = None


class DrawsAhead:
    """One effect's stream, drawn ahead in blocks of one kind: ``"uniform"`` (``rng.random``) or
    ``"normal"`` (``rng.standard_normal``).  Stands in for the ``numpy.random.Generator`` the effect's
    draw function (:mod:`sim.effects`) is given: it returns the values
    the generator itself would have returned to the same sequence of calls (:meth:`random`,
    :meth:`standard_normal`).

    ``ahead`` None: the blocks are filled on the caller's thread when it runs out (no worker; what a
    run without a second thread uses for its normals: one fill kernel call per block instead of one
    per frame, whose ~7 us of numba unboxing the generator cost more than 3 000 draws); :meth:`work_on`
    moves the filling to a worker from then on, the stream going on where it stands.
    """

    def __init__(self, rng: np.random.Generator, kind: str, ahead: Ahead | None, block: int = BLOCK):
        if kind not in ("uniform", "normal"):
            raise ValueError(f"kind {kind!r}: 'uniform' or 'normal'")
        if block < 1:
            raise ValueError(f"block = {block!r} must be >= 1")
        self.kind = kind
        self._rng = rng
        self._kernel = rk.fill_uniform_kernel if kind == "uniform" else rk.fill_standard_normal_kernel
        self._ahead = ahead
        self._block = block
        self._buf = np.empty(0)
        self._pos = 0
        self._next = None if ahead is None else ahead.submit(self._fill, block)

    def work_on(self, ahead: Ahead, block: int = BLOCK) -> None:
        """Fill the coming blocks, of ``block`` values, ahead on ``ahead``'s worker (the values do not
        change).  Blocks as big as a stream drawn ahead from the start: with the few frames a small
        one lasts, the loop would wait for the worker at every block (it fills one block ahead,
        queued behind the scan)."""
        if block < 1:
            raise ValueError(f"block = {block!r} must be >= 1")
        self._ahead = ahead
        self._block = block
        if self._next is None:
            self._next = ahead.submit(self._fill, self._block)

    def _fill(self, n: int) -> np.ndarray:
        out = np.empty(n)
        self._kernel(self._rng, out)      # releases the GIL: the loop's thread goes on meanwhile
        return out

    def _take(self, n: int) -> np.ndarray:
        if self._pos + n <= self._buf.size:           # the usual case: one slice of the block
            # A view, not a copy: each value is handed out once and the block is never written
            # again (a new block is a new array).  Left writeable: a read-only array would be
            # another type to numba, one more compilation of each kernel it is given to.
            out = self._buf[self._pos:self._pos + n]
            self._pos += n
            return out
        parts = [self._buf[self._pos:]]
        need = n - parts[0].size
        while need > 0:
            if self._next is None:       # no worker: the next block, now
                self._buf = self._fill(max(self._block, need))
            else:
                self._buf = self._next.result()
                self._next = self._ahead.submit(self._fill, max(self._block, need))
            k = min(need, self._buf.size)
            parts.append(self._buf[:k])
            self._pos = k
            need -= k
        return parts[1] if len(parts) == 2 and parts[0].size == 0 else np.concatenate(parts)

    def random(self, size: int) -> np.ndarray:
        if self.kind != "uniform":
            raise TypeError("a stream drawn ahead as normals cannot give uniforms (it would change the draws)")
        return self._take(int(size))

    def standard_normal(self, size: int) -> np.ndarray:
        if self.kind != "normal":
            raise TypeError("a stream drawn ahead as uniforms cannot give normals (it would change the draws)")
        return self._take(int(size))
