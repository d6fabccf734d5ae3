"""Scene files: TOML loaded into frozen dataclasses, validated on load.

A scene lists everything a closed-loop run simulates, and nothing else: an effect that is not in
``[scene] effects`` draws no random numbers and costs no time.  Every error names the file, the key
and what is allowed; a drone or bird under the ground or at the head is named too
(:mod:`sim.scene_placement`, :meth:`Scene.warnings`).  Tables::

    [scene]      name, duration_s, seed, effects = [...], start_utc (the recording's log times, UTC)
    [effects]    parameters of the listed effects (optional; documented defaults)
    [lidar]      preset = "mid40" | "prototype" | "horizon" (or custom optics: point_rate_hz,
                 prisms, ...), model = "exact" | "paraxial", min_range_m / max_range_m (the range
                 envelope, always applied; default: the preset's, sim.scan.presets.RANGE_ENVELOPE_M)
    [gimbal]     family, unit_seed, baud, feedback, address, pan0_deg, tilt0_deg,
                 frozen (true: the head never moves; the tracker still runs),
                 speed_table = "truth" | "nominal" | "path/to/table.json", send_delay_s
    [[target]]   geometry = "quadrotor" | "sphere" | "box", span_m / radius_m / size_m,
                 reflectivity, [target.trajectory] type = straight | circle | figure8 |
                 waypoints | manual (+ its parameters)
    [[background]] type = ground | wall | room | box (+ its parameters), reflectivity
    [[bird]]     a bird or a flock (count): id, count, wingspan_m, ..., [bird.trajectory] (its centre)
    [[tree]]     a trunk and a crown swaying in the wind: id, base_m, height_m, crown_radius_m, ...
                 (birds and trees: sim.scene_sky; [[target]] also takes id and class)
    [tracker]    foveatrack.tracker.TrackerConfig keys
    [imu]        an IMU on the lidar (only then simulated): rotation_deg, translation_m (its pose in
                 the lidar frame), nominal_*, noise keys (sim.imu; defaults: BMI088)
    [imu_poses]  the static poses of the lidar-IMU calibration: count, step_deg, step_m, dwell_s, move_s
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from foveatrack.config_util import as_bool, as_choice, as_float, as_vec, check_keys, read_toml
from foveatrack.errors import UserError
from gimbal.head_facts import DEFAULT_HEAD
from sim.scene_objects import MAX_TARGETS, TRAJECTORY_TYPES, object_id, trajectory_from_table  # noqa: F401

# Effects a scene can ask for, with their parameters and defaults (sources in the docstring of
# sim.effects).  Head effects act in gimbal/pts303h (sim/loop.py hands them over), link effects in
# sim/virtual_uart.py and sim/loop.py.
EFFECT_DEFAULTS: dict[str, dict[str, Any]] = {
    "range_noise": {"range_noise_m": 0.02},
    "angular_noise": {"angular_noise_deg": 0.03},
    "return_probability": {"range_80pct_m": 260.0},
    "beam_footprint": {"footprint_subrays": 7},
    "sunlight": {"sunlight_rate": 5e-5, "sunlight_max_range_m": 60.0},
    "motor_speed_noise": {"speed_noise_frac": 0.01, "speed_noise_segment_s": 0.01},
    "dropouts": {"dropout_rate": 0.01},
    "uart_bit_errors": {"uart_bit_error_rate": 1e-4},
    "uart_drops": {"uart_drop_rate": 1e-3},
    "uart_echo": {},
    "head_ripple": {},
    # insects and dust: isolated returns at short range, at a rate per second (sim.sensor)
    "stray_returns": {"stray_rate_hz": 2.0, "stray_min_range_m": 1.0, "stray_max_range_m": 15.0},
    # range noise growing with range, falling with reflectivity (shapes range_noise's draws)
    "range_noise_model": {"noise_limit_m": 0.15},
    # returned power against the incidence angle (Lambertian): no parameters
    "incidence": {},
    # fog / haze / dust as a visibility: extinction, droplet returns near the sensor
    # a beam's footprint on a near edge and a far surface: one echo, mixed or the stronger (sub-rays
    # of beam_footprint)
    "mixed_pixels": {"mixed_resolution_m": 0.75},
    "weather": {"weather_visibility_m": 1000.0, "weather_clutter_prob": 0.002, "weather_clutter_min_m": 1.0,
                "weather_clutter_max_m": 10.0},
    # the head and timing side (sources and stated assumptions in sim.effects, "Head and timing")
    "head_thermal_drift": {"head_delta_t_k": 20.0, "head_speed_coeff_per_k": -0.001},
    "head_dead_time_jitter": {"dead_time_jitter_s": 0.02},
    "link_latency_jitter": {"link_latency_jitter_s": 0.001},
    "lidar_clock_drift": {"lidar_clock_drift_ppm": -20.0},
    "head_backlash": {"head_backlash_deg": 0.2},
    "head_wind": {"wind_speed_m_s": 8.0, "wind_turbulence": 0.2, "head_stiffness_nm_per_rad": 100.0},
}
# Effects that act on another's draws or sub-rays, with what each needs listed beside it.
EFFECT_REQUIRES: dict[str, tuple[str, ...]] = {
    "range_noise_model": ("range_noise",),      # shapes the range noise's sigma
    "mixed_pixels": ("beam_footprint",),        # splits the beam into its sub-rays
}
# [effects] keys that may be negative, with their bounds (every other key is >= 0)
SIGNED_EFFECT_PARAMS: dict[str, tuple[float, float]] = {
    "head_delta_t_k": (-60.0, 60.0),             # from the calibration's temperature [K]
    "head_speed_coeff_per_k": (-0.01, 0.01),     # relative speed change per kelvin [1/K]
    "lidar_clock_drift_ppm": (-150.0, 150.0),    # inside the daemon's clock guard (DRIFT_PPM 200)
}
GEOMETRIES = ("quadrotor", "sphere", "box")
BACKGROUND_TYPES = ("ground", "wall", "room", "box")


# A scene is read from a file someone may have made by mistake or on purpose: every background body
# is ray-cast for every beam, so their count is capped (MAX_TARGETS, the objects': sim.scene_objects).
MAX_BACKGROUND = 4096

@dataclass(frozen=True)
class TargetSpec:
    body: Any  # sim.world.bodies.Body
    trajectory: Any  # a sim.world.trajectories object
    id: str = "drone-1"     # the truth's name for it (recordings of multi-object scenes)
    cls: str = "drone"      # "drone" or "clutter" (a balloon, a box carried by the wind)


@dataclass(frozen=True)
class GimbalSpec:
    family: str = "pts-303"
    unit_seed: int = 0
    baud: int = 9600
    feedback: str = "none"
    address: int = 1
    pan0_deg: float = 0.0
    tilt0_deg: float = 0.0
    frozen: bool = False
    speed_table: str = "truth"
    send_delay_s: float = 0.002


@dataclass(frozen=True)
class GateSpec:
    """``[gate]``: the command gate's limits for this scene (:mod:`foveatrack.gate`, the daemon's own
    ``[head]`` limits and ``[daemon] stale_frame_s``).  Without the table the simulator's gate passes
    every command unchanged.  The tilt stops are the head's.

    max_pan_byte, max_tilt_byte : 0..63; allow_turbo : bool; tilt_margin_deg : >= 0 [deg]
    stale_frame_s : > 0 [s] or None: a frame older than this when its command is sent (virtual time:
        ``[gimbal] send_delay_s``) steers nothing, STOP is sent instead
    """
    max_pan_byte: int = DEFAULT_HEAD.max_pan_byte          # defaults: the head facts', as the daemon's
    max_tilt_byte: int = DEFAULT_HEAD.max_tilt_byte
    allow_turbo: bool = DEFAULT_HEAD.allow_turbo
    tilt_margin_deg: float = DEFAULT_HEAD.tilt_margin_deg
    stale_frame_s: float | None = None


@dataclass(frozen=True)
class Scene:
    name: str
    path: str
    text: str
    duration_s: float
    seed: int
    effects: frozenset[str]
    effect_params: Mapping[str, Any]
    optics: Any  # RisleyOptics
    scan_model: str
    gimbal: GimbalSpec
    targets: tuple[TargetSpec, ...]
    background_prims: np.ndarray = field(repr=False)
    background_reflectivity: np.ndarray = field(repr=False)
    tracker: Any = None  # TrackerConfig
    tracker_table: Mapping[str, Any] = field(default_factory=dict)
    gate: GateSpec | None = None
    imu: Any = None        # sim.imu.ImuSpec, only if the scene has [imu]
    imu_poses: Any = None  # sim.imu.PoseSchedule, only if the scene has [imu_poses]
    # (blind zone, maximum range) [m] of the lidar, always applied; None: the Mid-40's
    range_envelope_m: tuple[float, float] | None = None
    # UTC at virtual time 0 [ns since 1970]: the recording's log times (what Foxglove's timeline
    # shows); fixed by the scene (default START_UTC), never the wall clock: same seed, same bits
    start_utc_ns: int = 1_767_225_600_000_000_000
    # birds and tree crowns (sim.world.sky.SkyObject), only if the scene lists [[bird]] / [[tree]]
    others: tuple = ()
    # the table the scene was built from (a copy): what with_run_overrides rebuilds it from
    table: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def multi_object(self) -> bool:
        """The scene's world holds more than one drone, or birds, trees or stray returns, or its
        tracker is the multi-object one (``[tracker.sky]``): its recording then carries the truth of
        every object (sim.recorder) and each object's rays are counted (the sky figures' bounds read
        them: a single target under ``[tracker.sky]`` was said to have allowed its confirmation
        "never", its rays taken as 1 a frame)."""
        return (len(self.targets) > 1 or bool(self.others) or self.has("stray_returns")
                or isinstance((self.tracker_table or {}).get("sky"), dict))

    @property
    def lidar_range_m(self) -> tuple[float, float]:
        """The lidar's range envelope (min, max) [m]: ``[lidar] min_range_m / max_range_m``, else the
        preset's (:data:`sim.scan.presets.RANGE_ENVELOPE_M`)."""
        if self.range_envelope_m is not None:
            return self.range_envelope_m
        from sim.scan.presets import DEFAULT_RANGE_ENVELOPE_M

        return DEFAULT_RANGE_ENVELOPE_M

    @cached_property
    def placement(self) -> tuple[list[str], list[str]]:
        """``(errors, warnings)`` of :func:`sim.scene_placement.placement_problems`, computed once per
        scene (a long scene's flock samples every bird's path: seconds; the load and ``warnings``
        both ask)."""
        from sim.scene_placement import placement_problems

        return placement_problems(self)

    def warnings(self) -> list[str]:
        """What in the scene runs but cannot be seen, in words: a drone or a bird below the ground or
        in the lidar's blind zone at some instant (:mod:`sim.scene_placement`), and what its
        ``[gimbal] speed_table`` file steers wrong by (:meth:`foveatrack.speed_table.SpeedTable.problems`,
        as a daemon config's table is judged); the CLIs that fly a scene print them at load.  Derived,
        so a scene changed by ``dataclasses.replace`` is judged as it is."""
        from foveatrack.sky.tracks import SkyTrackerConfig
        from foveatrack.speed_table import SpeedTable

        out = list(self.placement[1])
        table = self.gimbal.speed_table
        if table not in ("truth", "nominal"):      # the simulated unit's own curves need no check
            try:
                problems = SpeedTable.load(table).problems()
            except UserError:
                problems = []      # the run's own load names an unreadable table
            out += [f"{self.path} [gimbal] speed_table {table!r}: {p}" for p in problems]
        sky = (self.tracker_table or {}).get("sky")
        if isinstance(sky, dict):
            # the warm-up learns the background alone: as long as the run, and nothing is tracked
            warmup = sky.get("warmup_s", SkyTrackerConfig.warmup_s)
            if isinstance(warmup, (int, float)) and not isinstance(warmup, bool) and warmup >= self.duration_s:
                out.append(f"{self.path} [tracker.sky] warmup_s {warmup:g} is not shorter than the run "
                           f"({self.duration_s:g} s): the background learns alone the whole run, and nothing is tracked")
        return out

    def has(self, effect: str) -> bool:
        return effect in self.effects

    def param(self, key: str):
        return self.effect_params[key]


