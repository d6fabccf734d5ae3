"""Every driver runs its frames through the one step (foveatrack/frame_step.py), read from the sources.

A driver that calls the controller (``process``, ``command_sent``, ``on_imu``) or the gate (``decide``,
``wrote``, ``Limits.apply``) itself has written the frame loop again, and its safety rules drift from
the others' (issue 25: the live IMU calibration skipped the gate, LVX replay ran none, the daemon and
the simulator decided some STOPs outside it).  Every module of ``foveatrack``, ``sim`` and ``scripts``
is parsed and every such call, at any depth, is an error -- except in the step and the gate
themselves, inside a class that is a controller (it defines ``process`` and ``command_sent``: a
tracker, an adapter that wraps one), and in the modules listed below with their reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("foveatrack", "sim", "scripts")

CONTROLLER_CALLS = {"process", "command_sent", "on_imu"}
GATE_CALLS = {"decide", "wrote"}

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
