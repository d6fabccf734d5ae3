"""The head's facts are declared once (issue 25): the tilt stops, the limits, the turbo byte and the
link latency have one default each, in gimbal/head_facts.py, and every configuration is built from it.

Before: the stops were written four times (gate, tracker, daemon config, the PTS-303 family), the
latency 7.29 ms by hand in the tracker, the turbo byte twice, and the limit fields three times with
different defaults (a scene's [gate] allowed turbo, a daemon's [head] and the gate did not).
"""

import ast
from pathlib import Path

from foveatrack.device_config import HeadConfig
from foveatrack.gate import Limits
from foveatrack.speed_table import TURBO
from foveatrack.tracker import TrackerConfig
from gimbal.head_facts import DEFAULT_HEAD, HeadFacts
from gimbal.pelco import PAN_TURBO, frame_time_s
from gimbal.pts303h import HeadParams
from sim.scene import GateSpec

ROOT = Path(__file__).resolve().parents[1]
LIMIT_FIELDS = ("max_pan_byte", "max_tilt_byte", "allow_turbo", "tilt_margin_deg")


def test_every_configuration_takes_its_defaults_from_the_head_facts():
    assert Limits() == Limits.of(DEFAULT_HEAD)
    head = HeadConfig(port="/dev/null")
    assert head.facts == DEFAULT_HEAD and head.limits == Limits.of(DEFAULT_HEAD)
    gate = GateSpec()
    assert all(getattr(gate, k) == getattr(DEFAULT_HEAD, k) for k in LIMIT_FIELDS)
    assert gate.allow_turbo is False          # was True: now one default, the daemon's
    cfg = TrackerConfig()
    assert cfg.tilt_limits_deg == DEFAULT_HEAD.tilt_limits_deg and cfg.latency_s == DEFAULT_HEAD.frame_time_s
    assert DEFAULT_HEAD.frame_time_s == frame_time_s("D", 9600)     # 7.29 ms: a Pelco-D frame at 9600 baud
    p = HeadParams()
    assert (p.tilt_min_deg, p.tilt_max_deg) == DEFAULT_HEAD.tilt_limits_deg
    assert TURBO == PAN_TURBO == 0xFF
    # a head's own facts carry through to the gate
    facts = HeadFacts((-10.0, 40.0), max_pan_byte=20, allow_turbo=True, tilt_margin_deg=5.0)
    assert Limits.of(facts) == Limits(20, 63, True, (-10.0, 40.0), 5.0)


def _literals(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.Tuple) and all(isinstance(e, ast.Constant) for e in node.elts):
            yield tuple(e.value for e in node.elts)
        elif isinstance(node, ast.Constant) and isinstance(node.value, float):
            yield node.value


def test_no_module_declares_a_head_fact_again():
    # the stops as a literal pair, and the hand-written latency, appear nowhere but in head_facts.py
    bad = []
    for pkg in ("foveatrack", "gimbal", "sim"):
        for path in (ROOT / pkg).rglob("*.py"):
            if path.name == "head_facts.py":
                continue
            for lit in _literals(ast.parse(path.read_text())):
                if lit in ((-30.0, 60.0), (-30, 60), 0.00729):
                    bad.append(f"{path.relative_to(ROOT)}: {lit!r}")
    assert not bad, bad
