"""Hostile recordings (issue 32): the reader's cost is bounded by the file, whatever its bytes.

Costs are asserted as work counted (bytes the reader's searches cover, bytes a decompressor may
produce), never as wall-clock time."""

import mmap

import numpy as np
import pytest

from foveatrack.recording import RecordingReader, reader as reader_mod

from test_damaged_recordings import write_run


class CountingMmap(mmap.mmap):
    """An mmap whose ``find`` counts the bytes each search may cover."""

    scanned = 0

    def find(self, sub, start=None, end=None):
        q = super().find(sub, start, end)
        stop = len(self) if end is None else end
        CountingMmap.scanned += (q if q >= 0 else stop) - (start or 0) + 1
        return q


def test_resynchronising_over_a_long_damaged_stretch_costs_linear_work(tmp_path, monkeypatch):
    """A stretch of 0x06 bytes (each a chunk opcode, none a metadata one): each candidate looked for
    the next metadata opcode from scratch, so the work grew with the square of the stretch (a 242 kB
    file took over 30 s)."""
    p = tmp_path / "run.mcap"
    write_run(p, n_frames=60)
    data = bytearray(p.read_bytes())
    a, b = len(data) // 4, len(data) * 3 // 4
    data[a:b] = b"\x06" * (b - a)
    q = tmp_path / "bad.mcap"
    q.write_bytes(bytes(data))
    monkeypatch.setattr(reader_mod.mmap, "mmap", CountingMmap)
    CountingMmap.scanned = 0
    r = RecordingReader(q)
    n = sum(1 for _ in r.messages())
    assert n > 0 and r.damage
    assert CountingMmap.scanned < 20 * len(data), (CountingMmap.scanned, len(data))


def _chunk(payload: bytes, usize: int) -> bytes:
    import struct

    from foveatrack.recording import mcap_walk as mw

    body = mw.CHUNK_HEAD.pack(0, 0, usize, 0, 3) + b"lz4" + mw.U64.pack(len(payload)) + payload
    return mw.REC.pack(mw.OP_CHUNK, len(body)) + body


@pytest.mark.parametrize("claimed", [1000, 200 * 10**6])
def test_an_lz4_chunk_never_decompresses_past_a_cap(claimed):
    """lz4 chunks had no output cap: 2.5 MB became 864 MB.  Whether the header understates the size
    (1000 bytes) or claims it all (a ratio no recording has), the chunk is damage and the
    decompressor never produces the bulk of it."""
    import tracemalloc

    import lz4.frame

    from foveatrack.recording import mcap_walk as mw

    bomb = lz4.frame.compress(b"\0" * (200 * 10**6))         # ~0.8 MB that decompresses to 200 MB
    buf = _chunk(bomb, claimed)
    tracemalloc.start()
    try:
        with pytest.raises(mw.BadRecord):
            mw.chunk_records(buf, 0, len(buf) - mw.REC.size)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * 10**6, peak


def test_live_pacing_has_finite_waits(monkeypatch, tmp_path):
    """--speed 1e-300 and --wait-s inf ended in OverflowError; a sensor clock jump in the recording
    (power-on time to PTP time) made replay --live sleep for decades."""
    from foveatrack.errors import UserError
    from foveatrack.recording import live

    slept = []
    monkeypatch.setattr(live.time, "sleep", lambda s: slept.append(s))
    for bad in (1e-300, 0.0, float("nan"), -1.0):
        with pytest.raises(UserError, match="--speed"):
            live.Pacer(bad)
    p = live.Pacer(1.0)
    for t in (5.0, 5.1, 1.7e9, 1.7e9 + 0.1, 3.0):       # a jump forward, one back
        p.wait(t)
    assert p.jumps == 2 and all(0 <= s <= 0.11 for s in slept), slept
    rec = tmp_path / "r.mcap"
    write_run(rec, n_frames=2)
    for wait in (float("inf"), float("nan"), 1e12):
        with pytest.raises(UserError, match="--wait-s"):
            live.stream_recording(rec, 0, 1.0, wait)


