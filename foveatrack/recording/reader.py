"""Reading a recording: :class:`RecordingReader`, which skips damaged chunks and says what it skipped."""

from __future__ import annotations

import json
import mmap
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

from foveatrack.errors import UserError
from foveatrack.file_lock import lock_holder
from foveatrack.mcap_names import journal_path
from foveatrack.recording import mcap_walk as mw
from foveatrack.recording.format import (CHANNELS_META_NAME, DETECTIONS, FORMAT, IMU, MCAP_MAGIC, META_CRC_KEY,
                                         META_NAME, POINTS, READABLE_VERSIONS, VIEW_CHANNELS, ImuSamples, Message,
                                         PointsFrame, _decode_points, decode_imu_pb, decode_points_legacy_v2_v3,
                                         decode_points_v4, meta_crc32)


@dataclass(frozen=True)
class Damage:
    """One stretch of a recording the reader skipped.

    start_byte, end_byte : the bytes ``[start_byte, end_byte)`` that were skipped
    reason : what was wrong at ``start_byte`` (a chunk's CRC, an unreadable record, ...)
    cut_short : the stretch is an incomplete last record: the file ends inside it
    lost : messages lost per channel, from the message index the writer put after each chunk
        (None when no index of the lost data survived, e.g. a cut-short tail)
    lost_exact : ``lost`` is the whole of what the stretch held; False: at least that much
    lost_t_ns : (first, last) log time of the lost messages when known [ns]
    frames_before : lidar frames read before the stretch
    """

    start_byte: int
    end_byte: int
    reason: str
    cut_short: bool = False
    lost: dict[str, int] | None = None
    lost_exact: bool = False
    lost_t_ns: tuple[int, int] | None = None
    frames_before: int = 0

    @property
    def frames_lost(self) -> int | None:
        """Lidar frames lost in the stretch (a lower bound unless ``lost_exact``), None if unknown."""
        return None if self.lost is None else self.lost.get(POINTS, 0)

    def describe(self) -> str:
        """One line: which bytes, why, and what was lost."""
        where = f"bytes {self.start_byte}-{self.end_byte}"
        if self.cut_short:
            what = f"file cut short at byte {self.start_byte}: {self.reason} ({where})"
        else:
            what = f"skipped {where} ({self.end_byte - self.start_byte} bytes): {self.reason}"
        if self.lost is None:
            what += "; the messages in it are lost" if self.cut_short else \
                "; what it held is unknown (no index of it survived)"
        elif not self.lost:
            what += ("; no message in it (index bytes only)" if self.lost_exact else
                     "; no lost messages are known (no index of a damaged chunk survived)")
        else:
            n_f = self.lost.get(POINTS, 0)
            n_o = sum(self.lost.values()) - n_f
            exact = "" if self.lost_exact else "at least "
            what += (f"; {exact}{n_f} frame{'' if n_f == 1 else 's'} and {n_o} other record{'' if n_o == 1 else 's'}"
                     f" lost ({', '.join(f'{k} {v}' for k, v in sorted(self.lost.items()))})")
        if self.cut_short and self.lost is not None:
            # what the writer would have written after the cut is not in the file: say so (a stretch
            # with no message in it read as "nothing lost" of a run cut in half, a user's audit)
            what += "; whatever was written after it is not in the file"
        if self.lost_t_ns is not None:
            t0, t1 = self.lost_t_ns
            what += f", log time {_log_time_text(t0)}" if t0 == t1 else \
                f", log times {_log_time_text(t0)} to {_log_time_text(t1)}"
        return what


