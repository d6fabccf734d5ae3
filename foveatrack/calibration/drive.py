"""Driving the calibration procedure from any frame source and command sink (paper Appendix D.4).

:class:`CalibrationDriver` adapts a :class:`~foveatrack.calibration.Calibrator` to the simulator's
``controller(frame, send_t_s)`` hook; :func:`drive_calibration` runs it over any iterable of frames
with any command sink, so a real lidar + head driver reuses the same procedure.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from foveatrack.calibration import Calibrator
from foveatrack.calibration.procedure import TILT_UNSEEN_MAX_S
from foveatrack.control import STOP, HeadCommand
from foveatrack.errors import UserError
from foveatrack.frame_step import FrameSource, FrameStep
from foveatrack.frames import Frame
from foveatrack.gate import CommandGate


@dataclass(frozen=True)
class CalibrationOutput:
    """What a driver records for a frame driven by the calibration procedure (no tracking state)."""

    command: HeadCommand
    detection: object = None
    state: str = "calibrating"
    head_pan_deg: float = math.nan
    head_tilt_deg: float = math.nan
    head_sigma_pan_deg: float = math.nan
    head_sigma_tilt_deg: float = math.nan
    world_xyz: object = None
    world_sigma_m: float = math.nan
    error_pan_deg: float | None = None
    error_tilt_deg: float | None = None


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
        self.overridden: list[tuple[float, HeadCommand]] = []   # (t, what the head got instead)

    @property
    def finished(self) -> bool:
        return self.calibrator.done

    def process(self, frame: Frame, send_t_s: float) -> "CalibrationOutput":
        """The :class:`foveatrack.controller.Controller` step: this frame's command to send, with the
        head's tilt as the procedure sees it (the start tilt plus the corner's turn about the tilt
        axis; :meth:`Calibrator.tilt_since_start_deg`), which the command gate keeps from the stops.
        The start tilt is the plan's, or the one the corner data imply once they contradict the plan's
        (:meth:`Calibrator.start_tilt_deg`)."""
        cmd = self(frame, send_t_s)
        cal = self.calibrator
        if not hasattr(cal, "tilt_since_start_deg"):
            return CalibrationOutput(cmd)     # a procedure that cannot tell its tilt: NaN, the gate refuses tilt
        off_deg, off_sigma_deg, t_seen = cal.tilt_since_start_deg(frame.t_end_s)
        if t_seen is not None and self._tilt_driven_s(t_seen, frame.t_end_s) > TILT_UNSEEN_MAX_S:
            off_deg = off_sigma_deg = math.nan     # tilted too long unseen: the gate refuses more tilt
        start_deg, start_sigma_deg, _ = cal.start_tilt_deg()
        return CalibrationOutput(cmd, head_tilt_deg=start_deg + off_deg,
                                 head_sigma_tilt_deg=math.hypot(start_sigma_deg, off_sigma_deg))

    def _tilt_driven_s(self, since_s: float, now_s: float) -> float:
        """How long the procedure's commands drove the tilt between ``since_s`` and ``now_s`` [s]."""
        total = 0.0
        for k in range(len(self.sent) - 1, -1, -1):
            t, cmd = self.sent[k]
            t_next = self.sent[k + 1][0] if k + 1 < len(self.sent) else now_s
            if t_next <= since_s:
                break
            if cmd.tilt_dir:
                total += max(0.0, min(t_next, now_s) - max(t, since_s))
        return total

    def refuse_limited(self, why: list[str], out: "CalibrationOutput") -> None:
        """The command gate changed one of the procedure's commands (``why`` non-empty): the leg under
        way would be timed wrong and its speed measured wrong, so the run ends with an error (the
        driver stops the head).  The plan's speed bytes are cut to the limits beforehand, so this is a
        tilt stop, an unknown tilt or a stale frame."""
        if why:
            done = sum(1 for leg in self.calibrator.legs if leg.t_stop_s is not None)
            # the user's tilt0_deg may not be what the stops were counted from: say so
            start_deg, _, from_data = self.calibrator.start_tilt_deg()
            t0 = self.calibrator.plan.start_tilt_deg
            if from_data and not math.isfinite(start_deg):
                # the short legs' test is weak (a right tilt0_deg failed it in 1 of 7 simulated tall-room
                # runs): the second way out is for that user
                where = (f"with the tilt unknown (the pan legs' corner data contradict tilt0_deg {t0:g} but are too "
                         "short to tell the start tilt: measure it and set tilt0_deg, or, if it is right, give the "
                         "pan legs more room (max_excursion_deg, the corner farther from the pan axis) so that "
                         "their arcs show the axis)")
            elif not math.isfinite(out.head_tilt_deg):
                where = f"with the tilt unknown (the corner out of sight over {TILT_UNSEEN_MAX_S:g} s of tilt motion)"
            else:
                where = f"at estimated tilt {out.head_tilt_deg:.1f} +- {out.head_sigma_tilt_deg:.1f} deg"
                if from_data:
                    where += (f" (counted from the start tilt the pan legs' corner data imply, {start_deg:.1f} deg: "
                              f"they contradict tilt0_deg {t0:g})")
            if from_data and not math.isfinite(start_deg):
                # neither the limits nor the sight were the cause, and "a smaller max_excursion_deg" would
                # contradict the advice above
                raise UserError(f"the command gate refused the calibration's command ({', '.join(why)}) {where} "
                                f"after {done} legs: no table was written")
            raise UserError(f"the command gate refused the calibration's command ({', '.join(why)}) {where} after "
                            f"{done} legs: the plan would take the head past its limits, or out of the lidar's "
                            "sight of it; start it farther from its tilt stop (or with a smaller max_excursion_deg); "
                            "no table was written")

    def command_sent(self, t_s: float, cmd: HeadCommand) -> None:
        """The gate or the link changed a command: the procedure times its legs from its own commands
        (its plan is cut to the limits beforehand), so a change is recorded, not integrated."""
        self.overridden.append((t_s, cmd))

    def __call__(self, frame: Frame, send_t_s: float) -> HeadCommand:
        cmd = self.calibrator.step(frame)
        if self.calibrator.done:
            cmd = STOP
        if cmd is not None and cmd != self.current:
            self.current = cmd
            self.sent.append((send_t_s, cmd))
        return self.current


