"""Our GOSPA (foveatrack.sky.metrics.gospa) against Stone Soup's GOSPAMetric on the same tracks: a
third-party implementation nobody here wrote (test-only dependency)."""

import datetime

import numpy as np
import pytest

from foveatrack.sky.metrics import drone_metrics, gospa

stonesoup = pytest.importorskip("stonesoup", reason="stonesoup is a test dependency (pip install -e '.[test]')")
from stonesoup.metricgenerator.ospametric import GOSPAMetric  # noqa: E402
from stonesoup.types.state import State  # noqa: E402


def _states(points, when):
    return [State(np.asarray(p, float).reshape(3, 1), timestamp=when) for p in points]


@pytest.mark.parametrize("seed", range(40))
def test_gospa_equals_stone_soup(seed):
    rng = np.random.default_rng(seed)
    when = datetime.datetime(2026, 1, 1)
    truths = rng.uniform(-30, 30, (rng.integers(0, 7), 3))
    if len(truths) == 0 and seed % 2:   # Stone Soup needs one state at least (for its timestamp)
        truths = rng.uniform(-30, 30, (1, 3))
    # estimates: some truths with noise (some far off the cut-off), plus false ones
    est = [t + rng.normal(0, rng.choice([0.2, 2.0, 20.0]), 3) for t in truths if rng.random() < 0.8]
    est += list(rng.uniform(-30, 30, (rng.integers(0, 4), 3)))
    c, p = float(rng.choice([1.0, 5.0, 10.0])), float(rng.choice([1.0, 2.0, 3.0]))
    if not len(est):
        est = [rng.uniform(-30, 30, 3)]
    ours = gospa(np.array(est).reshape(-1, 3), truths, c, p)
    ss = GOSPAMetric(c=c, p=p)
    theirs, _ = ss.compute_gospa_metric(_states(est, when), _states(truths, when))
    for k in ("distance", "localisation", "missed", "false"):
        assert abs(ours[k] - float(theirs.value[k])) <= 1e-9, (k, ours[k], theirs.value[k])


def test_gospa_of_nothing_is_zero():
    assert gospa(np.empty((0, 3)), np.empty((0, 3)), 5.0)["distance"] == 0.0


def test_gospa_over_a_run_of_tracks_equals_stone_soup():
    # Two drones over 30 frames, three tracks (one false, one lost for a while): the per-frame distance
    rng = np.random.default_rng(7)
    t0 = datetime.datetime(2026, 1, 1)
    for k in range(30):
        when = t0 + datetime.timedelta(seconds=0.1 * k)
        truths = [np.array([30.0, 5 - 0.2 * k, 3.0]), np.array([30.0, -5 + 0.2 * k, 3.3])]
        est = [truths[0] + rng.normal(0, 0.1, 3)]
        if not 10 <= k < 15:
            est.append(truths[1] + rng.normal(0, 0.1, 3))
        if k % 3 == 0:
            est.append(np.array([60.0, rng.uniform(-5, 5), 4.0]))
        ours = gospa(est, truths, 5.0, 2.0)
        theirs, _ = GOSPAMetric(c=5.0, p=2.0).compute_gospa_metric(_states(est, when), _states(truths, when))
        assert abs(ours["distance"] - float(theirs.value["distance"])) <= 1e-9


def test_drone_metrics_count_switches_gaps_and_false_tracks():
    T = 50
    t = 0.1 * np.arange(T)
    xyz = np.stack([np.full(T, 30.0), np.linspace(-5, 5, T), np.full(T, 3.0)], 1)
    vis = np.arange(T) >= 5
    fov = (np.arange(T) % 10) < 6
    tracks = []
    for k in range(T):
        tr = []
        if 8 <= k < 20:
            tr.append((1, "drone" if k >= 11 else "unknown", xyz[k]))   # labelled drone 3 frames after it
        elif 22 <= k:
            tr.append((2, "drone", xyz[k]))          # a new id after a gap: one switch
        if k == 30:
            tr.append((9, "drone", np.array([50.0, 0, 0])))   # a false drone track
        if k == 31:
            tr.append((10, "bird", np.array([50.0, 0, 0])))   # a bird: not a false drone track
        tracks.append(tr)
    m = drone_metrics(t, {"a": {"xyz_m": xyz, "visible": vis, "in_fovea": fov}}, tracks)
    a = m["drones"]["a"]
    assert a["time_to_confirm_s"] == pytest.approx(0.3)
    assert a["time_to_drone_label_s"] == pytest.approx(0.6)
    assert a["id_switches"] == 1 and a["track_ids"] == [1, 2]
    assert a["continuity"] == pytest.approx(40 / 42)
    assert a["longest_revisit_gap_s"] == pytest.approx(0.4)
    assert m["false_drone_tracks"] == [9]
    assert m["false_drone_tracks_per_hour"] == pytest.approx(3600 / 5.0)


