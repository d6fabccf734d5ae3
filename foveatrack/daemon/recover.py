"""Completing a recording cut short (``kill -9``, power loss) from its command journal.

The daemon writes its recording behind a queue, and every frame meant for the head to
``<recording>.commands.jsonl`` *before* writing it to the port
(:class:`foveatrack.live_devices.CommandJournal`).  A killed daemon leaves a recording without its
end (no summary, no footer: readable only by a tolerant reader such as ours) that lacks the last
2-4 frames' commands the head did get.  :func:`recover` rewrites it as a complete MCAP:

1. every message the tolerant reader (:class:`~foveatrack.recording.RecordingReader`) gets from the
   cut-short file, in file order, with its own MCAP log time (the Foxglove view channels are drawn
   again from the records, as the writer always does);
2. a ``/commands`` record for every journal line the recording does not hold.  The recording's
   commands are matched to the journal in order (same bytes and source; each command was journaled
   just before it was written, so the recording's commands are a subsequence of the journal).  A
   journal line after the last recorded command, from the dead reckoning's own commands (tracker,
   watchdog, shutdown, ...: it carries its ``send_t_s``) is the command the recording lost: it is
   added as a proper command record (``from_journal: true``, ``frame_id`` null: its frame was lost
   with it) and replay feeds it to the dead reckoning as the daemon did.  Any other unmatched line
   -- the daemon's STOPs outside the dead reckoning (at start, while the head's pose is unknown),
   homing moves, a command whose record a full queue dropped -- is added too, with
   ``journal_only: true``: the head got it, replay does not feed it (the run's dead reckoning never
   saw it);
3. a ``/daemon`` event ``recovered`` saying what was done.

The new file is written beside the old one and renamed over it
(:func:`foveatrack.atomic_file.written_whole`, synced to the disk with its directory), with the old
file's permissions (the recorder's 0600): the original stays whole until the new one is complete.
A recovery killed before its rename leaves its temporary, which the next one removes.  A recording
that was closed properly is left as it is (a no-op, said so), and so is one whose journal a running
daemon holds (its lock); the recording itself is held under its lock for the whole rewrite, so a second
recover of it at once is refused.  A journal line that cannot be read is reported and skipped.
"""

from __future__ import annotations

import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

from foveatrack.atomic_file import RenameRefused, leftovers, temporary_name, written_whole
from foveatrack.errors import UserError
from foveatrack.recording.format import COMMANDS, DAEMON_EVENTS, IMU, POINTS, PointsFrame, ImuSamples

UNRECORDED_SOURCES = ("", "homing")   # journal sources the daemon never records (outside the dead reckoning)


@dataclass
class Recovery:
    """What :func:`recover` did to one recording."""

    path: Path
    journal: Path
    already_complete: bool = False
    recovered: bool = False
    frames: int = 0
    records_copied: int = 0
    commands_recorded: int = 0
    journal_lines: int = 0
    commands_added: int = 0          # the dead reckoning's commands after the last record, replayed
    journal_only_added: int = 0      # the head got them; not replayed
    bad_lines: list[str] = field(default_factory=list)
    reader_problem: str | None = None

    def describe(self) -> str:
        """One line for people (``foveatrack recover`` prints it; the daemon logs it)."""
        if self.already_complete:
            return (f"{self.path}: complete (closed by its writer), nothing to recover"
                    + (f"; its journal {self.journal.name} holds {self.journal_lines} commands" if self.journal_lines
                       else ""))
        s = (f"{self.path}: recovered: {self.frames} frames and {self.records_copied} records read from the cut-short "
             f"file, {self.commands_added} command(s) after its last record added from {self.journal.name}"
             + ("" if self.journal.exists() else " (there is none: the file was only completed)"))
        if self.journal_only_added:
            s += (f", {self.journal_only_added} more the head got outside the dead reckoning (STOPs at start or while "
                  f"its pose was unknown, homing) added as journal_only")
        s += f"; the file now holds all {self.commands_recorded + self.commands_added + self.journal_only_added} " \
             f"commands (the journal has {self.journal_lines})"
        if self.bad_lines:
            s += f"; {len(self.bad_lines)} damaged journal line(s) skipped"
        return s


