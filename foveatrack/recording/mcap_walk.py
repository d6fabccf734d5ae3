"""MCAP records read byte by byte (https://mcap.dev/spec), for a reader that must survive damage.

The ``mcap`` library's reader stops at the first record that does not verify;
:class:`foveatrack.recording.RecordingReader` walks the file with these instead, so that it can
skip a damaged chunk and resynchronise on the next one whose header holds together and whose CRC
verifies.  Every function takes the file's bytes (an ``mmap``) and positions; one that finds bytes
that do not hold together raises :class:`BadRecord`.
"""

from __future__ import annotations

import struct
import zlib

# MCAP records the reader walks itself (https://mcap.dev/spec): opcode u8, length u64, content.
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MINDEX = 1, 2, 3, 4, 5, 6, 7
OP_METADATA, OP_DATA_END = 0x0C, 0x0F
TOP_LEVEL_OPS = frozenset(range(0x01, 0x10))
REC = struct.Struct("<BQ")
CHUNK_HEAD = struct.Struct("<QQQII")         # message_start_time, message_end_time, uncompressed_size, crc, len(compression)
MSG_HEAD = struct.Struct("<HIQQ")            # channel_id, sequence, log_time, publish_time
U16, U32, U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
COMPRESSIONS = (b"", b"lz4", b"zstd")
DATA_END_SIZE = 1 + 8 + 4
FOOTER_SIZE = 1 + 8 + 8 + 8 + 4
MAX_CHUNK_RATIO = 64        # uncompressed / compressed bytes a chunk may claim (+ 1 MiB): a cap on every decompression


class BadRecord(Exception):
    """A record that does not hold together (the reader skips it and resynchronises)."""



def chunk_length(mm, pos: int, stop: int) -> int | None:
    """The record length of a chunk at ``pos`` if its header holds together and it ends by ``stop``."""
    if pos + REC.size + CHUNK_HEAD.size + 8 > stop or mm[pos] != OP_CHUNK:
        return None
    length = U64.unpack_from(mm, pos + 1)[0]
    clen = CHUNK_HEAD.unpack_from(mm, pos + REC.size)[4]
    c0 = pos + REC.size + CHUNK_HEAD.size
    if clen > 4 or c0 + clen + 8 > stop or mm[c0:c0 + clen] not in COMPRESSIONS:
        return None
    dlen = U64.unpack_from(mm, c0 + clen)[0]
    if length != CHUNK_HEAD.size + clen + 8 + dlen or pos + REC.size + length > stop:
        return None
    return length


def chunk_times(mm, pos: int, size: int) -> tuple[int, int] | None:
    if pos + REC.size + 16 > size or mm[pos] != OP_CHUNK:
        return None
    t0, t1 = struct.unpack_from("<QQ", mm, pos + REC.size)
    return (t0, t1) if t0 <= t1 else None


def chunk_records(mm, pos: int, length: int, require_crc: bool = False) -> list[tuple[int, object]]:
    """The records of the chunk at ``pos``: decompressed, size and CRC checked (``require_crc``: a CRC
    of 0, MCAP's "not computed", is damage too: the writer computed them all).  Each is
    ``(OP_MESSAGE, content)`` or ``(OP_CHANNEL, (id, topic, encoding))``: a channel is parsed here,
    once, so that one which does not hold together makes the chunk damage."""
    if chunk_length(mm, pos, len(mm)) != length:
        raise BadRecord("a chunk whose header does not hold together (damaged length or compression fields)")
    b = pos + REC.size
    _t0, _t1, usize, crc, clen = CHUNK_HEAD.unpack_from(mm, b)
    c0 = b + CHUNK_HEAD.size
    comp = mm[c0:c0 + clen]
    d0 = c0 + clen + 8
    raw = mm[d0:b + length]
    if comp and usize > MAX_CHUNK_RATIO * len(raw) + (1 << 20):
        # the writer's chunks hold one frame or a few: no decompressor may make more of them than this
        raise BadRecord(f"a chunk with an implausible uncompressed size ({usize} bytes from {len(raw)})")
    try:
        if comp == b"lz4":
            import lz4.frame

            dec = lz4.frame.LZ4FrameDecompressor()
            data = dec.decompress(raw, max_length=usize)     # never more than the header says
            if not dec.eof:
                raise BadRecord(f"a chunk that decompresses to more than the {usize} bytes its header says")
        elif comp == b"zstd":
            import zstandard

            data = zstandard.ZstdDecompressor().decompress(raw, max_output_size=usize)
        else:
            data = raw
    except BadRecord:
        raise
    except Exception as exc:  # noqa: BLE001 - any decompressor error means damaged bytes
        raise BadRecord(f"a chunk that does not decompress ({type(exc).__name__})") from None
    if len(data) != usize:
        raise BadRecord(f"a chunk of {len(data)} bytes where its header says {usize}")
    if crc == 0 and require_crc:
        raise BadRecord("a chunk without a CRC (0) in a recording whose writer gave every chunk one")
    if crc != 0 and zlib.crc32(data) != crc:
        raise BadRecord("a chunk whose CRC does not match its contents")
    out = []
    mv = memoryview(data)
    i, n = 0, len(data)
    while i < n:
        if n - i < REC.size:
            raise BadRecord("a chunk whose records do not add up")
        op, ln = REC.unpack_from(data, i)
        j = i + REC.size
        if j + ln > n or (op == OP_MESSAGE and ln < MSG_HEAD.size):
            raise BadRecord("a chunk whose records do not add up")
        if op == OP_CHANNEL:
            out.append((op, channel(mv[j:j + ln])))
        elif op == OP_MESSAGE:
            out.append((op, mv[j:j + ln]))
        i = j + ln
    return out


