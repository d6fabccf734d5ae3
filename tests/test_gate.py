"""The command gate (foveatrack.gate) is one piece that the simulator, replay and the daemon all run.

* the gate itself: a limited or stale command is what leaves, and the tracker's dead reckoning is told;
  a failed write leaves the head (and the reckoning) on the previous command;
* the simulator with a scene [gate] sends what the daemon would, records it as the daemon does
  (``limited``, ``tracker_command``), and the dead reckoning stays on the true head;
* replay of that recording re-enacts the same gate and gives the same commands, to the bit.
"""

from pathlib import Path

import numpy as np
import pytest

from foveatrack.control import STOP, HeadCommand
from foveatrack.gate import STALE_FRAME, CommandGate, Limits
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.replay import replay_recording
from foveatrack.speed_table import TURBO
from sim.loop import ClosedLoop
from sim.recorder import SimRecorder, recording_meta
from sim.scene import load_scene, scene_from_mapping

ROOT = Path(__file__).resolve().parents[1]


class _Out:
    def __init__(self, cmd, tilt=0.0, sigma=0.0):
        self.command, self.head_tilt_deg, self.head_sigma_tilt_deg = cmd, tilt, sigma


class _Tracker:
    def __init__(self):
        self.sent = []

    def command_sent(self, t, cmd):
        self.sent.append((t, cmd))


def test_the_gate_limits_stops_and_remembers_what_the_head_got():
    gate, tr = CommandGate(Limits(max_pan_byte=10, allow_turbo=False, tilt_limits_deg=(-30, 60), tilt_margin_deg=2)), _Tracker()
    cmd, why = gate.decide(tr, _Out(HeadCommand(1, TURBO, 1, 5), tilt=58.5), 1.0)
    assert cmd == HeadCommand(1, 10, 0, 0) and why == ["turbo", "tilt_stop_up"] and tr.sent == [(1.0, cmd)]
    assert gate.wrote(tr, 1.0, cmd, ok=True) == cmd
    # unchanged: the tracker already registered its own command, nothing more is said
    cmd2, why2 = gate.decide(tr, _Out(HeadCommand(-1, 3, 0, 0)), 1.1)
    assert why2 == [] and len(tr.sent) == 1
    # the write failed: the head keeps the previous command and the reckoning is told so, same instant
    assert gate.wrote(tr, 1.1, cmd2, ok=False) == cmd and tr.sent[-1] == (1.1, cmd)
    # a stale frame sends STOP, whatever the tracker wanted
    cmd3, why3 = gate.decide(tr, _Out(HeadCommand(-1, 3, 0, 0)), 1.2, stale=True)
    assert cmd3 == STOP and why3 == [STALE_FRAME] and tr.sent[-1] == (1.2, STOP)
    # without limits the gate passes commands through (a scene without [gate])
    assert CommandGate(None).decide(tr, _Out(HeadCommand(1, TURBO, 1, 63)), 2.0) == (HeadCommand(1, TURBO, 1, 63), [])


def _gated_scene(**gate):
    data = load_scene(ROOT / "scenes" / "fig12-tracking.toml")
    import tomllib

    table = tomllib.loads(Path(data.path).read_text())
    table["scene"]["duration_s"] = 8.0
    table["gate"] = gate
    return scene_from_mapping(table, f"{data.path} (gated)")


def _record(scene, path):
    loop = ClosedLoop(scene)
    with RecordingWriter(path, recording_meta(scene, loop)) as w:
        loop.frame_hook = SimRecorder(w)
        log = loop.run()
    return loop, log


def test_the_simulator_runs_the_daemons_gate_and_replay_re_enacts_it(tmp_path):
    free_loop, free_log = _record(_gated_scene(), tmp_path / "free.mcap")   # [gate] with the defaults
    loop, log = _record(_gated_scene(max_pan_byte=4, max_tilt_byte=2), tmp_path / "gated.mcap")
    cmds = np.array(log["command"])
    assert cmds[:, 1].max() <= 4 and cmds[:, 3].max() <= 2
    assert np.array(free_log["command"])[:, 1].max() > 4          # the limit did bind
    recorded = [r for r in RecordingReader(tmp_path / "gated.mcap").records("commands")]
    limited = [r for r in recorded if r.get("limited")]
    assert limited and all(set(r["limited"]) <= {"pan_speed", "tilt_speed"} for r in limited)
    assert all(r["pan_byte"] <= 4 for r in recorded)
    # the dead reckoning was told what the head got: estimate and truth agree as well as without limits
    err = np.abs(np.array(log["est_pan_deg"]) - np.array(log["head_pan_deg"]))
    free_err = np.abs(np.array(free_log["est_pan_deg"]) - np.array(free_log["head_pan_deg"]))
    assert np.nanmax(err) < max(0.5, 2 * np.nanmax(free_err))
    # replay runs the same gate from the recorded limits: the very commands
    res = replay_recording(tmp_path / "gated.mcap")
    assert res.comparison["commands_equal"] and np.array_equal(res.frames["command"], cmds)


def test_a_stale_frame_in_the_simulator_sends_stop_as_the_daemon_would(tmp_path):
    scene = _gated_scene(stale_frame_s=0.001)     # every command leaves 2 ms after its frame: all stale
    loop, log = _record(scene, tmp_path / "stale.mcap")
    assert all(tuple(c) == (0, 0, 0, 0) for c in log["command"])
    assert np.ptp(log["head_pan_deg"]) == 0.0 and np.ptp(log["head_tilt_deg"]) == 0.0   # the head never moved
    recorded = list(RecordingReader(tmp_path / "stale.mcap").records("commands"))
    assert recorded and all(STALE_FRAME in r["limited"] for r in recorded)
    assert any(r["tracker_command"] != [0, 0, 0, 0] for r in recorded)   # the tracker did want to move


@pytest.mark.parametrize("bad, key", [({"max_pan_byte": 64}, "max_pan_byte"), ({"stale_frame_s": 0}, "stale_frame_s"),
                                      ({"allow_turbo": "yes"}, "allow_turbo"), ({"speed": 1}, "speed")])
def test_gate_table_errors_name_the_key(bad, key):
    from foveatrack.errors import UserError

    with pytest.raises(UserError, match=key):
        _gated_scene(**bad)