def with_run_overrides(scene: Scene, duration_s: float | None = None, seed: int | None = None) -> Scene:
    """The scene with another duration and/or seed, rebuilt from the table it was built from (a
    file's or a mapping's alike) so that everything derived from them follows: a manual flight's
    path, a flock and a tree's sway are drawn from the seed over the duration.  (Scenes built from
    a mapping without text used to get only the two fields changed, their world drawn as before:
    every seed of a study flew the same flock.)  A change made to the built scene with
    ``dataclasses.replace`` is not in its table: make it after this call."""
    if duration_s is None and seed is None:
        return scene
    data = copy.deepcopy(dict(scene.table))
    sc = dict(data.get("scene", {}))
    if duration_s is not None:
        sc["duration_s"] = duration_s
    if seed is not None:
        sc["seed"] = seed
    data["scene"] = sc
    return scene_from_mapping(data, scene.path, scene.text)


def load_scene(path: str | Path) -> Scene:
    data, text = read_toml(path, "scene", "shipped scenes are in scenes/")
    return scene_from_mapping(data, str(path), text)


def scene_from_mapping(data: Mapping[str, Any], where: str = "scene", text: str = "") -> Scene:
    from foveatrack.tracker import TrackerConfig

    check_keys(data, ["scene", "effects", "lidar", "gimbal", "target", "background", "tracker", "gate", "imu",
                      "imu_poses", "bird", "tree"], where)
    sc = data.get("scene", {})
    w = f"{where} [scene]"
    check_keys(sc, ["name", "duration_s", "seed", "effects", "description", "start_utc"], w)
    start_utc_ns = utc_ns(sc.get("start_utc", START_UTC), f"{w} start_utc")
    duration = as_float(sc.get("duration_s", 10.0), "duration_s", w, lo=0, lo_open=True, hi=86400 * 2)
    seed = sc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise UserError(f"{w}: seed must be an integer >= 0, got {seed!r}")
    effects = sc.get("effects", [])
    if not isinstance(effects, list):
        raise UserError(f"{w}: effects must be a list of names from {sorted(EFFECT_DEFAULTS)}")
    for e in effects:
        if not isinstance(e, str) or e not in EFFECT_DEFAULTS:
            raise UserError(f"{w}: unknown effect {e!r}; allowed: {', '.join(sorted(EFFECT_DEFAULTS))}")
    params: dict[str, Any] = {}
    for e in effects:
        params.update(EFFECT_DEFAULTS[e])
    ep = data.get("effects", {})
    we = f"{where} [effects]"
    check_keys(ep, sorted({k for e in EFFECT_DEFAULTS for k in EFFECT_DEFAULTS[e]}), we)
    for k, v in ep.items():
        owner = next(e for e in EFFECT_DEFAULTS if k in EFFECT_DEFAULTS[e])
        if owner not in effects:
            raise UserError(f"{we}: {k} belongs to effect {owner!r}, which [scene] effects does not list")
        if k == "footprint_subrays":
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 64:
                raise UserError(f"{we}: footprint_subrays must be an integer in [1, 64], got {v!r}")
            params[k] = v
        elif k in SIGNED_EFFECT_PARAMS:
            lo, hi = SIGNED_EFFECT_PARAMS[k]
            params[k] = as_float(v, k, we, lo=lo, hi=hi)
        else:
            params[k] = as_float(v, k, we, lo=0)
    if "head_backlash" in effects and params["head_backlash_deg"] > 5.0:
        raise UserError(f"{we}: head_backlash_deg must be <= 5 (a worn head has a degree or so), "
                        f"got {params['head_backlash_deg']!r}")
    if "head_wind" in effects:
        if params["wind_speed_m_s"] > 40.0 or params["wind_turbulence"] > 1.0:
            raise UserError(f"{we}: the wind model covers wind_speed_m_s <= 40 and wind_turbulence <= 1, got "
                            f"{params['wind_speed_m_s']:g} and {params['wind_turbulence']:g}")
        if not params["head_stiffness_nm_per_rad"] >= 1.0:
            raise UserError(f"{we}: head_stiffness_nm_per_rad must be >= 1, got {params['head_stiffness_nm_per_rad']!r}")
    if "head_thermal_drift" in effects and not 1.0 + params["head_speed_coeff_per_k"] * params["head_delta_t_k"] > 0.5:
        raise UserError(f"{we}: head_speed_coeff_per_k * head_delta_t_k = "
                        f"{params['head_speed_coeff_per_k'] * params['head_delta_t_k']:g} would more than halve "
                        "the head's speeds; the drift model covers changes above -0.5")
    if "stray_returns" in effects and not params["stray_min_range_m"] < params["stray_max_range_m"]:
        raise UserError(f"{we}: stray_min_range_m = {params['stray_min_range_m']} must be below "
                        f"stray_max_range_m = {params['stray_max_range_m']}")

    for e, needs in EFFECT_REQUIRES.items():
        missing = [n for n in needs if e in effects and n not in effects]
        if missing:
            raise UserError(f"{w}: effect {e!r} acts on {', '.join(map(repr, missing))}; list it too")
    if "weather" in effects:
        if not params["weather_visibility_m"] > 0:
            raise UserError(f"{we}: weather_visibility_m must be > 0, got {params['weather_visibility_m']}")
        if not params["weather_clutter_prob"] <= 1:
            raise UserError(f"{we}: weather_clutter_prob must be in [0, 1], got {params['weather_clutter_prob']}")
        if not params["weather_clutter_min_m"] < params["weather_clutter_max_m"]:
            raise UserError(f"{we}: weather_clutter_min_m = {params['weather_clutter_min_m']} must be below "
                            f"weather_clutter_max_m = {params['weather_clutter_max_m']}")
    optics, scan_model, envelope = _lidar(data.get("lidar", {"preset": "mid40"}), f"{where} [lidar]")
    base_dir = Path(where).parent if Path(where).is_file() else None
    gimbal = _gimbal(data.get("gimbal", {}), f"{where} [gimbal]", base_dir)
    targets = data.get("target", [])
    if not isinstance(targets, list):
        raise UserError(f"{where}: [[target]] must be an array of tables")
    if len(targets) > MAX_TARGETS:    # 100 000 ran on for ever, the ray cast's cost growing with each
        raise UserError(f"{where}: {len(targets)} [[target]] tables; at most {MAX_TARGETS} in one scene")
    target_specs = tuple(_target(t, f"{where} [[target]] #{i + 1}", duration, seed + i, i) for i, t in enumerate(targets))
    from sim.scene_sky import sky_objects

    others, trunk_prims, trunk_refl = sky_objects(data, where, duration, seed, target_specs)
    bg = data.get("background", [])
    if not isinstance(bg, list):
        raise UserError(f"{where}: [[background]] must be an array of tables")
    if len(bg) > MAX_BACKGROUND:
        raise UserError(f"{where}: {len(bg)} [[background]] tables; at most {MAX_BACKGROUND} in one scene")
    prims, refl = [], []
    for i, b in enumerate(bg):
        p, r = _background(b, f"{where} [[background]] #{i + 1}")
        prims.extend(p)
        refl.extend([r] * len(p))
    prims.extend(trunk_prims)     # the trees' trunks: static, after the scene's own background
    refl.extend(trunk_refl)
    tracker_raw = data.get("tracker", {})
    if not isinstance(tracker_raw, Mapping):
        raise UserError(f"{where}: [tracker] must be a table of tracker keys, got {tracker_raw!r}")
    tracker_table = dict(tracker_raw)
    tracker = TrackerConfig.from_mapping(tracker_table, where=f"{where} [tracker]")
    imu, imu_poses = _imu(data, where)
    scene = Scene(
        name=str(sc.get("name", Path(where).stem)), path=where, text=text, duration_s=duration, seed=seed,
        effects=frozenset(effects), effect_params=params, optics=optics, scan_model=scan_model, gimbal=gimbal,
        targets=target_specs,
        background_prims=np.array(prims).reshape(-1, 13), background_reflectivity=np.array(refl, dtype=float),
        tracker=tracker, tracker_table=tracker_table, imu=imu, imu_poses=imu_poses,
        gate=_gate(data["gate"], f"{where} [gate]") if "gate" in data else None, range_envelope_m=envelope,
        start_utc_ns=start_utc_ns, others=others, table=copy.deepcopy(dict(data)),
    )
    errors, _ = scene.placement
    if errors:      # a drone the head can never see: the run would measure nothing
        raise UserError("; ".join(errors))
    return scene


