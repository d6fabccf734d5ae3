"""What the scene's lidar returns: ray casting and the effects the scene lists (closed-loop steps 4-5).

One object serves every driver of a scene's lidar — the closed loop (:mod:`sim.loop`) and the
real-time virtual Livox (:mod:`sim.lidar_server`) — so both produce the same points for the same
beams.  Each effect owns a random stream keyed by its name (:func:`sim.effects.effect_rng`); an
effect the scene does not list is never called.  The lidar's range envelope (blind zone, maximum
range: ``Scene.lidar_range_m``) is always applied and takes no draws.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from foveatrack.fixed_order import norm3
from foveatrack.livox.protocol import quantise_to_mm_grid
from sim import effects as fx
from sim import sensor_kernels as sk
from sim.scan.kernels import RAY_OK
from sim.scan.model import ScanModel
from sim.scan.optics import SpeedNoise
from sim.world import kernels as wk
from sim.world.sky import FlockPoses
from sim.world.trajectories import Straight, body_yaw_rad, heading_rad, position_velocity

_NONE = np.zeros(0)          # an effect that is off: no draws
_ZERO3 = np.zeros(3)         # the velocity a cull without an acceleration bound does not read
EFFECT_STREAMS = ("range_noise", "angular_noise", "return_probability", "sunlight", "dropouts", "stray_returns",
                  "weather")
CLUTTER_REFLECTIVITY_BYTE = 1   # a droplet's return: the weakest diffuse byte (sim.effects, weather)
STRAY_REFLECTIVITY = 0.1      # an insect's or a dust grain's return: weak
# The kind of value each effect takes from its stream, for the effects that take one kind only (these
# can be drawn ahead: sim.ahead.DrawsAhead); sunlight mixes kinds and is drawn frame by frame.
ONE_KIND_STREAMS = {"range_noise": "normal", "angular_noise": "normal", "return_probability": "uniform",
                    "dropouts": "uniform"}
_NORMALS_BLOCK = 16_384     # normals per block on one thread: ~60 us of draws, a few frames' worth


class _FlockCast(NamedTuple):
    """What casting a flock's birds together needs (:meth:`SceneSensor._cast_flock`), gathered once."""

    stop: int                 # the index in the scene's ``others`` after its last bird
    poses: FlockPoses
    members: np.ndarray       # 0 .. K-1
    radius_m: np.ndarray      # each bird's cull: bounding radius, top speed, acceleration bound (-1: none)
    max_speed_m_s: np.ndarray
    max_accel_m_s2: np.ndarray
    prims: np.ndarray         # the birds' primitive tables one after another: bird k's are the rows
    hinge: np.ndarray         # prim_start[k]:prim_start[k + 1] (sim.world.kernels.cast_flock_kernel)
    prim_start: np.ndarray

    @classmethod
    def of(cls, objects, culls, stop: int) -> _FlockCast:
        """The flock ``objects`` (``scene.others[start:stop]``), ``culls`` their (radius, speed, accel)."""
        radius, speed, accel = zip(*culls)
        return cls(stop, FlockPoses(objects), np.arange(len(objects)), np.array(radius, dtype=np.float64),
                   np.array(speed, dtype=np.float64), np.array([-1.0 if a is None else a for a in accel]),
                   np.concatenate([o.body.prims for o in objects]), np.concatenate([o.hinge for o in objects]),
                   np.cumsum([0] + [o.body.prims.shape[0] for o in objects]))


class _StraightBodies(NamedTuple):
    """The bodies cast on their own (``SceneSensor._single_bodies``) that fly straight passes
    (:class:`sim.world.trajectories.Straight`), gathered once: their positions at the chunk's mid time
    in one expression, and the targets among them cast together (``cast_together``: a yaw along the
    velocity, no hover, neither beam footprint nor incidence, which work on each body's poses)."""

    any: bool
    is_straight: list          # per single body
    cast_together: list        # per target
    run_at: dict               # the first target of each run of consecutive ones cast together: the run
    start_m: np.ndarray        # (K, 3) per single body (zeros where not straight)
    velocity_m_s: np.ndarray
    yaw: np.ndarray            # (K,) the heading of the velocity (heading_rad's: numpy's atan2)
    prims: np.ndarray          # the targets' primitive tables one after another, and where each starts
    prim_start: np.ndarray

    @classmethod
    def of(cls, bodies, n_targets: int, has: dict) -> _StraightBodies:
        is_straight = [type(spec.trajectory) is Straight for spec, _ in bodies]
        # the float64 values Straight keeps of its start and velocity (Straight.__post_init__)
        start = np.array([spec.trajectory.start_m if s else (0.0, 0.0, 0.0)
                          for (spec, _), s in zip(bodies, is_straight)], dtype=np.float64).reshape(-1, 3)
        velocity = np.array([spec.trajectory.velocity_m_s if s else (0.0, 0.0, 0.0)
                             for (spec, _), s in zip(bodies, is_straight)], dtype=np.float64).reshape(-1, 3)
        # the yaw of a straight pass is its velocity's at every time (body_yaw_rad; NaN: it hovers)
        yaw = heading_rad(velocity, default=math.nan) if len(bodies) else np.zeros(0)
        plain = not (has["beam_footprint"] or has["incidence"])
        together = [plain and is_straight[q] and not math.isnan(yaw[q]) and getattr(spec, "flap", None) is None
                    and getattr(spec, "fixed_yaw", None) is None for q, (spec, _) in enumerate(bodies[:n_targets])]
        targets = [spec for spec, _ in bodies[:n_targets]]
        prims = np.concatenate([t.body.prims for t in targets]) if targets else np.zeros((0, 13))
        runs: dict = {}
        first = None
        for q, flag in enumerate(together):
            if not flag:
                first = None
                continue
            if first is None:
                first = q
            runs.setdefault(first, []).append(q)
        prim_start = np.cumsum([0] + [t.body.prims.shape[0] for t in targets]).astype(np.int64)
        return cls(any(is_straight), is_straight, together, {a: np.array(r, dtype=np.int64) for a, r in runs.items()},
                   start, velocity, yaw, prims, prim_start)


