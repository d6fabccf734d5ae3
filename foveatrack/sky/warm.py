"""The multi-object tracker's numba kernels compiled (or loaded from numba's cache) before data flows.

Its kernels (the frame's validity and region tests, the direction cells and range background, the
per-point turn into the world and the dead reckoning's node angles, the clustering, Algorithm 1 in a D
and its box test, the filters' update and predictions, the classifier's features, the tracks' field test, the association's gate, the merge rule's
close pairs, the fovea's saccade times) run first when the tracker's warm-up ends, ~10 frames into a run: on a fresh install that
frame waited ~8 s for the compiler, in the daemon's live loop as in a simulated run.
:func:`compile_sky_kernels` steps a throwaway controller through frames past its warm-up with a small
object moving through a scattered background, once per process, nothing written anywhere; the
kernels that need tracks (confirmed ones, two of them, for some) are called once more on their own.
The daemon (:func:`foveatrack.daemon.runtime.compile_sky`) and the simulator's closed loop
(:meth:`sim.loop.ClosedLoop.run`) both call it.
"""

from __future__ import annotations

import math

import numpy as np

_done = False


def compile_sky_kernels(make_controller, rate_hz: float) -> None:
    """Step a throwaway :class:`~foveatrack.sky.controller.SkyController` (``make_controller()``: built
    only when the kernels are not ready yet -- its background map is 32 MB, and every run of a study
    asks) through synthetic frames past its warm-up; a second call in the process does nothing."""
    global _done
    if _done:
        return
    controller = make_controller()
    from foveatrack.frame_step import FrameStep, NoHead
    from foveatrack.frames import Frame
    from foveatrack.gate import CommandGate

    step = FrameStep(controller, CommandGate(None), NoHead())
    rng = np.random.default_rng(0)
    period = 1.0 / rate_hz
    for k in range(int(math.ceil(controller.sky.cfg.warmup_s / period)) + 8):
        t0 = k * period
        bg = np.column_stack([np.full(200, 40.0), rng.uniform(-10, 10, 200), rng.uniform(0, 10, 200)])
        obj = np.array([20.0, -2.0 + 0.05 * k, 3.0]) + rng.normal(0, 0.05, (12, 3))
        xyz = np.vstack([bg, obj])
        t_ns = np.sort(rng.integers(int(t0 * 1e9), int((t0 + period) * 1e9), len(xyz))).astype(np.int64)
        step(Frame(t0, t0 + period, xyz, t_ns, np.full(len(xyz), 30, np.uint8)), t0 + period)
    # the kernels that need tracks (confirmed ones, two of them, for some): loaded here even if the
    # synthetic object was not confirmed in time
    from foveatrack.kernels import association_kernel, box_inside_kernel, close_pairs_kernel, in_field_kernel

    two = np.ones((2, 3))
    # the fixated track's D for the learning (box_bounds' read-only bounds), with or without a region
    bound = np.zeros(3)
    bound.flags.writeable = False
    box_inside_kernel(two, bound, bound, np.empty(2, np.int64))
    from foveatrack.sky.motion import predictions_kernel, update_kernel

    update_kernel(np.ones((5, 3)), 0.1, np.ones(3), 1.0, 1.0, np.empty((5, 3)))     # a track's hit
    # the frame's predictions of every track, with the variances and without
    predictions_kernel(np.ones((2, 5, 3)), np.ones(2), np.ones(2), 1.0, np.empty((2, 3)), np.empty((2, 3)))
    predictions_kernel(np.ones((2, 5, 3)), np.ones(2), np.ones(2), 1.0, np.empty((2, 3)), np.empty((0, 3)))
    from foveatrack.sky.attention import fovea_turns_kernel

    fovea_turns_kernel(two, np.ones(9), np.ones(3), np.ones(9), np.ones(3), 1.0, 1.0, 1.0, 1.0, 1.0, 1.0,
                       np.empty((2, 3)), np.empty(2))       # the confirmed tracks' saccade times
    from foveatrack.sky.attention import threat_scores_kernel

    threat_scores_kernel(two, two, np.ones(2), np.zeros(3), 1.0, 1.0, np.empty(2))     # ... and threat scores
    close_pairs_kernel(two, 1.0, np.empty((1, 2), np.int64))
    yes = np.ones(2, np.bool_)
    association_kernel(two, two, two, 1.0, 1.0, 1.0, yes, yes, 1.0, np.empty((2, 2)), np.empty((2, 2), np.bool_))
    in_field_kernel(two, np.ones(9), np.ones(3), 0.5, np.empty(2, np.bool_))
    _done = True