START_UTC = "2026-01-01T00:00:00Z"     # a scene's start_utc unless it gives one (docs/recordings.md)
assert Scene.start_utc_ns == 1_767_225_600_000_000_000      # START_UTC, the dataclass's default


def utc_ns(text, where: str) -> int:
    """ns since 1970-01-01 UTC of an ISO 8601 time with its zone ("2026-01-01T00:00:00Z",
    "2026-06-01T14:30:00+02:00"); a UserError naming ``where`` otherwise."""
    import datetime as dt

    try:
        t = dt.datetime.fromisoformat(str(text)) if isinstance(text, str) else None
    except ValueError:
        t = None
    if isinstance(text, dt.datetime):       # TOML's own date-time (start_utc = 2026-01-01T00:00:00Z)
        t = text
    if t is None or t.tzinfo is None or t.year < 1970:
        raise UserError(f"{where}: {text!r} is not a UTC date and time with its zone after 1970, "
                        f'e.g. "2026-01-01T00:00:00Z"')
    d = t - dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)
    return (d.days * 86400 + d.seconds) * 1_000_000_000 + d.microseconds * 1000


def _imu(data: Mapping, where: str):
    if "imu" not in data and "imu_poses" not in data:
        return None, None
    from sim.imu import imu_from_table, poses_from_table

    for key in ("imu", "imu_poses"):
        if key in data and not isinstance(data[key], Mapping):
            raise UserError(f"{where}: [{key}] must be a table")
    if "imu_poses" in data and "imu" not in data:
        raise UserError(f"{where}: [imu_poses] needs an [imu] table (the IMU whose mount is calibrated)")
    imu = imu_from_table(data["imu"], f"{where} [imu]")
    poses = poses_from_table(data["imu_poses"], f"{where} [imu_poses]") if "imu_poses" in data else None
    return imu, poses


