"""The head shared between many tracks: the sky tracker sees every object, the attention picks the
track the fovea serves, and the paper's tracker drives the head to it (issue 28).

Per frame (a :class:`foveatrack.controller.Controller`, driven like the paper's tracker):

1. :class:`~foveatrack.sky.tracks.SkyTracker` takes the frame at the pose the tracker's dead
   reckoning gives (:class:`foveatrack.reconstruction.Reconstructor`) and measures the fixated
   track with Algorithm 1 in its D (paper App. D.2);
2. the head is steered by :meth:`foveatrack.tracker.Tracker.steer`, the paper's Algorithm 2 (App.
   D.3: dead band, proportional speed, the stop limits, the speed table):

   * on that Algorithm 1 detection when the fovea saw the track;
   * during a saccade (the fixated track coasting, or out of the field), on its predicted position
     turned into the lidar frame -- an aim point, a :class:`~foveatrack.detection.Detection` with
     ``n_points = 0``, which the output does not report as a detection;
   * with no confirmed track, on nothing: the paper's hold, search sweep and wait;
3. :class:`~foveatrack.sky.attention.Attention` chooses the track for the next frame.

The paper's single-target tracker stays the default everywhere; this runs only where a scene or a
configuration asks for it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace

import numpy as np

from foveatrack.config_util import check_keys
from foveatrack.detection import Detection, bearing_deg, frozen_maker, wrap_deg
from foveatrack.errors import UserError
from foveatrack.fixed_order import floats3, norm3
from foveatrack.frames import Frame
from foveatrack.reconstruction import rotation_rows
from foveatrack.sky.attention import ADDED_SINCE_RECORDED as ATTENTION_ADDED
from foveatrack.sky.attention import (Attention, AttentionConfig, bearing_off_axis_deg, fovea_turns, in_lidar,
                                      off_axis_deg, saccade_time_s, threat_scores)
from foveatrack.sky.classify import ADDED_SINCE_RECORDED as CLASSIFIER_ADDED
from foveatrack.space_of_interest import Box
from foveatrack.sky.tracks import ADDED_SINCE_RECORDED as TRACKER_ADDED
from foveatrack.sky.tracks import SkyFrameOutput, SkyTracker, SkyTrackerConfig
from foveatrack.tracker import Tracker, TrackOutput


@dataclass(frozen=True)
class SkyControlOutput:
    """One frame: the paper tracker's output for the head (``track``), every track (``sky``), the
    track the fovea served and the one it serves next, the tracks in the fovea, the threat scores,
    the operator's pinned track (None: none, or it was deleted).
    ``detection`` is Algorithm 1's in the fixated track's D (None during a saccade)."""
    track: TrackOutput
    sky: SkyFrameOutput
    fixated: int | None
    next_target: int | None
    in_fovea: tuple[int, ...]
    scores: dict
    pinned: int | None = None

    # what the drivers read of a controller's output (sim.loop, the command gate)
    @property
    def command(self):
        return self.track.command

    @property
    def state(self):
        return self.track.state

    @property
    def detection(self):
        return self.sky.fovea_detection

    @property
    def world_xyz(self):
        return self.track.world_xyz if self.sky.fovea_detection is not None else None

    @property
    def world_sigma_m(self):
        return self.track.world_sigma_m if self.sky.fovea_detection is not None else None

    @property
    def head_tilt_deg(self):
        return self.track.head_tilt_deg

    @property
    def head_sigma_tilt_deg(self):
        return self.track.head_sigma_tilt_deg

    def __getattr__(self, name):
        if name == "track":
            raise AttributeError(name)
        # the rest of a TrackOutput (errors, head estimate) as the paper tracker steered this frame
        # (toward the aim point during a saccade)
        return getattr(self.track, name)


_make_output = frozen_maker(SkyControlOutput)      # once a frame: without the frozen init's cost per field
_make_aim = frozen_maker(Detection)     # a saccade's aim point each frame (equal to Detection(...): tests/tracker/test_detection.py)


def sky_configs_from_mapping(data: Mapping, where: str, field_half_angle_deg: float | None = None
                             ) -> tuple[SkyTrackerConfig, AttentionConfig]:
    """The ``[tracker.sky]`` table: the sky tracker's keys, with ``[tracker.sky.attention]`` and
    ``[tracker.sky.classifier]`` sub-tables.  ``field_half_angle_deg``: the lidar's, used unless
    the table sets it."""
    if not isinstance(data, Mapping):
        raise UserError(f"{where}: expected a table, got {data!r}")
    data = dict(data)
    # every key the table may hold, its sub-tables too (a misspelt [tracker.sky.atention] was told
    # the allowed keys without "attention")
    check_keys(data, [f.name for f in fields(SkyTrackerConfig)] + ["attention"], where)
    att = data.pop("attention", {})
    cfg = SkyTrackerConfig.from_mapping(data, where)
    if "field_half_angle_deg" not in data and field_half_angle_deg is not None:
        cfg = replace(cfg, field_half_angle_deg=float(field_half_angle_deg))
    return cfg, AttentionConfig.from_mapping(att, where + ".attention")


def recorded_sky_table(table: Mapping) -> dict:
    """A recording's ``[tracker.sky]`` table as it ran: the keys the tracker has gained since the
    recording was made (:data:`foveatrack.sky.tracks.ADDED_SINCE_RECORDED`,
    :data:`foveatrack.sky.classify.ADDED_SINCE_RECORDED`,
    :data:`foveatrack.sky.attention.ADDED_SINCE_RECORDED`) at the values that
    behave as before them (a table from :func:`sky_table` has every key, and keeps its own)."""
    table = {**TRACKER_ADDED, **table}
    for sub, added in (("classifier", CLASSIFIER_ADDED), ("attention", ATTENTION_ADDED)):
        given = table.get(sub, {})
        if isinstance(given, Mapping):
            table[sub] = {**added, **given}
    return table


def sky_table(cfg: SkyTrackerConfig, attention_cfg: AttentionConfig) -> dict:
    """The ``[tracker.sky]`` table of these configurations, every setting (:meth:`SkyController.sky_table`)."""
    from dataclasses import asdict

    att = asdict(attention_cfg)
    att["protected_xyz_m"] = [float(v) for v in att["protected_xyz_m"]]
    return {**asdict(cfg), "attention": att}


#: the step [s] over which a track's bearing rate is taken from its velocity, for its saccade time
_RATE_S = 0.1


def _bearing_rates(p, u, pose, az: float, el: float) -> tuple[float, float]:
    """The (azimuth, elevation) rates [deg/s] of a track at ``p`` moving at ``u`` (world, 3 floats
    each) seen from ``pose`` (rows, offset), where its bearing is ``az``, ``el`` now: the bearing
    ``_RATE_S`` later, less this one (azimuth wrapped), over ``_RATE_S``."""
    az1, el1 = bearing_deg(*in_lidar([p[0] + _RATE_S * u[0], p[1] + _RATE_S * u[1], p[2] + _RATE_S * u[2]], *pose))
    return wrap_deg(az1 - az) / _RATE_S, (el1 - el) / _RATE_S


class SkyController:
    """Frames in, head commands out, every object tracked (module docstring)."""

    def __init__(self, tracker: Tracker, sky_cfg: SkyTrackerConfig | None = None,
                 attention_cfg: AttentionConfig | None = None):
        self.tracker = tracker
        # the paper tracker's D, when it is a box in the world, bounds what the sky tracker looks at
        # (the scenes' D keeps the ground out)
        space = tracker.config.space
        region = space if isinstance(space, Box) and getattr(space, "frame", "lidar") == "world" else None
        self.sky = SkyTracker(sky_cfg, region)
        self.attention = Attention(attention_cfg or AttentionConfig())
        # how fast Algorithm 2 turns each axis: its gain and top speed (the table's, or the configured
        # cap), for the attention's saccade times
        c = tracker.config
        vp = tracker.table.pan.max_speed_deg_s(c.allow_turbo)
        vt = tracker.table.tilt.max_speed_deg_s(False)
        ks = self.attention.cfg.saccade_gain_1_s
        self._head_speeds = (c.gain_pan_1_s if ks is None else ks,
                             vp if c.max_pan_speed_deg_s is None else min(vp, c.max_pan_speed_deg_s),
                             c.gain_tilt_1_s if ks is None else ks,
                             vt if c.max_tilt_speed_deg_s is None else min(vt, c.max_tilt_speed_deg_s))
        #: the last frame's output (None before the first): the tracks an operator may pin
        self.last_output: SkyControlOutput | None = None

    @classmethod
    def from_table(cls, tracker: Tracker, table: Mapping, where: str,
                   field_half_angle_deg: float | None = None) -> "SkyController":
        """The controller a ``[tracker.sky]`` table asks for around ``tracker``, as every driver builds
        it (the simulator for a scene, the daemon for its config, replay from a recording's table);
        ``field_half_angle_deg``: the lidar's, used unless the table sets it."""
        return cls(tracker, *sky_configs_from_mapping(table, where, field_half_angle_deg))

    @property
    def recon(self):
        return self.tracker.recon

    @property
    def last_command(self):
        """The last command the head was told it runs (:attr:`foveatrack.tracker.Tracker.last_command`)."""
        return self.tracker.last_command

    @property
    def config(self):
        """The paper tracker's configuration (what the drivers read of a controller: rate, D, offset)."""
        return self.tracker.config

    def rebased(self, t0_s: float, pan_deg: float, tilt_deg: float) -> "SkyController":
        """A fresh controller (:meth:`foveatrack.tracker.Tracker.rebased`: the lidar's clock restarted or
        the head was homed): the paper tracker rebased, the tracks, the learned background and the
        fovea's schedule started afresh (their times are of the old clock, and a homing means the pose
        the background was learned at was wrong), the operator's pin dropped (its track is gone); new
        tracks' ids go on from the old ones' (an id names one track for the whole run).  What the daemon
        does and replay repeats from its event."""
        new = SkyController(self.tracker.rebased(t0_s, pan_deg, tilt_deg), self.sky.cfg, self.attention.cfg)
        new.sky.continue_ids_from(self.sky)
        return new

    def correct_pose(self, t_s: float, dpan_deg: float, dtilt_deg: float) -> bool:
        """The pose check's drift correction of the dead reckoning (:meth:`foveatrack.tracker.Tracker.correct_pose`)."""
        return self.tracker.correct_pose(t_s, dpan_deg, dtilt_deg)

    def process(self, frame: Frame, send_t_s: float | None = None) -> SkyControlOutput:
        recon = self.tracker.recon
        fix = self.attention.target
        sky = self.sky.process(frame, recon, fix)
        det = sky.fovea_detection
        view = next((v for v in sky.tracks if v.track_id == fix), None)
        if det is None and view is not None:
            det = self._aim(view.xyz_m, frame.t_end_s)
        gains = None
        ks = self.attention.cfg.saccade_gain_1_s
        if ks is not None and view is not None and bearing_off_axis_deg(
                view.xyz_m, *self._pose_rows(frame.t_end_s)) > self.attention.cfg.fovea_half_angle_deg:
            gains = (ks, ks)        # a saccade: the fixated track is off the fovea
        # nothing to serve (no confirmed track, no candidate): the head holds where it looks, unless
        # the attention asks for the paper tracker's lost-target sweep (idle_search)
        out = self.tracker.steer(frame, det, send_t_s, gains, search=self.attention.cfg.idle_search)
        att = self.attention.cfg
        t_mid = 0.5 * (frame.t_start_s + frame.t_end_s)
        mid_pose = self._pose_rows(t_mid)
        half = att.fovea_half_angle_deg
        end_pose = self._pose_rows(frame.t_end_s)      # one pose for every track's saccade time
        # the head's speed now and each track's bearing rate: asked only by the saccade time that
        # counts the motion (an option; a flock's twenty tracks a frame need not pay for them)
        motion = att.saccade_counts_motion
        # per confirmed track, in one pass: in the fovea at the mid pose, its saccade time from the
        # end pose, its threat score (the attention's too)
        in_fovea, turn, scores, looks = set(), {}, {}, {}
        confirmed = [v for v in sky.tracks if v.confirmed]
        q_mid, turns = [], []       # per confirmed track: its point in the lidar frame at mid-frame, its saccade time
        P = np.array([v.xyz_m for v in confirmed]) if confirmed else None    # their positions, gathered once
        if motion:
            speeds, accels = recon.speeds_at(frame.t_end_s), recon.accels_deg_s2()
            for v in confirmed:
                p = v.xyz_m.tolist()
                q_mid.append(in_lidar(p, *mid_pose))
                az, el = bearing_deg(*in_lidar(p, *end_pose))
                rates = _bearing_rates(p, v.velocity_m_s.tolist(), end_pose, az, el)
                turns.append(saccade_time_s(az, el, att, self._head_speeds, rates, speeds, accels))
        elif confirmed:
            # without the motion, every track's in one kernel call (the same bits as the loop above
            # without the rates)
            q_mid, turns = fovea_turns(P, mid_pose, end_pose, att, self._head_speeds)
        if confirmed:
            # the threat scores in one kernel call (threat_score's bits), each by the class the attention
            # goes by
            classes = [self.attention.looks_like(v) for v in confirmed]
            for v, q, t, s, c in zip(confirmed, q_mid, turns, threat_scores(confirmed, classes, att, P), classes):
                if off_axis_deg(*q) <= half:
                    in_fovea.add(v.track_id)
                turn[v.track_id] = t
                scores[v.track_id] = s
                looks[v.track_id] = c
        # the candidate being verified counts too for the attention, which ends that look once the
        # candidate has been dwell_s in the fovea (without it every look ran saccade_timeout_s)
        cand = next((v for v in sky.tracks if v.track_id == self.attention.verifying and not v.confirmed), None)
        looked = in_fovea | ({cand.track_id} if cand is not None
                             and bearing_off_axis_deg(cand.xyz_m, *mid_pose) <= half else set())
        nxt = self.attention.update(frame.t_end_s, sky.tracks, looked, frame.t_end_s - frame.t_start_s, turn,
                                    scores, looks)
        self.last_output = _make_output(out, sky, fix, nxt, tuple(sorted(in_fovea)), scores, self.attention.pinned)
        return self.last_output

    def pin(self, track_id: int | None) -> None:
        """The operator's choice (:meth:`foveatrack.sky.attention.Attention.pin`): this track is the
        priority from the next frame on, while it lives; None unpins."""
        self.attention.pin(None if track_id is None else int(track_id))

    def confirmed_tracks(self) -> tuple:
        """The confirmed tracks of the last frame (:class:`~foveatrack.sky.tracks.TrackView`; empty
        before the first frame and after a rebase): those :meth:`pin` can make the priority."""
        out = self.last_output
        return () if out is None else tuple(v for v in out.sky.tracks if v.confirmed)

    @property
    def pinned(self) -> int | None:
        """The operator's pinned track (None: none, or it was deleted)."""
        return self.attention.pinned

    def sky_table(self) -> dict:
        """The effective ``[tracker.sky]`` table (every setting, JSON-plain), which
        :func:`sky_configs_from_mapping` reads back to the same configurations: what a recording
        keeps, so that replay rebuilds this controller."""
        return sky_table(self.sky.cfg, self.attention.cfg)

    def command_sent(self, t_s: float, cmd) -> None:
        self.tracker.command_sent(t_s, cmd)

    def on_imu(self, t_s, gyro_rad_s) -> None:
        self.tracker.on_imu(t_s, gyro_rad_s)

    def _pose_rows(self, t_s: float):
        """The lidar's dead-reckoned pose at ``t_s``: its rotation rows and offset (3 floats)."""
        recon = self.tracker.recon
        pan, tilt, _, _ = recon.angles_at(t_s)
        return rotation_rows(pan, tilt), floats3(recon.lidar_offset_m)

    def _aim(self, p_world: np.ndarray, t_s: float) -> Detection:
        """The track's position as the lidar would see it at ``t_s`` (an aim point, ``n_points = 0``)."""
        xyz = in_lidar(floats3(p_world), *self._pose_rows(t_s))
        q = np.array(xyz)
        az, el = bearing_deg(*xyz)
        return _make_aim(t_s, q, 0, az, el, norm3(q))