def head_after_a_kill(pan0_deg: float | None = None, tilt0_deg: float | None = None,
                      next_run: str = "the daemon's next run") -> str:
    """What a killed run leaves of the head (it reports no pose), said wherever its recording is
    completed: by the daemon's own start (with the config's start pose) and by ``foveatrack recover``
    (which has no config), so that a manual recover warns as the daemon's does."""
    where = (f"pan {pan0_deg:g} / tilt {tilt0_deg:g} deg" if pan0_deg is not None and tilt0_deg is not None
             else "its config's [head] pan0_deg / tilt0_deg")
    return (f"the head is where that run left it, and {next_run} assumes it at {where}; "
            "[head] on_start = \"home\" drives it home first (home_pan_deg / home_tilt_deg, by default there)")


class _LogTimes:
    """The rewritten file's log times: each message's own (set before it is written)."""

    def __init__(self, name: str):
        self.name = name
        self.current = 0

    def __call__(self, _t_ns: int) -> int:
        return self.current


def _command_fields(raw: bytes) -> tuple:
    """(pan_dir, pan_byte, tilt_dir, tilt_byte) of a Pelco pan/tilt or stop frame, else Nones."""
    from gimbal.errors import GimbalError
    from gimbal.pelco import decode

    try:
        c = decode(raw)
        if c.kind in ("stop", "pan_tilt"):
            return c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte
    except (GimbalError, ValueError):
        pass
    return None, None, None, None


def _match(recorded: list[dict], journal: list) -> tuple[list[bool], int]:
    """Which journal lines the recording holds (greedy, in order: same bytes and source), and the
    index after the last matched line."""
    used = [False] * len(journal)
    k = 0
    after = 0
    for r in recorded:
        raw, src = r.get("raw_hex"), r.get("source")
        for i in range(k, len(journal)):
            j = journal[i]
            if j.raw.hex() == raw and (src is None or j.source == src):
                used[i] = True
                k = after = i + 1
                break
    return used, after


def recover(path, journal=None, progress=None) -> Recovery:
    """Complete the recording at ``path`` from its command journal (module docstring); returns what
    was done.  ``progress(frames)`` is called every 100 frames copied.  UserError (one line) for a
    file that is not a recording or a journal a running driver holds."""
    from foveatrack.file_lock import hold, lock_holder, mark_recovering, unmark_recovering

    path = Path(path)
    # a symlink's target is what is rewritten (written_whole writes through it): its directory is the one
    # that must take the copy, and the one the leftovers are in
    real = Path(os.path.realpath(path))
    # the recording's own lock, held to the end (after the rename): a second recover of it (the daemon's
    # start and a user's, at once) cleared this one's copy between its writer's close and its rename
    lock, holder = hold(real), None
    deadline = time.monotonic() + 0.5
    while lock is None:
        holder = lock_holder(real)
        if holder is not None or time.monotonic() > deadline:
            break
        # held by no one: a reader's probe (recording_in_use) held it for an instant; going on without
        # the lock would let a second recover in (a file that cannot be locked at all goes on as before)
        time.sleep(0.01)
        lock = hold(real)
    if holder == "recover":
        raise UserError(f"{path} is being recovered by another process; let it finish, nothing was changed")
    if holder == "writer":
        # its writer's lock (foveatrack.file_lock): rewriting it now would lose what comes next
        raise UserError(f"{path} is still being written by a running process; stop it first (a stopped writer "
                        "completes its file itself), nothing was changed")
    # readers are told it is being recovered for as long as this mark is locked (file_lock.lock_holder)
    mark = mark_recovering(real) if lock is not None else None
    try:
        return _recover(path, real, journal, progress)
    finally:
        # the recording's lock first: a reader between the two finds the file free (file_lock.lock_holder)
        if lock is not None:
            os.close(lock)
        unmark_recovering(real, mark)


