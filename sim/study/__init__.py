"""What accuracy costs in time (issue 7): measured accuracy-vs-cost curves of every fidelity knob.

One module per axis, each with ``tasks(size) -> [task]`` (picklable frozen dataclasses whose
``run()`` returns a dict), ``collect(results) -> dict`` and ``pareto_points(axis) -> [point]``:

* :mod:`sim.study.scan_fidelity`   -- paraxial vs exact refraction: angular error vs ns per ray;
* :mod:`sim.study.sim_fidelity`    -- footprint sub-rays, per-point/per-frame target, head-pose grid:
  tracking metrics vs CPU per virtual second;
* :mod:`sim.study.sensing`         -- accumulation window: detection probability, bearing error,
  control latency; coverage vs accumulation time (paper Fig. 6e);
* :mod:`sim.study.calibration_time` -- dwell per speed byte: speed-table and reconstruction error
  (the shape of paper Fig. 11b);
* :mod:`sim.study.point_rate`      -- Mid-40 vs Horizon: tracking error vs compute per frame;
* :mod:`sim.study.levers`          -- controller, recording, head ripple, scan model in the loop,
  attitude source, speed table: tracking and world-position error vs CPU relative to the paper's loop;
* :mod:`sim.study.effect_costs`    -- every effect a scene can list, added alone to fig12: CPU per frame
  relative to fig12 as shipped and the change of the tracking error (``--axis effects`` runs it alone).

Every closed-loop number keeps its per-seed values and a 95 % interval (:mod:`sim.study.stats`);
the Pareto fronts (:mod:`sim.study.pareto`) rank only differences outside those intervals.

:func:`sim.study.runner.run_study` (``size`` = ``"quick"`` | ``"full"``, an executor from
:func:`sim.sweep.make_executor`) runs them all through :func:`sim.sweep.run_tasks`;
:func:`sim.study.report.write_report` turns the results into markdown (plots are drawn at the edge,
``foveatrack.cli.study_plots``).  Command: ``foveatrack study accuracy-vs-time --out DIR``.
"""
