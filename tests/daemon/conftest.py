import sys
from pathlib import Path

import pytest

# daemon_procs.py (helpers for the multi-process tests) is imported as a plain module.
sys.path.insert(0, str(Path(__file__).parent))

SCENE = Path(__file__).parent / "scene_track.toml"


@pytest.fixture(scope="session")
def sim_recording(tmp_path_factory):
    """A simulator recording of ``scene_track.toml``: ``(path, per-frame log, scene)``.  Shared by the
    replay tests; a test that damages it works on a copy."""
    from foveatrack.recording import RecordingWriter
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene

    path = tmp_path_factory.mktemp("rec") / "sim.mcap"
    scene = load_scene(SCENE)
    loop = ClosedLoop(scene)
    with RecordingWriter(path, recording_meta(scene, loop)) as w:
        loop.frame_hook = SimRecorder(w)
        log = loop.run()
    return path, log, scene
