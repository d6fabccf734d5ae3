"""The startup heap set aside from the cyclic collector once per process (foveatrack.startup_heap)."""

from __future__ import annotations

import gc
from pathlib import Path

from foveatrack import startup_heap as heap

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "fig12-tracking.toml"


def test_the_startup_heap_is_frozen_once_and_a_closed_loop_does_it_first(monkeypatch):
    from sim.loop import ClosedLoop
    from sim.scene import load_scene

    scene = load_scene(SCENE)
    gc.unfreeze()                                # whatever an earlier test froze, back in the collector
    monkeypatch.setattr(heap, "_frozen", False)
    try:
        assert gc.get_freeze_count() == 0
        ClosedLoop(scene)                        # the simulator freezes before it builds its own objects
        frozen = gc.get_freeze_count()
        assert heap._frozen and frozen > 10_000, frozen      # the imports: numpy, scipy, numba, ours
        kept = [[k] for k in range(5000)]
        heap.freeze_startup_heap()               # a second call: nothing more is frozen
        assert gc.get_freeze_count() == frozen and len(kept) == 5000
    finally:
        gc.unfreeze()
