"""The ``[[bird]]`` and ``[[tree]]`` tables of a scene (models: :mod:`sim.world.sky`).

Each table draws from its own random stream, keyed by its id (``bird:<id>``, ``tree:<id>``,
:func:`sim.effects.effect_rng`): adding a flock changes no drone's path, no other flock or tree, and
no effect's draws.  Every error names the file, the table and the key.  Keys (docs/scenes.md)::

    [[bird]]   id ("bird-N"; a flock's birds are "id/0", "id/1", ...), count (1; 1-200),
               wingspan_m (0.35; 0.2-1.5), wingspan_spread (0.1: +-10 % among a flock's birds),
               spread_m (flock radius, 3 m per cube root of the count), glide_fraction (0.3; 0-1),
               flap_amplitude_deg (40), reflectivity (0.25),
               [bird.trajectory]: the flock centre's path, as a [[target]]'s, at 5-20 m/s
    [[tree]]   id ("tree-N"), base_m ([x, y, z] of the trunk's foot), height_m (8), crown_radius_m (2),
               trunk_radius_m (0.15), sway_frequency_hz (0.3), damping_ratio (0.1), sway_m (RMS
               crown sway along the wind, 0.2), wind_deg (direction the wind blows toward, 90),
               reflectivity (crown, 0.25), trunk_reflectivity (0.3)
"""

from __future__ import annotations

from typing import Any, Mapping

from foveatrack.config_util import as_float, as_vec, check_keys
from foveatrack.errors import UserError
from foveatrack.fixed_order import norm3

MAX_BIRDS_PER_TABLE = 200
BIRD_KEYS = ["id", "count", "wingspan_m", "wingspan_spread", "spread_m", "glide_fraction", "flap_amplitude_deg",
             "reflectivity", "trajectory"]
TREE_KEYS = ["id", "base_m", "height_m", "crown_radius_m", "trunk_radius_m", "sway_frequency_hz", "damping_ratio",
             "sway_m", "wind_deg", "reflectivity", "trunk_reflectivity"]


def sky_objects(data: Mapping[str, Any], where: str, duration_s: float, seed: int, targets) -> tuple:
    """``(objects, trunk_prims, trunk_reflectivities)`` of a scene's ``[[bird]]`` and ``[[tree]]``
    tables (empty when it has none: nothing is drawn)."""
    from sim.scene_objects import MAX_TARGETS

    ids = [spec.id for spec in targets]
    if len(set(ids)) < len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise UserError(f"{where} [[target]]: id {dup!r} is used twice; give each target its own")
    birds = _array(data, "bird", where)
    trees = _array(data, "tree", where)
    if not birds and not trees:
        return (), [], []
    objects: list = []
    for i, t in enumerate(birds):
        objects.extend(_birds(t, f"{where} [[bird]] #{i + 1}", i, duration_s, seed))
    prims, refl = [], []
    for i, t in enumerate(trees):
        obj, p, r = _tree(t, f"{where} [[tree]] #{i + 1}", i, duration_s, seed)
        objects.append(obj)
        prims.append(p)
        refl.append(r)
    if len(objects) + len(targets) > MAX_TARGETS:
        raise UserError(f"{where}: {len(targets)} targets, {len(objects)} birds and crowns; at most {MAX_TARGETS} "
                        "moving objects in one scene")
    seen = set(ids)
    for o in objects:
        if o.id in seen:
            raise UserError(f"{where}: id {o.id!r} is used twice; every drone, bird and tree needs its own")
        seen.add(o.id)
    return tuple(objects), prims, refl


def _array(data, key: str, where: str) -> list:
    v = data.get(key, [])
    if not isinstance(v, list):
        raise UserError(f"{where}: [[{key}]] must be an array of tables")
    return v


