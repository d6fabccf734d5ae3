"""What marks an MCAP file, and a foveatrack recording among MCAP files: the recording layer writes
them (:mod:`foveatrack.recording.format`), and the bag reader (:mod:`foveatrack.sources.rosbag`), which
may not import that layer, tells a foveatrack recording from a ROS 2 bag by them; and the name of the
command journal a daemon keeps beside its recording (:mod:`foveatrack.live_devices` writes it, the
recording's reader points to it).  A core module."""

from pathlib import Path

MCAP_MAGIC = b"\x89MCAP0\r\n"        # an MCAP file's first bytes
META_NAME = "foveatrack"             # the metadata record (and header profile) of a foveatrack recording
JOURNAL_SUFFIX = ".commands.jsonl"   # <recording>.commands.jsonl: a daemon's command journal beside its recording


def journal_path(recording) -> Path:
    """The command journal of a recording: ``<recording>.commands.jsonl`` beside it."""
    recording = Path(recording)
    return recording.with_name(recording.name + JOURNAL_SUFFIX)
