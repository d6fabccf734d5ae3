"""Every driver runs its frames through the one step (foveatrack/frame_step.py), read from the sources.

A driver that calls the controller (``process``, ``command_sent``, ``on_imu``) or the gate (``decide``,
``wrote``, ``Limits.apply``) itself has written the frame loop again, and its safety rules drift from
the others' (issue 25: the live IMU calibration skipped the gate, LVX replay ran none, the daemon and
the simulator decided some STOPs outside it).  Every module of ``foveatrack``, ``sim`` and ``scripts``
is parsed and every such call, at any depth, is an error -- except in the step and the gate
themselves, inside a class that is a controller (it defines ``process`` and ``command_sent``: a
tracker, an adapter that wraps one), and in the modules listed below with their reason.

Absolute goals too (the daemon's homing: Pelco set-pan / set-tilt): before, the homing encoded and
wrote them itself and clamped its own tilt goal, a second tilt rule beside the gate's (issue 26).  A
goal is now decided by the gate (``decide_goal``) in :meth:`FrameStep.own_goal` and written by a sink's
``send_goal``; encoding an absolute set is the daemon's sink's alone.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("foveatrack", "sim", "scripts")

CONTROLLER_CALLS = {"process", "command_sent", "on_imu"}
GATE_CALLS = {"decide", "wrote", "decide_goal", "wrote_goal", "clamp_tilt_goal", "send_goal"}
# encoding an absolute move: only in the sink that writes the goal the gate decided
ABSOLUTE_CALLS = {"encode_set_pan", "encode_set_tilt", "encode_set_pan_word", "encode_set_tilt_word"}
ABSOLUTE_ALLOWED = {("foveatrack/daemon/frame_loop.py", "send_goal")}

# module -> why it may call them
ALLOWED = {
    "foveatrack/frame_step.py": "the one step",
    "foveatrack/gate.py": "the gate tells the controller what reached the head",
    "foveatrack/openloop/run.py": "the open-loop tracker (a fixed sensor) drives no head: no gate, no sink, "
                                  "and its process(frame) is not the Controller protocol",
}


def _is_limits_apply(call: ast.Call) -> bool:
    f = call.func
    return (isinstance(f, ast.Attribute) and f.attr == "apply"
            and "limit" in ast.unparse(f.value).lower())


def _controller_classes(tree: ast.AST) -> set[int]:
    """ids of the nodes inside classes that define both ``process`` and ``command_sent``."""
    inside = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            names = {n.name for n in node.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
            if {"process", "command_sent"} <= names:
                inside.update(id(n) for n in ast.walk(node))
    return inside


def step_bypasses(source: str, name: str = "<source>") -> list[str]:
    """Calls of the controller or the gate outside the step in ``source``: ``"name:line: call"``."""
    tree = ast.parse(source, name)
    exempt = _controller_classes(tree)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or id(node) in exempt:
            continue
        f = node.func
        if isinstance(f, ast.Attribute) and (f.attr in CONTROLLER_CALLS | GATE_CALLS) or _is_limits_apply(node):
            found.append((node.lineno, f"{name}:{node.lineno}: {ast.unparse(f)}(...)"))
    return [f for _, f in sorted(found)]


def absolute_moves(source: str, name: str = "<source>") -> list[str]:
    """Absolute moves encoded in ``source`` outside the allowed sink functions: ``"name:line: call"``."""
    tree = ast.parse(source, name)
    allowed = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and (name, node.name) in ABSOLUTE_ALLOWED:
            allowed.update(id(n) for n in ast.walk(node))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and id(node) not in allowed:
            f = node.func
            callee = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if callee in ABSOLUTE_CALLS:
                found.append((node.lineno, f"{name}:{node.lineno}: {ast.unparse(f)}(...)"))
    return [f for _, f in sorted(found)]


def _modules():
    for top in SCANNED:
        for p in sorted((ROOT / top).rglob("*.py")):
            rel = p.relative_to(ROOT).as_posix()
            if ".venv" in p.parts or "__pycache__" in p.parts:
                continue
            yield rel, p


def test_no_driver_calls_the_controller_or_the_gate_but_through_the_step():
    found = []
    for rel, p in _modules():
        if rel in ALLOWED:
            continue
        found += step_bypasses(p.read_text(encoding="utf-8"), rel)
    assert not found, ("these call the controller or the gate themselves; run the frame through "
                       "foveatrack.frame_step.FrameStep (or own_command for a driver's own STOP):\n  "
                       + "\n  ".join(found))


def test_the_drivers_are_scanned_and_run_the_step():
    """The rule sees the drivers of issue 25, and each of them builds the one step."""
    mods = {rel for rel, _ in _modules()}
    drivers = ["sim/loop.py", "foveatrack/replay/driver.py", "foveatrack/daemon/runtime.py",
               "foveatrack/calibration/drive.py", "foveatrack/imu_calib/live.py", "scripts/bench_daemon_frame.py",
               "scripts/bench_tracker.py"]
    for d in drivers:
        assert d in mods, d
        assert "FrameStep(" in (ROOT / d).read_text(encoding="utf-8"), f"{d} does not build the frame step"


def test_a_planted_call_is_found_at_any_depth():
    """What the rule catches: a lazy call in a nested function, the gate's limits applied by hand, and
    not the same calls inside a controller class."""
    planted = '''
def drive(tracker, gate, frame):
    def inner():
        out = tracker.process(frame, 0.1)
        return gate.decide(tracker, out, 0.1)
    cmd, why = gate.limits.apply(None, 0.0)
    return inner()

class Wrapper:
    def process(self, frame, send_t_s):
        return self.inner.process(frame, send_t_s)
    def command_sent(self, t_s, cmd):
        self.inner.command_sent(t_s, cmd)
'''
    found = step_bypasses(planted, "planted.py")
    assert [f.split(": ")[1] for f in found] == ["tracker.process(...)", "gate.decide(...)",
                                                 "gate.limits.apply(...)"], found


def test_absolute_goals_leave_only_through_the_step_and_the_gate():
    """The daemon's homing writes its set-pan / set-tilt through FrameStep.own_goal: nothing else in
    foveatrack, sim or scripts encodes an absolute move, and the homing asks the step for it."""
    found = []
    for rel, p in _modules():
        found += absolute_moves(p.read_text(encoding="utf-8"), rel)
    assert not found, ("these encode an absolute move themselves; write it through "
                       "foveatrack.frame_step.FrameStep.own_goal (the gate decides it):\n  " + "\n  ".join(found))
    assert "self.step.own_goal(" in (ROOT / "foveatrack/daemon/head_pose.py").read_text(encoding="utf-8")
    planted = """
from gimbal.pelco import encode_set_tilt
def home(head):
    head.send_raw(encode_set_tilt(1, 80.0, "pelco-d", "zenith"), "homing")
    gate.decide_goal("tilt", 80.0)
"""
    assert absolute_moves(planted, "planted.py") == ["planted.py:4: encode_set_tilt(...)"]
    assert step_bypasses(planted, "planted.py") == ["planted.py:5: gate.decide_goal(...)"]
