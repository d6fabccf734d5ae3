"""Normals drawn in blocks on the loop's own thread (no worker), and handed to a worker mid-stream,
are the generator's own values for the same calls."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim import effects as fx
from sim.ahead import Ahead, DrawsAhead
from sim.loop import ClosedLoop
from sim.scene import load_scene

SIZES = [3017, 0, 1, 4999, 16_384, 40_000, 7, 2]   # across block ends, bigger than a block, empty


@pytest.mark.parametrize("kind", ["normal", "uniform"])
@pytest.mark.parametrize("block", [1, 1000, 16_384])
def test_blocks_without_a_worker_then_with_one_give_the_generators_values(kind, block):
    draws = DrawsAhead(np.random.default_rng(3), kind, None, block=block)
    ref = np.random.default_rng(3)
    take = (lambda g, n: g.standard_normal(n)) if kind == "normal" else (lambda g, n: g.random(n))
    for n in SIZES:
        assert np.array_equal(take(draws, n), take(ref, n)), n
    worker = Ahead()
    try:
        draws.work_on(worker)
        for n in SIZES:
            assert np.array_equal(take(draws, n), take(ref, n)), n
    finally:
        worker.close()
    assert np.array_equal(take(draws, 70_000), take(ref, 70_000))   # synchronous again, same stream
    # through the effect's own functions: numpy's normal() itself, value for value
    if kind == "normal":
        assert np.array_equal(fx.range_noise_draws(draws, 500, 0.02), ref.normal(0.0, 0.02, 500))


def test_a_sensor_draws_its_normals_in_blocks_and_the_run_is_unchanged():
    scene = replace(load_scene(Path(__file__).resolve().parents[2] / "scenes" / "fig12-tracking.toml"),
                    duration_s=1.0, effects=frozenset({"range_noise", "angular_noise"}),
                    effect_params={"range_noise_m": 0.02, "angular_noise_deg": 0.03})
    loop = ClosedLoop(scene)
    assert isinstance(loop.sensor._sources["range_noise"], DrawsAhead)
    got = []
    loop.frame_hook = lambda frame, out, lp: got.append(frame.xyz.copy())
    loop.run()
    # the same run with the effects' streams given straight to the draw functions, frame by frame
    ref = ClosedLoop(scene)
    ref.sensor._sources = dict(ref.sensor.rngs)
    want = []
    ref.frame_hook = lambda frame, out, lp: want.append(frame.xyz.copy())
    ref.run()
    assert len(got) == len(want) == 10 and sum(len(x) for x in got) > 1000
    for a, b in zip(got, want):
        assert np.array_equal(a.view(np.int64), b.view(np.int64))
