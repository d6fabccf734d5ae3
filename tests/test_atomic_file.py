"""foveatrack.atomic_file: an output appears under its name only when whole, and nothing is left of one
cut short (a Ctrl-C during an export left a partial CSV and a corrupt NPZ under their final names)."""

import os
import stat

import pytest

from foveatrack.atomic_file import written_whole


def _listing(d):
    return sorted(p.name for p in d.iterdir())


def test_the_file_appears_only_when_the_block_ends(tmp_path):
    out = tmp_path / "a.csv"
    with written_whole(out) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".a.csv.") and tmp.name.endswith(".tmp")
        tmp.write_text("x,y\n")
        assert not out.exists()
    assert out.read_text() == "x,y\n" and _listing(tmp_path) == ["a.csv"]


@pytest.mark.parametrize("exc", [KeyboardInterrupt, OSError, ValueError])
def test_an_interrupted_write_leaves_neither_the_file_nor_a_temporary(tmp_path, exc):
    out = tmp_path / "a.csv"
    with pytest.raises(exc):
        with written_whole(out) as tmp:
            tmp.write_text("x,y\n1,2\n")
            raise exc()
    assert _listing(tmp_path) == []


def test_a_file_it_replaces_is_whole_until_then_and_keeps_its_mode(tmp_path):
    out = tmp_path / "a.csv"
    out.write_text("old\n")
    os.chmod(out, 0o640)
    with pytest.raises(KeyboardInterrupt):
        with written_whole(out) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert out.read_text() == "old\n" and _listing(tmp_path) == ["a.csv"]
    with written_whole(out) as tmp:
        tmp.write_text("new\n")
    assert out.read_text() == "new\n" and stat.S_IMODE(out.stat().st_mode) == 0o640


def test_a_new_file_gets_the_mode_open_gives_it(tmp_path):
    (tmp_path / "plain").write_text("")
    with written_whole(tmp_path / "a.csv") as tmp:
        tmp.write_text("")
    assert (tmp_path / "a.csv").stat().st_mode == (tmp_path / "plain").stat().st_mode


def test_a_symlink_is_written_through(tmp_path):
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "a.csv"
    target.write_text("old\n")
    link = tmp_path / "a.csv"
    link.symlink_to(target)
    with written_whole(link) as tmp:
        assert tmp.parent == tmp_path / "real"
        tmp.write_text("new\n")
    assert link.is_symlink() and target.read_text() == "new\n"


def test_fsync_syncs_the_file_before_its_rename_and_the_directory_after(tmp_path, monkeypatch):
    # recover rewrites a recording in place: after a power loss the old file or the whole new one
    out = tmp_path / "a.mcap"
    synced = []
    real = os.fsync

    def spy(fd):
        synced.append((os.readlink(f"/proc/self/fd/{fd}"), out.exists()))
        real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    with written_whole(out) as tmp:
        tmp.write_text("x")
    assert synced == []          # an export's default: no sync
    out.unlink()
    with written_whole(out, fsync=True) as tmp:
        tmp.write_text("x")
    d = os.path.realpath(tmp_path)
    assert synced == [(os.path.join(d, tmp.name), False), (d, True)]


def test_a_writer_that_makes_the_file_anew_still_gets_the_replaced_files_mode(tmp_path):
    # recover's RecordingWriter creates its file itself (exclusively, under the umask)
    out = tmp_path / "rec.mcap"
    out.write_text("old\n")
    os.chmod(out, 0o600)
    with written_whole(out) as tmp:
        tmp.unlink()
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    assert stat.S_IMODE(out.stat().st_mode) == 0o600


def test_leftovers_are_the_temporaries_of_that_name_only(tmp_path):
    from foveatrack.atomic_file import leftovers

    out = tmp_path / "rec.mcap"
    left = tmp_path / ".rec.mcap.0123abcd.tmp"      # what a process killed inside the block leaves
    for p in (left, out, tmp_path / ".rec.mcap.zzzzzzzz.tmp", tmp_path / ".rec.mcap.0123abcd.tmp.x",
              tmp_path / ".rec.mcap2.0123abcd.tmp", tmp_path / ".rec.mcap.recovering"):
        p.write_text("")
    assert leftovers(out) == [left]


