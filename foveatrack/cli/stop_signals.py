"""Ctrl-C and SIGTERM as a request to stop: for the commands that drive a head (the calibrations), and a
Ctrl-C that is not lost for the long runs (``simulate``)."""

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


class _Latch:
    interrupted = False


def _interrupt(signum, frame):
    _Latch.interrupted = True
    raise KeyboardInterrupt


@contextmanager
def interrupts_remembered():
    """A Ctrl-C raises KeyboardInterrupt at once, as Python's own handler does, and is also
    remembered, so that :func:`raise_if_interrupted` raises it again where the first one was lost.

    Python runs a signal's handler in whatever Python code runs at that moment, also in a weakref
    callback or a ``__del__`` run by the garbage collector, where an exception is printed
    ("Exception ignored in ...") and dropped, and code that catches it can drop it silently: the
    Ctrl-C is then lost and the run goes on (docs/interrupts.md; ``simulate --duration 3000`` went on
    for its 3000 s).  Only where Python's
    own handler is in place (not in a thread, not under another handler)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    _Latch.interrupted = False
    signal.signal(signal.SIGINT, _interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _Latch.interrupted = False


def raise_if_interrupted() -> None:
    """Raise KeyboardInterrupt if a Ctrl-C came (and was lost on its way): for long loops, once per step."""
    if _Latch.interrupted:
        raise KeyboardInterrupt