# A point's coordinates go out as int32 millimetres: beyond this range they would saturate and bend
# its bearing, so no maximum range may exceed it [m].
MAX_RANGE_LIMIT_M = 2_147_483.647


def _lidar(t: Mapping, w: str):
    from sim.scan.optics import OpticsError, optics_from_table, optics_overrides
    from sim.scan.presets import DEFAULT_RANGE_ENVELOPE_M, PRESETS, RANGE_ENVELOPE_M

    check_keys(t, ["preset", "model", "point_rate_hz", "prisms", "channel_offsets_deg", "beam_divergence_deg", "name",
                   "head_yaw_deg", "min_range_m", "max_range_m"], w)
    model = as_choice(t.get("model", "exact"), "model", w, ("exact", "paraxial"))
    rest = {k: v for k, v in t.items() if k not in ("preset", "model", "min_range_m", "max_range_m")}
    preset = None if "prisms" in t else t.get("preset", "mid40")
    if preset is not None and not isinstance(preset, str):    # a list or a table: "unhashable" traceback before
        raise UserError(f"{w}: preset must be a name ({', '.join(PRESETS)}), got {preset!r}")
    lo, hi = RANGE_ENVELOPE_M.get(preset, DEFAULT_RANGE_ENVELOPE_M) if isinstance(preset, str) else DEFAULT_RANGE_ENVELOPE_M
    lo = as_float(t.get("min_range_m", lo), "min_range_m", w, lo=0)
    hi = as_float(t.get("max_range_m", hi), "max_range_m", w, lo=0, hi=MAX_RANGE_LIMIT_M)
    if not lo < hi:
        raise UserError(f"{w}: min_range_m = {lo} must be below max_range_m = {hi}")
    try:
        if preset is None:
            if "preset" in t:
                raise UserError(f"{w}: give either preset or prisms, not both")
            return optics_from_table(rest, where=w), model, (lo, hi)
        if preset not in PRESETS:
            raise UserError(f"{w}: preset {preset!r} unknown; allowed: {', '.join(PRESETS)} (or give prisms)")
        optics = PRESETS[preset]
        if rest:
            optics = optics.with_(**optics_overrides(rest, w))
        return optics, model, (lo, hi)
    except OpticsError as exc:
        msg = str(exc)
        raise UserError(msg if msg.startswith(w) else f"{w}: {msg}") from None


