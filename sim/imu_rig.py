"""The simulated lidar-IMU rig of paper Section IV.A (Fig. 11): static poses in a scene, the lidar's
accumulated clouds and the IMU's samples, and the calibration error against accumulation time
(Fig. 11b, eq. (8)).

The rig: the lidar at ``T_world_lidar``, the IMU rigidly at ``X = T_lidar_imu`` (the scene's
``[imu]``).  Home pose: ``[imu_poses] home_rpy_deg / home_m`` (default: the lidar at the world origin
looking along +x, like the head of the other scenes).  Pose sequence (``[imu_poses]``): from home, each pose's lidar offset is a rotation of at
most ``step_deg`` about a random axis and a translation of at most ``step_m`` in a random direction,
drawn until the step from the previous pose is 0.8-1.2 x ``step_deg`` and 0.8-1.2 x ``step_m`` (so the
poses stay near home and every move turns and shifts the rig in all six degrees of freedom); the
draws come from the scene's stream "imu_poses".  The IMU samples from the stream "imu"; each
(lidar, pose) cloud from its own SceneSensor seeded from (seed, the lidar's name, pose): a lidar's
clouds, and so its result, do not depend on which other lidars run beside it or in which order
(issue 27: seeded by its place in ``--lidar``, the Mid-40 at 0.1 s gave 0.367 deg alone and 0.127 deg
as the second lidar).

The algorithms are :mod:`foveatrack.imu_calib`; this module only makes their input and scores them
against the truth.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, replace

import numpy as np

from foveatrack.errors import UserError
from foveatrack.imu_calib import handeye, procedure
from foveatrack.imu_calib.imu_integration import ImuSamples, relative_motions
from foveatrack.imu_calib.se3 import eq8_error, eq8_parts, inv_T, make_T, rotation_angle_deg, so3_exp, so3_log
from sim.effects import effect_rng
from sim.imu import PoseSchedule, RigTrajectory, simulate_imu

ACCUMULATE_DEFAULT_S = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


def prims_in_frame(prims: np.ndarray, T_world_frame: np.ndarray) -> np.ndarray:
    """The primitive table (:mod:`sim.world.kernels`) expressed in another frame: points (cols 1-3)
    transformed, axes and normals (cols 7-9, 10-12) rotated, sizes unchanged."""
    Ti = inv_T(T_world_frame)
    R, t = Ti[:3, :3], Ti[:3, 3]
    out = prims.copy()
    out[:, 1:4] = prims[:, 1:4] @ R.T + t
    out[:, 7:10] = prims[:, 7:10] @ R.T
    out[:, 10:13] = prims[:, 10:13] @ R.T
    return np.ascontiguousarray(out)


def pose_sequence(schedule: PoseSchedule, rng: np.random.Generator) -> list[np.ndarray]:
    """Lidar poses ``T_world_lidar`` (home first), see the module docstring."""
    home = schedule.T_world_home
    poses = [np.eye(4)]
    for _ in range(schedule.count - 1):
        prev = poses[-1]
        for _attempt in range(10_000):
            axis = rng.normal(size=3)
            r = axis / np.linalg.norm(axis) * np.radians(schedule.step_deg) * rng.uniform(0, 1) ** (1 / 3)
            d = rng.normal(size=3)
            t = d / np.linalg.norm(d) * schedule.step_m * rng.uniform(0, 1) ** (1 / 3)
            cand = make_T(so3_exp(r), t)
            rel = inv_T(prev) @ cand
            ang = rotation_angle_deg(rel[:3, :3])
            dist = float(np.linalg.norm(cand[:3, 3] - prev[:3, 3]))
            if (0.8 * schedule.step_deg <= ang <= 1.2 * schedule.step_deg
                    and 0.8 * schedule.step_m <= dist <= 1.2 * schedule.step_m):
                poses.append(cand)
                break
        else:  # pragma: no cover - the acceptance region is large
            raise RuntimeError("no pose step drawn within 10 000 tries")
    return [home @ p for p in poses]


@dataclass(frozen=True)
class RigData:
    X_true: np.ndarray
    X_nominal: np.ndarray
    lidar_poses: list          # T_world_lidar per pose
    windows: list              # static windows [(t0, t1)] [s]
    imu: ImuSamples
    clouds: dict               # lidar name -> [PoseCloud]

    def A_true(self) -> list:
        return [inv_T(a) @ b for a, b in zip(self.lidar_poses, self.lidar_poses[1:])]


def lidar_seed_key(name: str) -> int:
    """A lidar's part of its clouds' seed: from its name (CRC-32, the same on every run and machine)."""
    return zlib.crc32(name.encode("utf-8"))


def scan_model_for(scene, name: str):
    """The scan model of a named lidar: a Risley preset (with the scene's motor noise, if listed)
    or a spinning one (:mod:`sim.scan.spinning`)."""
    from sim.scan.presets import PRESETS, SPINNING_PRESETS
    from sim.scan.spinning import SpinningScanModel
    from sim.sensor import scene_scan_model

    if name in SPINNING_PRESETS:
        return SpinningScanModel(SPINNING_PRESETS[name])
    if name in PRESETS:
        return scene_scan_model(replace(scene, optics=PRESETS[name]))
    raise UserError(f"lidar {name!r} unknown; allowed: {', '.join(list(PRESETS) + list(SPINNING_PRESETS))}")


def check_rig_scene(scene, max_accumulate_s: float) -> None:
    """A UserError naming what the scene lacks for a simulated lidar-IMU calibration; the CLI asks
    before it starts a progress bar (the error used to print glued onto a started one)."""
    if scene.imu is None:
        raise UserError(f"{scene.path}: the scene has no [imu] table (the IMU to calibrate; see docs/imu-calibration.md)")
    if scene.background_prims.shape[0] == 0:
        raise UserError(f"{scene.path}: the scene has no [[background]]: the lidar has nothing to register against")
    schedule = scene.imu_poses or PoseSchedule()
    if max_accumulate_s > schedule.dwell_s + 1e-9:
        raise UserError(f"accumulation {max_accumulate_s:g} s is longer than the dwell per pose "
                        f"([imu_poses] dwell_s = {schedule.dwell_s:g} s)")


def simulate_rig(scene, lidars: list[str], max_accumulate_s: float, progress=None) -> RigData:
    """The rig's data: IMU samples over the whole sequence and, for each lidar, one cloud per pose
    (the first ``max_accumulate_s`` of its static window)."""
    from sim.sensor import SceneSensor

    check_rig_scene(scene, max_accumulate_s)
    schedule = scene.imu_poses or PoseSchedule()
    lidar_poses = pose_sequence(schedule, effect_rng(scene.seed, "imu_poses"))
    X = scene.imu.T_lidar_imu
    traj = RigTrajectory([T @ X for T in lidar_poses], schedule.dwell_s, schedule.move_s)
    imu = simulate_imu(traj, scene.imu.noise, schedule.duration_s, effect_rng(scene.seed, "imu"))
    windows = schedule.windows()
    clouds = {}
    for name in lidars:
        model = scan_model_for(scene, name)
        per_pose = []
        for p, (T, (t0, _t1)) in enumerate(zip(lidar_poses, windows)):
            seed = int(np.random.SeedSequence([scene.seed, lidar_seed_key(name), p]).generate_state(1)[0])
            local = replace(scene, targets=(), seed=seed,
                            background_prims=prims_in_frame(scene.background_prims, T))
            sensor = SceneSensor(local)
            xyz, ts = [], []
            t = t0
            while t < t0 + max_accumulate_s - 1e-12:
                t_end = min(t + 1.0, t0 + max_accumulate_s)
                chunk = model.scan_time(t, t_end)
                pts, t_ns, _, _ = sensor.returns(chunk, chunk.direction, t, t_end)
                xyz.append(pts)
                ts.append(t_ns * 1e-9)
                t = t_end
            per_pose.append(procedure.PoseCloud(np.vstack(xyz), np.concatenate(ts), t0))
            if progress is not None:
                progress.update(1)
        clouds[name] = per_pose
    return RigData(X, scene.imu.nominal_T_lidar_imu, lidar_poses, windows, imu, clouds)


@dataclass(frozen=True)
class Score:
    lidar: str
    accumulate_s: float
    X: np.ndarray
    rotation_error_deg: float       # angle of R_est R_true^T
    translation_error_m: float      # |t_est - t_true|
    eq8_mean: float                 # mean over pairs of eq. (8) with the true A
    eq8_translation_m: float        # mean translation part
    eq8_rotation_deg: float         # mean rotation part
    registration_rotation_deg: float     # mean |A_est vs A_true| rotation
    registration_translation_m: float    # mean translation
    rotation_sigma_deg: np.ndarray
    translation_sigma_m: np.ndarray
    points_per_pose: float
    imu_floor_rotation_deg: float      # X error from the true A and the IMU's B: what the IMU allows
    imu_floor_translation_m: float
    lidar_floor_rotation_deg: float    # X error from the registered A and the true B: what the lidar allows
    lidar_floor_translation_m: float
    rotation_rss_deg: float = float("nan")     # 1-sigma of the total angle (NaN: none given)
    translation_rss_m: float = float("nan")
    removed_pairs: tuple = ()
    warnings: tuple = ()


def score(data: RigData, result: procedure.CalibrationResult, lidar: str) -> Score:
    A_true = data.A_true()
    X = result.X
    e8 = [eq8_error(a, b, X) for a, b in zip(A_true, result.B)]
    parts = np.array([eq8_parts(a, b, X) for a, b in zip(A_true, result.B)])
    reg_r = [rotation_angle_deg(a[:3, :3].T @ t[:3, :3]) for a, t in zip(result.A, A_true)]
    reg_t = [float(np.linalg.norm(a[:3, 3] - t[:3, 3])) for a, t in zip(result.A, A_true)]
    npts = np.mean([len(procedure.accumulated(c, result.accumulate_s)) for c in data.clouds[lidar]])
    X_true = data.X_true
    B_true = [inv_T(X_true) @ a @ X_true for a in A_true]
    imu_floor = _x_error(handeye.solve_handeye(A_true, result.B).X, X_true)
    used = result.handeye.used       # the pairs the extrinsic kept (a slid registration is not the lidar's floor)
    lidar_floor = _x_error(handeye.solve_handeye([result.A[i] for i in used], [B_true[i] for i in used],
                                                 free=[result.registrations[i].free_directions for i in used]).X, X_true)
    return Score(
        lidar, result.accumulate_s, X,
        float(np.degrees(np.linalg.norm(so3_log(X[:3, :3] @ data.X_true[:3, :3].T)))),
        float(np.linalg.norm(X[:3, 3] - data.X_true[:3, 3])),
        float(np.mean(e8)), float(parts[:, 0].mean()), float(np.degrees(parts[:, 1].mean())),
        float(np.mean(reg_r)), float(np.mean(reg_t)),
        result.uncertainty.rotation_sigma_deg, result.uncertainty.translation_sigma_m, float(npts),
        *imu_floor, *lidar_floor, result.uncertainty.rotation_rss_deg, result.uncertainty.translation_rss_m,
        tuple(r.index for r in result.removed), tuple(result.warnings),
    )


def _x_error(X: np.ndarray, X_true: np.ndarray) -> tuple[float, float]:
    return (float(np.degrees(np.linalg.norm(so3_log(X[:3, :3] @ X_true[:3, :3].T)))),
            float(np.linalg.norm(X[:3, 3] - X_true[:3, 3])))


def run(scene, lidars: list[str], accumulate_s=ACCUMULATE_DEFAULT_S, bootstrap_samples: int = 200,
        progress_factory=None):
    """Simulate the rig, calibrate for every (lidar, accumulation time), score against the truth.

    Returns ``(data, {lidar: [(CalibrationResult, Score), ...]})``.  ``progress_factory(total, desc)``
    gives an object with ``update(n)`` and ``close()`` (tqdm), or None.
    """
    acc = sorted(set(float(a) for a in accumulate_s))
    schedule = scene.imu_poses or PoseSchedule()
    bar = progress_factory(len(lidars) * schedule.count, "simulating scans") if progress_factory else None
    data = simulate_rig(scene, lidars, max(acc), bar)
    if bar is not None:
        bar.close()
    motion = relative_motions(data.imu, data.windows)
    bar = progress_factory(len(lidars) * len(acc) * (schedule.count - 1), "registering") if progress_factory else None
    out = {}
    for name in lidars:
        rows = []
        for a in acc:
            res = procedure.calibrate(data.clouds[name], data.imu, data.windows, a, X0=data.X_nominal,
                                      bootstrap_samples=bootstrap_samples, seed=scene.seed, imu_motion=motion,
                                      progress=bar)
            rows.append((res, score(data, res, name)))
        out[name] = rows
    if bar is not None:
        bar.close()
    return data, out


def _finite_or_none(v) -> float | None:
    """A figure for JSON: None where there is none (a 1-sigma not given is NaN)."""
    return float(v) if np.isfinite(v) else None


def score_row(s: Score) -> dict:
    """A :class:`Score` as plain JSON-ready numbers."""
    return {
        "lidar": s.lidar, "accumulate_s": s.accumulate_s, "points_per_pose": s.points_per_pose,
        "eq8_mean": s.eq8_mean, "eq8_translation_m": s.eq8_translation_m, "eq8_rotation_deg": s.eq8_rotation_deg,
        "rotation_error_deg": s.rotation_error_deg, "translation_error_m": s.translation_error_m,
        "registration_rotation_deg": s.registration_rotation_deg,
        "registration_translation_m": s.registration_translation_m,
        "rotation_sigma_deg": [_finite_or_none(v) for v in s.rotation_sigma_deg],
        "translation_sigma_m": [_finite_or_none(v) for v in s.translation_sigma_m],
        "imu_floor_rotation_deg": s.imu_floor_rotation_deg, "imu_floor_translation_m": s.imu_floor_translation_m,
        "lidar_floor_rotation_deg": s.lidar_floor_rotation_deg,
        "lidar_floor_translation_m": s.lidar_floor_translation_m,
        "rotation_rss_sigma_deg": _finite_or_none(s.rotation_rss_deg),
        "translation_rss_sigma_m": _finite_or_none(s.translation_rss_m),
        "removed_pairs": list(s.removed_pairs), "warnings": list(s.warnings),
    }


def coverage_curves(scene, lidars: list[str], duration_s: float) -> dict:
    """Paper Fig. 6e coverage (Appendix C voxel definition) of each Risley lidar over ``duration_s``
    with the scene's scan model; spinning lidars have none (their pattern repeats every turn)."""
    from sim.scan.coverage import voxel_coverage
    from sim.scan.presets import PRESETS

    out = {}
    for name in lidars:
        if name in PRESETS:
            curve = voxel_coverage(scan_model_for(scene, name), duration_s)
            out[name] = (curve.times_s, curve.coverage)
    return out
