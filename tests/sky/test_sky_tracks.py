"""The sky tracker's hard cases on synthetic frames (tests/sky/synthetic.py): crossing objects,
clusters that merge and split, a bird inside the fixated drone's D, a track at the edge of the field,
scenery learned from a turning head."""

import math

import numpy as np
import pytest

from foveatrack.sky.tracks import SkyTracker, SkyTrackerConfig
from synthetic import Pose, run, straight


# without scenery in the frames, the tracks need not wait for the background to learn it
NO_WARMUP = SkyTrackerConfig(warmup_s=0.0)


def _confirmed(out):
    return {v.track_id: v for v in out.tracks if v.confirmed}


def _truth_at(obj, t):
    return obj(t)[0]


def _nearest_id(out, p):
    tracks = _confirmed(out)
    return min(tracks, key=lambda i: float(np.sum((tracks[i].xyz_m - p) ** 2)))


def test_crossing_tracks_keep_their_ids():
    # Two drones cross head-on, 0.3 m apart in height at the crossing (one cluster for a few frames).
    a = straight([30, 5, 3.0], [0, -2, 0])
    b = straight([30, -5, 3.3], [0, 2, 0])
    outs = run(SkyTracker(NO_WARMUP), [a, b], 6.0, wall=False)
    early, late = outs[10], outs[-1]
    ia, ib = _nearest_id(early, _truth_at(a, early.t_s)), _nearest_id(early, _truth_at(b, early.t_s))
    assert ia != ib
    assert set(_confirmed(late)) == {ia, ib}
    # after the crossing each id is still on its own drone
    for tid, obj in ((ia, a), (ib, b)):
        err = np.linalg.norm(_confirmed(late)[tid].xyz_m - _truth_at(obj, late.t_s))
        assert err < 0.5, (tid, err)


def test_two_clusters_merge_and_split_without_id_switch():
    # Two drones fly on at 2 m/s and cross at a shallow angle (0.5 m/s sideways each): their clusters
    # are one for about a second, then part.  Both ids survive the merge and follow their drones.
    a = straight([20, 2.0, 4.0], [2.0, -0.5, 0])
    b = straight([20, -2.0, 4.0], [2.0, 0.5, 0])
    outs = run(SkyTracker(NO_WARMUP), [a, b], 8.0, wall=False)
    ia = _nearest_id(outs[15], _truth_at(a, outs[15].t_s))
    ib = _nearest_id(outs[15], _truth_at(b, outs[15].t_s))
    assert ia != ib
    merged = [o for o in outs if o.n_objects == 1]
    assert len(merged) >= 5                              # really one cluster for half a second or more
    last = outs[-1]
    assert set(_confirmed(last)) == {ia, ib}
    for tid, obj in ((ia, a), (ib, b)):
        assert np.linalg.norm(_confirmed(last)[tid].xyz_m - _truth_at(obj, last.t_s)) < 0.5


def test_bird_inside_drones_d_does_not_pull_algorithm_1():
    drone = straight([30, 0, 3.0], [0, 0.5, 0], radius=0.2)
    bird = straight([30, -6.5, 3.95], [0, 5.0, 0], radius=0.15)    # passes 0.95 m above, inside D
    state = {}

    def fovea(prev):
        if prev is None:
            return None
        tid = next((v.track_id for v in prev.tracks if v.confirmed and abs(v.xyz_m[2] - 3.0) < 0.4
                    and abs(v.xyz_m[1] - 0.5 * prev.t_s) < 1.0), None)
        if tid is not None:
            state.setdefault("id", tid)
        return state.get("id")

    outs = run(SkyTracker(NO_WARMUP), [drone, bird], 3.0, wall=False, fovea=fovea)
    in_d = [o for o in outs if abs(_truth_at(bird, o.t_s - 0.05)[1] - _truth_at(drone, o.t_s - 0.05)[1]) < 1.0]
    assert len(in_d) >= 3
    for o in in_d:
        det = o.fovea_detection
        assert det is not None
        # the median of the drone's points alone: within its 0.2 m ball of the truth (in the world)
        d = _truth_at(drone, det.t_s)
        assert abs(det.xyz[2] - d[2]) < 0.2, (o.t_s, det.xyz, d)
        assert abs(det.xyz[1] - d[1]) < 0.2, (o.t_s, det.xyz, d)
    last = outs[-1]
    assert state["id"] in _confirmed(last)
    assert np.linalg.norm(_confirmed(last)[state["id"]].xyz_m - _truth_at(drone, last.t_s)) < 0.3


def test_track_at_the_edge_of_the_field_keeps_its_id():
    # The lidar sees 19.2 deg around its axis; the object flies outward along the field's edge,
    # weaving 0.4 m across it: part of its points or all of them are cut off in many frames.
    half = 19.2
    tan = math.tan(math.radians(half))

    def along_edge(t):
        x = 15.0 + 2.0 * t
        return np.array([x, x * tan + 0.4 * math.sin(2 * math.pi * t / 2.0), 0.0]), 0.25
    cfg = SkyTrackerConfig(field_half_angle_deg=half, warmup_s=0.0)
    outs = run(SkyTracker(cfg), [along_edge], 8.0, wall=False, half_angle_deg=half)
    cut = [o for o in outs if o.n_points < 30]
    assert len(cut) >= 10, "the object must be partly or wholly out of the field in many frames"
    ids = {v.track_id for o in outs[10:] for v in o.tracks if v.confirmed}
    assert len(ids) == 1                                    # one track the whole way, no new id
    v = _confirmed(outs[-1])[ids.pop()]
    assert np.linalg.norm(v.xyz_m - along_edge(outs[-1].t_s)[0]) < 0.6