def _recover(path: Path, real: Path, journal, progress) -> Recovery:
    """:func:`recover` under the recording's lock."""
    from foveatrack.file_lock import recording_in_use
    from foveatrack.live_devices import journal_in_use, journal_path, read_journal
    from foveatrack.recording import RecordingReader, RecordingWriter, RecordingWriteError
    from foveatrack.recording.records import CommandRecord, ns

    jpath = journal_path(path) if journal is None else Path(journal)
    reader = RecordingReader(path)
    if jpath.exists() and journal_in_use(jpath):
        raise UserError(f"{path}: its command journal {jpath} is held by a running process (a daemon still writing "
                        "this recording); stop it first, nothing was changed")
    lines, bad = read_journal(jpath)
    res = Recovery(path, jpath, journal_lines=len(lines), bad_lines=bad)
    if reader.closed():
        res.already_complete = True
        return res
    if not reader.meta.get("source"):
        raise UserError(f"{path}: not a recording of a driver with a command journal (no 'source' in its metadata)")
    for tmp in leftovers(real):
        if not recording_in_use(tmp):    # a killed recovery's; a running one holds its writer's lock
            tmp.unlink(missing_ok=True)
    _check_can_replace(path, real)
    mode = path.stat().st_mode & 0o777
    meta = dict(reader.meta)
    meta["recovered_from_journal"] = {"journal": jpath.name, "created_utc": reader.info.get("created_utc")}
    clock = _LogTimes(reader.info.get("log_time", "host_utc"))
    recorded_cmds: list[dict] = []
    last_t_ns, last_log = 0, 0
    # overwrite: the writer makes its file itself (exclusively), in place of written_whole's empty one;
    # written_whole syncs it once, before the rename (a temporary cut short is thrown away anyway), and
    # removes it on any exception: nothing of the rewrite is left beside the recording
    try:
        with written_whole(path, fsync=True) as tmp, RecordingWriter(
                tmp, meta, overwrite=True, created_utc=reader.info.get("created_utc"), log_time=clock,
                file_mode=mode, segment_index=_segment_index(reader.info)) as writer:
            for log_time, m in reader.logged_messages():
                clock.current = last_log = max(log_time, 0)
                r = m.record
                if isinstance(r, PointsFrame):
                    writer.write_points(r.t_ns, r.frame_index, r.xyz, r.t_ns_points, r.reflectivity)
                    res.frames += 1
                    if progress is not None and res.frames % 100 == 0:
                        progress(res.frames)
                elif isinstance(r, ImuSamples):
                    writer.write_imu(r.t_ns, r.frame_id, r.t_s, r.gyro_rad_s, r.accel_g)
                elif isinstance(r, dict):
                    rec = dict(r)
                    rec.pop("t_ns", None)
                    writer.write(m.channel, m.t_ns, rec)
                    if m.channel == COMMANDS:
                        recorded_cmds.append(r)
                else:      # a later version's binary channel: this version cannot write it back
                    raise UserError(f"{path}: a {m.channel} message this foveatrack cannot write back (a later "
                                    "version's channel): recover it with the version that recorded it; nothing was changed")
                res.records_copied += 1
                last_t_ns = max(last_t_ns, m.t_ns)
            if reader.capped is not None:      # the rewrite would lose what the cap left unread
                raise UserError(f"{path}: {reader.capped_text()}; nothing was changed")
            res.reader_problem = reader.problem
            res.commands_recorded = len(recorded_cmds)
            used, after = _match(recorded_cmds, lines)
            # host monotonic -> sensor time, for a line without its own send time (the daemon's STOPs)
            offsets = [j.t_mono_s - j.send_t_s for j in lines if j.send_t_s is not None]
            offsets += [r["host_written_s"] - r["send_t_s"] for r in recorded_cmds
                        if isinstance(r.get("host_written_s"), (int, float)) and isinstance(r.get("send_t_s"), (int, float))]
            offset = statistics.median(offsets) if offsets else None
            for i, j in enumerate(lines):
                if used[i]:
                    continue
                pd, pb, td, tb = _command_fields(j.raw)
                replayed = (i >= after and j.source not in UNRECORDED_SOURCES and j.send_t_s is not None
                            and pd is not None)
                send_t = j.send_t_s if j.send_t_s is not None else (
                    j.t_mono_s - offset if offset is not None else None)
                t_ns = ns(send_t) if send_t is not None and send_t >= 0 else last_t_ns
                clock.current = int(j.t_unix_s * 1e9) if j.t_unix_s is not None else last_log
                rec = CommandRecord(t_ns, j.raw, pd, pb, td, tb, frame_id=None, source=j.source or "unrecorded",
                                    send_t_s=send_t, host_written_s=j.t_mono_s).to_json()
                rec["from_journal"] = True
                rec["journal_line"] = j.line_no
                if not replayed:
                    rec["journal_only"] = True
                writer.write(COMMANDS, t_ns, rec)
                res.commands_added += replayed
                res.journal_only_added += not replayed
            clock.current = last_log
            writer.write(DAEMON_EVENTS, last_t_ns, {
                "event": "recovered", "commands_added": res.commands_added, "journal_only_added": res.journal_only_added,
                "journal": jpath.name, "journal_lines": len(lines), "bad_journal_lines": len(bad),
                "frames": res.frames, "reader_problem": res.reader_problem})
    except RecordingWriteError as exc:
        # the completed copy, not the recording, could not be written: say it of the recording
        # the space it needs is said for a full disk only (not an I/O error, a quota, a file-size limit)
        need = (f"; it needs about {real.stat().st_size:,} bytes free in {real.parent}" if exc.disk_full else "")
        raise UserError(f"{path}: not recovered: its completed copy could not be written beside it "
                        f"({exc.why}){need}; nothing was changed") from None
    except RenameRefused as exc:
        # the probe above showed the directory takes a new file: what is refused is the rename over it
        raise UserError(f"{path}: not recovered: the completed copy could not replace it "
                        f"({exc.strerror or exc}{_replace_hint(real)}); nothing was changed") from None
    res.recovered = True
    return res


