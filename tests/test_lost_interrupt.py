"""A Ctrl-C that Python drops on its way still stops ``foveatrack simulate`` (docs/interrupts.md).

Python runs a signal's handler in whatever Python code runs at that moment, also in a ``__del__`` or
a weakref callback run by the garbage collector; the KeyboardInterrupt raised there is printed
("Exception ignored in ...") and dropped.  A stressed run showed it (importlib's module-lock weakref
callback): ``simulate --duration 3000`` went on as if no Ctrl-C had come.  Here the SIGINT is raised
inside a ``__del__`` in the middle of a run, the way the garbage collector would have it land.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest

from foveatrack.cli import main
from foveatrack.recording import RecordingReader

ROOT = Path(__file__).resolve().parents[1]


class _SigintWhenCollected:
    def __del__(self):
        signal.raise_signal(signal.SIGINT)     # its handler runs here, inside __del__: the exception is dropped


@pytest.mark.parametrize("cores", ["--second-core", "--one-thread"])
def test_a_ctrl_c_lost_in_a_del_still_stops_simulate(tmp_path, monkeypatch, capsys, cores):
    from sim import recorder

    real_call = recorder.SimRecorder.__call__
    calls = []

    def call(self, frame, out, loop):
        real_call(self, frame, out, loop)
        calls.append(1)
        if len(calls) == 5:
            _SigintWhenCollected()          # dropped at once: its __del__ runs now

    monkeypatch.setattr(recorder.SimRecorder, "__call__", call)
    dropped = []        # what Python reports as "Exception ignored in ..."
    monkeypatch.setattr(sys, "unraisablehook", lambda u: dropped.append(u.exc_type))
    out = tmp_path / "run"
    rc = main(["simulate", str(ROOT / "scenes" / "fig12-tracking.toml"), "--duration", "20", "--out", str(out),
               cores, "--no-progress"])
    err = capsys.readouterr().err
    assert dropped == [KeyboardInterrupt]       # Python did drop it
    assert rc == 130 and "foveatrack: interrupted" in err, err
    assert not (out / "summary.json").exists()          # stopped, not run to its end
    r = RecordingReader(out / "run.mcap")
    frames = [f.frame_index for f in r.points()]
    assert frames == list(range(5))        # stopped after the frame it came in, every frame recorded
    assert r.complete, r.problem
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler     # Python's own handler is back