def test_track_out_of_view_too_long_is_deleted():
    cfg = SkyTrackerConfig(field_half_angle_deg=19.2, lost_out_of_view_s=1.0, warmup_s=0.0)

    def leave(t):
        return np.array([20.0, -3.0 + 3.0 * t, 0.0]), 0.2   # out of the field after ~3.5 s, for good
    outs = run(SkyTracker(cfg), [leave], 6.0, wall=False, half_angle_deg=19.2)
    assert any(_confirmed(o) for o in outs[:30])
    assert any(v.confirmed and not v.in_view for o in outs for v in o.tracks)   # coasting out of view
    assert not outs[-1].tracks


def test_scenery_is_learned_in_the_world_while_the_head_turns():
    # The head pans at 10 deg/s; the wall (60 m out) must become background (direction cells in the
    # world) and leave no confirmed track, while the drone -- which comes in from the side and then
    # flies in front of the learned wall -- is tracked all the way.
    pose = Pose(lambda t: (10.0 * math.sin(t), 0.0))
    a = straight([30, 6.5, 5.5], [0, -0.8, 0])      # in front of the wall (|y| < 1.5 at 30 m) after 6 s
    outs = run(SkyTracker(), [a], 8.0, pose=pose)
    # confirmed 1.3 s after the 1 s warm-up (its first clear hits come once it is off the cells it
    # crossed during the warm-up), then one id to the end
    for o in outs[25:]:
        conf = _confirmed(o)
        assert len(conf) == 1, o.t_s
        assert np.linalg.norm(next(iter(conf.values())).xyz_m - _truth_at(a, o.t_s - 0.05)) < 0.3, o.t_s
    assert outs[-1].n_foreground < 0.5 * outs[-1].n_points


@pytest.mark.xfail(strict=True, reason="not met: a drone in front of scenery during the background's warm-up "
                   "sets the scenery cells' nearest range to its own (foveatrack/openloop/range_background.py learns "
                   "the nearest return of a cell at once); it is background there until it leaves those cells")
def test_a_drone_in_front_of_scenery_during_the_warm_up_is_tracked():
    pose = Pose(lambda t: (10.0 * math.sin(t), 0.0))
    a = straight([30, 2, 3.0], [0, -0.8, 0])
    outs = run(SkyTracker(), [a], 4.0, pose=pose)
    assert all(len(_confirmed(o)) == 1 for o in outs[20:])


def test_same_frames_same_bits():
    a = straight([30, 5, 3.0], [0, -2, 0])
    b = straight([30, -5, 3.3], [0, 2, 0])
    o1 = run(SkyTracker(), [a, b], 2.0)
    o2 = run(SkyTracker(), [a, b], 2.0)
    for x, y in zip(o1, o2):
        assert [(v.track_id, v.xyz_m.tobytes(), v.velocity_m_s.tobytes()) for v in x.tracks] == \
               [(v.track_id, v.xyz_m.tobytes(), v.velocity_m_s.tobytes()) for v in y.tracks]


@pytest.mark.parametrize("spawn_clear_m, tracks", [(1.0, 1), (0.0, 2)])
def test_a_drone_split_into_two_clusters_keeps_one_track(spawn_clear_m, tracks):
    # A drone tracked from the start; from 2 s on the sparse scan sees a second part of it 0.8 m below
    # (two clusters: 0.8 m is over the 0.5 m gap) in every other frame.  That part starts no track of
    # its own beside the confirmed one (without the rule it does, and the two take the hits in turn).
    from synthetic import frame_of

    a = straight([30, 4, 3.0], [0, -1.0, 0], radius=0.05)
    part = straight([30, 4, 2.2], [0, -1.0, 0], radius=0.05)
    tracker = SkyTracker(SkyTrackerConfig(warmup_s=0.0, spawn_clear_m=spawn_clear_m))
    rng = np.random.default_rng(3)
    pose = Pose()
    outs = []
    for k in range(60):
        objs = [a, part] if k >= 20 and k % 2 == 0 else [a]
        outs.append(tracker.process(frame_of(objs, k * 0.1, (k + 1) * 0.1, pose, rng, n_per_object=12, wall=False),
                                    pose))
    assert max(o.n_objects for o in outs) == 2
    assert len({i for o in outs[20:] for i in _confirmed(o)}) == tracks


def test_a_track_is_classified_as_if_every_frame_were_classified_afresh(monkeypatch):
    # SkyTracker._classify skips a track whose classifier inputs did not change; a run that
    # classifies every track every frame must show the same features and labels, frame by frame
    from dataclasses import replace
    from pathlib import Path

    from foveatrack.sky import tracks as tracks_module
    from foveatrack.sky.classify import classify
    from sim.loop import ClosedLoop
    from sim.scene import load_scene

    scene = replace(load_scene(Path(__file__).resolve().parents[2] / "scenes" / "drone-and-flock.toml"),
                    duration_s=6.0)

    def views(loop):
        loop.run()
        return [[(v.track_id, v.label, v.seen_as, sorted(v.features.items())) for v in o.sky.tracks]
                for o in loop.sky_log]

    cached = views(ClosedLoop(scene))

    def afresh(self):
        # every track by classify, one at a time (classify_many's twin)
        for tr in self.tracks:
            tr.seen_as, tr.features = classify(tr, self.cfg.classifier)

    monkeypatch.setattr(tracks_module.SkyTracker, "_classify", afresh)
    fresh = views(ClosedLoop(scene))
    assert sum(len(f) for f in fresh) > 200 and any(v[1] == "bird" for f in fresh for v in f)
    assert cached == fresh