class _CallSink:
    """A command sink from a function ``send(t_s, command)`` (returns nothing: written; or the head's ok)."""

    def __init__(self, send: Callable[[float, HeadCommand], object]):
        self.fn = send

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        ok = self.fn(send_t_s, cmd)
        return True if ok is None else bool(ok)


def drive_calibration(calibrator: Calibrator, frames: FrameSource, send, send_delay_s: float = 0.0,
                      gate=None) -> CalibrationDriver:
    """Run a calibration from any frame source into any command sink (a real lidar + head, a replay).

    ``frames`` yields consecutive frames (e.g. :class:`foveatrack.frames.FrameSlicer` over a live
    Livox stream); ``send`` is a :class:`foveatrack.frame_step.CommandSink` or a function
    ``send(t_s, command)`` that writes the command (e.g. Pelco-D to the head's port); it is called
    once per frame, through the one frame step (:class:`foveatrack.frame_step.FrameStep`).  ``gate``:
    the :class:`foveatrack.gate.CommandGate` every command passes on its way (the daemon's limits on a
    real head; None: commands pass unchanged); a command it changes is replaced by STOP and ends the
    run with an error (:meth:`CalibrationDriver.refuse_limited`).  Stops consuming frames when the
    calibration is done (after sending a final STOP).  Returns the driver
    (``driver.calibrator.result()`` is the table).
    """
    driver = CalibrationDriver(calibrator)
    sink = send if hasattr(send, "send") else _CallSink(send)
    step = FrameStep(driver, gate if gate is not None else CommandGate(None), sink, source="calibration",
                     stop_on_change=True)
    for frame in frames:
        rec = step(frame, frame.t_end_s + send_delay_s)
        driver.refuse_limited(list(rec.limited), rec.output)
        if driver.finished:
            break
    return driver
