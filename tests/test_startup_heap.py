"""The startup heap set aside from the cyclic collector once per process (foveatrack.startup_heap)."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

from foveatrack import startup_heap as heap

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "fig12-tracking.toml"


def test_the_startup_heap_is_frozen_once_before_the_first_loop_which_is_still_freed(monkeypatch):
    from sim.loop import ClosedLoop
    from sim.scene import load_scene

    scene = load_scene(SCENE)
    gc.unfreeze()                                # whatever an earlier test froze, back in the collector
    monkeypatch.setattr(heap, "_frozen", False)
    try:
        assert gc.get_freeze_count() == 0
        first = [ClosedLoop(scene)]              # the simulator freezes the heap first
        frozen = gc.get_freeze_count()
        assert heap._frozen and frozen > 10_000, frozen      # the imports: numpy, scipy, numba, ours
        ClosedLoop(scene)                        # a second loop: nothing more is frozen
        assert gc.get_freeze_count() == frozen
        # the first loop was built after the freeze: its cycles (the loop and its link to the head)
        # are collected when it is dropped (frozen, it kept ~34 MB and its logs to the process's end)
        first[0].run()
        assert _freed_when_dropped(first)
    finally:
        gc.unfreeze()


def _freed_when_dropped(holder: list) -> bool:
    """Whether the one object in ``holder`` (its only reference) is collected once dropped."""
    gone = weakref.ref(holder.pop())
    gc.collect()
    return gone() is None


def test_the_daemon_freezes_the_heap_before_it_exists(tmp_path, monkeypatch):
    from foveatrack.daemon import Daemon, load_config

    gc.unfreeze()
    monkeypatch.setattr(heap, "_frozen", False)
    try:
        first = [Daemon(load_config(Path(__file__).resolve().parents[1] / "examples" / "daemon-virtual.toml"),
                        log_path=str(tmp_path / "log.jsonl"), status=False, install_signals=False)]
        first[0].log.close()
        assert heap._frozen and gc.get_freeze_count() > 10_000
        assert _freed_when_dropped(first)
    finally:
        gc.unfreeze()