def test_the_many_filters_predictions_are_each_filters_own_bit_for_bit():
    # the association predicts every track at once (motion.positions_many, variances_many), the merge
    # rule their positions: row i must be the same bits as filter i's own, whatever each filter's
    # time, state and noise
    from foveatrack.sky.motion import ConstantVelocityFilter, positions_many, predictions_many, variances_many

    rng = np.random.default_rng(7)
    filters = []
    for i in range(40):
        kf = ConstantVelocityFilter(rng.uniform(0, 5), rng.normal(size=3) * 30, 0.5 + 0.37 * i, 0.04, 3.0)
        for _ in range(int(rng.integers(0, 6))):
            kf.update(kf.t_s + rng.uniform(0.05, 0.3), kf.p + rng.normal(size=3))
        filters.append(kf)
    for t_s in (5.0, 7.3, 11.123456789):
        P, V = positions_many(filters, t_s), variances_many(filters, t_s)
        assert P.shape == V.shape == (40, 3)
        assert [a.tobytes() for a in predictions_many(filters, t_s)] == [P.tobytes(), V.tobytes()]
        for i, kf in enumerate(filters):
            p, v = kf.predicted(t_s)
            assert P[i].tobytes() == p.tobytes() and V[i].tobytes() == v.tobytes()
        assert kf.position_at(t_s).tobytes() == p.tobytes()
    assert positions_many([], 1.0).shape == variances_many([], 1.0).shape == (0, 3)
    assert [a.shape for a in predictions_many([], 1.0)] == [(0, 3), (0, 3)]


def test_the_predictions_kernel_is_its_numpy_twin():
    # positions_many / predictions_many run motion.predictions_kernel: the bits of the numpy
    # expressions _positions and _variances, for filters ahead of, at and behind the time asked
    from foveatrack.sky.motion import ConstantVelocityFilter, _gathered, _positions, _variances, predictions_kernel

    rng = np.random.default_rng(11)
    filters = []
    for i in range(25):
        kf = ConstantVelocityFilter(rng.uniform(0, 10), rng.normal(size=3) * 50, 0.3 + 1.1 * i, 0.04, 5.0)
        for _ in range(int(rng.integers(0, 5))):
            kf.update(kf.t_s + rng.uniform(0.01, 0.4), kf.p + rng.normal(size=3))
        filters.append(kf)
    for t_s in (0.0, 4.7, filters[3].t_s, 12.987654321):
        S, dt = _gathered(filters, t_s)
        t = np.array([f.t_s for f in filters])
        q = np.array([f.q for f in filters])
        pos, var = np.empty((25, 3)), np.empty((25, 3))
        predictions_kernel(S, t, q, t_s, pos, var)
        assert pos.tobytes() == _positions(S, dt).tobytes()
        assert var.tobytes() == _variances(S, dt, filters).tobytes()
        only = np.empty((25, 3))
        predictions_kernel(S, t, q, t_s, only, np.empty((0, 3)))      # positions alone
        assert only.tobytes() == pos.tobytes()


def test_the_filters_update_on_floats_is_the_array_forms_bits():
    # ConstantVelocityFilter.update runs predict's and the update's lines axis by axis on floats: every
    # state must be the bits of those lines on arrays, with a zero step and a measurement variance too
    from foveatrack.sky.motion import ConstantVelocityFilter

    def update_arrays(f, t_s, z_m, r_m2=None):
        f.predict(t_s)
        r = f.r if r_m2 is None else float(r_m2)
        s = f.a + r
        y = np.asarray(z_m, np.float64).reshape(3) - f.p
        ka, kb = f.a / s, f.b / s
        f.p = f.p + ka * y
        f.v = f.v + kb * y
        f.c = f.c - f.b * kb
        f.a = f.a * (r / s)
        f.b = f.b * (r / s)

    rng = np.random.default_rng(3)
    for _ in range(300):
        args = (rng.uniform(0, 5), rng.normal(size=3) * 30, rng.uniform(0.1, 40), rng.uniform(0.001, 0.5),
                rng.uniform(0.5, 20))
        f, g = ConstantVelocityFilter(*args), ConstantVelocityFilter(*args)
        t = args[0]
        for _ in range(int(rng.integers(1, 12))):
            t += float(rng.choice([0.0, rng.uniform(0.01, 0.5)]))
            z = f.p + rng.normal(size=3) * rng.uniform(0.01, 3)
            r = None if rng.uniform() < 0.7 else float(rng.uniform(0.001, 1))
            f.update(t, z, r)
            update_arrays(g, t, z, r)
            assert f.t_s == g.t_s and type(f.t_s) is type(g.t_s)
            for name in ("p", "v", "a", "b", "c"):
                a, b = getattr(f, name), getattr(g, name)
                assert a.dtype == b.dtype and a.shape == b.shape == (3,) and a.tobytes() == b.tobytes(), name


