"""Damaged recordings: nothing already recorded is lost.  The reader skips a damaged chunk (a bad CRC,
garbage over part of it, its length field included), finds the next valid chunk by its header and
CRC, returns every record of every undamaged chunk in order, and says exactly what it skipped.

(Found by a review: one corrupted chunk in the first third of a 50-frame recording ended the read
there; 14 of 50 frames came back.)  Chunk positions are taken from the file's own summary through
the ``mcap`` library: a second route to the layout the reader works out for itself."""

import numpy as np
import pytest
from mcap.reader import make_reader

from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.format import VIEW_CHANNELS

N_FRAMES = 50
CHANNELS = ("points", "detections", "commands", "head", "metrics")


def recs(lost):
    """The records among the lost messages: the writer also draws transforms and scene entities
    for Foxglove from each frame's records (tf, scene), which the reader counts as lost too."""
    return {k: v for k, v in lost.items() if k not in VIEW_CHANNELS}


def write_run(path, n_frames=N_FRAMES, **kw):
    """One chunk per frame: its points, detection, command, head estimate and metric."""
    rng = np.random.default_rng(7)
    with RecordingWriter(path, {"seed": 7}, **kw) as w:
        for k in range(n_frames):
            t = 1_000_000_000 + k * 100_000_000
            n = 40
            w.write_points(t, k, rng.normal(0, 20, (n, 3)), t - 50_000_000 + np.arange(n) * 1000,
                           rng.integers(0, 256, n).astype(np.uint8))
            w.write_detection(t + 1000, k, True, xyz_m=[10.0, 0.0, float(k)], n_points=5)
            w.write_command(t + 2000, b"\xff\x01\x00\x04\x20\x00\x25", frame_id=k, source="tracker")
            w.write_head_estimate(t + 3000, pan_deg=0.1 * k, tilt_deg=0.0, frame_id=k)
            w.write_metric(t + 4000, "processing_ms", 1.0 + k, frame_id=k)


def key(m):
    return (m.channel, m.t_ns)


def chunks(path):
    """(start, end of the chunk record, end of its message index, first, last message time) per chunk."""
    with open(path, "rb") as fh:
        s = make_reader(fh).get_summary()
    return [(c.chunk_start_offset, c.chunk_start_offset + c.chunk_length,
             c.chunk_start_offset + c.chunk_length + c.message_index_length, c.message_start_time, c.message_end_time)
            for c in sorted(s.chunk_indexes, key=lambda c: c.chunk_start_offset)]


def in_chunks(msgs, cks):
    return [m for m in msgs if any(c[3] <= m[1] <= c[4] for c in cks)]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    p = tmp_path_factory.mktemp("dmg") / "run.mcap"
    write_run(p)
    full = [key(m) for m in RecordingReader(p).messages()]
    cks = chunks(p)
    assert len(cks) == N_FRAMES and len(full) == 5 * N_FRAMES
    return p, p.read_bytes(), full, cks


def damaged(tmp_path, data: bytes | bytearray, name="bad.mcap"):
    q = tmp_path / name
    q.write_bytes(bytes(data))
    return q


def read_all(q):
    r = RecordingReader(q)
    return r, [key(m) for m in r.messages()]


def test_a_bad_crc_skips_that_chunk_only(run, tmp_path):
    p, data, full, cks = run
    k = 10                                   # in the first third
    start, end, idx_end, t0, t1 = cks[k]
    data = bytearray(data)
    data[start + 9 + 24] ^= 0x5A             # the chunk's uncompressed_crc field
    r, got = read_all(damaged(tmp_path, data))
    lost = in_chunks(full, [cks[k]])
    assert got == [m for m in full if m not in lost]        # every other record, in order
    assert [f.frame_index for f in r.points()] == [i for i in range(N_FRAMES) if i != k]
    assert r.complete                                        # the writer closed the file
    (d,) = r.damage
    assert (d.start_byte, d.end_byte) == (start, cks[k + 1][0])
    assert recs(d.lost) == {c: 1 for c in CHANNELS} and d.lost_exact and not d.cut_short
    assert "CRC" in d.reason
    assert f"bytes {start}-{cks[k + 1][0]}" in r.problem and "1 frame" in r.problem


