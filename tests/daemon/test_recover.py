"""``foveatrack recover``: a recording cut short completed from its command journal
(:mod:`foveatrack.daemon.recover`), without processes: the daemon's own kill -9 is in
tests/daemon/test_faults.py."""

import json
import os
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from failing_writes import metadata_write_fails

from foveatrack.cli import main
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.daemon.recover import recover
from foveatrack.errors import UserError
from gimbal.pelco import encode_pan_tilt, encode_set_pan, encode_stop

STOP = encode_stop(1)
LEFT = encode_pan_tilt(1, -1, 20, 0, 0)
RIGHT = encode_pan_tilt(1, 1, 30, 0, 0)


def _line(t, raw, source, send_t_s=None):
    r = {"t_mono_s": t, "t_unix_s": 1.8e9 + t, "raw_hex": raw.hex(), "source": source}
    if send_t_s is not None:
        r["send_t_s"] = send_t_s
    return json.dumps(r)


def _cut_short(tmp_path, frames=5):
    """A daemon-like recording of ``frames`` frames, each with a tracker command, copied while its writer
    was still open (what kill -9 leaves), and a journal that holds those commands, a STOP at start
    (never recorded), and three commands after the last recorded one."""
    live, cut = tmp_path / "live.mcap", tmp_path / "rec.mcap"
    w = RecordingWriter(live, {"source": "daemon", "config_text": "x"}, log_time="host")
    journal = [_line(100.0, STOP, "")]
    rng = np.random.default_rng(1)
    for i in range(frames):
        t_end = (i + 1) * 100_000_000
        xyz = np.round(rng.uniform(1, 5, (50, 3)) * 1000) / 1000
        w.write_points(t_end, i, xyz, np.linspace(t_end - 99_000_000, t_end, 50).astype(np.int64))
        w.write_detection(t_end, i, False)
        raw = LEFT if i % 2 else RIGHT
        send = t_end * 1e-9 + 0.002
        w.write_command(int(send * 1e9), raw, frame_id=i, source="tracker", send_t_s=send,
                        host_written_s=100.1 + 0.1 * i, pan_dir=1, pan_byte=20, tilt_dir=0, tilt_byte=0)
        journal.append(_line(100.1 + 0.1 * i - 0.0005, raw, "tracker", send))
    w.flush()
    shutil.copyfile(live, cut)
    os.chmod(cut, 0o600)
    w.close()
    for k in range(3):     # the frames in flight: their commands reached the head, not the recording
        send = (frames + 1 + k) * 0.1 + 0.002
        journal.append(_line(100.1 + 0.1 * (frames + k), LEFT, "tracker", send))
    (tmp_path / "rec.mcap.commands.jsonl").write_text("\n".join(journal) + "\n")
    return cut, len(journal)


