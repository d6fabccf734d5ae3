"""Ctrl-C and SIGTERM as a request to stop, for the commands that drive a head (the calibrations)."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def stop_on_signals():
    """Yield an event that SIGINT and SIGTERM set (instead of raising), so the run stops the head and
    ends through its own path; the previous handlers come back on exit."""
    stop = threading.Event()
    old = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
