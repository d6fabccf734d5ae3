"""A recording's file is held under an exclusive ``flock`` while its writer has it open
(:class:`foveatrack.recording.writer.RecordingWriter`), so that what reads or rewrites recordings
can tell a file still being written from one cut short: ``recover`` refuses it, ``replay`` and
``export`` read what it holds so far and say so instead of calling its end damage.  The kernel
drops the lock when the writer's process dies (a killed driver's file is then recoverable), as it
does a command journal's (:class:`foveatrack.live_devices.CommandJournal`), whose lock is asked with
the same probe (:func:`recording_in_use`).  ``recover`` holds the same lock while it rewrites a cut-short
recording (its completed copy beside it, renamed over it at the end): :func:`lock_holder` tells the two
apart, so a reader is told which one to wait for, by a mark recover keeps locked beside the file for as
long as it runs (:func:`mark_recovering`).  A core module: the recording layer and the live devices'
layer both use it."""

from __future__ import annotations

import os


def hold(path) -> int | None:
    """An exclusive ``flock`` on the recording's file (module docstring): the fd to close when the
    writer is done, None where the lock cannot be taken."""
    return _flocked(path, os.O_RDONLY)


def _flocked(path, flags: int) -> int | None:
    """``path`` opened with ``flags`` (never through a symlink; made 0644 with ``O_CREAT``, so that
    another user's reader can probe it) under an exclusive ``flock`` taken without waiting: its fd,
    None where either cannot be had."""
    try:
        import fcntl

        fd = os.open(path, flags | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except (ImportError, OSError):
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def recording_in_use(path) -> bool:
    """Whether a running writer holds the file at ``path`` under its exclusive ``flock`` (a recording's,
    :func:`hold`; a command journal's too, :func:`foveatrack.live_devices.journal_in_use`)."""
    try:
        import fcntl

        fd = os.open(path, os.O_RDONLY)
    except (ImportError, OSError):
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)          # closing drops the probe's own lock if it got one
    return False


def _recover_mark(path) -> str:
    real = os.path.realpath(path)
    return os.path.join(os.path.dirname(real), f".{os.path.basename(real)}.recovering")


def mark_recovering(path, wait_s: float = 0.5) -> int | None:
    """``foveatrack recover``'s mark beside the recording at ``path``, under an exclusive ``flock`` for
    as long as the recover runs (it holds the recording's own lock too): the fd to give
    :func:`unmark_recovering`, None where it cannot be made within ``wait_s``.  Not the temporary
    copy it writes: that copy's writer closes it, and so lets its lock go, before the copy is synced
    and renamed, and a killed recover's copy lies there unlocked; the mark's lock lasts the whole
    recover and dies with its process.

    A recover that has just renamed its copy over the file still holds the mark for a moment while
    a second one may take the new file's lock: the second waits for the mark.  A mark locked after
    its file was unlinked (the first recover removed it between our open and our lock) is no one's
    mark: it is made again."""
    import time

    mark = _recover_mark(path)
    deadline = time.monotonic() + wait_s
    while True:
        fd = _flocked(mark, os.O_RDWR | os.O_CREAT)
        if fd is not None:
            if _is_at(fd, mark):
                return fd
            os.close(fd)
        if time.monotonic() > deadline:
            return None
        time.sleep(0.01)


def _is_at(fd: int, path: str) -> bool:
    """Whether the open file ``fd`` is still the one at ``path`` (not unlinked or replaced since)."""
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False))
    except OSError:
        return False


def unmark_recovering(path, fd: int | None) -> None:
    """Remove :func:`mark_recovering`'s mark while its lock is held (so no reader finds it unlocked,
    and only while the path is still this mark: not a later recover's), then let the lock go."""
    if fd is None:
        return
    mark = _recover_mark(path)
    try:
        if _is_at(fd, mark):
            os.unlink(mark)
    except OSError:
        pass
    os.close(fd)


def lock_holder(path) -> str | None:
    """Who holds the recording at ``path`` under its lock: ``"recover"`` while ``foveatrack recover``'s
    mark beside it is locked (:func:`mark_recovering`), ``"writer"`` otherwise, None when nothing
    holds it.  A killed recover's leftovers (its copy, its mark) are not locked: a writer that holds the
    file later is still its writer."""
    if not recording_in_use(path):
        return None
    if recording_in_use(_recover_mark(path)):
        return "recover"
    # a recover that ended between the two probes took its mark away: asked again, the file is free
    return "writer" if recording_in_use(path) else None