def _official_commands(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        assert summary is not None and summary.statistics is not None
        msgs = [(c.topic, json.loads(m.data)) for _s, c, m in r.iter_messages() if c.topic == "/commands"]
    return [m for _t, m in msgs]


def test_a_cut_short_recording_gets_every_journaled_command_back(tmp_path):
    cut, n_journal = _cut_short(tmp_path)
    before = RecordingReader(cut)
    assert not before.closed() and len(before.records("commands")) == 5
    log_times = [lt for lt, _m in before.logged_messages("points")]
    res = recover(cut)
    assert res.recovered and res.frames == 5 and res.commands_added == 3 and res.journal_only_added == 1
    assert stat.S_IMODE(cut.stat().st_mode) == 0o600
    from foveatrack.atomic_file import leftovers

    assert leftovers(cut) == []          # nothing of the rewrite beside it
    cmds = _official_commands(cut)           # the mcap package reads it: summary, statistics, every message
    assert len(cmds) == n_journal == 9
    added = [c for c in cmds if c.get("from_journal")]
    assert [c["journal_line"] for c in added] == [1, 7, 8, 9]
    assert added[0]["journal_only"] and added[0]["source"] == "unrecorded"
    assert all(not c.get("journal_only") and c["source"] == "tracker" and c["frame_id"] is None
               and c["raw_hex"] == LEFT.hex() for c in added[1:])
    assert [c["send_t_s"] for c in added[1:]] == pytest.approx([0.602, 0.702, 0.802])
    r = RecordingReader(cut)
    assert r.closed() and len(list(r.points())) == 5 and r.meta["source"] == "daemon"
    assert r.records("daemon")[-1]["event"] == "recovered"
    # log times kept: the copied messages' are the original's
    assert [lt for lt, _m in r.logged_messages("points")] == log_times


def test_a_killed_daemons_recording_names_the_command_that_completes_it(tmp_path):
    # kill -9 inside a record being written (its length field not yet filled in: 2^64 - 1, as a user's
    # audit found it): replay and export said only what was damaged, not the journal beside the file
    cut, _ = _cut_short(tmp_path)
    with open(cut, "ab") as fh:
        fh.write(b"\x06" + (2 ** 64 - 1).to_bytes(8, "little") + b"\x00" * 40)
    r = RecordingReader(cut)
    assert len(list(r.points())) == 5                    # what replay and export read, then warn about
    assert r.damage and not r.complete
    assert f"`foveatrack recover {cut}` completes it" in r.warning(), r.warning()
    journal = cut.with_name(cut.name + ".commands.jsonl")
    journal.rename(tmp_path / "elsewhere.jsonl")          # no journal beside it: no such hint
    r = RecordingReader(cut)
    list(r.points())
    assert "damaged recording" in r.warning() and "foveatrack recover" not in r.warning()


def test_recover_of_a_complete_recording_is_a_no_op_that_says_so(tmp_path, capsys):
    cut, _ = _cut_short(tmp_path)
    assert main(["recover", str(cut)]) == 0
    # a manual recover warns of the head as the daemon's own start does when it completes the file (an
    # audit: after `foveatrack recover` by hand, the next start said nothing and assumed the head home)
    err = capsys.readouterr().err
    assert f"WARNING: the run that wrote {cut} was killed: the head is where that run left it" in err, err
    assert "on_start = \"home\"" in err
    data = cut.read_bytes()
    assert main(["recover", str(cut)]) == 0
    cap = capsys.readouterr()
    assert "complete (closed by its writer), nothing to recover" in cap.out, cap.out
    assert "was killed" not in cap.err
    assert cut.read_bytes() == data


def test_a_damaged_journal_line_is_reported_and_skipped(tmp_path, capsys):
    cut, n = _cut_short(tmp_path)
    j = tmp_path / "rec.mcap.commands.jsonl"
    lines = j.read_text().splitlines()
    lines.insert(7, '{"t_mono_s": 100.6, "raw_hex": "ff01zz')       # cut in the middle (a crash while appending)
    lines.insert(8, '{"t_mono_s": "soon", "raw_hex": "ff0100000001", "source": "tracker"}')
    j.write_text("\n".join(lines) + "\n")
    assert main(["recover", str(cut)]) == 0
    cap = capsys.readouterr()
    assert "line 8:" in cap.err and "line 9:" in cap.err and "skipped" in cap.err and "Traceback" not in cap.err
    assert "2 damaged journal line(s) skipped" in cap.out
    assert len(_official_commands(cut)) == n


def test_a_journal_held_by_a_running_daemon_is_not_touched(tmp_path):
    from foveatrack.errors import UserError
    from foveatrack.live_devices import CommandJournal

    cut, _ = _cut_short(tmp_path)
    data = cut.read_bytes()
    held = CommandJournal(tmp_path / "rec.mcap.commands.jsonl")
    try:
        with pytest.raises(UserError, match="held by a running process"):
            recover(cut)
    finally:
        held.close()
    assert cut.read_bytes() == data



def test_a_recording_still_being_written_is_not_touched_and_is_read_as_such(tmp_path):
    # A user ran 'recover' on a simulator's recording while it was still writing: it was rewritten
    # from the 45 frames then on disk and the writer's next 55 were lost.  The writer holds its
    # file's lock (foveatrack.file_lock): recover refuses and changes nothing; replay and
    # export read what it holds and say it is being written, not damaged; once closed, all is normal.
    from foveatrack.errors import UserError
    from foveatrack.file_lock import recording_in_use

    live = tmp_path / "live.mcap"
    w = RecordingWriter(live, {"source": "daemon", "config_text": "x"}, log_time="host")
    for i in range(3):
        t_end = (i + 1) * 100_000_000
        w.write_points(t_end, i, np.full((5, 3), 2.0), np.full(5, t_end, np.int64))
    w.flush()
    try:
        assert recording_in_use(live)
        data = live.read_bytes()
        with pytest.raises(UserError, match="still being written by a running process"):
            recover(live)
        assert live.read_bytes() == data
        r = RecordingReader(live)
        assert len(list(r.points())) == 3
        assert "still being written" in r.warning() and "damaged" not in r.warning(), r.warning()
    finally:
        w.close()
    assert not recording_in_use(live)
    r = RecordingReader(live)
    assert len(list(r.points())) == 3 and r.warning() is None


def test_not_a_recording_is_one_line(tmp_path, capsys):
    p = tmp_path / "x.mcap"
    p.write_bytes(b"hello")
    assert main(["recover", str(p)]) == 2
    assert "not a foveatrack recording" in capsys.readouterr().err


def test_a_killed_recover_leaves_the_original_whole_and_the_next_one_clears_its_temporary(tmp_path):
    # kill -9 (or a power loss) mid-rewrite: nothing half-written under the recording's name; the
    # temporary left beside it is removed by the next recover, which completes the file
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from foveatrack.atomic_file import leftovers

    cut, n_journal = _cut_short(tmp_path, frames=150)
    data = cut.read_bytes()
    before = sorted(p.name for p in tmp_path.iterdir())
    root = Path(__file__).resolve().parents[2]
    kill_at_100 = ("import os, signal, sys; from foveatrack.daemon.recover import recover; "
                   "recover(sys.argv[1], progress=lambda n: os.kill(os.getpid(), signal.SIGKILL))")
    out = subprocess.run([sys.executable, "-c", kill_at_100, str(cut)], cwd=root, capture_output=True,
                         env={**os.environ, "PYTHONPATH": str(root)}, timeout=120)
    assert out.returncode == -signal.SIGKILL, out.stderr
    assert cut.read_bytes() == data
    left = leftovers(cut)
    assert len(left) == 1 and left[0].stat().st_size > 0        # killed with 100 frames written
    res = recover(cut)
    assert res.recovered and res.frames == 150
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert len(_official_commands(cut)) == n_journal


def test_recover_leaves_a_temporary_another_running_recover_still_writes(tmp_path):
    from foveatrack.atomic_file import leftovers
    from foveatrack.file_lock import hold

    cut, _ = _cut_short(tmp_path)
    running = tmp_path / ".rec.mcap.0123abcd.tmp"
    running.write_bytes(b"being written")
    dead = tmp_path / ".rec.mcap.89abcdef.tmp"
    dead.write_bytes(b"cut short")
    fd = hold(running)          # the flock a running RecordingWriter holds on its file
    try:
        assert recover(cut).recovered
    finally:
        os.close(fd)
    assert leftovers(cut) == [running] and running.read_bytes() == b"being written"


# Recovering where the user may not write, or on a full disk (found as a non-root user; root's writes
# are never refused, so each refusal is raised here where the OS raises it for such a user).


def _unchanged(cut, before: bytes):
    from foveatrack.atomic_file import leftovers

    assert cut.read_bytes() == before
    assert leftovers(cut) == []      # nothing of the rewrite left beside it


def _no_new_file_beside(monkeypatch):
    """A directory this user may not write (root may, so the OS's refusal is raised here): the
    temporary beside the recording cannot be made."""
    import errno

    real_open = os.open

    def denied(path, *args, **kwargs):
        if str(path).endswith(".tmp"):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", denied)


def test_a_directory_that_takes_no_new_file_is_said_before_any_work(tmp_path, monkeypatch):
    """It failed only at the copy, naming the hidden temporary: 'cannot create recording
    .rec.mcap.recovering: Permission denied'."""
    import errno

    cut, _ = _cut_short(tmp_path)
    before = cut.read_bytes()
    _no_new_file_beside(monkeypatch)
    with pytest.raises(UserError) as exc:
        recover(cut)
    msg = str(exc.value)
    assert msg.startswith(f"{cut}: not recovered:") and "does not take a new file (Permission denied)" in msg, msg
    assert "nothing was changed" in msg and "recover the copy" in msg
    monkeypatch.undo()
    _unchanged(cut, before)


def test_a_rename_refused_leaves_nothing_beside_the_recording(tmp_path, monkeypatch):
    """Another user's recording in a sticky directory (/tmp): the rename over it is refused (EPERM)
    after the whole rewrite; the rewrite was left beside it and the error named only the temporary."""
    import errno

    cut, _ = _cut_short(tmp_path)
    before = cut.read_bytes()

    def refused(src, dst):
        raise PermissionError(errno.EPERM, "Operation not permitted", str(src))

    monkeypatch.setattr(os, "replace", refused)
    with pytest.raises(UserError) as exc:
        recover(cut)
    msg = str(exc.value)
    assert msg.startswith(f"{cut}: not recovered: the completed copy could not replace it (Operation not "
                          "permitted") and msg.endswith("nothing was changed"), msg
    _unchanged(cut, before)


def test_a_full_disk_under_the_rewrite_is_said_of_the_recording(tmp_path, monkeypatch):
    """The copy's first write failing (ENOSPC) left its empty temporary and said 'cannot write
    recording .rec.mcap.recovering ...; the 0 frame(s) written before are kept'."""
    import errno

    cut, _ = _cut_short(tmp_path)
    before = cut.read_bytes()

    metadata_write_fails(monkeypatch, errno.ENOSPC)
    with pytest.raises(UserError) as exc:
        recover(cut)
    msg = str(exc.value)
    assert msg.startswith(f"{cut}: not recovered: its completed copy could not be written beside it (no space "
                          "left on its disk") and "nothing was changed" in msg, msg
    assert ".tmp" not in msg
    _unchanged(cut, before)


def test_a_directory_that_cannot_be_read_to_sync_it_is_recovered_and_said_so(tmp_path, monkeypatch):
    """A write+search-only directory (0333): the rename over the recording succeeds, the directory's
    open to sync it is refused; recover said 'the completed copy could not replace it ...; nothing was
    changed' of a recording it had replaced."""
    import errno

    cut, _ = _cut_short(tmp_path)
    real_open = os.open

    def no_read(path, flags, *args, **kwargs):
        if os.path.isdir(path) and flags & getattr(os, "O_DIRECTORY", 0):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", no_read)
    res = recover(cut)
    monkeypatch.undo()
    from foveatrack.atomic_file import leftovers

    assert res.recovered and RecordingReader(cut).closed() and leftovers(cut) == []


def _linked(tmp_path):
    """A cut-short recording in ``ro/`` reached through symlinks (it and its journal) in ``mine/``."""
    (tmp_path / "ro").mkdir()
    (tmp_path / "mine").mkdir()
    cut, _ = _cut_short(tmp_path / "ro")
    link = tmp_path / "mine" / "rec.mcap"
    link.symlink_to(cut)
    (tmp_path / "mine" / "rec.mcap.commands.jsonl").symlink_to(tmp_path / "ro" / "rec.mcap.commands.jsonl")
    return cut, link


def test_through_a_symlink_the_targets_directory_is_the_one_probed(tmp_path, monkeypatch):
    """The probe was made beside the link while the copy is written beside its target: a target's
    directory that takes no new file failed at the copy and was said as a refused rename."""
    import errno

    cut, link = _linked(tmp_path)
    before = cut.read_bytes()
    real_open = os.open

    def read_only_share(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and os.path.dirname(os.path.abspath(path)) == str(tmp_path / "ro"):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", read_only_share)
    with pytest.raises(UserError) as exc:
        recover(link)
    monkeypatch.undo()
    msg = str(exc.value)
    assert msg.startswith(f"{link}: not recovered:") and f"{tmp_path / 'ro'} does not take a new file" in msg, msg
    _unchanged(cut, before)
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["rec.mcap", "rec.mcap.commands.jsonl"]


def test_through_a_symlink_the_sticky_hint_is_of_the_targets_directory(tmp_path, monkeypatch):
    import errno

    cut, link = _linked(tmp_path)
    os.chmod(tmp_path / "ro", 0o1777)           # a sticky directory (as /tmp) holding another user's file

    def refused(src, dst):
        raise PermissionError(errno.EPERM, "Operation not permitted", str(src))

    monkeypatch.setattr(os, "replace", refused)
    monkeypatch.setattr(os, "geteuid", lambda: 4242)
    with pytest.raises(UserError) as exc:
        recover(link)
    assert "only its owner may replace it" in str(exc.value), str(exc.value)


def test_a_permission_error_reading_the_recording_is_not_a_refused_rename(tmp_path, monkeypatch):
    import errno

    cut, _ = _cut_short(tmp_path)

    def unreadable(self, *a, **k):
        raise PermissionError(errno.EACCES, "Permission denied", str(cut))

    monkeypatch.setattr(RecordingReader, "logged_messages", unreadable)
    with pytest.raises(PermissionError) as exc:
        recover(cut)
    assert exc.value.filename == str(cut)


def test_a_second_recover_of_the_same_file_is_refused_while_the_first_runs(tmp_path, monkeypatch):
    """The daemon's start and a user's 'foveatrack recover' at once: the second one's leftovers cleanup
    removed the first one's copy between its writer's close (its lock gone) and its rename, and the
    first failed with FileNotFoundError naming the recording."""
    import foveatrack.atomic_file as af

    cut, n_journal = _cut_short(tmp_path)
    before = cut.read_bytes()
    real = af._fsync
    second = []

    def fsync_spy(path, flags):
        # the first recover has closed its copy and syncs it before the rename: the second starts now
        if not second and str(path).endswith(".tmp"):
            try:
                second.append(recover(cut))
            except UserError as exc:
                second.append(exc)
            assert cut.read_bytes() == before
        return real(path, flags)

    monkeypatch.setattr(af, "_fsync", fsync_spy)
    res = recover(cut)
    assert res.recovered and len(_official_commands(cut)) == n_journal
    assert isinstance(second[0], UserError), second
    msg = str(second[0])
    assert msg == f"{cut} is being recovered by another process; let it finish, nothing was changed", msg
    assert recover(cut).already_complete           # the lock is let go after the rename


def test_a_recording_being_recovered_is_read_as_such_not_as_still_being_written(tmp_path, monkeypatch, capsys):
    """'export' of a recording while 'foveatrack recover' rewrote it said "still being written by a
    running process": recover holds the writer's lock (it must, or a second recover or a reader would
    take its half-written state for the file's), but no writer is adding to the file; the user had
    nothing to stop, and should wait for the recover and read the completed file."""
    import foveatrack.atomic_file as af
    from foveatrack.file_lock import recording_in_use

    cut, _ = _cut_short(tmp_path)
    real = af._fsync
    during = []

    def fsync_spy(path, flags):
        # the recover has written its copy and syncs it before the rename: read the recording now
        if not during and str(path).endswith(".tmp"):
            assert recording_in_use(cut)        # the lock as strong as before
            capsys.readouterr()
            rc = main(["export", str(cut), "--csv", str(tmp_path / "points.csv")])
            during.append((rc, capsys.readouterr().err, _warning_after_reading(cut)))
        return real(path, flags)

    monkeypatch.setattr(af, "_fsync", fsync_spy)
    assert recover(cut).recovered
    (rc, err, warning), = during
    assert rc == 0 and "being recovered by a running 'foveatrack recover'" in err, err
    assert "once the recover has finished" in err and "still being written" not in err, err
    assert warning.startswith(f"note: {cut} is being recovered"), warning
    assert not recording_in_use(cut) and _warning_after_reading(cut) is None


def _warning_after_reading(path):
    r = RecordingReader(path)
    list(r.points())
    return r.warning()

def test_only_a_full_disk_is_said_to_need_space_and_every_error_ends_nothing_was_changed(tmp_path, monkeypatch):
    """'it needs about N bytes free' was said for any failed write of the copy (an I/O error too); the
    probe's refusal ended '...recover the copy', not 'nothing was changed' as every other one does."""
    import errno
    from types import SimpleNamespace

    import foveatrack.recording.writer as writer_mod

    cut, _ = _cut_short(tmp_path)
    before = cut.read_bytes()

    metadata_write_fails(monkeypatch, errno.EIO)
    monkeypatch.setattr(writer_mod.os, "statvfs", lambda _p: SimpleNamespace(f_bavail=10**9, f_frsize=4096))
    with pytest.raises(UserError) as exc:
        recover(cut)
    msg = str(exc.value)
    assert "(Input/output error); nothing was changed" in msg and "bytes free" not in msg, msg
    monkeypatch.undo()
    _unchanged(cut, before)

    _no_new_file_beside(monkeypatch)
    with pytest.raises(UserError) as exc:
        recover(cut)
    assert str(exc.value).endswith("nothing was changed"), str(exc.value)


def test_recover_takes_the_lock_a_readers_probe_held_for_an_instant(tmp_path, monkeypatch):
    """Every reader probes a recording's lock (recording_in_use) for an instant: a recover that asked
    for the lock in that instant found no one holding it afterwards and went on without it, which
    lets a second recover in (the race the lock is there for).  It asks again."""
    import foveatrack.daemon.recover as rc
    import foveatrack.file_lock as fl

    real_hold, asked = fl.hold, []

    def probed_hold(p):            # the first three asks meet a reader's probe
        asked.append(p)
        return None if len(asked) <= 3 else real_hold(p)

    monkeypatch.setattr(fl, "hold", probed_hold)
    held = []
    monkeypatch.setattr(rc, "_recover", lambda path, real, journal, progress: held.append(fl.recording_in_use(real)))
    f = tmp_path / "run.mcap"
    f.write_bytes(b"not yet a recording")
    rc.recover(f)
    assert held == [True] and len(asked) == 4, (held, asked)


def test_a_killed_recovers_leftovers_do_not_make_a_writers_file_read_as_being_recovered(tmp_path):
    """Readers were told "being recovered" of any held file with a recover's temporary copy beside it:
    a recover killed mid-copy (kill -9) left one, and the next writer's file was said to be recovered,
    not written.  A recover is known by its mark's lock, which dies with its process."""
    from foveatrack.file_lock import _recover_mark, hold, lock_holder, mark_recovering, unmark_recovering

    cut, _ = _cut_short(tmp_path)
    leftover = cut.parent / f".{cut.name}.0123abcd.tmp"
    leftover.write_bytes(b"a killed recover's copy")
    Path(_recover_mark(cut)).write_bytes(b"")                 # and its mark, unlocked now
    fd = hold(cut)                                          # a writer holds the file
    try:
        assert lock_holder(cut) == "writer"
        mark = mark_recovering(cut)                         # a running recover's mark, locked
        assert mark is not None and lock_holder(cut) == "recover"
        unmark_recovering(cut, mark)
        assert not Path(_recover_mark(cut)).exists() and lock_holder(cut) == "writer"
    finally:
        os.close(fd)
    assert lock_holder(cut) is None


def test_the_recover_mark_is_readable_by_others_waited_for_and_never_anothers(tmp_path, monkeypatch):
    """A review's findings: the mark was made 0600, so another user's reader could not probe it and
    was told "still being written"; a second recover that took the renamed file's lock while the
    first still held the mark ran without one; and a reader asked between a recover's two unlocks
    was told "writer" of a free file."""
    import threading

    import foveatrack.file_lock as fl

    cut, _ = _cut_short(tmp_path)
    old_umask = os.umask(0o022)
    try:
        first = fl.mark_recovering(cut)
    finally:
        os.umask(old_umask)
    mark = Path(fl._recover_mark(cut))
    assert first is not None and mark.stat().st_mode & 0o044 == 0o044
    # a second recover waits for the first's mark and then makes its own
    threading.Timer(0.1, fl.unmark_recovering, (cut, first)).start()
    second = fl.mark_recovering(cut, wait_s=2.0)
    assert second is not None and fl._is_at(second, str(mark))
    fl.unmark_recovering(cut, second)
    assert not mark.exists()
    # the recording free by the time the mark is asked about: nothing holds it
    probes = iter([True, False, False])
    monkeypatch.setattr(fl, "recording_in_use", lambda p: next(probes))
    assert fl.lock_holder(cut) is None