def test_a_failed_write_names_the_output(tmp_path):
    """A write on a full disk raises an OSError that names no file (or the hidden temporary): an
    export there ended on 'foveatrack: error: No space left on device'.  Simulated: the OS's error
    raised inside the block, where a write to the temporary raises it."""
    import errno

    out = tmp_path / "a.csv"
    with pytest.raises(OSError) as exc:
        with written_whole(out) as tmp:
            raise OSError(errno.ENOSPC, "No space left on device")
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(out)
    with pytest.raises(PermissionError) as exc:
        with written_whole(out) as tmp:
            raise PermissionError(errno.EACCES, "Permission denied", str(tmp))
    assert exc.value.filename == str(out) and _listing(tmp_path) == []


def test_a_directory_that_cannot_be_opened_to_sync_is_no_failure_to_write(tmp_path, monkeypatch):
    """A directory this user may write and search but not read (0333): the rename succeeds, the
    directory's open to sync it is refused.  That was raised as a failure to write the file (recover
    said 'nothing was changed' of a recording it had replaced); the file is whole under its name."""
    import errno

    out = tmp_path / "a.mcap"
    out.write_text("old\n")
    real_open = os.open

    def no_read(path, flags, *args, **kwargs):
        if flags & getattr(os, "O_DIRECTORY", 0):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", no_read)
    with written_whole(out, fsync=True) as tmp:
        tmp.write_text("new\n")
    monkeypatch.undo()
    assert out.read_text() == "new\n" and _listing(tmp_path) == ["a.mcap"]


def test_only_a_refused_rename_is_a_rename_refused(tmp_path, monkeypatch):
    """recover said 'the completed copy could not replace it' of any PermissionError inside the block
    (one reading the recording too): the rename's refusal has its own class."""
    import errno

    from foveatrack.atomic_file import RenameRefused, leftovers, temporary_name

    out = tmp_path / "a.csv"
    with pytest.raises(PermissionError) as exc:
        with written_whole(out):
            raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "input"))
    assert not isinstance(exc.value, RenameRefused)

    def refused(src, dst):
        raise PermissionError(errno.EPERM, "Operation not permitted", str(src))

    monkeypatch.setattr(os, "replace", refused)
    with pytest.raises(RenameRefused) as exc:
        with written_whole(out) as tmp:
            tmp.write_text("x")
    assert exc.value.filename == str(out) and _listing(tmp_path) == []
    # the temporaries' one name: what leftovers finds
    t = temporary_name(out)
    t.write_text("")
    assert t.parent == tmp_path and leftovers(out) == [t]


def test_a_rename_that_fails_otherwise_keeps_its_own_names(tmp_path, monkeypatch):
    """A temporary removed under it (ENOENT) was said as the output itself missing."""
    import errno

    out = tmp_path / "a.csv"
    with pytest.raises(FileNotFoundError) as exc:
        with written_whole(out) as tmp:
            tmp.unlink()
    assert exc.value.filename == str(tmp) and exc.value.filename2 == str(out)

    def cross(src, dst):
        raise OSError(errno.EXDEV, "Invalid cross-device link", str(src), None, str(dst))

    monkeypatch.setattr(os, "replace", cross)
    with pytest.raises(OSError) as exc:
        with written_whole(out) as tmp:
            tmp.write_text("x")
    assert exc.value.errno == errno.EXDEV and exc.value.filename == str(tmp) and _listing(tmp_path) == []


def test_a_temporary_that_cannot_be_made_is_said_of_the_output(tmp_path, monkeypatch):
    """'export --csv /sys/out.csv' said '/sys/.out.csv.1a2b3c4d.tmp: Permission denied'."""
    import errno

    out = tmp_path / "out.csv"
    real_open = os.open

    def denied(path, flags, *args, **kwargs):
        if flags & os.O_CREAT:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", denied)
    with pytest.raises(PermissionError) as exc:
        with written_whole(out):
            pass
    assert exc.value.filename == str(out) and ".tmp" not in str(exc.value)