def test_the_field_test_of_many_points_is_each_points_own():
    # every track's two points of a frame are tested at once (SkyTracker._in_view_many): each answer
    # must be the one the scalar form gives (R.T p - offset in floats, mat3T_vec's order), at the
    # field's rim too
    from foveatrack.reconstruction import rotation_rows

    tracker = SkyTracker(SkyTrackerConfig(field_half_angle_deg=19.2))
    rng = np.random.default_rng(11)
    cos_field = math.cos(math.radians(19.2))

    def scalar(p, rows, off):
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
        px, py, pz = p.tolist()
        ox, oy, oz = off.tolist()
        x = (r00 * px + r10 * py + r20 * pz) - ox
        y = (r01 * px + r11 * py + r21 * pz) - oy
        z = (r02 * px + r12 * py + r22 * pz) - oz
        r = math.sqrt(x * x + y * y + z * z)
        return r > 0 and x >= cos_field * r

    for _ in range(20):
        rows = rotation_rows(rng.uniform(-180, 180), rng.uniform(-30, 60))
        off = rng.normal(size=3) * 0.05
        axis = np.array([rows[0][0], rows[1][0], rows[2][0]])      # the lidar's axis in the world
        P = np.concatenate([rng.normal(size=(200, 3)) * 40.0,
                            axis * 30.0 + rng.normal(size=(200, 3)) * 10.0, np.zeros((1, 3))])
        got = tracker._in_view_many(P, rows, off)
        assert got == [scalar(p, rows, off) for p in P] and all(type(b) is bool for b in got)
        assert 0 < sum(got) < len(got)
    assert SkyTracker(SkyTrackerConfig())._in_view_many(P, rows, off) == [True] * len(P)


def _confirmed_track(tracker, tid, xyz, v, hits, t_s):
    from foveatrack.sky.motion import ConstantVelocityFilter
    from foveatrack.sky.tracks import SkyTrack
    cfg = tracker.cfg
    kf = ConstantVelocityFilter(t_s, xyz, cfg.q_m2_s3, cfg.r_m2, cfg.v0_sigma_m_s)
    kf.v = np.array(v, float)
    tr = SkyTrack(tid, kf, t_s, t_s, confirmed_t_s=t_s)
    tr.history = [(t_s, np.array(xyz, float), np.array([0.3, 0.3, 0.1]), 3)] * hits
    tr.origin_xyz_m = tr.last_xyz_m = np.array(xyz, float)
    return tr


@pytest.mark.parametrize("merge_frames", [5, 0])
def test_two_tracks_on_one_object_become_one(merge_frames):
    # Two confirmed tracks 0.3 m apart with one velocity (a crown's part or a split cluster started a
    # second track on a drone; the two would take its hits in turn, an id switch each time), and a
    # pair as close that flies apart (two drones crossing).  After merge_frames frames together the
    # first pair's track with fewer hits goes; without the rule (0, and the close rule's 15 frames
    # not reached) both stay.
    from foveatrack.frames import Frame

    tracker = SkyTracker(SkyTrackerConfig(warmup_s=0.0, merge_frames=merge_frames))
    empty = lambda k: Frame(k * 0.1, (k + 1) * 0.1, np.empty((0, 3)), np.empty(0, np.int64))
    pose = Pose()
    tracker.process(empty(0), pose)
    tracker.tracks = [_confirmed_track(tracker, 3, [30, 0, 3.0], [0, -1, 0], 12, 0.1),
                      _confirmed_track(tracker, 7, [30, 0, 3.3], [0, -1, 0.2], 20, 0.1),
                      _confirmed_track(tracker, 8, [30, 9, 3.0], [0, -2, 0], 10, 0.1),
                      _confirmed_track(tracker, 9, [30, 9, 3.3], [0, 2, 0], 30, 0.1)]
    deleted = [i for k in range(1, 8) for i in tracker.process(empty(k), pose).deleted_now]
    left = {tr.track_id for tr in tracker.tracks}
    if merge_frames:
        assert deleted == [3] and left == {7, 8, 9}          # 3 had fewer hits than 7
    else:
        assert deleted == [] and left == {3, 7, 8, 9}


@pytest.mark.parametrize("replay", [True, False])
def test_a_drone_seen_in_the_warm_up_is_confirmed_when_it_ends(replay):
    # A drone crosses the field from the first frame, in front of the scenery's wall.  The warm-up's
    # frames are tracked at its end (warmup_replay), when the background knows what stayed: the drone
    # is confirmed in the first frame after the warm-up.  Without it the tracker starts from that
    # frame and needs three more.
    a = straight([30, 6, 3.0], [0, -4.0, 0])
    outs = run(SkyTracker(SkyTrackerConfig(warmup_replay=replay)), [a], 2.5)
    first = next(k for k, o in enumerate(outs) if o.confirmed_now)
    if replay:
        assert outs[first].t_s == pytest.approx(1.1)
    else:
        assert outs[first].t_s >= 1.3 - 1e-9
    (tid,) = outs[first].confirmed_now
    assert np.linalg.norm(_confirmed(outs[first])[tid].xyz_m - _truth_at(a, outs[first].t_s)) < 0.5
    # only what a frame showed is ever reported deleted
    shown = set()
    for o in outs:
        assert set(o.deleted_now) <= shown
        shown |= {v.track_id for v in o.tracks}


@pytest.mark.parametrize("close_frames, gone", [(4, [3]), (0, [])])
def test_two_tracks_close_for_long_become_one_whatever_their_velocities(close_frames, gone):
    # two tracks taking one object's hits in turn drag each other's velocity about: close in
    # position alone for merge_close_frames frames in a row is enough
    from foveatrack.frames import Frame

    tracker = SkyTracker(SkyTrackerConfig(warmup_s=0.0, merge_frames=0, merge_close_frames=close_frames))
    empty = lambda k: Frame(k * 0.1, (k + 1) * 0.1, np.empty((0, 3)), np.empty(0, np.int64))
    pose = Pose()
    tracker.process(empty(0), pose)
    tracker.tracks = [_confirmed_track(tracker, 3, [30, 0, 3.0], [0, -1, 0], 12, 0.1),
                      _confirmed_track(tracker, 7, [30, 0, 3.0], [0, -1, 1.2], 20, 0.1)]
    deleted = [i for k in range(1, 4) for i in tracker.process(empty(k), pose).deleted_now]
    assert deleted == []                                  # 3 frames: not yet
    assert list(tracker.process(empty(4), pose).deleted_now) == gone


