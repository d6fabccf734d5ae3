"""A full disk under a running daemon: the head still gets every command (a STOP among them), the
run goes on, and what could not be written -- the recording, the command journal, the log -- is said
once when it happens and again at the end.  (Found as a non-root user on a 2 MB tmpfs: the recording
stopped in silence, seen only as a growing drop count; then the journal's ENOSPC was raised out of
the loop, the shutdown's STOP died on the same write, and the run ended on "foveatrack: error: No
space left on device" naming no file.)

The full disk is /dev/full (every write fails with ENOSPC, for root too) for the journal and the log,
and a recording whose SDK writer fails its flush as on a full disk."""

import errno
import os
import time
from pathlib import Path

import pytest

from daemon_procs import loop_head_daemon, silent_lidar_table

from foveatrack.control import STOP
from foveatrack.daemon import Daemon
from foveatrack.daemon.support import JsonLog
from foveatrack.live_devices import CommandJournal

FULL = "/dev/full"
pytestmark = pytest.mark.skipif(not os.path.exists(FULL), reason="no /dev/full on this system")


def _daemon(tmp_path, extra: str = "") -> Daemon:
    return loop_head_daemon(tmp_path, extra=extra)


def test_a_journal_on_a_full_disk_never_keeps_a_command_from_the_head():
    j = CommandJournal(FULL)
    j.write(b"\xff\x01\x00\x00\x00\x00\x01", "tracker", 1.0)     # raised ENOSPC into the loop before
    j.write(b"\xff\x01\x00\x00\x00\x00\x01", "shutdown", 1.1)
    assert j.error is not None and j.error.errno == errno.ENOSPC and j.lost == 2
    j.close()


def test_a_log_on_a_full_disk_does_not_stop_the_run():
    log = JsonLog(FULL)
    log.event("progress", frames=1)
    log.event("stop")
    assert log.error is not None and log.error.errno == errno.ENOSPC and log.lost == 2
    log.close()


def test_the_daemon_says_once_what_a_full_disk_stopped_and_tracks_on(tmp_path, capsys):
    d = _daemon(tmp_path)
    d._open()
    try:
        d.head.journal.close()
        d.head.journal = CommandJournal(FULL)
        d.log = JsonLog(FULL)
        w = d.recorder.writer

        class FullDisk:          # the SDK writer's flush on a full disk, as the SDK says it
            def __init__(self, sdk):
                self.sdk = sdk

            def flush(self):
                raise RuntimeError("FoxgloveError: MCAP error: I/O error from writing, or reading a compression "
                                   "stream")

            def __getattr__(self, name):
                return getattr(self.sdk, name)

        w._w = FullDisk(w._w)
        d.recorder.submit(lambda writer: writer.flush())
        deadline = time.monotonic() + 10
        while d.recorder.error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        raw, written = d.head.send(STOP, "watchdog", 0.5)
        assert written                           # the head got it though nothing could journal it
        d.log.event("progress")
        d._watch_outputs()
        d._watch_outputs()                       # each said once, not at every tick
        err = capsys.readouterr().err
        rec = Path(d.recording_path)
        assert err.count("WARNING") == 3, err
        assert f"WARNING: cannot write recording {rec}" in err and "tracking goes on" in err
        assert f"WARNING: command journal {FULL}: cannot write (No space left on device)" in err
        assert f"WARNING: --log {FULL}: cannot write (No space left on device)" in err
        problems = d.problems()
        assert any(p.startswith(f"cannot write recording {rec}") for p in problems), problems
        assert any(p.startswith(f"command journal {FULL}") for p in problems), problems
    finally:
        d._shutdown()        # sends its STOP through the failed journal: must not raise
    assert d.final_stats is not None


