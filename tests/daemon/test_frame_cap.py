"""A recording that claims millions of frames (issue 32): replay and export read at most a capped
number of them and say so in one line naming the file and what was capped.

The crafted file is a real (frameless) daemon recording followed by lz4 chunks of one empty lidar
frame repeated 8000 times each: within the decompression cap, ~1.5 frames per byte of file, so
20 such chunks (~110 kB) claim 160 000 frames, and a 1 MB file 1.5 M (gigabytes of replay and export).
Bounded cost is asserted as frames read, never as wall-clock time."""

import struct
import zlib

import lz4.frame
import numpy as np
import pytest

from foveatrack.cli import main
from foveatrack.recording import POINTS, RecordingReader, RecordingWriter
from foveatrack.recording import mcap_walk as mw
from foveatrack.recording.reader import FRAME_CAP_FLOOR, MIN_BYTES_PER_FRAME, frame_cap
from foveatrack.replay import replay_recording

from test_replay_hostile import daemon_recording_without_frames

FRAMES_PER_CHUNK = 8_000
POINTS_CID = 900          # a channel id the daemon's writer does not use


def _string(s: str) -> bytes:
    return struct.pack("<I", len(s)) + s.encode()


def _record(op: int, body: bytes) -> bytes:
    return mw.REC.pack(op, len(body)) + body


def empty_frame_payload(tmp_path) -> tuple[bytes, str]:
    """The /points message of a frame without points, and its channel's message encoding, as our
    writer writes them."""
    from mcap.reader import make_reader

    p = tmp_path / "one.mcap"
    with RecordingWriter(p, {}) as w:
        w.write_points(1_000_000_000, 0, np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.uint8))
    with open(p, "rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages(topics=["/points"]):
            return bytes(message.data), channel.message_encoding
    raise AssertionError("no /points message written")


def crafted_chunk(payload: bytes, encoding: str) -> bytes:
    """One lz4 chunk: the points channel, then FRAMES_PER_CHUNK copies of ``payload`` on it."""
    chan = _record(mw.OP_CHANNEL, struct.pack("<HH", POINTS_CID, 0) + _string("/points") + _string(encoding)
                   + struct.pack("<I", 0))
    msg = _record(mw.OP_MESSAGE, mw.MSG_HEAD.pack(POINTS_CID, 0, 1_000_000_000, 1_000_000_000) + payload)
    records = chan + msg * FRAMES_PER_CHUNK
    comp = lz4.frame.compress(records)
    assert len(records) <= mw.MAX_CHUNK_RATIO * len(comp) + (1 << 20)      # within the decompression cap
    body = (mw.CHUNK_HEAD.pack(1_000_000_000, 1_000_000_000, len(records), zlib.crc32(records), 3) + b"lz4"
            + mw.U64.pack(len(comp)) + comp)
    return _record(mw.OP_CHUNK, body)


def data_end_offset(data: bytes) -> int:
    """Where a closed recording's end-of-data record starts (from its footer)."""
    f = len(data) - 8 - mw.FOOTER_SIZE
    summary_start = struct.unpack_from("<Q", data, f + 9)[0]
    end = (summary_start or f) - mw.DATA_END_SIZE
    assert data[end] == mw.OP_DATA_END
    return end


@pytest.fixture
def many_frames(tmp_path):
    """A frameless daemon recording cut before its end-of-data record, then 20 crafted chunks."""
    base = daemon_recording_without_frames(tmp_path)
    data = base.read_bytes()
    end = data_end_offset(data)
    chunk = crafted_chunk(*empty_frame_payload(tmp_path))
    out = tmp_path / "many.mcap"
    out.write_bytes(data[:end] + chunk * 20)
    claimed = 20 * FRAMES_PER_CHUNK
    assert claimed > 2 * frame_cap(out.stat().st_size)
    return out, claimed


def test_the_cap_follows_the_file_size():
    assert frame_cap(0) == FRAME_CAP_FLOOR
    assert frame_cap(10**9) == 10**9 // MIN_BYTES_PER_FRAME


def test_a_recording_claiming_many_frames_is_read_up_to_the_cap_and_says_so(many_frames):
    path, claimed = many_frames
    cap = frame_cap(path.stat().st_size)
    r = RecordingReader(path)
    n = sum(1 for _ in r.messages(POINTS))
    assert n == cap < claimed
    assert r.capped is not None and r.capped[1] == cap
    w = r.warning()
    assert w.startswith(f"WARNING: recording {path} read in part") and "cap on frames per file" in w
    assert "\n" not in w
    # an explicit cap (--max-frames) stops it there
    r = RecordingReader(path, max_frames=100)
    assert sum(1 for _ in r.points()) == 100 and "--max-frames" in r.warning()


def test_replay_of_many_frames_ends_at_the_cap_with_a_warning(many_frames, capsys):
    path, claimed = many_frames
    cap = frame_cap(path.stat().st_size)
    res = replay_recording(path)
    assert "cap on frames per file" in res.comparison["recording_capped"]
    # every copy after the first goes back in time: skipped and counted, never more than the cap
    assert res.frames["frame_index"].size <= cap
    capsys.readouterr()
    assert main(["replay", str(path), "--json", "--max-frames", "500"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    capped = [ln for ln in err if "read in part" in ln]
    assert len(capped) == 1 and str(path) in capped[0] and "after 500 frames" in capped[0], err


@pytest.mark.parametrize("flag,out", [("--csv", "p.csv"), ("--npz", "p.npz"), ("--lvx", "p.lvx"),
                                      ("--trajectory", "t.csv")])
def test_export_of_many_frames_ends_at_the_cap_with_one_warning(many_frames, tmp_path, capsys, flag, out):
    path, claimed = many_frames
    assert main(["export", str(path), flag, str(tmp_path / out), "--max-frames", "2000"]) == 0
    cap_out = capsys.readouterr()
    err = cap_out.err.strip().splitlines()
    if flag == "--lvx":    # this hand-made recording names no lidar: the .lvx's device type is said to be a guess
        guess = [ln for ln in err if "the recording names no lidar" in ln]
        assert len(guess) == 1 and guess[0].startswith("note: "), err
        err.remove(guess[0])
    assert len(err) == 1 and err[0].startswith(f"WARNING: recording {path} read in part"), err
    assert "after 2000 frames" in err[0] and "cap on frames per file" in err[0]


def test_max_frames_must_be_a_positive_count(many_frames, tmp_path, capsys):
    path, _ = many_frames
    assert main(["export", str(path), "--csv", str(tmp_path / "p.csv"), "--max-frames", "0"]) == 2
    assert main(["replay", str(path), "--max-frames", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("--max-frames") == 2 and "Traceback" not in err
