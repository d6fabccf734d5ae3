"""An output that stops at its first failed write instead of raising it.

The daemon writes its command journal, its JSON log and its warnings from the control loop's tick.
On a full disk (ENOSPC), or a closed pipe, a write that raised there ended the loop, and the
shutdown's STOP died on the same write before it reached the head.  Such an output keeps its first
failure in ``error``, writes nothing after it (counting the writes lost in ``lost``), and the driver
says the failure once (``foveatrack.daemon.record_queue``).
"""

from __future__ import annotations


class StopsAtFirstFailure:
    """A mixin for an output: :meth:`_guarded` runs a write unless an earlier one failed."""

    error: OSError | None = None     # the write that failed; nothing is written after it
    lost: int = 0                    # writes not made since (the failed one among them)

    def _guarded(self, write, *args) -> bool:
        """``write(*args)``; False, without raising, where it fails or an earlier one did."""
        if self.error is not None:
            self.lost += 1
            return False
        try:
            write(*args)
        except OSError as exc:
            self.error = exc
            self.lost += 1
            return False
        return True


def close_quietly(fh) -> None:
    """Close a file whose buffered line failed: the close writes it again and fails again, and the
    failure is said already (``StopsAtFirstFailure.error``)."""
    try:
        fh.close()
    except OSError:
        pass