def _gate(t: Mapping, w: str) -> GateSpec:
    if not isinstance(t, Mapping):
        raise UserError(f"{w}: must be a table of gate keys, got {t!r}")
    check_keys(t, ["max_pan_byte", "max_tilt_byte", "allow_turbo", "tilt_margin_deg", "stale_frame_s"], w)
    kw: dict[str, Any] = {}
    for k in ("max_pan_byte", "max_tilt_byte"):
        if k in t:
            v = t[k]
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 0x3F:
                raise UserError(f"{w}: {k} must be an integer speed byte in [0, 63], got {v!r}")
            kw[k] = v
    if "allow_turbo" in t:
        kw["allow_turbo"] = as_bool(t["allow_turbo"], "allow_turbo", w)
    if "tilt_margin_deg" in t:
        kw["tilt_margin_deg"] = as_float(t["tilt_margin_deg"], "tilt_margin_deg", w, lo=0, hi=30)
    if "stale_frame_s" in t:
        kw["stale_frame_s"] = as_float(t["stale_frame_s"], "stale_frame_s", w, lo=0, lo_open=True, hi=10)
    return GateSpec(**kw)


def _gimbal(t: Mapping, w: str, base_dir: Path | None = None) -> GimbalSpec:
    from gimbal.client import STANDARD_BAUDS
    from gimbal.pts303h import FEEDBACK_MODES, HEAD_FAMILIES

    check_keys(t, ["family", "unit_seed", "baud", "feedback", "address", "pan0_deg", "tilt0_deg", "frozen",
                   "speed_table", "send_delay_s"], w)
    kw: dict[str, Any] = {}
    if "family" in t:
        kw["family"] = as_choice(t["family"], "family", w, tuple(HEAD_FAMILIES))
    for k in ("unit_seed", "baud", "address"):
        if k in t:
            v = t[k]
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise UserError(f"{w}: {k} must be an integer >= 0, got {v!r}")
            kw[k] = v
    if "address" in kw and not 1 <= kw["address"] <= 255:
        raise UserError(f"{w}: address must be a Pelco-D address 1-255, got {kw['address']}")
    if "baud" in kw and kw["baud"] not in STANDARD_BAUDS:
        raise UserError(f"{w}: baud {kw['baud']} is not a standard rate ({', '.join(map(str, STANDARD_BAUDS))})")
    if "feedback" in t:
        kw["feedback"] = as_choice(t["feedback"], "feedback", w, tuple(FEEDBACK_MODES))
    for k in ("pan0_deg", "tilt0_deg"):
        if k in t:
            kw[k] = as_float(t[k], k, w, lo=-180, hi=180)
    if "send_delay_s" in t:
        kw["send_delay_s"] = as_float(t["send_delay_s"], "send_delay_s", w, lo=0, hi=0.1)
    if "frozen" in t:
        kw["frozen"] = as_bool(t["frozen"], "frozen", w)
    if "speed_table" in t:
        v = t["speed_table"]
        if not isinstance(v, str) or not v:
            raise UserError(f"{w}: speed_table must be 'truth', 'nominal' or a path to a table JSON")
        if v not in ("truth", "nominal") and base_dir is not None and not Path(v).is_absolute():
            v = str(base_dir / v)  # a table file next to the scene, wherever the run starts from
        kw["speed_table"] = v
    spec = GimbalSpec(**kw)
    from gimbal.pts303h import HeadParams

    params = HeadParams.for_family(spec.family)
    if not params.tilt_min_deg <= spec.tilt0_deg <= params.tilt_max_deg:
        # the closed loop would clamp it to the stop, silently: the run starts somewhere else
        raise UserError(f"{w}: tilt0_deg {spec.tilt0_deg:g} is beyond the {spec.family} head's tilt stops "
                        f"[{params.tilt_min_deg:g}, {params.tilt_max_deg:g}] deg")
    return spec


