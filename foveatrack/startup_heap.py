"""The heap a long run starts with, set aside from Python's cyclic garbage collector.

A run imports numpy, scipy, numba and the product (~85 000 objects in the daemon, ~170 000 in the
simulator) and keeps them to the end; a full collection walks every one of them.  It runs whenever
the objects kept since the last one reach a quarter of those (a daemon's records, a run's log):
~19 ms for the daemon's ~85 000 (measured, 2026-12-07), a stall inside the 100 ms frame whose p99
target is 10 ms; and in the simulator the collector took 0.13 ms of a ~1.1 ms frame (three 60 s
runs of the swarm with the flock, ``gc.callbacks`` timed), 0.057 ms with the startup heap frozen.

:func:`freeze_startup_heap` collects once and then freezes (``gc.freeze``) what is alive, once per
process.  ``sim.loop.ClosedLoop`` and the daemon call it from ``__new__``, before the instance exists:
the collector takes a frozen object for a reference from outside, so a cycle through one -- the
loop and its link to the head hold each other -- would keep every object on it, and all they hold,
until the process ends (a review found the first loop of a process kept so: ~34 MB and its logs).
Frozen objects are still freed by reference counting when dropped; what was alive at the call and
sits on a cycle stays.  The numbers a run computes do not depend on when the collector runs.  (What
the allocator gives back to the system is :mod:`foveatrack.daemon.heap`'s.)

Numba fills its CPU typing and target contexts (~48 000 objects, ~0.18 s) when the first kernel is
called, which came after the freeze: every full collection walked them (~15-24 ms each, one in a
60 s sky run alone in its process).  They are filled before the freeze now, once per process as
before.  (The first full collection comes later then: Python waits for a quarter of what its last
one kept, the frozen heap included; in a process that runs loop after loop it frees more dropped
loops at once: 35-47 ms, once in three 60 s runs, where it was 14-25 ms in the first.)
"""

from __future__ import annotations

import gc
import sys

_frozen = False


def freeze_startup_heap() -> None:
    """Collect, then freeze every object alive now (module docstring); a second call does nothing."""
    global _frozen
    if _frozen:
        return
    _frozen = True
    if "numba" in sys.modules:     # its contexts as its first kernel call fills them (module docstring)
        from numba.core.registry import cpu_target
        cpu_target.typing_context.refresh()
        cpu_target.target_context.refresh()
    gc.collect()
    gc.freeze()