def test_a_revisit_gap_ends_with_the_drones_last_frame_in_the_field():
    T = 100
    t = 0.1 * np.arange(T)
    xyz = np.stack([np.full(T, 30.0), np.linspace(-5, 5, T), np.full(T, 3.0)], 1)
    vis = np.ones(T, bool)
    fov = np.arange(T) < 20                       # in the fovea for 2 s, then never again
    tracks = [[(1, "drone", xyz[k])] for k in range(T)]
    field = np.arange(T) < 50                     # ... and out of the lidar's field from 5 s on
    d = {"xyz_m": xyz, "visible": vis, "in_fovea": fov}
    always = drone_metrics(t, {"a": d}, tracks)["drones"]["a"]["longest_revisit_gap_s"]
    left = drone_metrics(t, {"a": {**d, "in_field": field}}, tracks)["drones"]["a"]["longest_revisit_gap_s"]
    assert always == pytest.approx(8.0) and left == pytest.approx(3.0)
    # out of the field for a while and back: the time away counts (the head chose to look elsewhere)
    back = np.where((np.arange(T) >= 50) & (np.arange(T) < 70), False, True)
    assert drone_metrics(t, {"a": {**d, "in_field": back}}, tracks)["drones"]["a"]["longest_revisit_gap_s"] \
        == pytest.approx(8.0)


def test_the_fovea_share_counts_the_frames_in_the_field():
    # in the fovea for its first 2 s, in the field (the space of interest) for 5 s, hit by rays for
    # all 10: a share of its 50 frames in the field, not of the 100 it was hit
    T = 100
    t = 0.1 * np.arange(T)
    xyz = np.stack([np.full(T, 30.0), np.linspace(-5, 5, T), np.full(T, 3.0)], 1)
    d = {"xyz_m": xyz, "visible": np.ones(T, bool), "in_fovea": np.arange(T) < 20}
    tracks = [[(1, "drone", xyz[k])] for k in range(T)]
    assert drone_metrics(t, {"a": d}, tracks)["drones"]["a"]["fovea_share"] == pytest.approx(0.2)
    field = np.arange(T) < 50
    assert drone_metrics(t, {"a": {**d, "in_field": field}}, tracks)["drones"]["a"]["fovea_share"] == pytest.approx(0.4)
    assert drone_metrics(t, {"a": {**d, "in_field": np.zeros(T, bool)}}, tracks)["drones"]["a"]["fovea_share"] == 0.0


def test_a_track_passing_by_a_drone_does_not_take_its_match():
    # The drone's own track follows it 0.3 m off; a crown's track (labelled clutter) passes through
    # the drone's position.  CLEAR MOT keeps the drone's match while its track stays within match_m:
    # no id switch (by the assignment alone the passing track took the drone for a few frames: two).
    T = 40
    t = 0.1 * np.arange(T)
    xyz = np.stack([np.full(T, 30.0), np.linspace(-2, 2, T), np.full(T, 3.0)], 1)
    crossing = np.stack([np.full(T, 30.0), np.full(T, 0.0), np.linspace(5.0, 1.0, T)], 1)
    tracks = [[(1, "drone", xyz[k] + [0.0, 0.0, 0.3]), (7, "clutter", crossing[k])] for k in range(T)]
    d = {"xyz_m": xyz, "visible": np.ones(T, bool), "in_fovea": None}
    a = drone_metrics(t, {"a": d}, tracks)["drones"]["a"]
    assert a["id_switches"] == 0 and a["track_ids"] == [1]
    # ... but a track that leaves the drone hands it on: from frame 21 track 1 drifts off at 5 m/s, and
    # track 7, on the drone from frame 20, takes it once track 1 is 2 m away (frame 25): one switch
    gone = [[(1, "drone", xyz[k] + [0.0, 0.0, 0.3 + 0.5 * max(0, k - 20)])] + ([(7, "drone", xyz[k])] if k >= 20 else [])
            for k in range(T)]
    b = drone_metrics(t, {"a": d}, gone)["drones"]["a"]
    assert b["id_switches"] == 1 and b["track_ids"] == [1, 7]


def test_a_drone_keeps_its_track_when_another_drones_track_comes_nearer():
    # Two drones 1.2 m apart, each with its own track between them: 0.55 m from its drone and 0.65 m
    # from the other, then from frame 10 0.7 m from its drone and 0.5 m from the other.  By the
    # assignment alone the drones swap tracks at frame 10 (two switches); CLEAR MOT keeps each one's.
    T = 20
    t = 0.1 * np.arange(T)
    a_xyz = np.tile([30.0, 0.0, 3.0], (T, 1))
    b_xyz = np.tile([30.0, 1.2, 3.0], (T, 1))
    tracks = [[(1, "drone", np.array([30.0, 0.55 if k < 10 else 0.7, 3.0])),
               (2, "drone", np.array([30.0, 0.65 if k < 10 else 0.5, 3.0]))] for k in range(T)]
    d = {"a": {"xyz_m": a_xyz, "visible": np.ones(T, bool), "in_fovea": None},
         "b": {"xyz_m": b_xyz, "visible": np.ones(T, bool), "in_fovea": None}}
    m = drone_metrics(t, d, tracks)["drones"]
    assert m["a"]["track_ids"] == [1] and m["b"]["track_ids"] == [2]
    assert m["a"]["id_switches"] == 0 and m["b"]["id_switches"] == 0