def test_garbage_over_a_chunk_and_its_length_field(run, tmp_path):
    p, data, full, cks = run
    k = 12
    start, end, idx_end, t0, t1 = cks[k]
    data = bytearray(data)
    mid = (start + end) // 2
    data[start + 1: mid] = np.random.default_rng(1).integers(0, 256, mid - start - 1, dtype=np.uint8).tobytes()
    r, got = read_all(damaged(tmp_path, data))
    lost = in_chunks(full, [cks[k]])
    assert got == [m for m in full if m not in lost]
    (d,) = r.damage
    assert (d.start_byte, d.end_byte) == (start, cks[k + 1][0])
    # the chunk's header is garbage, but its message index after it survived: what it held is known
    assert recs(d.lost) == {c: 1 for c in CHANNELS}
    assert r.complete and "1 frame" in r.problem


def test_garbage_across_two_chunks(run, tmp_path):
    p, data, full, cks = run
    k = 5
    a, b = cks[k][1] - 100, cks[k + 1][0] + 120      # the end of chunk 5 (+ its index) and the start of chunk 6
    data = bytearray(data)
    data[a:b] = bytes(b - a)
    r, got = read_all(damaged(tmp_path, data))
    lost = in_chunks(full, cks[k:k + 2])
    assert got == [m for m in full if m not in lost]
    assert [f.frame_index for f in r.points()] == [i for i in range(N_FRAMES) if i not in (k, k + 1)]
    assert len(r.damage) == 1 and r.damage[0].start_byte == cks[k][0] and r.damage[0].end_byte == cks[k + 2][0]


