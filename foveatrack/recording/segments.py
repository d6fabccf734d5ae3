"""A recording split into segments: the file names, one rule for the writer, replay and recover.

The daemon's ``[recording] segment_minutes`` ends its file every that many minutes and goes on in a
new one (:meth:`foveatrack.recording.RecordingWriter.next_segment`), as ``ros2 bag record
--max-bag-duration`` does: the MCAP writer keeps an index entry per chunk (one chunk a frame, ~10 MB an
hour) until its file closes, so one file for a day's run grows the daemon by a quarter of a GB.

The first segment is the configured path; segment k >= 1 is ``<stem>.partNNNN<suffix>`` beside it
(``runs/20261128T060000Z.mcap``, ``runs/20261128T060000Z.part0001.mcap``, ...), which sorts after the
first and in order up to 9999 segments.  Each is a complete recording with the run's metadata and
its ``segment_index``, and its own command journal (``<segment>.commands.jsonl``).
"""

from __future__ import annotations

import re
from pathlib import Path

_PART = re.compile(r"^(?P<stem>.+)\.part(?P<k>\d{4,})$")


def segment_path(first: str | Path, k: int) -> Path:
    """The file of segment ``k`` (0: ``first`` itself) of the run whose first segment is ``first``."""
    first = Path(first)
    if k < 0:
        raise ValueError(f"segment index must be >= 0, got {k}")
    return first if k == 0 else first.with_name(f"{first.stem}.part{k:04d}{first.suffix}")


def first_segment(path: str | Path) -> tuple[Path, int]:
    """(the run's first segment, this file's index) from a file's name alone."""
    path = Path(path)
    m = _PART.match(path.stem)
    if m is None:
        return path, 0
    return path.with_name(m["stem"] + path.suffix), int(m["k"])


def following_segments(first: str | Path) -> list[Path]:
    """The segments after ``first`` that exist beside it, in order, up to the first one missing."""
    out, k = [], 1
    while (p := segment_path(first, k)).is_file():
        out.append(p)
        k += 1
    return out


class RunReader:
    """The segments of one run read as one recording: the reader calls of
    :class:`~foveatrack.recording.RecordingReader` (``messages``, ``records``, ``damage``,
    ``problem``, ...) over the first segment and those that follow it, in order.

    A following segment belongs to the run when its metadata is the first's (the same configuration,
    start time and writer) with its own ``segment_index``; the chain ends before the first that does
    not (a file left from another run with the same name), and :attr:`notes` says so."""

    def __init__(self, readers: list, notes: list[str]):
        self.parts = readers
        self.notes = notes
        first = readers[0]
        self.path, self.meta, self.info, self.meta_checked = first.path, first.meta, first.info, first.meta_checked
        self.max_frames = first.max_frames
        self.size = sum(r.size for r in readers)

    # the whole run's state, from its parts (known after a full iteration, as for one file)
    @property
    def complete(self):
        states = [r.complete for r in self.parts]
        return None if None in states else all(states)

    @property
    def damage(self) -> list:
        return [d for r in self.parts for d in r.damage]

    @property
    def unattributed(self) -> dict:
        out: dict = {}
        for r in self.parts:
            for k, v in r.unattributed.items():
                out[k] = out.get(k, 0) + v
        return out

    @property
    def capped(self):
        return next((r.capped for r in self.parts if r.capped is not None), None)

    def capped_text(self) -> str | None:
        return next((r.capped_text() for r in self.parts if r.capped is not None), None)

    @property
    def problem(self) -> str | None:
        parts = [f"{r.path.name}: {r.problem}" for r in self.parts if r.problem]
        return "; ".join(parts) if parts else None

    def damage_not_held(self) -> list:
        """Every part's :meth:`~foveatrack.recording.RecordingReader.damage_not_held`, in order."""
        return [d for r in self.parts for d in r.damage_not_held()]

    def held_text(self) -> str | None:
        held = [h for h in (r.held_text() for r in self.parts) if h]
        return "; ".join(held) if held else None

    def warning(self) -> str | None:
        lines = [w for w in (r.warning() for r in self.parts) if w] + [f"note: {n}" for n in self.notes]
        return "\n".join(lines) if lines else None

    def logged_messages(self, channels=None):
        for r in self.parts:
            yield from r.logged_messages(channels)

    def messages(self, channels=None):
        for r in self.parts:
            yield from r.messages(channels)

    def points(self):
        for r in self.parts:
            yield from r.points()

    def imu(self):
        for r in self.parts:
            yield from r.imu()

    def records(self, channel: str) -> list[dict]:
        return [rec for r in self.parts for rec in r.records(channel)]

    def closed(self) -> bool:
        return all(r.closed() for r in self.parts)

    def channels(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for r in self.parts:
            for k, v in r.channels().items():
                out[k] = out.get(k, 0) + v
        return out


def _same_run(first, other) -> bool:
    """Whether ``other`` continues the run ``first`` began: the same start time and configuration
    (a segment ``recover`` completed says so in its meta, and logs its own times)."""
    def run_meta(r):
        return {k: v for k, v in r.meta.items() if k != "recovered_from_journal"}

    return (first.info.get("created_utc") == other.info.get("created_utc")
            and first.info.get("format_version") == other.info.get("format_version")
            and run_meta(first) == run_meta(other))


def open_run(path: str | Path, max_frames: int | None = None, segment_alone: bool = False):
    """The recording at ``path``: a :class:`~foveatrack.recording.RecordingReader`, or a
    :class:`RunReader` over it and the segments that follow it.  A later segment given alone is read
    alone where ``segment_alone`` (its points and records: ``export``), else it is a
    :class:`~foveatrack.errors.UserError` naming the run's first (``replay``: the tracker's state and
    the head's pose come from the segments before it)."""
    from foveatrack.errors import UserError
    from foveatrack.recording.reader import RecordingReader

    first = RecordingReader(path, max_frames)
    k = first.info.get("segment_index")
    if k is not None and segment_alone:
        return first
    if k is not None:
        start, _ = first_segment(path)
        raise UserError(f"{path} is segment {k} of a recording split into segments: a segment alone replays "
                        f"without the head's pose and the tracker's state before it; give the run's first "
                        f"segment ({start.name if start != Path(path) else 'the file without .partNNNN'}), "
                        f"which reads those after it too")
    readers, notes = [first], []
    for i, p in enumerate(following_segments(path), start=1):
        r = RecordingReader(p, max_frames)
        if r.info.get("segment_index") != str(i) or not _same_run(first, r):
            notes.append(f"{p.name} is not segment {i} of {Path(path).name} (another run's file): the run is read "
                         f"up to the segment before it")
            break
        readers.append(r)
    return first if len(readers) == 1 else RunReader(readers, notes)