@pytest.mark.parametrize("key", ["warmup_replay", "lone_returns"])
@pytest.mark.parametrize("value, ok", [(True, True), (False, True), (1, False), ("yes", False)])
def test_the_sky_tables_switches_are_true_or_false(key, value, ok):
    from foveatrack.errors import UserError
    if ok:
        assert getattr(SkyTrackerConfig.from_mapping({key: value}, "[tracker.sky]"), key) is value
    else:
        with pytest.raises(UserError, match=rf"\[tracker.sky\]: {key} must be true or false"):
            SkyTrackerConfig.from_mapping({key: value}, "[tracker.sky]")


@pytest.mark.parametrize("gate", [0.0, -1.0])
def test_a_lone_return_gate_that_takes_nothing_is_refused(gate):
    from foveatrack.errors import UserError
    with pytest.raises(UserError, match=r"lone_gate_m must be > 0"):
        SkyTrackerConfig.from_mapping({"lone_gate_m": gate}, "[tracker.sky]")


def test_the_track_the_fovea_turns_to_is_not_given_up_while_the_head_gets_there():
    # Two confirmed tracks in the field, unseen since 0.1 s (at the rosette's sparse rim).  The one the
    # fovea is turning to (a revisit) lives on past lost_after_s (2 s) up to lost_out_of_view_s (5 s):
    # on the crossing (seed 29) a revisit's track was deleted 0.3 s before the head brought it into
    # the fovea, and the drone came back under a new id.  The other goes at 2 s.
    from foveatrack.frames import Frame

    tracker = SkyTracker(SkyTrackerConfig(warmup_s=0.0))
    empty = lambda k: Frame(k * 0.1, (k + 1) * 0.1, np.empty((0, 3)), np.empty(0, np.int64))
    pose = Pose()
    tracker.process(empty(0), pose)
    tracker.tracks = [_confirmed_track(tracker, 3, [30, 5, 3.0], [0, -1, 0], 12, 0.1),
                      _confirmed_track(tracker, 8, [30, -5, 3.0], [0, 1, 0], 12, 0.1)]
    gone_at = {}
    for k in range(1, 60):
        for i in tracker.process(empty(k), pose, fovea_track_id=3).deleted_now:
            gone_at[i] = (k + 1) * 0.1
    assert 2.0 < gone_at[8] <= 2.3 and 5.0 < gone_at[3] <= 5.3, gone_at


def test_only_the_time_in_the_field_counts_toward_losing_a_track():
    # A confirmed track unseen from 0.1 s on; the head looks 40 deg away until 1.5 s, then back.  The
    # scan could not have seen it while it was out of the field, so it is lost after lost_after_s
    # (2 s) in the field: at 3.5 s, not at 2 s.  On the crossing (seed 33) the head turned back to a
    # drone it had left 1.7 s before, and its track was deleted 0.5 s after the drone was back in
    # the field, at the rosette's sparse rim, with no ray on it yet: the drone came back under a new id.
    # One that stays out of the field goes after lost_out_of_view_s (5 s), as before.
    from foveatrack.frames import Frame

    tracker = SkyTracker(SkyTrackerConfig(warmup_s=0.0, field_half_angle_deg=19.2))
    empty = lambda k: Frame(k * 0.1, (k + 1) * 0.1, np.empty((0, 3)), np.empty(0, np.int64))
    pose = Pose(lambda t: (40.0 if t < 1.5 else 0.0, 0.0))
    tracker.process(empty(0), pose)
    tracker.tracks = [_confirmed_track(tracker, 3, [30, 5, 3.0], [0, 0, 0], 12, 0.1),
                      _confirmed_track(tracker, 8, [-30, 5, 3.0], [0, 0, 0], 12, 0.1)]   # behind: never in the field
    gone_at = {}
    for k in range(1, 60):
        for i in tracker.process(empty(k), pose).deleted_now:
            gone_at[i] = (k + 1) * 0.1
    assert 3.5 <= gone_at[3] <= 3.7 and 5.0 < gone_at[8] <= 5.3, gone_at


@pytest.mark.parametrize("clear_hits, confirmed, takes", [(2, False, False), (0, False, True), (2, True, True)])
def test_a_candidate_seen_off_the_scenery_takes_no_object_on_it(clear_hits, confirmed, takes):
    # A tentative track with two hits 0.1 s apart off the scenery gates metres wide: on the tree line
    # such a candidate on the drone took a crown's part 3 m below it and the drone started over.  An
    # object on the scenery in its gate is not its; off the scenery it is.  A candidate never seen off
    # the scenery, and a confirmed track (a drone in front of a crown), take it as before.
    from foveatrack.sky.motion import positions_many
    from foveatrack.sky.tracks import SkyObject

    tracker = SkyTracker(NO_WARMUP)
    tr = _confirmed_track(tracker, 1, [30.0, 0.0, 8.0], [0.0, 0.0, 0.0], 2, 0.0)
    tr.kf.c = np.full(3, 8.0)              # the velocity of two hits 0.1 s apart: 2.8 m/s a side
    tr.clear_hits = clear_hits
    tr.confirmed_t_s = 0.0 if confirmed else None
    tracker.tracks = [tr]
    below = np.array([30.0, 0.5, 6.0])      # 2 m below, 0.4 s on: within the chi-square gate and gate_max_m
    for on_scenery, expect in ((True, takes), (False, True)):
        ob = SkyObject(below, 0.4, 6, np.array([0.5, 0.5, 0.5]), on_scenery)
        match, allowed = tracker._associate([ob], 0.4, positions_many([tr.kf], 0.4))
        assert (match == [(0, 0)]) is expect, (on_scenery, match, allowed)