def _birds(t, w: str, index: int, duration_s: float, seed: int) -> list:
    from sim.effects import effect_rng
    from sim.scene_objects import object_id, trajectory_from_table
    from sim.world import sky

    check_keys(t, BIRD_KEYS, w)
    count = t.get("count", 1)
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_BIRDS_PER_TABLE:
        raise UserError(f"{w}: count must be an integer in [1, {MAX_BIRDS_PER_TABLE}], got {count!r}")
    obj_id = object_id(t.get("id", f"{'flock' if count > 1 else 'bird'}-{index + 1}"), w)
    lo, hi = sky.WINGSPAN_RANGE_M
    b0 = as_float(t.get("wingspan_m", 0.35), "wingspan_m", w, lo=lo, hi=hi)
    spread = as_float(t.get("wingspan_spread", 0.1), "wingspan_spread", w, lo=0, hi=0.5)
    radius = as_float(t.get("spread_m", 3.0 * count ** (1 / 3) if count > 1 else 0.0), "spread_m", w, lo=0, hi=500)
    glide = as_float(t.get("glide_fraction", 0.3), "glide_fraction", w, lo=0, hi=1)
    amp = as_float(t.get("flap_amplitude_deg", 40.0), "flap_amplitude_deg", w, lo=0, hi=80)
    refl = as_float(t.get("reflectivity", 0.25), "reflectivity", w, lo=0, lo_open=True, hi=1)
    rng = effect_rng(seed, f"bird:{obj_id}")
    centre = trajectory_from_table(t.get("trajectory"), w, "bird", duration_s, int(rng.integers(2**31)))
    slo, shi = sky.BIRD_SPEED_RANGE_M_S
    if centre.max_speed_m_s < slo:
        raise UserError(f"{w}.trajectory: the flock flies at up to {centre.max_speed_m_s:.1f} m/s; birds fly at "
                        f"{slo:g}-{shi:g} m/s")
    members = sky.flock_offsets(rng, count, radius, sky.SharedPath(centre), b0) if count > 1 else [centre]
    out = []
    for k, traj in enumerate(members):
        b = min(max(b0 * (1.0 + spread * (2.0 * rng.random() - 1.0)), lo), hi) if count > 1 else b0
        body = sky.bird_body(b, refl)
        flap = sky.flap_schedule(rng, sky.wingbeat_hz(b), duration_s, glide, amp)
        out.append(sky.SkyObject(obj_id if count == 1 else f"{obj_id}/{k}", "bird", body.body, traj, b,
                                 body.bounding_radius_m, hinge=body.hinge, flap=flap))
    return out


def _tree(t, w: str, index: int, duration_s: float, seed: int):
    from sim.effects import effect_rng
    from sim.scene_objects import object_id
    from sim.world import bodies, sky

    check_keys(t, TREE_KEYS, w)
    obj_id = object_id(t.get("id", f"tree-{index + 1}"), w)
    if "base_m" not in t:
        raise UserError(f"{w}: base_m ([x, y, z] of the trunk's foot) is missing")
    base = as_vec(t["base_m"], "base_m", w, 3)
    height = as_float(t.get("height_m", 8.0), "height_m", w, lo=1, hi=60)
    crown_r = as_float(t.get("crown_radius_m", 2.0), "crown_radius_m", w, lo=0.2, hi=15)
    trunk_r = as_float(t.get("trunk_radius_m", 0.15), "trunk_radius_m", w, lo=0.02, hi=3)
    if not crown_r < height / 2:
        raise UserError(f"{w}: crown_radius_m = {crown_r:g} must be below half of height_m = {height:g}")
    freq = as_float(t.get("sway_frequency_hz", 0.3), "sway_frequency_hz", w, lo=0.02, hi=3)
    zeta = as_float(t.get("damping_ratio", 0.1), "damping_ratio", w, lo=0.005, hi=1)
    sway = as_float(t.get("sway_m", 0.2), "sway_m", w, lo=0, hi=5)
    wind = as_float(t.get("wind_deg", 90.0), "wind_deg", w)
    refl = as_float(t.get("reflectivity", 0.25), "reflectivity", w, lo=0, lo_open=True, hi=1)
    trunk_refl = as_float(t.get("trunk_reflectivity", 0.3), "trunk_reflectivity", w, lo=0, lo_open=True, hi=1)
    rng = effect_rng(seed, f"tree:{obj_id}")
    crown = sky.crown_body(crown_r, rng, refl)
    rest = (base[0], base[1], base[2] + height - crown_r)
    path = sky.crown_sway(rng, rest, freq, zeta, sway, wind, duration_s)
    trunk_top = height - 1.6 * crown_r      # the trunk reaches into the crown's lower part
    trunk = bodies.box((base[0], base[1], base[2] + trunk_top / 2), (trunk_r, trunk_r, trunk_top / 2))
    radius = max(norm3(p[1:4]) + float(p[4]) for p in crown.prims)
    return sky.SkyObject(obj_id, "tree", crown, path, 2.0 * crown_r, radius, fixed_yaw=0.0), trunk, trunk_refl
