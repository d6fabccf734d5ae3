"""Freed frame memory handed back to the system (glibc), so a daemon's RSS follows what it holds.

glibc serves an allocation of at least ``M_MMAP_THRESHOLD`` (128 kB at start) with its own mapping,
returned to the system when freed -- but it raises that threshold to the size of each such block
freed (up to 32 MB), so after the first frames a frame's arrays (48 k points at 480 k points/s:
1.2 MB of x, y, z alone) come from the heap, and what a backlog freed stays there: the daemon's RSS
rose in steps at every load spike and never came down (issue 26's soak: +31 MB an hour after the
first 5 minutes, load 2-4).  A fixed threshold (``mallopt``) turns that adaptation off: every block of
128 kB or more is mapped and unmapped, so freed frames leave the process at once
(tests/daemon/test_heap.py shows the difference on 8 MB and 1.2 MB arrays).  The price is a fresh
mapping's page faults for each large array, paid on the frame's own thread.
"""

from __future__ import annotations

M_MMAP_THRESHOLD = -3          # glibc's malloc.h
MMAP_THRESHOLD_BYTES = 128 * 1024


def _glibc(name: str, *argtypes):
    """The C library's function ``name`` with its argument types, or None where there is none (not
    glibc)."""
    import ctypes
    import ctypes.util

    try:
        fn = getattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), name)
    except (OSError, AttributeError):
        return None
    fn.argtypes = list(argtypes)
    fn.restype = ctypes.c_int
    return fn


def return_freed_memory(threshold_bytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold at ``threshold_bytes`` for this process; whether it was set (False
    where the C library is not glibc: nothing changes there)."""
    import ctypes

    mallopt = _glibc("mallopt", ctypes.c_int, ctypes.c_int)
    return mallopt is not None and mallopt(M_MMAP_THRESHOLD, int(threshold_bytes)) == 1


def trim_freed_memory() -> bool:
    """Hand the free pages inside glibc's heaps back to the system (``malloc_trim(0)``: the top of each
    heap and whole free pages inside it, by ``madvise``); whether anything was released.  Where the C
    library is not glibc, nothing (False).

    The daemon trims once a recording segment is closed, on the recording's thread: the MCAP writer
    frees a segment's index (~250 B a frame) at its close, and the holes it leaves between live blocks
    stayed resident, a heap that settled ~1 MB higher over the first three or four segments (issue 26's
    hour: +1.07 MB/hour after minute 5).  Once a minute from the loop's tick it cost the latency
    (docs/daemon.md: the re-faulted pages are paid by later frames); once a segment it is ~1/5 of that."""
    import ctypes

    malloc_trim = _glibc("malloc_trim", ctypes.c_size_t)
    return malloc_trim is not None and malloc_trim(0) == 1