def test_the_fixated_drones_d_is_not_learned_into_the_background():
    # A drone flies in at 2 m/s (confirmed, 2.4 m from where it was first seen), then hovers at 0.1 m/s
    # while the sparse scan puts a single return on it per frame: too few for an object, so nothing
    # matched protects its points.  The fovea is on it, and Algorithm 1 measures it in its D; what
    # lies in that D is not learned as scenery (flock seed +240: the hovering drone became background
    # and its track took a bird 2.9 m away).  When its returns come back to 6 a frame, they are hits.
    from synthetic import frame_of

    def drone(t):
        x = 30.0 + min(t, 1.2) * 2.0 + max(t - 1.2, 0.0) * 0.1
        return np.array([x, 2.0, 3.0]), 0.15
    tracker = SkyTracker(NO_WARMUP)
    pose = Pose()
    rng = np.random.default_rng(4)
    outs, fov = [], None
    for k in range(60):
        n = 8 if k < 12 else 1 if k < 40 else 6
        out = tracker.process(frame_of([drone], k * 0.1, (k + 1) * 0.1, pose, rng, n_per_object=n, wall=False), pose, fov)
        outs.append(out)
        conf = _confirmed(out)
        fov = min(conf) if conf else None
    late = outs[45:]
    assert all(len(_confirmed(o)) == 1 for o in late)
    tid = next(iter(_confirmed(late[0])))
    assert all(tid in _confirmed(o) for o in late)
    assert sum(v.hit for o in late for v in o.tracks if v.track_id == tid) >= 12    # its returns are hits again


def test_what_a_user_can_get_wrong_in_the_sky_table_is_named():
    # a misspelt sub-table is told the keys it may be (attention among them); a cell too fine for
    # memory or too coarse to mean anything, a correlation threshold no correlation reaches, are refused
    from foveatrack.errors import UserError
    from foveatrack.sky.controller import sky_configs_from_mapping

    with pytest.raises(UserError, match=r"unknown key\(s\) 'atention'; allowed keys: .*attention"):
        sky_configs_from_mapping({"atention": {"revisit_s": 2.0}}, "s.toml [tracker.sky]")
    for cell in (0.000001, 0.05, 6.0, 90.0):
        with pytest.raises(UserError, match=r"cell_deg must be in \[0.1, 5.0\]"):
            sky_configs_from_mapping({"cell_deg": cell}, "s.toml [tracker.sky]")
    assert sky_configs_from_mapping({"cell_deg": 0.1}, "w")[0].cell_deg == 0.1
    with pytest.raises(UserError, match="flap_autocorr"):
        sky_configs_from_mapping({"classifier": {"flap_autocorr": 5.0}}, "s.toml [tracker.sky]")