def test_export_lvx_over_a_sensor_clock_jump_allocates_by_points_not_by_time(tmp_path, capsys):
    """Power-on time to PTP time between two frames made export --lvx size its slot grid by the
    time between them (3.83 PiB).  Now both sides are written, every point at its recorded time,
    and the unfilled gap is said."""
    from foveatrack.cli import main
    from foveatrack.livox.lvx import read_lvx
    from foveatrack.recording import RecordingWriter

    rec = tmp_path / "jump.mcap"
    rng = np.random.default_rng(1)
    times = []
    with RecordingWriter(rec, {"point_rate_hz": 100_000.0}) as w:
        for k, t_end in enumerate((2_000_000_000, 2_100_000_000, 1_700_000_000_000_000_000)):
            t = t_end - 100_000_000 + np.arange(50) * 10_000
            times.append(t)
            w.write_points(t_end, k, rng.uniform(1, 20, (50, 3)), t, np.full(50, 7, np.uint8))
    assert main(["export", str(rec), "--lvx", str(tmp_path / "j.lvx")]) == 0
    assert "1 gap(s) in the point times" in capsys.readouterr().out
    got = np.concatenate([b.t_ns for b in read_lvx(tmp_path / "j.lvx")])
    assert np.array_equal(np.sort(got), np.concatenate(times))


def test_a_damaged_metadata_record_is_named_as_damage(tmp_path, capsys):
    """One bit turned format version 3 into 2 and every point decoded differently, without a word
    (now: 4 into 3, format 3's decoding of the points)."""
    from foveatrack.cli import main
    from foveatrack.errors import UserError

    p = tmp_path / "run.mcap"
    write_run(p, n_frames=3)
    data = bytearray(p.read_bytes())
    i = data.index(b"format_version") + len("format_version") + 4
    assert data[i:i + 1] == b"4"
    data[i] ^= 0x07                                   # "4" -> "3"
    q = tmp_path / "v2.mcap"
    q.write_bytes(bytes(data))
    with pytest.raises(UserError, match="metadata record is damaged"):
        RecordingReader(q)
    assert main(["export", str(q), "--csv", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "metadata record is damaged" in err[0]
    assert RecordingReader(p).meta_checked


def test_a_chunk_crc_of_zero_is_damage_where_the_writer_wrote_them(tmp_path):
    from mcap.reader import make_reader

    p = tmp_path / "run.mcap"
    write_run(p, n_frames=6)
    with open(p, "rb") as fh:
        cks = sorted(c.chunk_start_offset for c in make_reader(fh).get_summary().chunk_indexes)
    data = bytearray(p.read_bytes())
    data[cks[3] + 9 + 24:cks[3] + 9 + 28] = bytes(4)      # CRC 0: "not computed"
    q = tmp_path / "crc0.mcap"
    q.write_bytes(bytes(data))
    r = RecordingReader(q)
    frames = [m.record.frame_index for m in r.messages("points")]
    assert frames == [0, 1, 2, 4, 5]
    assert len(r.damage) == 1 and "without a CRC" in r.damage[0].reason


def test_a_recording_is_private_and_never_written_through_a_symlink(tmp_path):
    """Recordings were created world-readable with the config inside, and the writer opened its path
    following symlinks (check-then-open)."""
    import os
    import stat

    from foveatrack.recording import RecordingWriter
    from foveatrack.recording.writer import RecordingExistsError

    p = tmp_path / "r.mcap"
    write_run(p, n_frames=1)
    assert stat.S_IMODE(p.stat().st_mode) == 0o600
    target = tmp_path / "victim.txt"
    link = tmp_path / "link.mcap"
    os.symlink(target, link)                       # dangling: exists() is False for it
    with pytest.raises(RecordingExistsError):
        RecordingWriter(link, {})
    assert not target.exists()
    target.write_text("keep")
    RecordingWriter(link, {}, overwrite=True).close()
    assert target.read_text() == "keep" and not link.is_symlink()


def test_the_writer_child_does_not_import_from_the_working_directory(tmp_path, monkeypatch):
    """The writer child ran as ``python -c``: a signal.py in the working directory ran inside it."""
    from foveatrack.recording.writer_process import RecordingProcess

    marker = tmp_path / "ran"
    (tmp_path / "signal.py").write_text(f"open({str(marker)!r}, 'w').close()\nraise SystemExit(3)\n")
    monkeypatch.chdir(tmp_path)
    with RecordingProcess().open(tmp_path / "p.mcap", {"seed": 1}) as w:
        w.write_points(1000, 0, np.zeros((3, 3)), np.arange(3), np.zeros(3, np.uint8))
    assert not marker.exists()
    assert RecordingReader(tmp_path / "p.mcap").meta == {"seed": 1}