def _log_time_text(t_ns: int) -> str:
    """A log time as people read it: UTC where it is one (a recording since log times in UTC), else
    seconds (virtual or sensor time, as older recordings logged)."""
    if t_ns < UTC_LOG_TIMES_FROM_NS:
        return f"{t_ns / 1e9:.3f} s"
    import datetime as dt

    return dt.datetime.fromtimestamp(t_ns // 10**9, dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S") + \
        f".{t_ns % 10**9 // 10**6:03d} UTC"


UTC_LOG_TIMES_FROM_NS = 10**18    # 2001-09-09: no sensor or virtual clock runs that long

# The cap on lidar frames read from one file.  A frame takes ~31 bytes on disk at the least (an empty
# frame alone in a zstd chunk of 1000, flush_every_frames' maximum; ~300 bytes one per chunk), but a
# crafted chunk of identical messages claims a frame per 0.25 byte within the decompression cap
# (mcap_walk.MAX_CHUNK_RATIO): a 1 MB file, 4 M frames and gigabytes of replay and export.  So a file
# yields at most one frame per MIN_BYTES_PER_FRAME of its size, and any file FRAME_CAP_FLOOR frames.
MIN_BYTES_PER_FRAME = 8
FRAME_CAP_FLOOR = 10_000


def frame_cap(size_bytes: int) -> int:
    """The most lidar frames a recording of ``size_bytes`` is read for (see MIN_BYTES_PER_FRAME)."""
    return max(FRAME_CAP_FLOOR, int(size_bytes) // MIN_BYTES_PER_FRAME)


def read_head(path, n: int) -> bytes:
    """The first ``n`` bytes of a recording (or an ``.lvx``), to tell what it is; a UserError naming who
    may read it where this user may not: the writer makes a recording its owner's alone (0600), so a
    user replaying a service's recording met a bare "Permission denied"."""
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except PermissionError:
        from foveatrack.errors import access_text

        raise UserError(f"{path}: this user may not read it ({access_text(path)}); read it as its owner, or have "
                        "them share it (a copy, or chmod g+r and a group this user is in): foveatrack makes a "
                        "recording readable by its owner only (it holds the configuration)") from None


class RecordingReader:
    """Read a recording, also one cut short or damaged: nothing that was recorded and is intact is lost.

    ``meta`` (the writer's meta dict), ``info`` (format and versions); :meth:`messages` iterates
    in file order.  After a full iteration: ``complete`` says whether the data section ended properly
    (the writer was closed); ``damage`` lists each stretch of bytes skipped (:class:`Damage`: byte range,
    why, which messages were lost) and ``problem`` sums them up in one line (None if nothing was skipped).

    A damaged chunk (CRC mismatch, garbage over it, its length field included) is skipped and reading
    resumes at the next chunk whose header holds together and whose CRC verifies -- found by scanning
    the bytes, not by trusting a length that may itself be damaged.  Messages of a channel whose
    definition was in a damaged chunk are attributed by the channel table the writer puts in the
    metadata (or the file's summary, for recordings written before it did); messages of a channel
    that no intact record names are counted in ``problem``.
    Reading stops after ``max_frames`` lidar frames (default :func:`frame_cap` of the file's size: a
    crafted file claiming millions of frames ends in bounded memory and time); ``capped`` then says
    where, and ``problem`` and :meth:`warning` say so.
    Raises UserError naming the file if it is not a foveatrack recording.
    """

    def __init__(self, path: str | os.PathLike, max_frames: int | None = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise UserError(f"recording {self.path} does not exist or is not a file")
        self.size = self.path.stat().st_size
        if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, int)
                                       or max_frames < 1):
            raise UserError(f"max_frames {max_frames!r}: give a whole number of frames >= 1")
        self.max_frames = frame_cap(self.size) if max_frames is None else max_frames
        #: (byte offset where reading stopped, frames read) when the frame cap stopped it, else None
        self.capped: tuple[int, int] | None = None
        head = read_head(self.path, len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            what = "is empty" if self.size == 0 else "does not start with the MCAP magic"
            if 0 < self.size < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(head):
                what = f"is cut short after {self.size} bytes, before its metadata"
            raise UserError(f"{self.path} is not a foveatrack recording: the file {what}")
        self.info: dict[str, str] = {}
        self.meta: dict = {}
        self.complete: bool | None = None
        self.damage: list[Damage] = []
        self.unattributed: dict[int, int] = {}
        self._meta_channels: dict[int, str] = {}
        self._summary: tuple[int, int] | None = None
        self._channels_read: dict[int, str] = {}
        self._binary: set[str] = set()     # channels whose Channel record names an encoding other than JSON
        self._summary_channels: dict[int, str] | None = None
        self._require_crc = False          # the writer says it gave every chunk a CRC (chunk_crcs)
        #: the metadata record's checksum: True (verified), None (a recording made before it had one)
        self.meta_checked: bool | None = None
        for _ in self._records(stop_after_meta=True):
            break      # our writer puts its metadata before any message: a message first is not ours
        if not self.info:
            raise UserError(self._why_no_meta())

    def _why_no_meta(self) -> str:
        """The error for a file that starts with the MCAP magic and has no metadata record of ours, in
        words: a valid MCAP from another program (its Header names the writer), one of ours cut short
        or damaged before its metadata (its Header's profile says ours), or damage."""
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            profile = library = None
            try:
                op, length = mw.REC.unpack_from(mm, len(MCAP_MAGIC))
                if op == mw.OP_HEADER and len(MCAP_MAGIC) + mw.REC.size + length <= self.size:
                    profile, i = mw.string(mm, len(MCAP_MAGIC) + mw.REC.size)
                    library, _ = mw.string(mm, i)
            except (struct.error, mw.BadRecord):
                pass
            closed = self._data_end_pos(mm) is not None
        no_meta = f"no '{META_NAME}' metadata record"
        not_ours = f"{self.path} is not a foveatrack recording"
        ours = f"{self.path} is a foveatrack recording (its Header's profile) without its metadata"
        if profile == "foveatrack" and self.damage:
            # ours, cut or damaged before its metadata: a recording that holds nothing replayable
            return f"{ours}: damaged or cut short before it ({self.problem})"
        if self.damage:
            return f"{not_ours}: {no_meta} ({self.problem})"
        if profile is None:
            return f"{not_ours}: {no_meta} and no MCAP Header record after the magic"
        if profile != "foveatrack":
            by = f"written by {library!r}" if library else "whose Header names no writer"
            return (f"{not_ours}: {'a valid' if closed else 'an unfinished'} MCAP file {by} (profile {profile!r}) "
                    f"with {no_meta}: foveatrack replays and exports only what 'simulate --out' and 'daemon' record "
                    f"(Foxglove opens any MCAP)")
        if closed:
            return f"{ours}: {no_meta} in a closed file (its metadata was never written)"
        return (f"{ours}: the file ends at byte {self.size} before it, its writer not closed (cut short "
                f"right after it started, e.g. kill -9 or power loss)")

    # ------------------------------------------------------------------ reporting

    @property
    def problem(self) -> str | None:
        """One line saying what was skipped (None: nothing)."""
        parts = self._skipped(self.damage)
        if self.capped is not None:
            parts.append(self.capped_text())
        if not parts and self.complete is False:
            parts.append(f"the file ends at byte {self.size} without its end-of-data record: the writer was not "
                         f"closed (cut short, e.g. kill -9 or power loss); every whole chunk before it was read")
        return "; ".join(parts) if parts else None

    def _skipped(self, damage) -> list[str]:
        """What ``damage`` (some of :attr:`damage`) and the messages of unknown channels lost, a phrase each."""
        parts = [d.describe() for d in damage]
        if self.unattributed:
            n = sum(self.unattributed.values())
            parts.append(f"{n} message(s) of channel id(s) {sorted(self.unattributed)} skipped: their channel "
                         f"was defined in a damaged chunk")
        return parts

    def damage_not_held(self) -> list:
        """The skipped stretches that are damage: every one, but for a file a running process holds
        (:meth:`held_text`) its cut-short end, which is that process's next bytes (a writer's) or what
        it completes (a recover's).  A stretch skipped before the end is damage all the same."""
        if self.held_text() is not None and self.damage and self.damage[-1].cut_short:
            return self.damage[:-1]
        return list(self.damage)

    def capped_text(self) -> str | None:
        """One line naming what the frame cap left unread (None: it did not stop the reading)."""
        if self.capped is None:
            return None
        pos, n = self.capped
        why = ("--max-frames" if self.max_frames != frame_cap(self.size) else
               f"at most one frame per {MIN_BYTES_PER_FRAME} bytes of the file, and any file {FRAME_CAP_FLOOR}: "
               f"more is a crafted or damaged file; --max-frames N raises it")
        return (f"reading stopped at byte {pos} of {self.size} after {n} frames, the cap on frames per file "
                f"({why}): the rest of the file was not read")

    def held_text(self) -> str | None:
        """The sentence for an unfinished file a running process holds under its lock (after a full
        iteration; ``replay`` and ``export`` alike), None otherwise: its end is then not damage."""
        if self.complete is True:
            return None
        if self.held_by == "recover":
            # recover holds the file's lock while it writes the completed file beside it: not a writer
            return (f"{self.path} is being recovered by a running 'foveatrack recover': read what the cut-short "
                    f"file held up to byte {self.size}; run this again once the recover has finished (it replaces "
                    f"the file with the completed one)")
        if self.held_by == "writer":
            # a writer holds it (foveatrack.file_lock): its end is the writer's next bytes, not damage
            return (f"{self.path} is still being written by a running process: read what it held up to "
                    f"byte {self.size} (its end is the writer's next data, not damage)")
        return None

    def warning(self) -> str | None:
        """The line a command prints after reading the whole recording (``replay`` and ``export`` alike):
        ``WARNING: damaged recording, ...`` naming every skipped stretch and what it held, a ``note``
        for a file whose writer was not closed, None for an intact closed file."""
        problem = self.problem
        if problem is None:
            return None
        held = self.held_text()
        if held is not None:
            # its end is not damage; a stretch skipped before it is, and is said first
            damaged = self._skipped(self.damage_not_held())
            return "\n".join(([f"WARNING: damaged recording {self.path}, {'; '.join(damaged)}"] if damaged else [])
                             + [f"note: {held}"])
        if self.damage or self.unattributed:
            return f"WARNING: damaged recording {self.path}, {problem}{self._recover_hint()}"
        if self.capped is not None:
            return f"WARNING: recording {self.path} read in part: {problem}"
        return f"note: {self.path}: {problem}"

    def _recover_hint(self) -> str:
        """A daemon's recording cut short (kill -9, power loss) with its command journal beside it:
        what completes it (replay and export said only what was damaged, a user's audit)."""
        journal = journal_path(self.path)
        if self.complete or not journal.exists():
            return ""
        return (f"; its command journal {journal.name} is beside it: `foveatrack recover {self.path}` completes "
                f"it (the commands after its last record, and a closed file)")

    # ------------------------------------------------------------------ walking the file

    def _records(self, stop_after_meta: bool = False) -> Iterator[tuple[str, int, bytes]]:
        """Yield (channel name, log time [ns], payload) in file order, skipping damage (see class doc)."""
        self.complete = False
        self.damage = []
        self.unattributed = {}
        self.capped = None
        self.held_by = lock_holder(self.path)     # "writer", "recover" or None (foveatrack.file_lock)
        self.in_use = self.held_by is not None
        size = self.size
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            data_end = self._data_end_pos(mm)
            channels: dict[int, str] = {}
            self._channels_read = channels
            frames = 0
            pos = len(MCAP_MAGIC)
            prev_ok = prev_times = None   # opcode of the last record read intact; the last intact chunk's times
            while True:
                if pos == size:
                    return
                if pos == data_end:
                    self.complete = True
                    return
                try:
                    if size - pos < mw.REC.size:
                        raise mw.BadRecord(f"{size - pos} stray byte(s) after the last whole record")
                    op, length = mw.REC.unpack_from(mm, pos)
                    body = pos + mw.REC.size
                    end = body + length
                    if op not in mw.TOP_LEVEL_OPS:
                        raise mw.BadRecord(f"no MCAP record starts there (opcode 0x{op:02x})")
                    if end > size:
                        raise mw.BadRecord(f"a record whose length field ({length} bytes) runs past the end of the file")
                    if op == mw.OP_CHUNK:
                        recs = mw.chunk_records(mm, pos, length, self._require_crc)
                    elif op == mw.OP_MINDEX:
                        mw.message_index(mm, body, length)
                        recs = ()
                    elif op == mw.OP_DATA_END:
                        if length != 4:
                            raise mw.BadRecord("a damaged end-of-data record")
                        self.complete = True
                        return
                    elif op == mw.OP_FOOTER:
                        raise mw.BadRecord("a footer where data was expected")
                    elif op == mw.OP_METADATA:
                        recs = ((op, mw.metadata(mm[body:end])),)
                    elif op in (mw.OP_MESSAGE, mw.OP_CHANNEL):
                        if op == mw.OP_MESSAGE and length < mw.MSG_HEAD.size:
                            raise mw.BadRecord("a damaged message record")
                        content = mw.channel(mm[body:end]) if op == mw.OP_CHANNEL else memoryview(mm[body:end])
                        recs = ((op, content),)
                    else:
                        recs = ()
                except mw.BadRecord as exc:
                    if stop_after_meta and not self.info:
                        self.damage.append(Damage(pos, size, str(exc)))
                        return
                    resume, found = self._resync(mm, pos, data_end)
                    self.damage.append(self._account(mm, pos, resume, str(exc), prev_ok, prev_times, frames, found))
                    prev_ok = prev_times = None
                    if resume is None:
                        return
                    pos = resume
                    continue
                for rop, content in recs:
                    if rop == mw.OP_MESSAGE:
                        cid, _seq, log_time, _pub = mw.MSG_HEAD.unpack_from(content, 0)
                        name = channels.get(cid) or self._fallback_channel(cid)
                        if name is None:
                            self.unattributed[cid] = self.unattributed.get(cid, 0) + 1
                            continue
                        if name == POINTS:
                            if frames >= self.max_frames:
                                self.capped = (pos, frames)
                                return
                            frames += 1
                        yield name, log_time, bytes(content[mw.MSG_HEAD.size:])
                    elif rop == mw.OP_CHANNEL:
                        cid, topic, encoding = content       # parsed (and checked) where it was read
                        channels[cid] = topic
                        if encoding != "json":
                            self._binary.add(topic)
                    elif rop == mw.OP_METADATA and content[0] == CHANNELS_META_NAME:
                        self._add_channel_table(content[1])
                    elif rop == mw.OP_METADATA and not self.info and content[0] == META_NAME:
                        self._set_meta(content[1])
                        if stop_after_meta:
                            self.complete = None     # not known until a full walk
                            yield "", 0, b""
                            return
                if op == mw.OP_CHUNK:
                    prev_times = mw.chunk_times(mm, pos, size)
                prev_ok = op
                pos = end

    def _data_end_pos(self, mm) -> int | None:
        """Where the end-of-data record sits, from the footer of a closed file (None: no valid footer)."""
        size = self.size
        f = size - len(MCAP_MAGIC) - mw.FOOTER_SIZE
        if f < len(MCAP_MAGIC) or mm[size - len(MCAP_MAGIC):] != MCAP_MAGIC:
            return None
        op, length = mw.REC.unpack_from(mm, f)
        if op != mw.OP_FOOTER or length != 20:
            return None
        summary_start, _summary_offset_start, summary_crc = struct.unpack_from("<QQI", mm, f + 9)
        if summary_start:
            if not len(MCAP_MAGIC) < summary_start <= f or zlib.crc32(mm[summary_start:f + 9 + 16]) != summary_crc:
                return None
            de = summary_start - mw.DATA_END_SIZE
        else:
            de = f - mw.DATA_END_SIZE
        if de < len(MCAP_MAGIC) or mw.REC.unpack_from(mm, de) != (mw.OP_DATA_END, 4):
            return None
        if summary_start:
            self._summary = (summary_start, f)
        return de

    def _fallback_channel(self, cid: int) -> str | None:
        """The name of a channel whose definition was not read (it was in a damaged chunk)."""
        name = self._channels_read.get(cid) or self._meta_channels.get(cid)
        if name is not None:
            return name
        if self._summary_channels is None:
            self._summary_channels = self._read_summary_channels()
        return self._summary_channels.get(cid)

    def _read_summary_channels(self) -> dict[int, str]:
        out: dict[int, str] = {}
        span = self._summary
        if span is None:
            return out
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            pos, stop = span
            while pos + mw.REC.size <= stop:
                op, length = mw.REC.unpack_from(mm, pos)
                end = pos + mw.REC.size + length
                if end > stop:
                    break
                if op == mw.OP_CHANNEL:
                    try:
                        cid, topic, encoding = mw.channel(mm[pos + mw.REC.size:end])
                    except mw.BadRecord:    # the summary's CRC held: a writer's fault, not ours to name
                        pos = end
                        continue
                    out[cid] = topic
                    if encoding != "json":
                        self._binary.add(topic)
                pos = end
        return out

    def _resync(self, mm, pos: int, data_end: int | None) -> tuple[int | None, list[int]]:
        """The next place to read on from after damage at ``pos``: the first chunk after it whose
        header holds together and whose CRC verifies, else the end-of-data record (closed file),
        else None.  Also returns the positions of chunks after ``pos`` whose header holds together
        but whose contents do not (damaged chunks in the stretch)."""
        stop = self.size if data_end is None else data_end
        found: list[int] = []
        p = pos
        scan = mw.ByteScan(mm, stop, bytes([mw.OP_CHUNK, mw.OP_METADATA]))
        self._last_scan = scan
        while True:
            p = scan.next(p)
            if p < 0:
                return data_end, found
            if mm[p] == mw.OP_METADATA:
                if p > pos and self._channel_table_at(mm, p, stop):
                    return p, found
                p += 1
                continue
            length = mw.chunk_length(mm, p, stop)
            if length is not None:
                try:
                    mw.chunk_records(mm, p, length, self._require_crc)
                    if p > pos:
                        return p, found
                except mw.BadRecord:
                    pass
                found.append(p)
            p += 1

    @staticmethod
    def _channel_table_at(mm, p: int, stop: int) -> bool:
        """A whole channel-table metadata record starts at ``p`` (the writer puts one after the chunk
        where channels first appear: reading resumes there, so a damaged chunk does not take it along)."""
        if p + mw.REC.size > stop:
            return False
        _op, length = mw.REC.unpack_from(mm, p)
        end = p + mw.REC.size + length
        if end > stop or length > (1 << 20):
            return False
        name = CHANNELS_META_NAME.encode()
        if mm[p + mw.REC.size:p + mw.REC.size + 4 + len(name)] != mw.U32.pack(len(name)) + name:
            return False        # not its name: no copy of up to 1 MiB per metadata opcode byte
        try:
            name, _md = mw.metadata(mm[p + mw.REC.size:end])
        except mw.BadRecord:
            return False
        return name == CHANNELS_META_NAME

    def _account(self, mm, pos, resume, reason, prev_ok, prev_times, frames, found) -> Damage:
        """What the skipped stretch ``[pos, resume)`` held, from the message index the writer put after
        each chunk: exact for a damaged chunk whose header holds (its index starts where it ends), a
        lower bound when the stretch starts with bytes that do not hold together (the index found
        just before the next readable record); index records of the intact chunk before the stretch
        (their times lie in its time range) are not counted as lost."""
        size = self.size
        end = size if resume is None else resume
        heads = sorted({p for p in found if pos <= p < end})
        bounds = ([] if heads and heads[0] == pos else [pos]) + heads + [end]
        lost: dict[int, int] | None = None
        times: list[int] = []
        exact = True

        in_intact_index = False

        def add(chain, skip=None):
            nonlocal lost, in_intact_index
            lost = {} if lost is None else lost
            for cid, ts in chain:
                if skip is not None and ts and all(skip[0] <= t <= skip[1] for t in ts):
                    in_intact_index = True
                    continue
                lost[cid] = lost.get(cid, 0) + len(ts)
                times.extend(ts)

        for s, e in zip(bounds, bounds[1:]):
            if s in heads:                      # a damaged chunk whose header holds together
                after = s + mw.REC.size + mw.U64.unpack_from(mm, s + 1)[0]
                chain = mw.index_chain(mm, after, e)
                if chain is not None:
                    add(chain)
                    continue
                exact = False
                chain = mw.index_chain_ending_at(mm, after, e)
            else:                               # bytes that do not hold together
                exact = False
                chain = mw.index_chain_ending_at(mm, s, e)
            if chain:
                add(chain, prev_times if s == pos and prev_ok in (mw.OP_CHUNK, mw.OP_MINDEX) else None)
        cut_short = resume is None and mw.record_runs_past(mm, pos, size)
        if cut_short:
            if mm[pos] == mw.OP_MINDEX and prev_ok in (mw.OP_CHUNK, mw.OP_MINDEX):
                reason, lost, exact = "its last record, a message index of the chunk before it, is incomplete", {}, True
            else:
                reason = "its last record is incomplete"
                t = mw.chunk_times(mm, pos, size)
                if t is not None:
                    times.extend(t)
        elif resume is None:
            reason += "; no readable chunk after it"
        if in_intact_index and not cut_short:
            reason += " (in the message index of the intact chunk before it)"
        names: dict[str, int] | None = None
        if lost is not None:
            names = {}
            for cid, n in lost.items():
                name = self._fallback_channel(cid) or f"channel id {cid}"
                names[name] = names.get(name, 0) + n
        return Damage(pos, end, reason, cut_short, names, exact and lost is not None,
                      (min(times), max(times)) if times else None, frames)

    def _set_meta(self, md: dict[str, str]) -> None:
        if META_CRC_KEY in md:
            if md[META_CRC_KEY] != meta_crc32(md):
                raise UserError(f"{self.path}: its metadata record is damaged (checksum {META_CRC_KEY} "
                                f"{md[META_CRC_KEY]!r}, its contents give {meta_crc32(md)!r}): the format version, "
                                f"configuration and speed table in it cannot be trusted")
            self.meta_checked = True
        self._require_crc = md.get("chunk_crcs") == "required"
        if md.get("format") != FORMAT:
            raise UserError(f"{self.path} is an MCAP file but not a foveatrack recording (format {md.get('format')!r})")
        if md.get("format_version") not in READABLE_VERSIONS:
            raise UserError(
                f"{self.path} has recording format version {md.get('format_version')!r}; "
                f"this foveatrack reads versions {', '.join(READABLE_VERSIONS)}"
            )
        self.info = dict(md)
        try:
            self.meta = json.loads(md.get("meta_json", "{}"))
            self._meta_channels = {int(k): v for k, v in json.loads(md.get("channels_json", "{}")).items()}
            if not isinstance(self.meta, dict):
                raise ValueError("not an object")
        except (ValueError, AttributeError, TypeError, RecursionError):
            raise UserError(f"{self.path}: its metadata JSON is damaged") from None

    def _add_channel_table(self, md: dict[str, str]) -> None:
        try:
            self._meta_channels.update({int(k): v for k, v in json.loads(md.get("channels_json", "{}")).items()})
        except (ValueError, AttributeError, TypeError, RecursionError):
            pass    # a damaged table: the Channel records (or the summary) still name the channels

    # ------------------------------------------------------------------ public reading

    def messages(self, channels: Iterable[str] | str | None = None) -> Iterator[Message]:
        """Messages in file order, optionally only those of ``channels`` (names without '/'); a
        message's ``t_ns`` is its record's own (the sensor's or simulator's clock), not the MCAP log
        time, which may be UTC (``log_time`` in the metadata; the view channels' messages: the log
        time).  A channel this version does not know gives its records if its encoding is JSON, its raw bytes
        otherwise (a later version's binary channel: read past, not taken for damage)."""
        for _log_time, m in self.logged_messages(channels):
            yield m

    def logged_messages(self, channels: Iterable[str] | str | None = None) -> Iterator[tuple[int, Message]]:
        """``(MCAP log time [ns], message)`` as :meth:`messages` gives them (a recording rewritten
        with its own log times: :mod:`foveatrack.daemon.recover`)."""
        want = {channels} if isinstance(channels, str) else None if channels is None else set(channels)
        if self.info.get("format_version") in ("1", "2", "3"):
            return self._messages(want)
        # format 4: a frame's index is in its /detections record, read along whether asked for or not
        inner = None if want is None else want | {DETECTIONS} if POINTS in want else want
        return with_frame_index(self._messages(inner), want)

    def _messages(self, want: set[str] | None) -> Iterator[Message]:
        version = self.info.get("format_version")
        for name, log_time, data in self._records():
            if want is None and name in VIEW_CHANNELS:
                continue        # drawn for Foxglove from the records (protobuf); asked for by name: raw bytes
            if want is not None and name not in want:
                continue
            if name in VIEW_CHANNELS:
                yield int(log_time), Message(name, int(log_time), data)
                continue
            try:
                if name == POINTS:
                    record = (_decode_points(data) if version == "1" else
                              decode_points_legacy_v2_v3(data, version == "3") if version in ("2", "3") else
                              decode_points_v4(data))
                elif name == IMU:
                    record = decode_imu_pb(data)
                elif name in self._binary:
                    # a later version's binary channel, which this one does not know: its raw bytes,
                    # not "damaged" for being new
                    record = bytes(data)
                else:
                    record = json.loads(data)
                    if not isinstance(record, dict):    # every record we write is an object
                        raise TypeError(f"a JSON {type(record).__name__}, not an object")
            except RecursionError:
                raise UserError(f"{self.path}: a {name} message at log time {log_time} ns is damaged: JSON "
                                f"nested too deep") from None
            except (ValueError, KeyError, TypeError) as exc:
                raise UserError(f"{self.path}: a {name} message at log time {log_time} ns is damaged: {exc}") from None
            yield int(log_time), Message(name, _record_t_ns(record, log_time), record)

    def points(self) -> Iterator[PointsFrame]:
        """The lidar frames, in order."""
        for m in self.messages(POINTS):
            yield m.record

    def imu(self) -> Iterator[ImuSamples]:
        """The IMU batches fed to the tracker, one per frame, in order (none in a recording made
        before the channel existed, or of a run without an IMU)."""
        for m in self.messages(IMU):
            yield m.record

    def records(self, channel: str) -> list[dict]:
        """All JSON records of one channel."""
        return [m.record for m in self.messages(channel)]

    def closed(self) -> bool:
        """Whether the file was closed by its writer (a valid footer and end-of-data record), from its
        last bytes alone: a recording cut short (kill -9, power loss) is not."""
        with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            return self._data_end_pos(mm) is not None

    def channels(self) -> dict[str, int]:
        """Message count per channel (reads the whole file)."""
        out: dict[str, int] = {}
        for name, _t, _d in self._records():
            out[name] = out.get(name, 0) + 1
        return out


def with_frame_index(messages: Iterable[tuple[int, Message]], want: set[str] | None) -> Iterator[tuple[int, Message]]:
    """Format 4's ``(log time, message)`` pairs with each frame's index filled in (those of ``want``,
    all if None): a frame (``/points``, with ``frame_index`` -1) waits, with what follows it, for the
    first ``/detections`` record after it (every driver writes one right after the points, in the same
    chunk), whose ``frame_index`` it takes.  A frame without one before the next frame or the end (a
    file of points alone) takes the frame before it's index + 1 (the first: 0)."""
    from dataclasses import replace

    held: list[tuple[int, Message]] = []
    last = -1

    def release(k: int) -> Iterator[tuple[int, Message]]:
        log_time, pts = held[0]
        if want is None or POINTS in want:
            yield log_time, Message(pts.channel, pts.t_ns, replace(pts.record, frame_index=k))
        yield from (lm for lm in held[1:] if want is None or lm[1].channel in want)
        held.clear()

    for lm in messages:
        m = lm[1]
        if m.channel == POINTS:
            if held:
                last += 1
                yield from release(last)
            held.append(lm)
            continue
        if not held:
            if want is None or m.channel in want:
                yield lm
            continue
        held.append(lm)
        if m.channel == DETECTIONS and isinstance(m.record, dict):
            k = m.record.get("frame_index")
            if isinstance(k, int) and not isinstance(k, bool):
                last = k
                yield from release(k)
    if held:
        yield from release(last + 1)


def _record_t_ns(record, log_time: int) -> int:
    """The time a record carries (a JSON record's ``t_ns``, a frame's or IMU batch's ``t_ns``); the
    log time for one without (a later version's binary channel).  Before log times in UTC both were
    the same."""
    t = record.get("t_ns") if isinstance(record, dict) else getattr(record, "t_ns", None)
    return int(t) if isinstance(t, int) and not isinstance(t, bool) else int(log_time)

