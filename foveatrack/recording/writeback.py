"""A recording's written pages sent to the disk and out of the page cache in steps, so a long recording
neither piles up dirty pages nor fills the cache (issue 26's soak).

A recording at 480 k points/s writes ~350 MB a minute that is read again, if ever, long after.  Left
to the kernel, the dirty pages pile up until the background threshold (``vm.dirty_background_ratio``,
10 % of the memory here: ~2.3 GB, six or seven minutes of recording) and are then written back while
the recording goes on; a write that meets the kernel's dirty throttling sleeps inside the Foxglove
SDK, which holds the interpreter lock while it writes (docs/recordings.md), and the daemon's frame
loop waits with it.  Seen in the soak: the latency p99 per minute doubled from the minute the dirty
pages reached the threshold (minute 3 with two recordings at once, minute 6 with one), with or
without the heap's trim.

:class:`WritebackPacer` keeps this file's share small instead: after a flush, once ``step_bytes`` more
have been written, ``fdatasync`` (the interpreter lock released) sends them to the disk, and
``posix_fadvise(DONTNEED)`` drops the file's clean pages from the cache.  Costs: one sync per step
on the writer's own thread (the frame loop does not wait for it), and a reader of the fresh file
reads it from the disk.
"""

from __future__ import annotations

import os
import time


class WritebackPacer:
    """Sync and drop a file's pages every ``step_bytes`` written (module docstring).  ``syncs`` and
    ``sync_s`` count what it did."""

    def __init__(self, path, step_bytes: int):
        self.step_bytes = int(step_bytes)
        self._fd = os.open(path, os.O_RDONLY)   # the writer's handle is the SDK's; any descriptor syncs the file
        self._synced = 0
        self.syncs = 0
        self.sync_s = 0.0

    def after_flush(self) -> None:
        size = os.fstat(self._fd).st_size
        if size - self._synced < self.step_bytes:
            return
        self.sync()

    def sync(self) -> None:
        t = time.perf_counter()
        getattr(os, "fdatasync", os.fsync)(self._fd)     # (macOS has no fdatasync)
        if hasattr(os, "posix_fadvise"):
            os.posix_fadvise(self._fd, 0, 0, os.POSIX_FADV_DONTNEED)
        self._synced = os.fstat(self._fd).st_size
        self.syncs += 1
        self.sync_s += time.perf_counter() - t

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
