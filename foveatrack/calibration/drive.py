"""Driving the calibration procedure from any frame source and command sink (paper Appendix D.4).

:class:`CalibrationDriver` adapts a :class:`~foveatrack.calibration.Calibrator` to the simulator's
``controller(frame, send_t_s)`` hook; :func:`drive_calibration` runs it over any iterable of frames
with any command sink, so a real lidar + head driver reuses the same procedure.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from foveatrack.calibration import Calibrator
from foveatrack.control import STOP, HeadCommand
from foveatrack.frames import Frame


class CalibrationDriver:
    """Adapter from a :class:`Calibrator` to a loop that sends one command per frame.

    ``driver(frame, send_t_s) -> HeadCommand``: feeds the frame to the calibrator and returns the
    command to send now.  The calibrator's ``None`` ("keep the current command") is turned into the
    latched command, and a finished calibration always gives STOP, so a driver that re-sends every
    frame (the closed-loop simulator, a Pelco-D keep-alive) and one that sends only changes both
    work.  ``sent`` lists ``(send_t_s, command)`` at every change.  This is the ``controller`` of
    ``sim.loop.ClosedLoop``.
    """

    def __init__(self, calibrator: Calibrator):
        self.calibrator = calibrator
        self.current: HeadCommand = STOP
        self.sent: list[tuple[float, HeadCommand]] = []

    @property
    def finished(self) -> bool:
        return self.calibrator.done

    def __call__(self, frame: Frame, send_t_s: float) -> HeadCommand:
        cmd = self.calibrator.step(frame)
        if self.calibrator.done:
            cmd = STOP
        if cmd is not None and cmd != self.current:
            self.current = cmd
            self.sent.append((send_t_s, cmd))
        return self.current


def drive_calibration(calibrator: Calibrator, frames: Iterable[Frame], send: Callable[[float, HeadCommand], None],
                      send_delay_s: float = 0.0) -> CalibrationDriver:
    """Run a calibration from any frame source into any command sink (a real lidar + head, a replay).

    ``frames`` yields consecutive frames (e.g. :class:`foveatrack.frames.FrameSlicer` over a live
    Livox stream); ``send(t_s, command)`` writes the command (e.g. Pelco-D to the head's port) and
    is called once per frame.  Stops consuming frames when the calibration is done (after sending a
    final STOP).  Returns the driver (``driver.calibrator.result()`` is the table).
    """
    driver = CalibrationDriver(calibrator)
    for frame in frames:
        t = frame.t_end_s + send_delay_s
        send(t, driver(frame, t))
        if driver.finished:
            break
    return driver


# ---------------------------------------------------------------------------------------------------
