"""The fovea's schedule: priority by threat score, revisits of the other drones, return, pin."""

import numpy as np
import pytest

from foveatrack.sky.attention import Attention, AttentionConfig, threat_score
from foveatrack.sky.tracks import TrackView


def view(tid, xyz, vel=(0, 0, 0), label="drone", confirmed=True):
    return TrackView(tid, confirmed, label, np.array(xyz, float), np.array(vel, float), True, True, {})


def test_threat_score_orders_class_closing_speed_and_distance():
    cfg = AttentionConfig(protected_xyz_m=(0.0, 0.0, 0.0))
    near = view(0, [20, 0, 0])
    far = view(1, [80, 0, 0])
    closing = view(2, [80, 0, 0], vel=(-10, 0, 0))
    leaving = view(3, [80, 0, 0], vel=(10, 0, 0))
    bird = view(4, [20, 0, 0], label="bird")
    s = {v.track_id: threat_score(v, cfg) for v in (near, far, closing, leaving, bird)}
    assert s[0] > s[1] and s[2] == 2 * s[1] and s[3] == s[1] and s[4] < s[1]
    assert threat_score(view(5, [20, 0, 0], confirmed=False), cfg) == 0.0


def _run(att, views_fn, fovea_fn, duration_s, dt=0.1):
    """The schedule over time; ``fovea_fn(target)``: the ids in the fovea given the target served."""
    served = []
    for k in range(int(round(duration_s / dt))):
        t = (k + 1) * dt
        target = att.target
        served.append((t, target))
        att.update(t, views_fn(t), fovea_fn(target), dt)
    return served


def test_revisits_each_other_drone_and_returns_to_the_priority():
    cfg = AttentionConfig(revisit_s=2.0, dwell_s=0.3, saccade_timeout_s=1.0)
    att = Attention(cfg)
    views = [view(0, [20, 0, 0]), view(1, [60, 10, 0]), view(2, [70, -10, 0]), view(3, [30, 5, 0], label="bird")]
    served = _run(att, lambda t: views, lambda target: set() if target is None else {target}, 12.0)
    ids = [s for _, s in served if s is not None]
    assert ids.count(0) > 0.6 * len(ids)                   # the priority (nearest drone) most of the time
    assert 3 not in ids                                    # birds are not revisited
    for tid in (1, 2):                                     # each other drone at least once per revisit time
        times = [t for t, s in served if s == tid]
        gaps = np.diff([0.0] + times + [12.0])
        assert times and gaps.max() <= cfg.revisit_s + cfg.dwell_s + 2 * cfg.saccade_timeout_s, (tid, gaps)
    # after each revisit the fovea comes back to the priority track
    for (t0, a), (t1, b) in zip(served, served[1:]):
        if a in (1, 2) and b != a:
            assert b in (0, 1, 2)


def test_a_revisit_that_never_reaches_the_track_times_out():
    cfg = AttentionConfig(revisit_s=1.0, dwell_s=0.3, saccade_timeout_s=0.5)
    att = Attention(cfg)
    views = [view(0, [20, 0, 0]), view(1, [60, 10, 0])]
    served = _run(att, lambda t: views, lambda target: {0} if target == 0 else set(), 6.0)
    runs, cur = [], 0
    for _, s in served:
        if s == 1:
            cur += 1
        elif cur:
            runs.append(cur)
            cur = 0
    assert runs and max(runs) <= 6                         # never longer than the timeout (5 frames + 1)
    assert [s for _, s in served].count(0) > len(served) // 2


def test_pin_overrides_the_score_while_the_track_lives():
    att = Attention(AttentionConfig(revisit_s=100.0))
    views = [view(0, [20, 0, 0]), view(1, [60, 10, 0])]
    att.update(0.1, views, set(), 0.1)
    assert att.target == 0
    att.pin(1)
    att.update(0.2, views, set(), 0.1)
    assert att.target == 1
    att.update(0.3, views[:1], set(), 0.1)                 # the pinned track is gone: unpinned
    assert att.target == 0 and att.pinned is None


def _cand(tid, hits):
    return TrackView(tid, False, "unknown", np.zeros(3), np.zeros(3), True, True, {}, clear_hits=hits)


def test_a_candidate_being_verified_holds_the_fovea_until_dwell_or_timeout():
    # two rim candidates whose hit counts take turns leading: re-chosen every frame, the head turned to
    # one and back to the other and neither reached the fovea (two-drones-crossing, seed 28)
    cfg = AttentionConfig(dwell_s=0.5, saccade_timeout_s=2.0)
    att = Attention(cfg)
    targets = []
    for k in range(30):
        t = 0.1 * (k + 1)
        lead = 2 + k
        views = [_cand(0, lead if k % 2 else lead - 1), _cand(1, lead - 1 if k % 2 else lead)]
        targets.append(att.update(t, views, set(), 0.1))
    # held from the first choice until the 2 s timeout, then the leader of that frame
    assert targets[:20] == [1] * 20 and targets[20] in (0, 1) and targets[21:] == [targets[20]] * 9
    # in the fovea for dwell_s: done, the next choice is made afresh
    att = Attention(cfg)
    got = [att.update(0.1 * (k + 1), [_cand(0, 5), _cand(1, 3)], {0}, 0.1) for k in range(6)]
    assert got == [0] * 6 and att._verify_dwell_s == 0.0 and att._verify_start_s == pytest.approx(0.6)
    # a confirmed track takes the fovea at once; a candidate that dies is let go
    att = Attention(cfg)
    att.update(0.1, [_cand(0, 5), _cand(1, 3)], set(), 0.1)
    assert att.update(0.2, [_cand(1, 3)], set(), 0.1) == 1
    assert att.update(0.3, [_cand(1, 3), view(2, [20, 0, 0])], set(), 0.1) == 2 and att.verifying is None


def test_the_schedule_goes_by_what_a_track_looks_like_not_its_waiting_label():
    # a track the classifier's rules call a drone while its label still waits (rule 5) is revisited and
    # scored as a drone; one labelled drone that now looks like a bird is not
    cfg = AttentionConfig(revisit_s=1.0, dwell_s=0.3, saccade_timeout_s=0.5)
    pending = TrackView(1, True, "unknown", np.array([60.0, 10, 0]), np.zeros(3), True, True, {}, 0, "drone")
    turned = TrackView(2, True, "drone", np.array([70.0, -10, 0]), np.zeros(3), True, True, {}, 0, "bird")
    assert threat_score(pending, cfg) == threat_score(view(1, [60, 10, 0]), cfg)
    served = _run(Attention(cfg), lambda t: [view(0, [20, 0, 0]), pending, turned],
                  lambda target: set() if target is None else {target}, 6.0)
    ids = {s for _, s in served}
    assert 1 in ids and 2 not in ids