def _check_can_replace(path: Path, real: Path) -> None:
    """Before any work: the completed copy is written beside the recording (``real``: ``path`` resolved,
    a symlink's target) and renamed over it, so that directory must take a new file (a directory this
    user may not write failed only at the copy, naming the hidden temporary).  The probe is named as
    written_whole names its temporaries (:func:`temporary_name`), so one left by a kill between its two
    lines is cleared as theirs are."""
    tmp = temporary_name(real)
    try:
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600))
    except OSError as exc:
        raise UserError(f"{path}: not recovered: recover writes the completed file beside it and renames it "
                        f"over it, and {real.parent} does not take a new file ({exc.strerror or exc}): copy the "
                        f"recording and its {path.name}.commands.jsonl to a directory you can write, and "
                        "recover the copy; nothing was changed") from None
    tmp.unlink(missing_ok=True)


def _replace_hint(path: Path) -> str:
    """Why a rename over ``path`` is refused where its directory is writable: a sticky directory
    (/tmp) lets only a file's owner replace it."""
    import stat

    try:
        d, f = path.parent.stat(), path.stat()
    except OSError:
        return ""
    me = os.geteuid()
    if d.st_mode & stat.S_ISVTX and me not in (f.st_uid, d.st_uid):
        from foveatrack.errors import owner_names

        owner = owner_names(f)[0]
        return (f": {path.name} belongs to {owner}, and in a directory with the sticky bit (as /tmp) only its "
                f"owner may replace it: let {owner} recover it, or recover a copy of it and its journal")
    return ""


def unfinished_recordings(directory) -> list[Path]:
    """Recordings in ``directory`` that have a command journal and were not closed by their writer,
    whose journal no running process holds (a killed daemon's), oldest first."""
    from foveatrack.live_devices import JOURNAL_SUFFIX, journal_in_use
    from foveatrack.recording import RecordingReader

    out = []
    d = Path(directory)
    if not d.is_dir():
        return out
    for j in sorted(d.glob("*" + JOURNAL_SUFFIX), key=lambda p: p.stat().st_mtime):
        rec = j.with_name(j.name[:-len(JOURNAL_SUFFIX)])
        if not rec.is_file() or journal_in_use(j):
            continue
        try:
            if not RecordingReader(rec).closed():
                out.append(rec)
        except UserError:
            continue          # not a recording (cut short before its metadata): nothing to complete
    return out


def _segment_index(info: dict) -> int:
    """A segment's place in its run (:mod:`foveatrack.recording.segments`), kept by the rewrite."""
    k = str(info.get("segment_index", "0"))
    return int(k) if k.isdigit() else 0


def recover_directory(directory, log_event=None, exclude=()) -> list[Recovery]:
    """Complete every unfinished recording in ``directory`` from its journal (the daemon's start: a
    killed run's recording); each said on stderr and as a ``recording_recovered`` log event (or
    ``recording_recovery_failed`` with the reason: a start never fails for an old recording)."""
    import sys

    done = []
    skip = {Path(p).resolve() for p in exclude}
    for rec in unfinished_recordings(directory):
        if rec.resolve() in skip:
            continue
        try:
            res = recover(rec)
        except (UserError, OSError) as exc:
            msg = f"{rec}: not recovered: {exc}"
            print(f"WARNING: {msg}", file=sys.stderr, flush=True)
            if log_event is not None:
                log_event("recording_recovery_failed", recording=str(rec), reason=str(exc))
            continue
        print(f"foveatrack: {res.describe()}", file=sys.stderr, flush=True)
        for line in res.bad_lines:
            print(f"WARNING: {line}", file=sys.stderr, flush=True)
        if log_event is not None:
            log_event("recording_recovered", recording=str(rec), message=res.describe(), frames=res.frames,
                      commands_added=res.commands_added, journal_only_added=res.journal_only_added,
                      journal_lines=res.journal_lines, bad_journal_lines=res.bad_lines)
        done.append(res)
    return done
