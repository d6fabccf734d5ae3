"""A recording's pages go to the disk every step (foveatrack.recording.writeback): the file is the
same to the byte, and the syncs happen once per step written."""

import os

from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.writeback import WritebackPacer

from test_writer_process import META, write_all


def test_the_paced_file_is_the_same_to_the_byte(tmp_path):
    with RecordingWriter(tmp_path / "kernel.mcap", META, created_utc="fixed", writeback_step_bytes=0) as w:
        write_all(w)
        assert w._pacer is None
    with RecordingWriter(tmp_path / "paced.mcap", META, created_utc="fixed", writeback_step_bytes=1) as w:
        write_all(w)
        syncs = w._pacer.syncs
    assert syncs >= 6          # a step of one byte: a sync at every flush (every frame, and the extra one)
    assert (tmp_path / "paced.mcap").read_bytes() == (tmp_path / "kernel.mcap").read_bytes()
    assert len(list(RecordingReader(tmp_path / "paced.mcap").records("detections"))) == 6


def test_a_sync_comes_once_a_step_has_been_written(tmp_path):
    path = tmp_path / "f.bin"
    with open(path, "wb") as f:
        pacer = WritebackPacer(path, 1000)
        for k in range(10):
            f.write(b"x" * 300)
            f.flush()
            pacer.after_flush()
        # 3000 bytes in steps of at least 1000: after 1200 (4 writes), 2400 (8); 3000 is 600 past
        assert pacer.syncs == 2 and pacer.sync_s > 0
        pacer.close()
    assert os.path.getsize(path) == 3000
