"""The earliest confirmation the scan's rays allow (sim.sky_bounds.scan_allows_confirm_s): what part
of a slow confirmation is the rosette's and what part the tracker's (issue 28)."""

import numpy as np
import pytest

from sim.sky_bounds import scan_allows_confirm_s

T = np.round(0.1 * np.arange(1, 41), 10)      # frame end times of a 4 s run


def _bound(rays, tracked=None, min_points=2, hits=3, window=15):
    rays = np.asarray(rays + [0] * (T.size - len(rays)))
    tracked = np.ones(T.size, bool) if tracked is None else tracked
    return scan_allows_confirm_s(T, tracked, rays, min_points, hits, window)


def test_three_frames_of_two_rays_confirm_at_the_third_from_the_first_ray():
    # first ray at frame 1 (t 0.2); frames 2, 4 and 7 carry two rays or more: confirmable at t 0.8
    assert _bound([0, 1, 2, 0, 3, 1, 0, 2]) == pytest.approx(0.8 - 0.2)


def test_single_rays_never_make_an_object():
    assert _bound([1] * 40) is None
    assert _bound([1] * 40, min_points=1) == pytest.approx(0.2)


def test_hits_further_apart_than_the_window_do_not_confirm():
    rays = [2] + [0] * 9 + [2] + [0] * 9 + [2]         # every 10th frame: 3 hits span 21 frames
    assert _bound(rays) is None
    assert _bound(rays, window=21) == pytest.approx(2.0)


def test_the_warm_up_frames_count_for_entering_but_not_as_hits():
    tracked = T > 1.0 + 1e-9
    rays = [2, 2, 2] + [0] * 9 + [2, 2, 2]
    assert _bound(rays) == pytest.approx(0.2)
    assert _bound(rays, tracked) == pytest.approx(1.5 - 0.1)


def test_a_tracked_warm_up_counts_its_hits_and_reports_at_its_end():
    # warmup_replay: the warm-up's frames are tracked when it ends (frame index 10, t 1.1), so hits
    # in it count, but no confirmation is reported before then
    rays = [2, 2, 2] + [0] * 9 + [2, 2, 2]
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(rays + [0] * (T.size - len(rays))), 2, 3, 15,
                                 reported_from=10) == pytest.approx(1.1 - 0.1)
    late = [0] * 11 + [2, 2, 2]                       # first seen after the warm-up: as before
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(late + [0] * (T.size - len(late))), 2, 3, 15,
                                 reported_from=10) == pytest.approx(1.4 - 1.2)


def test_never_hit_is_none():
    assert _bound([]) is None


def test_with_lone_returns_a_track_started_by_two_rays_takes_single_rays_as_hits():
    # the tracker with lone_returns: frame 1 (two rays) starts it, frames 3 and 5 (one ray each) are
    # hits: confirmable at t 0.6, where objects alone (two rays a frame) never confirm it
    rays = [0, 2, 0, 1, 0, 1] + [0] * 34
    assert _bound(rays) is None
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(rays), 2, 3, 15,
                                 lone_returns=True) == pytest.approx(0.6 - 0.2)
    # single rays before any frame of two rays start nothing: the window counts from the start
    early = [1, 1, 1, 1] + [0] * 10 + [2] + [0] * 25
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(early), 2, 3, 15, lone_returns=True) is None
    # and the window holds: a start 15 frames before the third hit is too old
    far = [2] + [0] * 13 + [1, 1] + [0] * 24
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(far), 2, 3, 15, lone_returns=True) is None
    assert scan_allows_confirm_s(T, np.ones(T.size, bool), np.asarray(far), 2, 3, 16, lone_returns=True) == pytest.approx(1.5)