def _target(t: Mapping, w: str, duration_s: float, seed: int, index: int = 0) -> TargetSpec:
    from sim.world import bodies

    check_keys(t, ["geometry", "span_m", "radius_m", "size_m", "reflectivity", "trajectory", "id", "class"], w)
    obj_id = object_id(t.get("id", f"drone-{index + 1}"), w)
    cls = as_choice(t.get("class", "drone"), "class", w, ("drone", "clutter"))
    geom = as_choice(t.get("geometry", "quadrotor"), "geometry", w, GEOMETRIES)
    refl = as_float(t.get("reflectivity", 0.3), "reflectivity", w, lo=0, lo_open=True, hi=1)
    if geom == "quadrotor":
        body = bodies.quadrotor(as_float(t.get("span_m", 0.35), "span_m", w, lo=0.05, hi=5), refl)
    elif geom == "sphere":
        body = bodies.sphere_body(as_float(t.get("radius_m", 0.2), "radius_m", w, lo=0.01, hi=10), refl)
    else:
        size = as_vec(t.get("size_m", [0.3, 0.3, 0.1]), "size_m", w, 3)
        if min(size) <= 0:
            raise UserError(f"{w}: size_m must be positive, got {list(size)}")
        body = bodies.box_body(size, refl)
    return TargetSpec(body, trajectory_from_table(t.get("trajectory"), w, "target", duration_s, seed), obj_id, cls)