def _reach(radius_m, max_speed_m_s, t0: float, t1: float):
    """How near a ray must pass a body's position at the chunk's mid-time to be cast on it: its bounding
    radius plus how far it can fly in half the chunk (1 % and 1 mm to spare); floats or arrays."""
    return radius_m + max_speed_m_s * 0.5 * (t1 - t0) * 1.01 + 1e-3


def scene_scan_model(scene) -> ScanModel:
    """The scene's scanner, with motor speed noise only if the scene lists it (its own stream)."""
    noise = None
    if scene.has("motor_speed_noise"):
        noise = SpeedNoise(sigma_frac=scene.param("speed_noise_frac"), segment_s=scene.param("speed_noise_segment_s"))
    return ScanModel(scene.optics, scene.scan_model, speed_noise=noise,
                     rng=fx.effect_rng(scene.seed, "motor_speed_noise") if noise else None)


class SceneSensor:
    """Returns of a scene's lidar for beams already turned into the world by the head.

    ``target_motion``: "per_point" (each point sees the target where it is at the point's own
    time; default) or "per_frame" (the target frozen at the interval's mid-time: the cheaper
    snapshot model the accuracy-vs-time study measures against).
    """

    def __init__(self, scene, target_motion: str = "per_point"):
        if target_motion not in ("per_point", "per_frame"):
            raise ValueError(f"target_motion {target_motion!r}: 'per_point' or 'per_frame'")
        self.scene = scene
        self.target_motion = target_motion
        self.rngs = {name: fx.effect_rng(scene.seed, name) for name in EFFECT_STREAMS}
        self.draw_calls = {name: 0 for name in self.rngs}
        self._sources = dict(self.rngs)   # where each effect's values come from (drawn ahead or not)
        # Normals are drawn in blocks even on one thread (the same values; sim.ahead.DrawsAhead): one
        # numba fill per block, not per frame (passing a Generator to numba costs ~7 us a call).
        from sim.ahead import DrawsAhead

        for effect, kind in ONE_KIND_STREAMS.items():
            if kind == "normal" and scene.has(effect):
                self._sources[effect] = DrawsAhead(self.rngs[effect], kind, None, block=_NORMALS_BLOCK)
        self._bg = np.ascontiguousarray(scene.background_prims)
        refl = [spec.body.reflectivity for spec in scene.targets]
        refl += [obj.body.reflectivity for obj in scene.others]      # birds, crowns (sim.world.sky)
        if self._bg.shape[0]:
            refl.append(scene.background_reflectivity)
        # Stray near returns (insects, dust): one more row, after the background (sim.effects)
        self._stray_prim = sum(r.size for r in refl)
        if scene.has("stray_returns"):
            refl.append(np.array([STRAY_REFLECTIVITY]))
        self._refl_table = np.concatenate(refl) if refl else np.zeros(0)
        self._refl_byte_table = np.clip(np.round(self._refl_table * 100), 0, 255).astype(np.uint8)
        # The range limit per primitive: for the return probability, and for the range noise model
        # (the datasheet's 260 m at 80 % where the scene does not list the return probability).
        from sim.scene import EFFECT_DEFAULTS

        range_80pct_m = (scene.param("range_80pct_m") if scene.has("return_probability")
                         else EFFECT_DEFAULTS["return_probability"]["range_80pct_m"])
        self._range_limit_m = (fx.range_limit_m(self._refl_table, range_80pct_m)
                               if scene.has("return_probability") or scene.has("range_noise_model")
                               else np.zeros(self._refl_table.size))
        # Incidence, weather, the range noise model (sim.effects): their scales, asked once.
        self._noise_limit_m = self._param_if("range_noise_model", "noise_limit_m")
        self._extinction_1_m = (fx.extinction_1_m(scene.param("weather_visibility_m")) if scene.has("weather") else 0.0)
        self._cos = _NONE            # this frame's |cos incidence| per ray (effect incidence)
        self._share = _NONE          # this frame's share of the beam in its echo (effect mixed_pixels)
        # A Livox's rain/fog suppression (the SDK's lidar command 0x03, sim.virtual_lidar): drops the
        # droplet returns of the weather effect; their draws are taken either way.
        self.rain_fog_suppression = False
        self.last_clutter = 0        # droplet returns placed in the last frame (before suppression)
        # The range envelope, always on: the blind zone and the maximum range (sim.scan.presets).
        self._min_range_m, self._max_range_m = scene.lidar_range_m
        # The noise effects' scales, as their draw functions compute them (sim.effects).
        self._range_noise_m = self._param_if("range_noise", "range_noise_m")
        self._angular_noise_rad = math.radians(self._param_if("angular_noise", "angular_noise_deg"))
        self._dropout_rate = self._param_if("dropouts", "dropout_rate")
        # Which effects act, asked once (a frame asked the scene eight times).
        self._has = {name: scene.has(name) for name in
                     ("return_probability", "dropouts", "range_noise", "angular_noise", "sunlight", "beam_footprint",
                      "stray_returns", "incidence", "weather", "mixed_pixels")}
        self._target_prim_end = sum(spec.body.prims.shape[0] for spec in scene.targets)
        # Per target, what sizes its per-frame cull (computed once: both walk Python objects).
        # (bounding radius, top speed, acceleration bound or None): the cone over the frame, then the
        # ray's own instant (wk.moving_cull_kernel)
        self._cull = [(spec.body.bounding_radius_m, spec.trajectory.max_speed_m_s,
                       getattr(spec.trajectory, "max_accel_m_s2", None)) for spec in scene.targets]
        self._cull_others = [(obj.bounding_radius_m, obj.trajectory.max_speed_m_s,
                              getattr(obj.trajectory, "max_accel_m_s2", None)) for obj in scene.others]
        self._singles_of = None       # the flocks _singles was made for (_single_bodies)
        self._reaches: dict = {}      # the culls' reaches per group and chunk length (_reach_for)
        self._blocks = None           # the chunk's direction bounds (_ray_blocks), made once a chunk
        # A flock's birds are cast together (sim.world.sky.FlockPoses: the same values, a twentieth of
        # the Python calls); with a beam footprint each body's sub-rays are cast on their own.
        self._flocks = {} if self._has["beam_footprint"] else {
            a: _FlockCast.of(scene.others[a:b], self._cull_others[a:b], b) for a, b in FlockPoses.groups(scene.others)}
        # Multi-object scenes: the first primitive of each object (drones, then birds and crowns), for
        # the rays that hit each (``last_object_rays``) and the stray returns placed (``last_strays_m``).
        self._object_prim_start = np.cumsum([0] + [spec.body.prims.shape[0] for spec in scene.targets]
                                            + [obj.body.prims.shape[0] for obj in scene.others])
        # ... and the object of each of their primitives (sim.sensor_kernels.object_rays_kernel)
        self._object_of_prim = np.repeat(np.arange(self._object_prim_start.size - 1),
                                         np.diff(self._object_prim_start))
        self.last_object_rays: np.ndarray | None = None
        # each object's position at the last chunk's mid time (what its cull centred on; the truth's too),
        # as Python floats [x, y, z] (the truth's form: a flock's in one conversion, not one a bird)
        self.last_mid_xyz_m: list[list[float]] | None = None
        # ... and its velocity there where the cull asked for it (None where it did not): the truth's too
        self.last_mid_velocity: list | None = None
        self.last_strays_m = np.zeros((0, 3))
        # Work counters (timing-free evidence that a scene costs only what it holds).
        self.rays_total = 0
        self.rays_cast_targets = 0
        self.rays_cast_background = 0

    def returns(self, chunk, d_world: np.ndarray, t0: float, t1: float):
        """Points for one scan chunk whose beams point along ``d_world`` (world frame).

        ``[t0, t1)`` bounds the chunk's times (it sizes the per-target cull).  Returns
        ``(xyz (n, 3) [m] lidar frame, t_ns (n,), reflectivity byte (n,), on_target (n,) bool)``,
        in time order; xyz on the 1 mm grid of a Livox's Cartesian output (``quantise_to_mm_grid``).
        """
        scene = self.scene
        has = self._has
        n = len(chunk)
        # 4. ray casting: targets (culled) then background.
        rng_m = np.empty(n)
        rng_m.fill(np.inf)
        prim = np.empty(n, dtype=np.int64)
        prim.fill(-1)
        if has["incidence"]:
            self._cos = np.ones(n)
        if has["mixed_pixels"]:
            self._share = np.ones(n)
        offset = 0
        mids, vels = [], []
        # each ray's instant, as the poses take it (the per-ray cull's): its time [ns], which the kernels
        # and _ray_times turn into seconds for the rays they need (t_ns * 1e-9, the same bits as an
        # array of all of them), or the mid time
        self._t_ray = chunk.t_ns if self.target_motion == "per_point" else np.full(n, 0.5 * (t0 + t1))
        self._blocks = None
        culled = self._cull_bodies(t0, t1, chunk, d_world)
        straight = self._straight
        for q, (spec, (c, v, idx)) in enumerate(zip(scene.targets, culled)):
            run = straight.run_at.get(q)
            if run is not None:      # targets q.. on straight passes, cast together
                self._cast_straight(run, d_world, rng_m, prim)
            elif not straight.cast_together[q]:
                self._cast_on(spec, idx, d_world, rng_m, prim, offset)
            mids.append(c.tolist())
            vels.append(None if v is None else v.tolist())
            offset += spec.body.prims.shape[0]
        k = 0
        single = len(scene.targets)      # culled[single]: the next body cast on its own
        while k < len(scene.others):
            if k in self._flocks:
                flock = self._flocks[k]
                c, v = self._cast_flock(flock, t0, t1, chunk, d_world, rng_m, prim, offset)
                mids += c
                vels += v
                offset += int(flock.prim_start[-1])
                k = flock.stop
                continue
            obj = scene.others[k]
            c, v, idx = culled[single]
            single += 1
            self._cast_on(obj, idx, d_world, rng_m, prim, offset)
            mids.append(c.tolist())
            vels.append(None if v is None else v.tolist())
            offset += obj.body.prims.shape[0]
            k += 1
        self.last_mid_xyz_m = mids
        self.last_mid_velocity = vels
        self.rays_total += n
        if self._bg.shape[0]:
            self.rays_cast_background += n
            wk.cast_static_kernel(d_world, self._bg, offset, rng_m, prim)
            if has["incidence"]:
                wk.cos_incidence_static_kernel(d_world, rng_m, prim, self._bg, offset, self._cos)
        if has["stray_returns"]:
            self._strays(chunk, d_world, t0, t1, rng_m, prim)
        # 5. effects, each only if listed (draws in a fixed order, one call per effect and frame),
        # applied to the hits and gathered in scan order in one pass.
        if scene.multi_object:     # the hits per object, and all of them, in one pass
            self.last_object_rays = np.zeros(self._object_prim_start.size - 1, dtype=np.int64)
            n_hit = sk.object_rays_kernel(prim, chunk.status, self._object_of_prim, self.last_object_rays)
        else:
            n_hit = sk.count_hits_kernel(prim, chunk.status)
        u_return = u_dropout = range_normals = angular_normals = _NONE
        if has["return_probability"]:
            u_return = fx.return_draws(self._stream("return_probability"), n_hit)
        if has["dropouts"]:
            u_dropout = fx.dropout_draws(self._stream("dropouts"), n_hit)
        if has["range_noise"]:
            range_normals = fx.range_noise_normals(self._stream("range_noise"), n_hit)
        if has["angular_noise"] and n_hit:
            angular_normals = fx.angular_noise_normals(self._stream("angular_noise"), n_hit)
        clutter = _NONE
        if has["weather"]:
            clutter = self._droplets(chunk)
        n_out = n_hit + (int(np.count_nonzero(np.isfinite(clutter))) if clutter.size else 0)
        xyz = np.empty((n_out, 3))
        pt_ns = np.empty(n_out, dtype=np.int64)
        refl_byte = np.empty(n_out, dtype=np.uint8)
        on_target = np.empty(n_out, dtype=np.bool_)
        k = sk.assemble_returns_kernel(
            prim, chunk.status, rng_m, chunk.direction, chunk.t_ns, self._range_limit_m, self._refl_byte_table,
            self._target_prim_end, u_return, u_dropout, self._dropout_rate, range_normals, self._range_noise_m,
            angular_normals, self._angular_noise_rad, True, self._min_range_m, self._max_range_m,
            self._refl_table, self._ray_gain(), self._extinction_1_m, self._noise_limit_m,
            clutter, CLUTTER_REFLECTIVITY_BYTE, xyz, pt_ns, refl_byte, on_target)
        xyz, pt_ns, refl_byte, on_target = xyz[:k], pt_ns[:k], refl_byte[:k], on_target[:k]
        if has["sunlight"] and n:
            # Sunlight false alarms are appended, then the frame is put back in time order (stable:
            # a false alarm after a real return of the same instant).
            xyz, pt_ns, refl_byte, on_target = self._sunlight(chunk, xyz, pt_ns, refl_byte, on_target)
            order = np.argsort(pt_ns, kind="stable")
            xyz, pt_ns, refl_byte, on_target = xyz[order], pt_ns[order], refl_byte[order], on_target[order]
        # The points are what a Livox outputs (Cartesian data types 0/2): int32 mm, which the live
        # client turns into float64 metres (the kernel's mm grid: the bits of quantise_to_mm_grid).
        return xyz, pt_ns, refl_byte, on_target

    def warm_up(self, chunk) -> None:
        """Run every kernel of :meth:`returns` once (compiled, or loaded from numba's cache), for a
        real-time driver to call before data flows.  ``chunk``: a few rays of the scene's scan; the
        first ray of each target is pointed at it, so that its cull finds a candidate and the
        moving-body cast runs too.  Call it on a throwaway sensor: it draws from the streams."""
        d = chunk.direction.copy()
        t_mid_s = float(chunk.t_ns.mean()) * 1e-9
        for i, spec in enumerate(self.scene.targets[:len(d)]):
            c = spec.trajectory.position(np.array([t_mid_s]))[0]
            d[i] = c / max(norm3(c), 1e-9)
        chunk = replace(chunk, direction=d, status=np.zeros_like(chunk.status))
        t0, t1 = chunk.t_ns[0] * 1e-9, chunk.t_ns[-1] * 1e-9 + 1e-6
        self.returns(chunk, d, t0, t1)

    def draw_ahead(self, ahead) -> None:
        """From now on, the one-kind streams of the effects the scene lists are drawn ahead in blocks
        on ``ahead``'s worker (:class:`sim.ahead.DrawsAhead`): the same values, off the loop's thread."""
        from sim.ahead import DrawsAhead

        for effect, kind in ONE_KIND_STREAMS.items():
            if not self.scene.has(effect):
                continue
            if self._sources[effect] is self.rngs[effect]:
                self._sources[effect] = DrawsAhead(self.rngs[effect], kind, ahead)
            else:     # drawn in blocks on this thread so far: the coming blocks go to the worker
                self._sources[effect].work_on(ahead)

    def _param_if(self, effect: str, key: str) -> float:
        return float(self.scene.param(key)) if self.scene.has(effect) else 0.0

    def _stream(self, effect: str) -> np.random.Generator:
        """The effect's random stream, counting the call (tests check unlisted effects draw nothing)."""
        self.draw_calls[effect] += 1
        return self._sources[effect]

    def _ray_gain(self) -> np.ndarray:
        """Per ray, the power gain of incidence and of the footprint's share (empty: neither listed)."""
        if self._has["incidence"] and self._has["mixed_pixels"]:
            return self._cos * self._share
        if self._has["incidence"]:
            return self._cos
        if self._has["mixed_pixels"]:
            return self._share
        return _NONE

    def _droplets(self, chunk) -> np.ndarray:
        """Droplet returns of the weather effect: per ray the range of its droplet (inf: none), or
        none at all while the rain/fog suppression is on (drawn either way: the stream does not
        depend on the mode)."""
        p = self.scene.param
        rays, r = fx.weather_clutter_draws(self._stream("weather"), np.flatnonzero(chunk.status == RAY_OK),
                                           p("weather_clutter_prob"), p("weather_clutter_min_m"), p("weather_clutter_max_m"))
        self.last_clutter = int(rays.size)
        clutter = np.full(len(chunk), np.inf)
        if not self.rain_fog_suppression:
            clutter[rays] = r
        return clutter

    def _strays(self, chunk, d_world, t0, t1, rng_m, prim):
        """Insects and dust (effect ``stray_returns``): Poisson(rate x frame length) returns, each on a
        ray drawn uniformly from the chunk (the rays are uniform in time) at a range uniform in
        [min, max]; a stray nearer than what the ray hit replaces that return (a lidar reports the
        first), one on a ray that left no prism (status not OK) or beyond the hit is lost.  Draws: the
        count, then the rays, then the ranges, from the effect's own stream."""
        rng = self._stream("stray_returns")
        n = len(chunk)
        k = int(rng.poisson(self.scene.param("stray_rate_hz") * (t1 - t0)))
        self.last_strays_m = np.zeros((0, 3))
        if k == 0 or n == 0:
            return
        rays = rng.integers(0, n, k)
        r = rng.uniform(self.scene.param("stray_min_range_m"), self.scene.param("stray_max_range_m"), k)
        ok = (chunk.status[rays] == RAY_OK) & (r < rng_m[rays])
        rays, r = rays[ok], r[ok]
        rng_m[rays] = r
        prim[rays] = self._stray_prim
        if self._has["incidence"]:
            self._cos[rays] = 1.0      # an insect or a grain: no surface to be oblique to
        if self._has["mixed_pixels"]:
            self._share[rays] = 1.0
        self.last_strays_m = d_world[rays] * r[:, None]      # world frame, for the truth

    def _cull_bodies(self, t0, t1, chunk, d_world) -> list:
        """The bodies cast on their own (the targets, then the others outside a flock, in order): each
        one's position and velocity at the chunk's mid time (the velocity None where the cull does not
        need it) and the rays that can meet it, ``(c, v, idx)``: those passing within its cone over the
        chunk (its bounding radius and how far it can fly in half the chunk), then of those the rays
        that can meet it at their own instant (not with a beam footprint, whose divergence widens the
        cone instead).  Culled in one call (:func:`sim.world.kernels.bodies_candidates_kernel`), whose
        direction bounds on blocks of rays (:meth:`_ray_blocks`) skip the rays far from a body: a
        call per body and pass over every ray cost 7 us each, 36 us a frame on the swarm's drones."""
        bodies, radius, speed, accel = self._single_bodies()
        if not bodies:
            return []
        footprint = self._has["beam_footprint"]
        t = np.array([0.5 * (t0 + t1)])
        straight = self._straight
        # the straight passes' positions in one expression (Straight.position's, element for element)
        # and their velocities; the other bodies' rows filled in below (velocity 0 where the cull takes
        # none: without an acceleration bound, or with a beam footprint, it is not read)
        centres = straight.start_m + t[0] * straight.velocity_m_s
        vels = straight.velocity_m_s.copy()
        out = []
        for q, (spec, cull) in enumerate(bodies):
            if straight.is_straight[q]:
                c, v = centres[q], (None if cull[2] is None or footprint else vels[q])
            else:
                if cull[2] is None or footprint:
                    c, v = spec.trajectory.position(t)[0], None
                else:   # in one evaluation where the path has one (a manual flight's clip, a circle's trig)
                    p, v = position_velocity(spec.trajectory, t)
                    c, v = p[0], v[0]
                centres[q] = c
                vels[q] = _ZERO3 if v is None else v
            out.append((c, v))
        reach = self._reach_for(None, radius, speed, t0, t1)
        if footprint:   # beam divergence can catch a body just outside the central ray's path
            div = math.radians(max(self.scene.optics.beam_divergence_deg))
            reach = np.array([r + norm3(c) * div / 2 for r, c in zip(reach.tolist(), centres)])
        idx, start = wk.bodies_candidates_kernel(d_world, chunk.status, self._t_ray, 0.5 * (t0 + t1), centres, vels,
                                                 reach, radius, accel, speed, not footprint,
                                                 *self._ray_blocks(chunk, d_world))
        self._cull_idx, self._cull_start = idx, start
        bounds = start.tolist()
        return [(c, v, idx[a:b]) for (c, v), a, b in zip(out, bounds, bounds[1:])]

    def _reach_for(self, group, radius, speed, t0, t1) -> np.ndarray:
        """:func:`_reach` of a group's bodies (``group``: None for the bodies cast on their own, a
        flock's start for its birds), kept per chunk length: a run's frames have a dozen distinct
        ``t1 - t0`` in their last bits, and the four array operations cost ~4 us a call."""
        key = (group, t1 - t0)
        reach = self._reaches.get(key)
        if reach is None:
            if len(self._reaches) > 64:
                self._reaches.clear()
            reach = self._reaches[key] = _reach(radius, speed, t0, t1)
        return reach

    def _single_bodies(self):
        """The bodies cast on their own, ``[(body, cull)]`` (the targets, then the others outside the
        flocks of ``_flocks``), and their culls' bounding radii, top speeds and acceleration bounds
        (-1: none) as arrays; made again if ``_flocks`` is replaced (a test casts a flock bird by bird)."""
        if self._singles_of is not self._flocks:
            flocked = {k for a, f in self._flocks.items() for k in range(a, f.stop)}
            bodies = list(zip(self.scene.targets, self._cull)) + [
                (obj, cull) for k, (obj, cull) in enumerate(zip(self.scene.others, self._cull_others))
                if k not in flocked]
            self._singles = (bodies, np.array([float(c[0]) for _, c in bodies]),
                             np.array([float(c[1]) for _, c in bodies]),
                             np.array([-1.0 if c[2] is None else float(c[2]) for _, c in bodies]))
            self._singles_of = self._flocks
            self._reaches.clear()
            self._straight = _StraightBodies.of(bodies, len(self.scene.targets), self._has)
        return self._singles

    def _ray_blocks(self, chunk, d_world):
        """This chunk's direction bounds on blocks of rays (:func:`sim.world.kernels.ray_blocks_kernel`),
        made once for every cull of the chunk."""
        if self._blocks is None:      # reset by returns() for each chunk
            nb = -(-len(chunk) // wk.CULL_BLOCK)
            axis, cos, sin = np.empty((nb, 3)), np.empty(nb), np.empty(nb)
            wk.ray_blocks_kernel(d_world, chunk.status, axis, cos, sin)
            self._blocks = (axis, cos, sin)
        return self._blocks

    def _cast_straight(self, run: np.ndarray, d_world, rng_m, prim) -> None:
        """Cast the targets ``run`` (consecutive, on straight passes: ``_StraightBodies.run_at``) on
        their rays of this chunk's cull in one call (:func:`sim.world.kernels.cast_straight_kernel`:
        what :meth:`_cast_on` does body by body, ~8 us of Python each)."""
        start = self._cull_start
        self.rays_cast_targets += int(start[run[-1] + 1] - start[run[0]])
        st = self._straight
        wk.cast_straight_kernel(self._cull_idx, start, run, d_world, self._t_ray, st.start_m, st.velocity_m_s, st.yaw,
                                st.prims, st.prim_start, rng_m, prim)

    def _cast_flock(self, flock: _FlockCast, t0, t1, chunk, d_world, rng_m, prim, offset):
        """:meth:`_cast_on` for each bird of a flock in turn, in a few calls: the birds' poses
        evaluated together (:class:`sim.world.sky.FlockPoses`), the rays culled for every bird in one
        call (:func:`sim.world.kernels.bodies_candidates_kernel`: bird by bird, the rays in order, on
        the chunk's direction bounds as the bodies cast on their own) and cast on them in one
        (:func:`sim.world.kernels.cast_flock_kernel`); returns their positions and velocities at the
        chunk's mid time (two lists of [x, y, z] lists)."""
        t_mid = 0.5 * (t0 + t1)
        poses = flock.poses
        centres, vel = poses.positions_velocities(flock.members, np.full(flock.members.size, t_mid))
        reach = self._reach_for(flock.stop, flock.radius_m, flock.max_speed_m_s, t0, t1)
        idx, start = wk.bodies_candidates_kernel(d_world, chunk.status, self._t_ray, t_mid, centres, vel, reach,
                                                 flock.radius_m, flock.max_accel_m_s2, flock.max_speed_m_s, True,
                                                 *self._ray_blocks(chunk, d_world))
        m = np.repeat(flock.members, start[1:] - start[:-1])     # each ray's bird (np.diff's subtraction)
        self.rays_cast_targets += idx.size
        if idx.size:
            t_pose = self._ray_times(idx)
            pos, yaw = poses.poses(m, t_pose)
            wk.cast_flock_kernel(idx, m, d_world, pos, yaw, poses.wing_angles(m, t_pose), flock.prims, flock.hinge,
                                 flock.prim_start, offset, rng_m, prim)
        return centres.tolist(), vel.tolist()

    def _ray_times(self, idx) -> np.ndarray:
        """The instants [s] of the rays ``idx``: their own (per_point), or the mid time (per_frame)."""
        t = self._t_ray[idx]
        return t * 1e-9 if t.dtype.kind == "i" else t

    def _cast_on(self, spec, idx, d_world, rng_m, prim, offset) -> None:
        """Cast the rays ``idx`` (the body's candidates, :meth:`_cull_bodies`) on one moving body, each at
        its own instant."""
        traj = spec.trajectory
        self.rays_cast_targets += idx.size
        if idx.size == 0:
            return
        t_pose = self._ray_times(idx)
        fixed_yaw = getattr(spec, "fixed_yaw", None)      # a tree's crown keeps its yaw
        if fixed_yaw is None:     # along its velocity: position and velocity in one evaluation where the path has one
            pos, vel = position_velocity(traj, t_pose)
            yaw = body_yaw_rad(traj, t_pose, vel)
        else:
            pos = traj.position(t_pose)
            yaw = np.full(idx.size, fixed_yaw)
        prims = spec.body.prims
        flap = getattr(spec, "flap", None)
        if flap is not None:     # a bird: its wings at each ray's own time
            flap_rad = flap.angle_rad(t_pose)

            def cast(rays, d, r, p):
                wk.cast_flapping_kernel(rays, d, pos, yaw, flap_rad, prims, spec.hinge, offset, r, p)
        else:
            def cast(rays, d, r, p):
                wk.cast_moving_kernel(rays, d, pos, yaw, prims, offset, r, p)
        if not self._has["beam_footprint"]:
            cast(idx, d_world, rng_m, prim)
            self._incidence_on(spec, idx, d_world, pos, yaw, rng_m, prim, offset, flap)
            return
        # Beam footprint: sub-rays over the divergence ellipse; the return is the nearest sub-ray
        # range if at least half of the sub-rays hit (a partial hit on a thin arm may still return).
        offs = fx.footprint_offsets(self.scene.optics.beam_divergence_deg, self.scene.param("footprint_subrays"))
        d = d_world[idx]
        up = np.array([0.0, 0.0, 1.0])
        e_az = np.cross(up, d)
        e_az /= np.maximum(np.linalg.norm(e_az, axis=1, keepdims=True), 1e-12)
        e_el = np.cross(d, e_az)
        if self._has["mixed_pixels"]:
            self._mixed(offs, d, e_az, e_el, cast, idx, rng_m, prim, offset, prims.shape[0])
            self._incidence_on(spec, idx, d_world, pos, yaw, rng_m, prim, offset, flap)
            return
        hits = np.zeros(idx.size, dtype=np.int64)
        best = np.full(idx.size, np.inf)
        best_prim = np.full(idx.size, -1, dtype=np.int64)
        local = np.arange(idx.size, dtype=np.int64)
        for a, b in offs:
            sub = d + a * e_az + b * e_el
            sub /= np.linalg.norm(sub, axis=1, keepdims=True)
            r = np.full(idx.size, np.inf)
            p = np.full(idx.size, -1, dtype=np.int64)
            cast(local, sub, r, p)
            hits += p >= 0
            nearer = r < best
            best[nearer] = r[nearer]
            best_prim[nearer] = p[nearer]
        ret = hits * 2 >= len(offs)
        take = ret & (best < rng_m[idx])
        rng_m[idx[take]] = best[take]
        prim[idx[take]] = best_prim[take]
        self._incidence_on(spec, idx, d_world, pos, yaw, rng_m, prim, offset, flap)

    def _mixed(self, offs, d, e_az, e_el, cast, idx, rng_m, prim, offset, n_prims):
        """Mixed pixels (effect ``mixed_pixels``): each sub-ray of the candidate beams against this
        body and the static background, then one echo per beam (:func:`sim.sensor_kernels.
        mixed_pixel_kernel`); a beam whose footprint touches the body takes it if nearer than what
        an earlier body gave.  Moving objects behind (other drones, birds, crowns) are not mixed in."""
        k = idx.size
        sub_r = np.full((k, len(offs)), np.inf)
        sub_p = np.full((k, len(offs)), -1, dtype=np.int64)
        local = np.arange(k, dtype=np.int64)
        bg_offset = int(self._object_prim_start[-1])
        for s, (a, b) in enumerate(offs):
            sub = d + a * e_az + b * e_el
            sub /= np.linalg.norm(sub, axis=1, keepdims=True)
            r = np.full(k, np.inf)
            p = np.full(k, -1, dtype=np.int64)
            cast(local, sub, r, p)
            if self._bg.shape[0]:
                wk.cast_static_kernel(sub, self._bg, bg_offset, r, p)
            sub_r[:, s] = r
            sub_p[:, s] = p
        touched = np.any((sub_p >= offset) & (sub_p < offset + n_prims), axis=1)
        out_r = np.empty(k)
        out_p = np.empty(k, dtype=np.int64)
        share = np.empty(k)
        sk.mixed_pixel_kernel(sub_r, sub_p, self._refl_table, float(self.scene.param("mixed_resolution_m")),
                              out_r, out_p, share)
        take = touched & (out_r < rng_m[idx])
        rng_m[idx[take]] = out_r[take]
        prim[idx[take]] = out_p[take]
        self._share[idx[take]] = share[take]

    def _incidence_on(self, spec, idx, d_world, pos, yaw, rng_m, prim, offset, flap):
        """|cos incidence| of the rays ``idx`` that hit this body (effect incidence), along the
        central ray; a bird's flapping wings are left at 1 (their pose is not kept here)."""
        if self._has["incidence"] and flap is None:
            wk.cos_incidence_moving_kernel(idx, d_world, pos, yaw, rng_m, prim, spec.body.prims, offset, self._cos)

    def _sunlight(self, chunk, xyz, pt_ns, refl_byte, on_target):
        rng = self._stream("sunlight")
        ok = chunk.status == RAY_OK
        n_false = rng.binomial(int(ok.sum()), self.scene.param("sunlight_rate"))
        if n_false == 0:
            return xyz, pt_ns, refl_byte, on_target
        pick = rng.choice(np.flatnonzero(ok), n_false, replace=False)
        r = rng.uniform(0.5, self.scene.param("sunlight_max_range_m"), n_false)
        inside = (r >= self._min_range_m) & (r <= self._max_range_m)   # the envelope gates them too
        if not inside.all():
            pick, r = pick[inside], r[inside]
            n_false = r.size
        xyz = np.vstack([xyz, quantise_to_mm_grid(chunk.direction[pick] * r[:, None])])
        pt_ns = np.concatenate([pt_ns, chunk.t_ns[pick]])
        refl_byte = np.concatenate([refl_byte, np.full(n_false, 1, dtype=np.uint8)])
        on_target = np.concatenate([on_target, np.zeros(n_false, dtype=bool)])
        return xyz, pt_ns, refl_byte, on_target