def test_close_pairs_kernel_is_the_distance_matrix_and_argwhere():
    """close_pairs_kernel (the merge rule's pairs) against its twin, the numpy form the rule used: the
    distance matrix summed x, y, z, np.argwhere row-major and a < b; ties at the limit, a repeated
    point, NaN rows, one row and none."""
    from foveatrack.kernels import close_pairs_kernel

    def twin(P, limit):
        d = P[:, None, :] - P[None, :, :]
        dist = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])
        return [(a, b) for a, b in np.argwhere(dist <= limit).tolist() if a < b]

    rng = np.random.default_rng(5)
    for n in (0, 1, 2, 7, 25, 60):
        for limit in (0.0, 0.6, 3.0):
            P = rng.normal(0.0, 2.0, (n, 3)) + [30.0, 0.0, 5.0]
            if n >= 4:
                P[3] = P[1]                                  # a distance of 0
                P[2] = P[0] + [limit, 0.0, 0.0]              # at the limit (or a rounding off it)
            if n >= 7:
                P[5] = np.nan
            out = np.empty((n * (n - 1) // 2, 2), np.int64)
            k = close_pairs_kernel(P, limit, out)
            assert [tuple(p) for p in out[:k].tolist()] == twin(P, limit)


def test_association_is_the_numpy_gate_and_scipy_s_assignment():
    """The association's gated costs (association_kernel) against their numpy twin, element for
    element, and its pairs against scipy's assignment on the twin's costs, where no two allowed pairs
    share a track or an object and where they do; ties at the gates, candidates against objects on
    the scenery, NaN, one track, one object."""
    from scipy.optimize import linear_sum_assignment

    from foveatrack.kernels import association_kernel
    from foveatrack.sky.motion import ConstantVelocityFilter
    from foveatrack.sky.tracks import _BIG, SkyObject, SkyTrack

    def twin(P, V, O, cfg, candidate, on_scenery):
        d = O[None, :, :] - P[:, None, :]
        d2 = d * d
        e = d2 / (V[:, None, :] + cfg.r_m2)
        cost = e[..., 0] + e[..., 1] + e[..., 2]
        dist2 = d2[..., 0] + d2[..., 1] + d2[..., 2]
        allowed = (cost <= cfg.gate_chi2) & (dist2 <= cfg.gate_max_m * cfg.gate_max_m)
        allowed &= ~(candidate[:, None] & on_scenery[None, :])
        return np.where(allowed, cost, _BIG), allowed

    rng = np.random.default_rng(41)
    cfg = SkyTrackerConfig()
    fast = slow = 0
    for trial in range(400):
        n, m = int(rng.integers(1, 12)), int(rng.integers(1, 8))
        P = rng.normal(0.0, 2.0, (n, 3)) + [30.0, 0.0, 5.0]
        V = rng.uniform(0.01, 2.0, (n, 3))
        O = P[rng.integers(0, n, m)] + rng.normal(0.0, rng.choice([0.3, 1.0, 2.5]), (m, 3))
        if trial % 9 == 0:
            O[0] = P[0] + [cfg.gate_max_m, 0.0, 0.0]          # at the distance gate
        if trial % 13 == 0:
            O[-1, 1] = np.nan
        candidate = rng.random(n) < 0.3
        on_scenery = rng.random(m) < 0.3
        cost = np.empty((n, m))
        allowed = np.empty((n, m), np.bool_)
        k = association_kernel(P, V, O, cfg.r_m2, cfg.gate_chi2, cfg.gate_max_m * cfg.gate_max_m, candidate,
                               on_scenery, _BIG, cost, allowed)
        want_cost, want_allowed = twin(P, V, O, cfg, candidate, on_scenery)
        assert k == want_allowed.sum() and np.array_equal(allowed, want_allowed)
        assert cost.tobytes() == want_cost.tobytes()
        if not k:
            continue
        # the tracker's pairs on tracks at P (their filters' variances V, r_m2 added above) and objects O
        tracker = SkyTracker(cfg)
        for i in range(n):
            kf = ConstantVelocityFilter(0.0, P[i], cfg.q_m2_s3, cfg.r_m2, cfg.v0_sigma_m_s)
            kf.a = V[i].copy()
            tr = SkyTrack(i, kf, 0.0, 0.0)
            tr.clear_hits = int(candidate[i])
            tracker.tracks.append(tr)
        objs = [SkyObject(O[j], 0.0, 5, np.full(3, 0.3), bool(on_scenery[j])) for j in range(m)]
        match, got_allowed = tracker._associate(objs, 0.0, P.copy())
        rows, cols = linear_sum_assignment(want_cost)
        assert match == [(int(i), int(j)) for i, j in zip(rows, cols) if want_allowed[i, j]]
        assert np.array_equal(got_allowed, want_allowed)
        conflict = (want_allowed.sum(axis=0) > 1).any() or (want_allowed.sum(axis=1) > 1).any()
        slow += conflict
        fast += not conflict
    assert fast > 50 and slow > 50


def _frames_of_points(points_per_frame):
    """Frames at 10 Hz holding the given world points (lists of (3,)), each at its frame's mid time."""
    from foveatrack.frames import Frame

    out = []
    for k, pts in enumerate(points_per_frame):
        t0, t1 = k * 0.1, (k + 1) * 0.1
        xyz = np.array(pts, float).reshape(-1, 3)
        t_ns = np.full(len(xyz), int(round((t0 + 0.05) * 1e9)), np.int64)
        out.append(Frame(t0, t1, xyz, t_ns))
    return out


@pytest.mark.parametrize("lone_returns, offset_m, confirmed_at", [(True, 0.0, 2), (False, 0.0, None),
                                                                   (True, 1.5, None)])
def test_a_far_drone_s_lone_returns_confirm_the_track_its_object_started(lone_returns, offset_m, confirmed_at):
    # A small drone 40 m out at the rosette's sparse rim: one frame holds three of its returns (an
    # object, which starts a track), the next frames one return each.  With lone_returns those are
    # hits of the track (step 5b) and it is confirmed at the third frame; objects alone never
    # confirm it; a lone return beyond lone_gate_m (1 m) of the prediction is not its.
    cfg = SkyTrackerConfig(warmup_s=0.0, lone_returns=lone_returns)
    p = lambda k: np.array([40.0, 2.0 - 0.1 * k, 5.0])            # 1 m/s sideways
    cluster = [p(0) + d for d in ([0, 0, 0], [0, 0.1, 0], [0, 0, 0.1])]
    frames = _frames_of_points([cluster] + [[p(k) + [0.0, 0.0, offset_m]] for k in range(1, 6)])
    tracker = SkyTracker(cfg)
    outs = [tracker.process(f, Pose()) for f in frames]
    confirmed = [k for k, o in enumerate(outs) if any(v.confirmed for v in o.tracks)]
    assert (confirmed[0] if confirmed else None) == confirmed_at, confirmed
    # lone returns start no track, and the classifier's history holds the one object
    assert [v.track_id for v in outs[-1].tracks] == [0]
    assert len(tracker.tracks[0].history) == 1
    if confirmed_at is not None:
        assert np.linalg.norm(outs[-1].tracks[0].xyz_m - p(5.5)) < 0.3


def test_the_prune_cuts_the_history_as_the_window_s_filter_does():
    # _prune cuts a history in time order at its first hit inside the window (a prefix goes, and the
    # list stays as it is when none does); one out of order (a hit appended earlier than the one
    # before, a NaN) is filtered hit by hit: either way, the hits the window's filter keeps
    from foveatrack.sky.features import history_rows, kept_rows
    from foveatrack.sky.motion import ConstantVelocityFilter
    from foveatrack.sky.tracks import SkyObject, SkyTrack

    cfg = SkyTrackerConfig(warmup_s=0.0)
    rng = np.random.default_rng(11)
    side = np.array([0.3, 0.3, 0.1])
    for case in range(200):
        tracker = SkyTracker(cfg)
        t_s = 10.0
        times = np.sort(rng.uniform(t_s - 2 * cfg.history_s, t_s, int(rng.integers(1, 20)))).tolist()
        if case % 4 == 1:
            rng.shuffle(times)
        elif case % 4 == 2:
            times[int(rng.integers(len(times)))] = math.nan
        elif case % 4 == 3:
            times = [t_s - cfg.history_s + 0.5] * len(times)     # none older than the window
        tr = SkyTrack(0, ConstantVelocityFilter(0.0, np.zeros(3), cfg.q_m2_s3, cfg.r_m2, cfg.v0_sigma_m_s), 0.0, t_s,
                      hit_now=True)
        tr.origin_xyz_m = np.zeros(3)
        tr.rows_of = tr.history         # the classifier's rows kept in step, as a new track's are
        for t in times:
            tracker._hit(tr, t, np.ones(3) * t, SkyObject(np.ones(3), t, 3, side))
        tr.last_hit_t_s = t_s           # not lost
        want = [h for h in tr.history if h[0] >= t_s - cfg.history_s]
        assert tr.history_in_order == all(b >= a for a, b in zip(times, times[1:]))
        tracker.tracks = [tr]
        before = tr.history
        tracker._prune(t_s, None, 0.1)
        assert [h[0] for h in tr.history] == [h[0] for h in want] and all(a is b for a, b in zip(tr.history, want))
        if len(want) == len(before) and tr.history_in_order:
            assert tr.history is before
        # the rows the classifier reads are the history's, bit for bit, cut or filtered, and after a
        # hit more and the next frame's prune
        rows = kept_rows(tr)
        assert rows is not None and rows.tobytes() == history_rows(tr.history).tobytes()
        tracker._hit(tr, t_s + 0.5, np.full(3, 2.0), SkyObject(np.ones(3), t_s + 0.5, 4, side))
        tracker._prune(t_s + 1.0, None, 0.1)
        rows = kept_rows(tr)
        assert rows is not None and rows.tobytes() == history_rows(tr.history).tobytes()


def test_the_distances_on_floats_are_norm3_s_of_the_arrays():
    # ConstantVelocityFilter.distance_at and fixed_order.dist3 work on floats: the bits of norm3 of the
    # arrays' difference (the prediction's position_at included), over many scales
    from foveatrack.fixed_order import dist3, norm3
    from foveatrack.sky.motion import ConstantVelocityFilter

    rng = np.random.default_rng(5)
    for _ in range(2000):
        scale = 10.0 ** rng.uniform(-3, 3)
        a, b = rng.normal(size=3) * scale, rng.normal(size=3) * scale
        assert dist3(a, b) == norm3(a - b)
        kf = ConstantVelocityFilter(rng.uniform(0, 5), a, 20.0, 0.04, 3.0)
        kf.update(kf.t_s + rng.uniform(0.0, 0.3), a + rng.normal(size=3))
        t = kf.t_s + rng.uniform(-0.1, 2.0)
        assert kf.distance_at(t, b) == norm3(b - kf.position_at(t))


def test_the_filters_update_kernel_is_its_twin_on_floats():
    # ConstantVelocityFilter.update runs motion.update_kernel: every state the bits of update_floats,
    # its plain-Python twin, with a zero step, a step back, a measurement variance of its own, and
    # infinities and NaN passing through
    from foveatrack.sky.motion import update_floats, update_kernel

    rng = np.random.default_rng(9)
    for k in range(3000):
        state = rng.normal(size=(5, 3)) * 10.0 ** rng.uniform(-3, 3, (5, 1))
        state[2:] = np.abs(state[2:])
        dt = float(rng.choice([0.0, rng.uniform(-0.2, 0.5), rng.uniform(0.0, 5.0)]))
        z = state[0] + rng.normal(size=3) * rng.uniform(0.01, 5)
        if k % 50 == 0:
            z[int(rng.integers(3))] = [np.inf, -np.inf, np.nan][k // 50 % 3]
        r, q = float(rng.uniform(0.001, 1.0)), float(rng.uniform(0.1, 40.0))
        out = np.empty((5, 3))
        update_kernel(state, dt, z, r, q, out)
        assert out.tobytes() == update_floats(state, dt, z, r, q).tobytes()


def test_a_lone_return_that_is_an_object_is_not_a_second_tracks_hit():
    # min_points 1 makes an object of a single return: it is the object's track's hit, and not also
    # a lone return (step 5b) of the idle track next to it -- one return, one track
    cfg = SkyTrackerConfig(warmup_s=0.0, lone_returns=True, min_points=1)
    tracker = SkyTracker(cfg)
    frames = _frames_of_points([[[30.0, 0.0, 5.0], [30.0, 0.8, 5.0]], [[30.0, 0.4, 5.0]]])
    for f in frames:
        out = tracker.process(f, Pose())
    assert len(out.tracks) == 2
    assert sum(v.hit for v in out.tracks) == 1, [(v.track_id, v.hit) for v in out.tracks]


def test_a_return_algorithm_1_took_for_the_fixated_track_is_no_lone_hit_of_another():
    # two drones 1.2 m apart, each a 3-return object, both confirmed; then one return between them,
    # inside the fixated track's D (1 m half-size) and within lone_gate_m of the other track: it is
    # the fixated track's hit by Algorithm 1, and not also the other's lone hit (a reviewer's find)
    cfg = SkyTrackerConfig(warmup_s=0.0, lone_returns=True)
    a, b = np.array([40.0, 0.0, 5.0]), np.array([40.0, 1.2, 5.0])
    cluster = lambda c: [c + d for d in ([0, 0, 0], [0, 0.1, 0], [0, 0, 0.1])]
    frames = _frames_of_points([cluster(a) + cluster(b)] * 4 + [[a + [0.0, 0.6, 0.0]]])
    tracker = SkyTracker(cfg)
    outs = [tracker.process(f, Pose(), 0 if k == 4 else None) for k, f in enumerate(frames)]
    last = {v.track_id: v for v in outs[-1].tracks}
    assert set(last) == {0, 1} and last[0].confirmed and last[1].confirmed
    assert last[0].hit and not last[1].hit, (last[0].hit, last[1].hit)