def test_a_cut_short_tail_reads_every_whole_chunk_before_it(run, tmp_path):
    p, data, full, cks = run
    k = 40
    start, end = cks[k][:2]
    r, got = read_all(damaged(tmp_path, data[: (start + end) // 2]))
    assert got == in_chunks(full, cks[:k])
    assert not r.complete
    (d,) = r.damage
    assert d.cut_short and d.start_byte == start and d.end_byte == (start + end) // 2
    assert "cut short" in r.problem and f"byte {start}" in r.problem


def test_a_tail_cut_in_an_index_says_what_follows_is_not_in_the_file(run, tmp_path):
    # cut 3 bytes into the records after chunk 40 (its message index): no message is in the cut
    # stretch, and the line said only "no messages lost" of a run cut in half (a user's audit)
    p, data, full, cks = run
    end = cks[40][1]
    r, got = read_all(damaged(tmp_path, data[:end + 3]))
    assert got == in_chunks(full, cks[:41])
    (d,) = r.damage
    assert d.cut_short and d.lost == {} and d.lost_exact
    assert "no message in it (index bytes only); whatever was written after it is not in the file" in d.describe()
    assert "no messages lost" not in r.problem


def test_damage_in_the_middle_and_a_cut_short_tail(run, tmp_path):
    p, data, full, cks = run
    data = bytearray(data[: cks[30][0] + 50])
    data[cks[3][0] + 200] ^= 0xFF                       # inside chunk 3's compressed records
    r, got = read_all(damaged(tmp_path, data))
    assert got == [m for m in in_chunks(full, cks[:30]) if m not in in_chunks(full, [cks[3]])]
    assert [d.cut_short for d in r.damage] == [False, True]
    assert recs(r.damage[0].lost) == {c: 1 for c in CHANNELS}
    assert not r.complete


def test_damage_in_the_first_chunk_which_defines_the_channels(run, tmp_path):
    """The channels are defined in the first chunk; the metadata names them too, so the records of
    every later chunk are still attributed to their channels."""
    p, data, full, cks = run
    data = bytearray(data)
    data[cks[0][0] + 120] ^= 0x01
    r, got = read_all(damaged(tmp_path, data))
    assert got == [m for m in full if m not in in_chunks(full, [cks[0]])]
    assert recs(r.damage[0].lost) == {c: 1 for c in CHANNELS}


@pytest.mark.slow
def test_one_flipped_byte_anywhere_loses_at_most_its_chunk(run, tmp_path):
    """Every chunk in turn gets one byte flipped at a random place in its record or its index: the
    reader returns a subsequence of the full recording holding everything outside that chunk, and
    reports a damage stretch whenever it returns less."""
    p, data, full, cks = run
    rng = np.random.default_rng(3)
    for k, (start, end, idx_end, t0, t1) in enumerate(cks):
        bad = bytearray(data)
        bad[int(rng.integers(start, idx_end))] ^= 1 << int(rng.integers(0, 8))
        r, got = read_all(damaged(tmp_path, bad))
        must = [m for m in full if m not in in_chunks(full, [cks[k]])]
        it = iter(got)
        assert all(m in it for m in must), k            # in order, nothing outside the chunk lost
        assert set(got) <= set(full), k
        if len(got) < len(full):
            assert r.damage and r.problem, k
        assert r.complete, k


def test_an_undamaged_recording_reports_nothing(run):
    p, data, full, cks = run
    r, got = read_all(p)
    assert got == full and r.damage == [] and r.problem is None and r.complete


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_other_compressions_resynchronise_too(tmp_path, compression):
    p = tmp_path / "r.mcap"
    write_run(p, n_frames=12, compression=compression)
    full = [key(m) for m in RecordingReader(p).messages()]
    cks = chunks(p)
    data = bytearray(p.read_bytes())
    data[cks[4][0] + 9 + 24] ^= 0x10
    r, got = read_all(damaged(tmp_path, data))
    assert got == [m for m in full if m not in in_chunks(full, [cks[4]])]
    assert recs(r.damage[0].lost) == {c: 1 for c in CHANNELS}


def test_older_recordings_take_the_channels_from_the_summary(tmp_path, monkeypatch):
    """Recordings written before the channel table was in the metadata define each channel only in
    the chunk where it is first used.  With that chunk damaged, a closed file's summary (CRC-checked)
    still names them; in a file cut short as well, the messages that no intact record attributes
    are counted in ``problem``, not passed off as another channel's."""
    import foveatrack.recording.writer as rec

    monkeypatch.setattr(rec.RecordingWriter, "_channel_table", lambda self: None)   # no table, as before
    p = tmp_path / "old.mcap"
    write_run(p, n_frames=10)
    full = [key(m) for m in RecordingReader(p).messages()]
    cks = chunks(p)
    data = bytearray(p.read_bytes())
    data[cks[0][0] + 9 + 24] ^= 0x01
    r, got = read_all(damaged(tmp_path, data))
    assert got == [m for m in full if m not in in_chunks(full, [cks[0]])]
    assert recs(r.damage[0].lost) == {c: 1 for c in CHANNELS} and not r.unattributed
    r, got = read_all(damaged(tmp_path, data[: cks[8][0] + 30], "old_cut.mcap"))
    with open(p, "rb") as fh:
        s = make_reader(fh).get_summary()
    # every channel has a message in every frame's chunk but /scene_keyframe (once a second: chunk 0)
    every_frame = sorted(c.id for c in s.channels.values() if c.topic != "/scene_keyframe")
    per_chunk = sum(s.statistics.channel_message_counts[i] for i in every_frame) // 10
    assert got == [] and sorted(r.unattributed) == every_frame
    assert sum(r.unattributed.values()) == 7 * per_chunk
    assert f"{7 * per_chunk} message(s) of channel id(s) {every_frame} skipped" in r.problem