def test_a_stderr_on_a_full_disk_does_not_end_the_tick(tmp_path):
    # stderr redirected to a file on the same full disk (2>>daemon.err): the tick's warning about the
    # full disk raised ENOSPC out of _watch_outputs and ended the tracking (review)
    from foveatrack.daemon.support import StatusLine

    d = _daemon(tmp_path)
    d._open()
    full = open(FULL, "w")
    try:
        d.log = JsonLog(FULL)
        d.log.event("progress")
        d.status = StatusLine(stream=full, enabled=True)
        d.status.show("10.0 Hz")                  # the status line itself: not raised either
        d._watch_outputs()                        # says the log's failure: the write fails, the tick goes on
        assert d.status.error is not None and d.status.error.errno == errno.ENOSPC
        d.status.note("and nothing more is tried")
        d.status.done()
    finally:
        d.status = StatusLine(enabled=False)
        d._shutdown()
        try:
            full.close()                         # its buffer still holds what could not be written
        except OSError:
            pass
    assert d.final_stats is not None


@pytest.mark.parametrize("table", ["nominal", "example"])
def test_a_daemon_with_stderr_on_a_full_disk_runs_and_exits_with_its_own_code(tmp_path, table):
    # the start's warnings (the nominal table has one) and the last lines (frames, problems: the
    # example table has no start warning) were print()s: ENOSPC ended the command with 1, before the
    # run or after it; now it runs and exits 3 (no lidar data, as with a writable stderr)
    import subprocess
    import sys

    from daemon_procs import ROOT, env

    speed_table = "nominal" if table == "nominal" else str(ROOT / "examples" / "pts303h-unit3-speed-table.json")
    cfg = tmp_path / "d.toml"
    cfg.write_text(f'{silent_lidar_table()}[head]\nport = "loop://"\nspeed_table = "{speed_table}"\n')
    with open(FULL, "w") as full:
        r = subprocess.run([sys.executable, "-m", "foveatrack", "daemon", "--config", str(cfg), "--duration-s", "1",
                            "--no-status"], cwd=ROOT, env=env(), stdout=subprocess.PIPE, stderr=full, timeout=120)
    assert r.returncode == 3, r.returncode


def test_each_segments_journal_that_fails_is_said_and_stays_said(tmp_path, capsys):
    # a recording in segments: the first segment's journal failed, then the rollover closed it -- its
    # loss vanished from the run's last lines -- and the new segment's journal failing later was never
    # said, "journal" being said already (review).  Each journal is its own fault, by its path.
    from foveatrack.live_devices import journal_path

    d = _daemon(tmp_path, "segment_minutes = 1")
    d._open()
    try:
        first = d.head.journal.path
        d.head.journal._f.close()
        d.head.journal._f = open(FULL, "a", buffering=1)         # the first segment's disk fills
        d.head.send(STOP, "watchdog", 0.5)
        d._watch_outputs()
        d._next_segment_if_due(100.0)
        d._next_segment_if_due(161.0)                             # the rollover: a new journal
        second = d.head.journal.path
        assert second != first and second == str(journal_path(d._segment_path(1)))
        assert any(f"command journal {first}" in p for p in d.problems()), d.problems()   # still said at the end
        d.head.send(STOP, "watchdog", 1.0)                        # the new journal works
        d._watch_outputs()
        d.head.journal._f.close()
        d.head.journal._f = open(FULL, "a", buffering=1)          # ... until its disk fills too
        d.head.send(STOP, "watchdog", 1.5)
        d._watch_outputs()
        d._watch_outputs()
        err = capsys.readouterr().err
        assert err.count(f"WARNING: command journal {first}: cannot write") == 1, err
        assert err.count(f"WARNING: command journal {second}: cannot write") == 1, err
        problems = d.problems()
        assert [p for p in problems if p.startswith("command journal")] == [
            p for p in problems if p.startswith(f"command journal {first}") or p.startswith(f"command journal {second}")]
        assert sum(p.startswith("command journal") for p in problems) == 2, problems
    finally:
        d._shutdown()
    assert d.final_stats is not None
