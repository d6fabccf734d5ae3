"""Writes that fail as on a full disk, for the recording's tests: root's writes are never refused
and a test cannot fill the disk, so the OS's error is raised where the SDK would meet it."""

from __future__ import annotations

import os

from foveatrack.recording import RecordingWriter


class FailingFlush:
    """An SDK writer whose flush fails as on a full disk (the SDK's words: "I/O error from writing")."""

    def __init__(self, sdk):
        self.sdk = sdk

    def flush(self):
        raise RuntimeError("FoxgloveError: MCAP error: I/O error from writing, or reading a compression stream")

    def __getattr__(self, name):
        return getattr(self.sdk, name)


def metadata_write_fails(monkeypatch, err: int) -> None:
    """A file's first write (its metadata) fails with the OS's ``err``, where the SDK writes it."""
    def fail(self, md):
        def write():
            raise OSError(err, os.strerror(err))
        self._sdk(write)

    monkeypatch.setattr(RecordingWriter, "_write_meta", fail)