def _background(b: Mapping, w: str):
    from sim.world import bodies

    kind = as_choice(b.get("type") if isinstance(b, Mapping) else None, "type", w, BACKGROUND_TYPES)
    keys = {"ground": ["height_m"], "wall": ["centre_m", "normal", "width_m", "height_m"],
            "room": ["size_m", "centre_m"], "box": ["centre_m", "size_m", "yaw_deg"]}[kind]
    check_keys(b, ["type", "reflectivity"] + keys, w)
    refl = as_float(b.get("reflectivity", 0.5), "reflectivity", w, lo=0, lo_open=True, hi=1)
    optional = ("yaw_deg", "centre_m") if kind == "room" else ("yaw_deg",)
    need = [k for k in keys if k not in b and k not in optional]
    if need:
        raise UserError(f"{w}: type {kind!r} needs {', '.join(need)}")
    if kind == "ground":
        return [bodies.ground(as_float(b["height_m"], "height_m", w, lo=0, lo_open=True))], refl
    if kind == "wall":
        n = as_vec(b["normal"], "normal", w, 3)
        if math.hypot(*n) == 0:
            raise UserError(f"{w}: normal must not be zero")
        return [bodies.wall(as_vec(b["centre_m"], "centre_m", w, 3), n, as_float(b["width_m"], "width_m", w, lo=0, lo_open=True),
                            as_float(b["height_m"], "height_m", w, lo=0, lo_open=True))], refl
    if kind == "room":
        size = as_vec(b["size_m"], "size_m", w, 3)
        if min(size) <= 0:
            raise UserError(f"{w}: size_m must be positive, got {list(size)}")
        return bodies.room(size, as_vec(b.get("centre_m", [0, 0, 0]), "centre_m", w, 3)), refl
    size = as_vec(b["size_m"], "size_m", w, 3)
    if min(size) <= 0:
        raise UserError(f"{w}: size_m must be positive, got {list(size)}")
    return [bodies.box(as_vec(b["centre_m"], "centre_m", w, 3), tuple(s / 2 for s in size),
                       math.radians(as_float(b.get("yaw_deg", 0.0), "yaw_deg", w)))], refl
