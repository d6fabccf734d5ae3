"""Byte-fed Pelco frame parsers: ``feed(bytes) -> frames``, no I/O (pyserial ``FramedPacket`` style).

The parser

* resynchronises after garbage: bytes before a sync byte (FF for Pelco-D, A0 for Pelco-P) are
  skipped;
* rejects bad checksums (and a Pelco-P frame without its ETX): the candidate's first byte is
  discarded and the search for a sync byte restarts *inside* the candidate, so a real frame that
  began within rejected bytes is still found;
* handles frames split across reads and several frames in one read;
* drops a partial frame when the gap between two of its bytes exceeds ``max_gap_s``.

The last point fixes a field bug (facts file, "merged-reply bug"): a truncated reply followed,
after a pause, by the next reply can form a checksum-valid frame whose position word is
fabricated.  Gap dropping needs byte times: pass ``t_s`` to :meth:`feed` (one time for the whole
chunk, or one per byte).  Without times the parser cannot tell and does not try.

Guarantee (tested by fuzzing): every frame returned is a checksum-valid run of consecutive input
bytes in which no inter-byte gap exceeds ``max_gap_s``; no exception escapes ``feed``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from gimbal.pelco import (
    ETX_P,
    FRAME_LEN,
    STX_P,
    SYNC_D,
    PelcoCommand,
    checksum_d,
    checksum_p,
)

_SYNC = {SYNC_D: "D", STX_P: "P"}

DEFAULT_MAX_GAP_S = 0.05
"""Default largest inter-byte gap inside one frame [s].  At 2400 baud a byte takes 4.2 ms and a
USB-serial adapter may hold bytes for its 16 ms latency timer, so a real frame can show gaps of
~20 ms at the host; 50 ms is still far below any query/reply period."""


@dataclass
class ParserStats:
    frames: int = 0
    bad_frames: int = 0  # checksum / ETX failures
    garbage_bytes: int = 0  # bytes skipped while hunting for a sync byte
    gap_drops: int = 0  # partial frames dropped after an inter-byte gap


class PelcoParser:
    """Parser for Pelco-D and/or Pelco-P frames.

    protocols : 'D', 'P' or 'DP' (both: the head's "adaptive" receiver)
    max_gap_s : float > 0 [s], inter-byte gap after which a partial frame is dropped
    """

    def __init__(self, protocols: str = "DP", max_gap_s: float = DEFAULT_MAX_GAP_S) -> None:
        if not protocols or any(p not in FRAME_LEN for p in protocols):
            raise ValueError(f"protocols={protocols!r}; allowed 'D', 'P' or 'DP'")
        if not max_gap_s > 0:
            raise ValueError(f"max_gap_s={max_gap_s!r} must be > 0")
        self._syncs = {b: p for b, p in _SYNC.items() if p in protocols}
        self.max_gap_s = float(max_gap_s)
        self._buf = bytearray()
        self._last_t: float | None = None
        self.stats = ParserStats()

    def reset(self) -> None:
        """Forget any partial frame."""
        self._buf.clear()
        self._last_t = None

    @property
    def idle(self) -> bool:
        """No partial frame is being assembled (the next byte may start a frame)."""
        return not self._buf

    @property
    def pending(self) -> bytes:
        """Bytes of the partial frame being assembled."""
        return bytes(self._buf)

    def feed(
        self, data: bytes | bytearray, t_s: float | Sequence[float] | None = None
    ) -> list[PelcoCommand]:
        """Feed received bytes; return the complete, valid frames they finish, in order.

        data : the bytes of one read
        t_s : arrival time [s] of the chunk (all its bytes), or one time per byte, or None (no
              gap detection).  Times must not decrease.
        """
        data = bytes(data)
        if t_s is None or isinstance(t_s, (int, float)):
            times = None if t_s is None else [float(t_s)] * len(data)
        else:
            times = [float(x) for x in t_s]
            if len(times) != len(data):
                raise ValueError(f"{len(times)} byte times for {len(data)} bytes")
        out: list[PelcoCommand] = []
        n = len(data)
        i = 0
        while i < n:
            if not self._buf and data[i] == SYNC_D and i + 7 <= n:
                cmd = self.take_clean_d(data, i, times)
                if cmd is not None:
                    out.append(cmd)
                    i += 7
                    continue
            b = data[i]
            t = None if times is None else times[i]
            i += 1
            if t is not None:
                if self._buf and self._last_t is not None and t - self._last_t > self.max_gap_s:
                    self.stats.gap_drops += 1
                    self._buf.clear()
                self._last_t = t
            if not self._buf:
                if b in self._syncs:
                    self._buf.append(b)
                else:
                    self.stats.garbage_bytes += 1
                continue
            self._buf.append(b)
            self._drain(out)
        return out

    def take_clean_d(
        self, data: bytes, i: int, times: Sequence[float] | None
    ) -> PelcoCommand | None:
        """Fast path: the clean Pelco-D frame ``data[i:i+7]`` at once, or None (nothing consumed).

        Applies only when no partial frame is pending, this parser takes Pelco-D, ``data[i]`` is
        the sync byte, the checksum holds and no inter-byte gap inside the frame exceeds
        ``max_gap_s`` (``times``: one time per byte of ``data``, or None).  Then it returns the
        frame and leaves the parser exactly as feeding the seven bytes one by one would (stats,
        last byte time); otherwise it changes nothing and the caller takes the byte-by-byte route.
        Tested against that route on fuzzed streams.
        """
        if self._buf or SYNC_D not in self._syncs or data[i] != SYNC_D:
            return None
        j = i + 7
        if j > len(data):
            return None
        key = bytes(data[i:j])
        cmd = _D_FRAMES.get(key)
        if cmd is None:
            if sum(key[1:6]) & 0xFF != key[6]:
                return None
            cmd = _d_command(key)
        if times is not None:
            gap = self.max_gap_s
            prev = times[i]
            for k in range(i + 1, j):
                t = times[k]
                if t - prev > gap:
                    return None
                prev = t
            self._last_t = prev
        self.stats.frames += 1
        return cmd

    # -- internals -------------------------------------------------------------------------
    def _drain(self, out: list[PelcoCommand]) -> None:
        while self._buf:
            proto = self._syncs[self._buf[0]]
            n = FRAME_LEN[proto]
            if len(self._buf) < n:
                return
            cand = bytes(self._buf[:n])
            cmd = _check(cand, proto)
            if cmd is not None:
                self.stats.frames += 1
                out.append(cmd)
                del self._buf[:n]
                # anything left (only possible mid-resync) must start at a sync byte
                self._skip_to_sync(0)
                continue
            self.stats.bad_frames += 1
            self._skip_to_sync(1)

    def _skip_to_sync(self, start: int) -> None:
        for j in range(start, len(self._buf)):
            if self._buf[j] in self._syncs:
                self.stats.garbage_bytes += j - start
                del self._buf[:j]
                return
        self.stats.garbage_bytes += max(0, len(self._buf) - start)
        self._buf.clear()


_D_FRAMES: dict[bytes, PelcoCommand] = {}
"""Decoded checksum-valid Pelco-D frames by their 7 bytes (a command is immutable; a controller
sends few distinct frames, so decoding each once saves the dataclass checks on every frame)."""
_D_FRAMES_MAX = 4096


def _d_command(frame: bytes) -> PelcoCommand:
    """The command of a checksum-valid 7-byte Pelco-D frame, decoded once per distinct frame."""
    cmd = _D_FRAMES.get(frame)
    if cmd is None:
        if len(_D_FRAMES) >= _D_FRAMES_MAX:
            _D_FRAMES.clear()
        cmd = _D_FRAMES[frame] = PelcoCommand("D", frame[1], frame[2], frame[3], frame[4], frame[5])
    return cmd


def _check(cand: bytes, proto: str) -> PelcoCommand | None:
    if proto == "D":
        if checksum_d(cand[1:6]) != cand[6]:
            return None
        return _d_command(cand)
    if cand[6] != ETX_P or checksum_p(cand[:7]) != cand[7]:
        return None
    return PelcoCommand("P", cand[1] + 1, cand[2], cand[3], cand[4], cand[5])


class PelcoDParser(PelcoParser):
    """Pelco-D only (sync 0xFF, 7-byte frames)."""

    def __init__(self, max_gap_s: float = DEFAULT_MAX_GAP_S) -> None:
        super().__init__("D", max_gap_s)


class PelcoPParser(PelcoParser):
    """Pelco-P only (STX 0xA0, 8-byte frames with ETX 0xAF)."""

    def __init__(self, max_gap_s: float = DEFAULT_MAX_GAP_S) -> None:
        super().__init__("P", max_gap_s)
