"""What a driver drives: the controller protocol of the driver skeleton (docs/architecture.md).

A controller takes each frame and the time its command will be sent, and returns an output whose
``command`` is the :class:`~foveatrack.control.HeadCommand` to send; the command gate
(:mod:`foveatrack.gate`) may change that command (limits, stale frames) or the link may fail to
deliver it, and then the controller is told what the head really got, at the same instant, with
``command_sent``.  :class:`foveatrack.tracker.Tracker` (Algorithms 1 and 2) and
:class:`foveatrack.calibration.drive.CalibrationDriver` (Appendix D.4) are the two controllers; the
simulator, replay, the daemon and the live calibration drive them the same way.
"""

from __future__ import annotations

from typing import Any, Protocol

from foveatrack.control import HeadCommand
from foveatrack.frames import Frame


class ControllerOutput(Protocol):
    command: HeadCommand


class Controller(Protocol):
    def process(self, frame: Frame, send_t_s: float) -> Any:
        """The output for ``frame`` (its ``command`` is what to send at ``send_t_s``)."""

    def command_sent(self, t_s: float, cmd: HeadCommand) -> None:
        """The head got ``cmd`` at ``t_s`` (replacing any command registered at that instant)."""
