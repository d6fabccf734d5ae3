"""One frame's step, the middle of every driver (docs/architecture.md, "The driver skeleton").

Every driver -- the simulator, replay (a recording or an LVX file), the daemon, the speed-table
calibration, the live IMU calibration and the benchmarks -- is a frame source, a clock policy (when
the command is sent) and a command sink around this one step::

    frame, send time --> controller.process --> CommandGate.decide --> sink.send --> CommandGate.wrote
                         (Tracker: Alg. 1 + 2,  (limits, tilt stops,   (virtual UART,  (a failed write: the
                          a calibration driver)  stale frame, driver    serial port,    head keeps its last
                                                 reasons to STOP)       nothing)        command; the
                                                                                        controller is told)

and returns one typed :class:`StepRecord`.  Whenever the gate or the sink changes what reaches the
head, the controller (the tracker's dead reckoning) is told at the same instant, here and only here:
no driver calls the controller or the gate itself (``tests/test_frame_step_rule.py`` reads the
sources).  The driver's own commands (a watchdog's or a shutdown's STOP, one before a new sensor
clock) go through :meth:`FrameStep.own_command`, the same way to the head, and so do its absolute
goals (the daemon's homing, Pelco set-pan / set-tilt) through :meth:`FrameStep.own_goal`: the gate
keeps a tilt goal inside the stops as it keeps a speed command, and says why it moved it.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

from foveatrack.control import STOP, HeadCommand
from foveatrack.frames import Frame
from foveatrack.gate import CommandGate


class FrameSource(Protocol):
    """Where frames come from: the scene's sensor, a recording, an LVX file, a live Livox stream."""

    def __iter__(self) -> Iterator[Frame]:
        ...


class CommandSink(Protocol):
    """Where a command goes: the virtual UART, a serial port, or nowhere (replay, a frozen head).

    A sink may also define ``head_ran(cmd) -> HeadCommand | None``, asked after each write: the
    command the head ran instead of ``cmd`` (None: the write's outcome says it all).  A replay under
    another configuration has it: the recorded points were seen while the head ran the recorded
    commands, and the dead reckoning must follow those, not the replayed tracker's."""

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        """Write ``cmd`` at ``send_t_s`` (the controller's clock); True when the head got it, False when
        it did not (the head keeps running its last command).  ``source``: who sent it ("tracker", or
        a driver's own reason: "watchdog", "shutdown", ...)."""
        ...


class GoalSink(Protocol):
    """A sink that can also write absolute goals (the daemon's serial port)."""

    def send_goal(self, axis: str, goal_deg: float, source: str) -> bool:
        """Write the absolute move of ``axis`` ("pan" or "tilt") to ``goal_deg``; True when the head
        got it."""
        ...


class NoHead:
    """The sink of a head that gets nothing (a frozen head, an LVX replay): every write fails, so the
    controller is told the head kept its last command (STOP, as it started)."""

    def send(self, cmd: HeadCommand, send_t_s: float, source: str) -> bool:
        return False


@dataclass(frozen=True)
class StepRecord:
    """What one step did.

    output : the controller's output for the frame (None for a driver's own command)
    proposed : the controller's command (before the gate)
    command : the command written to the sink (after the gate)
    limited : why the gate changed it (empty: unchanged)
    reached_head : the sink's word: the head got ``command``
    head_command : what the head runs after the step (``command``, or its last one)
    """

    send_t_s: float
    output: Any
    proposed: HeadCommand
    command: HeadCommand
    limited: tuple[str, ...]
    reached_head: bool
    head_command: HeadCommand


@dataclass(frozen=True)
class GoalRecord:
    """What one absolute goal did (:meth:`FrameStep.own_goal`).

    axis : "pan" or "tilt"; asked_deg : the driver's goal; goal_deg : the goal written (after the gate;
    None: refused, nothing written); limited : why the gate changed it; reached_head : the sink's word
    """

    axis: str
    asked_deg: float
    goal_deg: float | None
    limited: tuple[str, ...]
    reached_head: bool