class ByteScan:
    """The next position at or after ``p`` of any of ``values`` in ``mm[:stop]``, for a caller whose ``p``
    only grows: each value's next position is found once and kept until ``p`` passes it, so a scan of
    a stretch costs O(its length) however the values are spread (two ``find`` calls per candidate
    made resynchronisation quadratic where one value was rare: a 242 kB file took over 30 s).
    ``scanned`` counts the bytes the finds covered."""

    def __init__(self, mm, stop: int, values: bytes):
        self.mm, self.stop = mm, stop
        self._next = {bytes([v]): -2 for v in values}   # -2: not looked for yet; -1: none left
        self.scanned = 0

    def next(self, p: int) -> int:
        best = -1
        for v, q in self._next.items():
            if q != -1 and q < p:
                q = self.mm.find(v, p, self.stop)
                self.scanned += (q if q >= 0 else self.stop) - p + 1
                self._next[v] = q
            if q >= 0 and (best < 0 or q < best):
                best = q
        return best


def string(buf, i: int) -> tuple[str, int]:
    """The MCAP string (u32 length, UTF-8) at ``i`` and the position after it; one whose length runs
    past the buffer is a BadRecord (it was cut silently, or a struct.error traceback)."""
    if i + 4 > len(buf):
        raise BadRecord(f"a string at byte {i} of a record of {len(buf)} bytes")
    n = U32.unpack_from(buf, i)[0]
    if i + 4 + n > len(buf):
        raise BadRecord(f"a string of {n} bytes at byte {i} of a record of {len(buf)} bytes")
    return bytes(buf[i + 4:i + 4 + n]).decode("utf-8", "replace"), i + 4 + n


def channel(content) -> tuple[int, str, str]:
    """A Channel record's (id, topic without its '/', message encoding); one that does not hold
    together is a BadRecord (a crafted chunk whose CRC holds gave a struct.error traceback)."""
    if len(content) < 4:
        raise BadRecord(f"a channel record of {len(content)} bytes")
    cid = U16.unpack_from(content, 0)[0]
    try:
        topic, i = string(content, 4)
        encoding, _ = string(content, i)
    except BadRecord as exc:
        raise BadRecord(f"a channel record that does not hold together ({exc})") from None
    return cid, topic.lstrip("/"), encoding


def metadata(content) -> tuple[str, dict[str, str]]:
    try:
        name, i = string(content, 0)
        n = U32.unpack_from(content, i)[0]
        i += 4
        stop = i + n
        md = {}
        while i < stop:
            k, i = string(content, i)
            v, i = string(content, i)
            md[k] = v
    except struct.error:
        raise BadRecord("a metadata record that does not hold together") from None
    if i != stop or stop != len(content):
        raise BadRecord("a metadata record that does not hold together")
    return name, md


def message_index(mm, body: int, length: int) -> tuple[int, list[int]]:
    """(channel id, log times) of a message index record whose content is ``mm[body:body+length]``."""
    if length < 6:
        raise BadRecord("a damaged message index record")
    cid, n = struct.unpack_from("<HI", mm, body)
    if n % 16 or length != 6 + n:
        raise BadRecord("a damaged message index record")
    return cid, [U64.unpack_from(mm, body + 6 + 16 * k)[0] for k in range(n // 16)]


def index_chain(mm, pos: int, stop: int) -> list[tuple[int, list[int]]] | None:
    """Consecutive message index records from ``pos`` up to exactly ``stop`` (None if they do not)."""
    out = []
    while pos < stop:
        if pos + REC.size > stop:
            return None
        op, length = REC.unpack_from(mm, pos)
        if op != OP_MINDEX or pos + REC.size + length > stop:
            return None
        try:
            out.append(message_index(mm, pos + REC.size, length))
        except BadRecord:
            return None
        pos += REC.size + length
    return out if pos == stop else None


def index_chain_ending_at(mm, start: int, stop: int) -> list[tuple[int, list[int]]] | None:
    """The longest run of message index records in ``[start, stop)`` that ends exactly at ``stop``
    (the index of a chunk whose own header is damaged)."""
    p = start
    while True:
        p = mm.find(bytes([OP_MINDEX]), p, stop)
        if p < 0:
            return None
        chain = index_chain(mm, p, stop)
        if chain:
            return chain
        p += 1


def record_runs_past(mm, pos: int, size: int) -> bool:
    """The record at ``pos`` has a known opcode and a length that runs past the end of the file."""
    if size - pos < REC.size:
        return True
    op, length = REC.unpack_from(mm, pos)
    return op in TOP_LEVEL_OPS and pos + REC.size + length > size and length < (1 << 40)
