"""ClosedLoop.objects_log keeps each frame's truth compact and builds it when read (sim.objects_truth.
TruthLog): every frame read gives what ObjectsTruth.at gave built in the frame (the code it replaces),
object for object, flocks, crowns whose velocity the cull did not evaluate, stray returns and all;
last_objects is the last frame's."""

from __future__ import annotations

import numpy as np
import pytest

from sim.loop import ClosedLoop
from sim.objects_truth import ObjectsTruth, TruthLog
from sim.study.sky_objects import sky_scene


def _run_with_eager_truth(scene):
    """The run, and each frame's truth built in the frame as the loop built it before (ObjectsTruth.at
    on the sensor's values of that frame), with what last_objects gave in the frame."""
    truth = ObjectsTruth(scene)
    eager, seen = [], []
    strays_seen = [0]

    def hook(frame, out, loop):
        s = loop.sensor
        strays = s.last_strays_m if scene.has("stray_returns") else np.zeros((0, 3))
        k = len(eager)
        period = loop.tracker.config.period_s
        t_mid = 0.5 * (k * period + (k + 1) * period)        # the loop's own frame mid (ClosedLoop.step)
        eager.append(truth.at(t_mid, s.last_object_rays, strays, strays_seen[0], s.last_mid_xyz_m,
                              s.last_mid_velocity))
        strays_seen[0] += len(strays)
        seen.append(loop.last_objects)

    loop = ClosedLoop(scene, frame_hook=hook)
    loop.run()
    return loop, eager, seen


@pytest.mark.parametrize("name, seed, flock_of", [("swarm-of-five", None, "drone-and-flock"),
                                                  ("drone-tree-line", 39, None), ("drone-and-flock", 230, None)])
def test_the_truth_read_is_the_truth_built_in_the_frame(name, seed, flock_of):
    scene = sky_scene(name, 4.0, seed, None, flock_of)
    loop, eager, seen = _run_with_eager_truth(scene)
    log = loop.objects_log
    assert isinstance(log, TruthLog) and len(log) == len(eager) == 40
    assert list(log) == eager and log == eager and eager == list(log)
    assert [log[k] for k in range(len(log))] == eager and log[3:7] == eager[3:7] and log[-1] == eager[-1]
    assert seen == eager and loop.last_objects == eager[-1]
    assert loop.last_objects is loop.last_objects          # built once a frame
    assert all(type(o).__name__ == "ObjectTruth" and isinstance(o.xyz_m, tuple) and isinstance(o.velocity_m_s, tuple)
               for fr in log for o in fr)
    if name == "drone-tree-line":       # crowns: velocities the cull did not evaluate, strays
        assert any(v is None for v in loop.sensor.last_mid_velocity)
        assert any(o.id.startswith("stray-") for fr in log for o in fr)


def test_an_empty_log_and_a_scene_with_one_target():
    scene = sky_scene("swarm-of-five", 0.3, None, None, None)
    loop = ClosedLoop(scene)
    assert loop.last_objects is None and len(loop.objects_log) == 0 and loop.objects_log == []
    assert loop.objects_log != [[]] and not loop.objects_log
    loop.run()
    assert len(loop.objects_log) == 3 and loop.objects_log != []