class FrameStep:
    """controller -> gate -> sink -> the controller told what reached the head (module docstring).

    controller : :class:`foveatrack.controller.Controller` (replace it with :meth:`rebase` where the
        driver starts a fresh one: a new sensor clock, a homed head)
    gate : the driver's :class:`CommandGate`
    sink : :class:`CommandSink`
    source : the name the sink is given for the controller's commands
    stop_on_change : a driver whose controller must not be overridden (a calibration times its legs
        from its own commands): when the gate changes a command, STOP is written instead and the
        record says why; the driver ends the run.
    """

    def __init__(self, controller, gate: CommandGate, sink: CommandSink, source: str = "tracker",
                 stop_on_change: bool = False):
        self.controller = controller
        self.gate = gate
        self.sink = sink
        self.source = source
        self.stop_on_change = stop_on_change

    def __call__(self, frame: Frame | None, send_t_s: float, *, imu: Iterable | None = None, stale: bool = False,
                 stop_why: tuple[str, ...] = ()) -> StepRecord:
        """Step ``frame`` whose command is sent at ``send_t_s``.

        imu : ``(t_s, gyro_rad_s)`` batches of the lidar's gyro up to the frame, fed to the controller
            first (a tracker with ``attitude = "gyro"``), as the driver received them
        stale : the frame was too old when processed (the driver's clock judges): STOP is sent
        stop_why : the driver's other reasons to send STOP instead (the daemon's head link is down)
        ``frame`` None: a controller that steers by time alone (the live IMU calibration's moves)."""
        c = self.controller
        if imu is not None:
            for t_s, gyro in imu:
                c.on_imu(t_s, gyro)
        out = c.process(frame, send_t_s)
        cmd, why = self.gate.decide(c, out, send_t_s, stale=stale, stop_why=stop_why)
        if why and self.stop_on_change and not cmd.is_stop:
            cmd = STOP
            c.command_sent(send_t_s, cmd)
        ok = self.sink.send(cmd, send_t_s, self.source)
        head = self.gate.wrote(c, send_t_s, cmd, ok, self._ran_instead(cmd))
        return StepRecord(send_t_s, out, out.command, cmd, tuple(why), bool(ok), head)

    def own_command(self, send_t_s: float, cmd: HeadCommand, source: str) -> StepRecord:
        """A command of the driver's own (a watchdog's or a shutdown's STOP), told to the controller,
        written and accounted for as the controller's are."""
        self.controller.command_sent(send_t_s, cmd)
        ok = self.sink.send(cmd, send_t_s, source)
        head = self.gate.wrote(self.controller, send_t_s, cmd, ok, self._ran_instead(cmd))
        return StepRecord(send_t_s, None, cmd, cmd, (), bool(ok), head)

    def _ran_instead(self, cmd: HeadCommand) -> HeadCommand | None:
        """The sink's word on a command the head ran instead of ``cmd`` (:class:`CommandSink`)."""
        head_ran = getattr(self.sink, "head_ran", None)
        return None if head_ran is None else head_ran(cmd)

    def own_goal(self, axis: str, goal_deg: float, source: str) -> GoalRecord:
        """An absolute goal of the driver's own (the daemon's homing): decided by the gate, written by
        the sink (``send_goal``).  The controller is not told: a driver homes a head whose pose is
        unknown, and starts a fresh controller at the goals written (:meth:`rebase`)."""
        goal, why = self.gate.decide_goal(axis, goal_deg)
        ok = goal is not None and bool(self.sink.send_goal(axis, goal, source))
        self.gate.wrote_goal(ok)
        return GoalRecord(axis, float(goal_deg), goal, tuple(why), ok)

    def rebase(self, controller) -> None:
        """A fresh controller (its dead reckoning restarted) for a head that is stopped."""
        self.controller = controller
        self.gate.head_cmd = STOP
