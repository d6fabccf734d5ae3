"""Axis 7 -- the effects: what each effect a scene can list costs per frame and does to fig12's tracking.

For every effect of :data:`sim.scene.EFFECT_DEFAULTS` (read when the study runs, so an effect added
to that table is measured without a change here) but the excluded ones below, ``fig12-tracking``
runs with the effect added to its list, at its documented default parameters, and is paired by
seed with fig12 as shipped (the **reference**):

* CPU per frame of the whole closed loop, as the paired ratio to the reference on the same seed
  (with its interval) and in ms, and the paired change in ms;
* the tracking error rms after acquisition and over all frames, and the acquisition time: each the
  interval over seeds and the paired change against the reference.

Excluded (:data:`EXCLUDED`): the effects fig12 already lists (range noise, motor speed noise, the
return probability): adding them changes nothing, and measuring them removed would answer another
question (what the reference's own effects cost).  An effect that needs another listed
(:data:`sim.scene.EFFECT_REQUIRES`: ``range_noise_model`` shapes ``range_noise``, ``mixed_pixels``
splits ``beam_footprint``'s beams) is added with what it needs and fig12 lacks; its row is named
so (``mixed_pixels + beam_footprint``), and the needed effect's own row shows its share.

Each run first runs a short throwaway loop with the same effect, so that its kernels are loaded
from numba's cache (or compiled) before anything is timed.
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass

from sim.study.common import SCENES_DIR, SCENE_FILES, run_loop, seeds_for, strip_private
from sim.study.stats import interval, paired_delta, paired_ratio

REFERENCE = "fig12 as shipped"
METRICS = ("error_rms_acq_deg", "error_rms_all_deg", "acquisition_s", "cpu_per_virtual_s", "ms_per_frame")


def _fig12_data() -> dict:
    return tomllib.loads((SCENES_DIR / SCENE_FILES["fig12"]).read_text())


def excluded() -> dict[str, str]:
    """Effects the axis leaves out, each with why."""
    return {e: "already listed by fig12, the reference" for e in _fig12_data()["scene"].get("effects", [])}


EXCLUDED = excluded()


def measured_effects() -> list[str]:
    """The effects the axis measures: every one a scene can list, but :func:`excluded`'s."""
    from sim.scene import EFFECT_DEFAULTS

    skip = excluded()
    return [e for e in EFFECT_DEFAULTS if e not in skip]


def label(effect: str | None) -> str:
    """The row's name: the effect, with what it needs and fig12 lacks (``mixed_pixels + beam_footprint``)."""
    if effect is None:
        return REFERENCE
    from sim.scene import EFFECT_REQUIRES

    listed = _fig12_data()["scene"].get("effects", [])
    return " + ".join([effect] + [e for e in EFFECT_REQUIRES.get(effect, ()) if e not in listed])


def effect_scene(effect: str | None, duration_s: float, seed: int):
    """fig12-tracking with ``effect`` added to its list (None: as shipped), at ``duration_s``, ``seed``."""
    from sim.scene import EFFECT_DEFAULTS, scene_from_mapping

    data = copy.deepcopy(_fig12_data())
    data["scene"]["duration_s"] = duration_s
    data["scene"]["seed"] = seed
    if effect is not None:
        if effect not in EFFECT_DEFAULTS:
            raise ValueError(f"unknown effect {effect!r}; allowed: {', '.join(EFFECT_DEFAULTS)}")
        from sim.scene import EFFECT_REQUIRES

        listed = list(data["scene"].get("effects", []))
        data["scene"]["effects"] = listed + [e for e in EFFECT_REQUIRES.get(effect, ()) if e not in listed] + [effect]
    return scene_from_mapping(data, f"{SCENES_DIR / SCENE_FILES['fig12']} (+ {effect or 'nothing'})")


@dataclass(frozen=True)
class EffectTask:
    effect: str | None          # None: the reference
    seed: int
    duration_s: float

    axis = "effects"

    @property
    def cost_hint(self) -> float:
        return self.duration_s * 0.02

    @property
    def label(self) -> str:
        return label(self.effect)

    def run(self) -> dict:
        run_loop(effect_scene(self.effect, 0.2, self.seed))      # the effect's kernels loaded, untimed
        m = strip_private(run_loop(effect_scene(self.effect, self.duration_s, self.seed)))
        m["ms_per_frame"] = 1000.0 * m["cpu_s"] / max(m["frames"], 1)
        return m


def tasks(size, effects: list[str] | None = None) -> list[EffectTask]:
    """The reference and each effect (``effects``: a subset of :func:`measured_effects`; default all)
    on ``size.seeds`` paired seeds of ``size.levers_duration_s`` virtual seconds."""
    chosen = measured_effects() if effects is None else list(effects)
    seed0 = _fig12_data()["scene"]["seed"]
    return [EffectTask(e, seed, size.levers_duration_s) for seed in seeds_for(seed0, size.seeds)
            for e in [None] + chosen]


def collect(results) -> dict:
    """Per effect: each metric's interval over seeds, its paired change against the reference, and
    the CPU-per-frame ratio to the reference on the same seed."""
    labels = []
    for t, _ in results:
        if t.label not in labels:
            labels.append(t.label)
    labels.sort(key=lambda s: s != REFERENCE)
    by = {lab: {t.seed: r for t, r in results if t.label == lab} for lab in labels}
    ref = by.get(REFERENCE, {})
    rows = []
    for lab in labels:
        have = by[lab]
        row = {"effect": lab, "seeds": len(have), "ci": {}, "delta": {}}
        for k in METRICS:
            row["ci"][k] = interval([have[s].get(k) for s in sorted(have)])
            row["delta"][k] = paired_delta({s: r.get(k) for s, r in have.items()},
                                           {s: r.get(k) for s, r in ref.items()})
        row["cost_ratio"] = paired_ratio({s: r["ms_per_frame"] for s, r in have.items()},
                                         {s: r["ms_per_frame"] for s, r in ref.items()})
        rows.append(row)
    duration = next((t.duration_s for t, _ in results), None)
    return {"scene": "fig12-tracking", "duration_s": duration, "seeds": sorted(ref), "reference": REFERENCE,
            "excluded": excluded(), "rows": rows}


def merge(old: dict | None, new: dict, cpu: str | None = None) -> dict:
    """``new``'s rows over ``old``'s (the same reference and seeds): a run of some effects updates
    their rows and keeps the others'.  Rows of runs with other seeds or durations, or measured on
    another CPU than ``cpu`` (the old run's ``run["cpu"]``; None: not compared), are dropped: their
    milliseconds beside this run's reference mixed two machines in one table, under this run's
    header."""
    other_cpu = cpu is not None and (old or {}).get("run", {}).get("cpu") not in (None, cpu)
    if not old or other_cpu or old.get("seeds") != new["seeds"] or old.get("duration_s") != new["duration_s"]:
        return new
    rows = {r["effect"]: r for r in old["rows"]}
    rows.update({r["effect"]: r for r in new["rows"]})
    order = [REFERENCE] + [r for r in rows if r != REFERENCE]
    return dict(new, rows=[rows[k] for k in order if k in rows])


__all__ = ["EXCLUDED", "REFERENCE", "EffectTask", "collect", "effect_scene", "excluded", "measured_effects",
           "merge", "tasks"]