def test_a_drone_is_not_confirmed_by_another_drone_s_track_that_drifts_onto_it():
    # Drone a's track 1 is on it from frame 2; from frame 10 a is gone and track 1 is on drone b;
    # b's own track 5 comes at frame 25.  Before, b counted as confirmed at frame 10, by a's track
    # (swarm-of-five: drone-5 "confirmed 1.8 s in", its rays allowed 7.7 s).  It is a's track that
    # went over to b: b's confirmation is its own track's, and its labelling too.
    T = 40
    t = 0.1 * np.arange(T)
    a_xyz = np.tile([30.0, 0.0, 3.0], (T, 1))
    a_xyz[10:] = np.nan
    b_xyz = np.tile([30.0, 5.0, 3.0], (T, 1))
    tracks = []
    for k in range(T):
        tr = []
        if 2 <= k < 10:
            tr.append((1, "drone", a_xyz[k]))
        elif 10 <= k:
            tr.append((1, "drone", b_xyz[k] + [0.0, 0.3, 0.0]))
        if k >= 25:
            tr.append((5, "unknown" if k < 30 else "drone", b_xyz[k]))
        tracks.append(tr)
    d = {"a": {"xyz_m": a_xyz, "visible": np.arange(T) < 10, "in_fovea": None},
         "b": {"xyz_m": b_xyz, "visible": np.ones(T, bool), "in_fovea": None}}
    m = drone_metrics(t, d, tracks)["drones"]
    assert m["a"]["time_to_confirm_s"] == pytest.approx(0.2)
    assert m["b"]["time_to_confirm_s"] == pytest.approx(2.5)
    assert m["b"]["time_to_drone_label_s"] == pytest.approx(3.0)
    # track 1 is the one b stays matched to (CLEAR MOT keeps it: track 5 is a second track on b);
    # continuity and the revisit gaps start at its first match
    assert m["b"]["first_matched_s"] == pytest.approx(1.0) and m["b"]["track_ids"] == [1]


def test_a_drone_never_in_the_field_has_no_revisit_gap():
    # matched all along (a track on it from the rim's returns) but never inside the field and D: the
    # fovea owes it nothing, as one in the field for a single frame is owed one frame
    T = 50
    t = 0.1 * np.arange(T)
    xyz = np.tile([30.0, 0.0, 3.0], (T, 1))
    d = {"xyz_m": xyz, "visible": np.ones(T, bool), "in_fovea": np.zeros(T, bool)}
    tracks = [[(1, "drone", xyz[k])] for k in range(T)]
    never = drone_metrics(t, {"a": {**d, "in_field": np.zeros(T, bool)}}, tracks)["drones"]["a"]
    once = drone_metrics(t, {"a": {**d, "in_field": np.arange(T) == 0}}, tracks)["drones"]["a"]
    assert never["longest_revisit_gap_s"] == 0.0 and never["longest_revisit_gap_from_s"] is None
    assert once["longest_revisit_gap_s"] == pytest.approx(0.1)


def test_a_drone_in_the_field_no_track_followed_was_never_revisited():
    # no track near it at any frame: no gap is measured (None), where 0.0 read as "revisited within
    # any revisit time"; and the report's run does not count as one whose every gap was within 3 s
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
    from sky_tracks_report import run_longest_gap

    T = 30
    t = 0.1 * np.arange(T)
    xyz = np.tile([30.0, 0.0, 3.0], (T, 1))
    d = {"xyz_m": xyz, "visible": np.ones(T, bool), "in_fovea": np.zeros(T, bool), "in_field": np.ones(T, bool)}
    m = drone_metrics(t, {"a": d, "b": {**d, "in_fovea": np.ones(T, bool)}},
                      [[(1, "drone", xyz[k] + [0.0, 0.0, 0.0])] if k > 100 else [] for k in range(T)])
    assert m["drones"]["a"]["longest_revisit_gap_s"] is None and m["drones"]["a"]["first_matched_s"] is None
    assert run_longest_gap(m) is None
    assert run_longest_gap({"drones": {"a": {"longest_revisit_gap_s": 2.5}, "b": {"longest_revisit_gap_s": 0.3}}}) == 2.5
