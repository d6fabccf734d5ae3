"""A recording's file is held under an exclusive ``flock`` while its writer has it open
(:class:`foveatrack.recording.writer.RecordingWriter`), so that what reads or rewrites recordings
can tell a file still being written from one cut short: ``recover`` refuses it, ``replay`` and
``export`` read what it holds so far and say so instead of calling its end damage.  The kernel
drops the lock when the writer's process dies (a killed driver's file is then recoverable), as it
does a command journal's (:class:`foveatrack.live_devices.CommandJournal`), whose lock is asked with
the same probe (:func:`recording_in_use`).  ``recover`` holds the same lock while it rewrites a cut-short
recording (its completed copy beside it, renamed over it at the end): :func:`lock_holder` tells the two
apart, so a reader is told which one to wait for.  A core module: the recording layer and the live
devices' layer both use it."""

from __future__ import annotations

import os


def hold(path) -> int | None:
    """An exclusive ``flock`` on the recording's file (module docstring): the fd to close when the
    writer is done, None where the lock cannot be taken."""
    try:
        import fcntl

        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
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


def lock_holder(path) -> str | None:
    """Who holds the recording at ``path`` under its lock: ``"recover"`` when a temporary copy of it lies
    beside it (``foveatrack recover`` writing the completed file, :func:`foveatrack.atomic_file.written_whole`;
    a writer never writes beside its recording), ``"writer"`` otherwise, None when nothing holds it."""
    from foveatrack.atomic_file import leftovers

    if not recording_in_use(path):
        return None
    return "recover" if leftovers(path) else "writer"
