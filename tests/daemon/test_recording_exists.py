"""A daemon whose recording file already exists refuses to start, leaves the file as it was, and says
how to fix the config: '{time}' in [recording] path (a new file per start) or overwrite = true.
(Before, it said only "recording X already exists; choose another path or remove it", which sent
the user renaming files by hand before every start.)"""

import pytest

from daemon_procs import loop_head_daemon

from foveatrack.device_config import DaemonConfig
from foveatrack.errors import UserError
from foveatrack.recording import RecordingExistsError, RecordingReader, RecordingWriter


def _daemon(tmp_path, rec_path, extra=""):
    return loop_head_daemon(tmp_path, rec_path, extra, log_path=str(tmp_path / "d.jsonl"))


def _close(d):
    d.client.close()
    d.head.close()
    d.recorder.close()


def test_the_writer_names_the_file_and_the_way_out(tmp_path):
    p = tmp_path / "r.mcap"
    p.write_text("precious")
    with pytest.raises(RecordingExistsError) as exc:
        RecordingWriter(p, {})
    assert isinstance(exc.value, UserError) and exc.value.path == p
    assert str(p) in str(exc.value) and "--overwrite" in str(exc.value) and "overwrite = true" in str(exc.value)
    assert p.read_text() == "precious"


def test_an_existing_recording_path_says_how_to_fix_the_config(tmp_path):
    p = tmp_path / "run.mcap"
    p.write_text("precious")
    d = _daemon(tmp_path, p)
    with pytest.raises(UserError) as exc:
        d._open()
    msg = str(exc.value)
    assert str(tmp_path / "d.toml") in msg and "[recording] path" in msg and str(p) in msg
    assert "{time}" in msg and "overwrite = true" in msg
    assert p.read_text() == "precious"


def test_a_time_stamped_path_taken_within_the_same_second(tmp_path, monkeypatch):
    p = tmp_path / "run-20260101T000000Z.mcap"
    p.write_text("precious")
    monkeypatch.setattr(DaemonConfig, "recording_path", lambda self, now=None: p)
    d = _daemon(tmp_path, tmp_path / "run-{time}.mcap")
    with pytest.raises(UserError, match="same second") as exc:
        d._open()
    assert "overwrite = true" in str(exc.value) and p.read_text() == "precious"


def test_overwrite_true_replaces_it(tmp_path):
    p = tmp_path / "run.mcap"
    p.write_text("old")
    d = _daemon(tmp_path, p, "overwrite = true")
    d._open()
    _close(d)
    meta = RecordingReader(p).meta
    # the typed configuration that runs, without the raw [tracker] table beside it (issue 25)
    assert meta["source"] == "daemon" and "tracker" in meta and "tracker_table" not in meta


def test_a_command_journal_planted_as_a_link_is_refused_and_its_target_untouched(tmp_path):
    """Issue 32: the daemon opened the command journal beside its recording following links, with the
    default mode (a link planted at ``run.mcap.commands.jsonl`` got every head command appended to
    its target).  Now the start is a one-line error naming the journal, the target is as it was, and
    nothing is left running or behind (the new recording is removed)."""
    import threading

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    p = tmp_path / "run.mcap"
    (tmp_path / "run.mcap.commands.jsonl").symlink_to(victim)
    before = threading.active_count()
    d = _daemon(tmp_path, p)
    with pytest.raises(UserError, match=r"command journal .*run\.mcap\.commands\.jsonl: cannot write "
                                        r"\(it is a symbolic link\)"):
        d._open()
    assert victim.read_text() == "precious\n"
    assert not p.exists() and threading.active_count() == before


def test_a_command_journal_is_the_owners_alone(tmp_path):
    import os
    import stat

    from foveatrack.live_devices import CommandJournal

    old = os.umask(0o022)
    try:
        j = CommandJournal(tmp_path / "r.mcap.commands.jsonl")
    finally:
        os.umask(old)
    j.write(b"\xff\x01\x00\x00\x00\x00\x01")
    j.close()
    assert stat.S_IMODE(os.stat(tmp_path / "r.mcap.commands.jsonl").st_mode) == 0o600
