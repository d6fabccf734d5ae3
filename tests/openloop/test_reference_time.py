"""``--reference`` compared at the time of what was measured: a detection's own time when the points
carry times (the median time of its points), the frame's stamp when they do not -- and the summary
says which."""

import numpy as np
import pytest

from foveatrack.frames import Frame
from foveatrack.openloop import OpenLoopConfig, track_source
from foveatrack.space_of_interest import Box

SPEED = 8.0            # m/s along y
T0 = 1_717_243_800     # a unix time, as a recording's stamps are


def _truth(t_s):
    return np.column_stack([np.full_like(t_s, 20.0), SPEED * (t_s - T0) - 4.0, np.full_like(t_s, 2.0)])


def _frames(point_times: bool, n=10):
    """10 Hz frames of a drone seen 60-80 ms into each scan (a rosette crosses it late), its returns
    where it was at their times; without point times every return carries the stamp."""
    rng = np.random.default_rng(4)
    out = []
    for k in range(n):
        stamp_ns = T0 * 10**9 + k * 100_000_000
        t_ns = stamp_ns + np.sort(rng.integers(60_000_000, 80_000_000, 12))
        xyz = _truth(t_ns * 1e-9)
        if not point_times:
            t_ns = np.full(12, stamp_ns)
        out.append((stamp_ns * 1e-9 + 0.12, Frame(stamp_ns * 1e-9, stamp_ns * 1e-9 + 0.1, xyz, t_ns)))
    return out


def _reference():
    t = T0 + np.arange(0.0, 1.2, 0.01)      # 100 Hz
    return t, _truth(t)


def test_the_reference_is_taken_at_the_detections_time_when_the_points_have_times():
    cfg = OpenLoopConfig(space=Box((15.0, -10.0, 0.0), (25.0, 10.0, 4.0)))
    res = track_source(_frames(point_times=True), cfg, reference=_reference())
    ref = res.summary["reference"]
    assert ref["error"]["frames"] == 10
    # the drone moved 0.5-0.6 m between the stamp and its returns: at the stamp that was the error
    assert ref["error"]["max_m"] < 0.05
    assert ref["matched_at"].startswith("each detection's time")
    np.testing.assert_array_equal(res.frames["ref_t_s"], res.frames["det_t_s"])


def test_without_point_times_the_frame_stamp_is_all_there_is():
    cfg = OpenLoopConfig(space=Box((15.0, -10.0, 0.0), (25.0, 10.0, 4.0)))
    res = track_source(_frames(point_times=False), cfg, reference=_reference())
    ref = res.summary["reference"]
    assert ref["matched_at"].startswith("each frame's stamp")
    np.testing.assert_array_equal(res.frames["ref_t_s"], res.frames["t_s"])
    e = res.frames["error_m"]
    assert np.all((e > 0.45) & (e < 0.7))     # the drone's 60-80 ms at 8 m/s: the frame's, not the code's, error


def _summary_lines(point_times: bool, reference, keep=None) -> list[str]:
    from foveatrack.cli.track_cmd import format_summary

    cfg = OpenLoopConfig(space=Box((15.0, -10.0, 0.0), (25.0, 10.0, 4.0)))
    frames = [fr for k, fr in enumerate(_frames(point_times)) if keep is None or k in keep]
    return format_summary(track_source(frames, cfg, reference=reference)).splitlines()


@pytest.mark.parametrize("point_times", [True, False], ids=["detection-time", "stamp"])
def test_the_text_summary_says_which_time_the_reference_was_sampled_at(point_times):
    # the JSON summary said it (reference.matched_at); the text printed the distance alone
    lines = _summary_lines(point_times, _reference())
    k = next(i for i, line in enumerate(lines) if "distance to the reference" in line)
    want = "each detection's time (the median time of its points)" if point_times else "each frame's stamp"
    assert lines[k + 1].startswith(f"  the reference was sampled at {want}"), lines


@pytest.mark.parametrize("shift, hint", [(-T0, "look like seconds from its start"), (None, "look like ns since 1970")],
                         ids=["relative-seconds", "ns"])
def test_no_reference_sample_says_both_time_spans(shift, hint):
    # a reference in seconds from its start against unix-time frames: "no tracked frame has a reference
    # sample (0 frames have one)" and nothing of why
    t, xyz = _reference()
    t = t + shift if shift is not None else t * 1e9
    lines = _summary_lines(False, (t, xyz))
    line = next(line for line in lines if "no tracked frame has a reference sample" in line)
    span = "0.000 .. 1.190 s" if shift is not None else "1.71724e+18 .. 1.71724e+18 s"
    assert f"the reference spans {span}, the tracked frames {T0}.000 .. {T0}.900 s" in line, line
    assert "they do not overlap" in line and hint in line, line


def test_overlapping_spans_with_no_sample_near_a_tracked_frame_say_so():
    # frames at 0.0-0.2 s and 0.8-0.9 s, the reference at 0.4-0.6 s only: within the frames' span, near none
    t, xyz = _reference()
    near = (t >= T0 + 0.4) & (t <= T0 + 0.6)
    lines = _summary_lines(False, (t[near], xyz[near]), keep=[0, 1, 2, 8, 9])
    line = next(x for x in lines if "no tracked frame has a reference sample" in x)
    assert f"the reference spans {T0 + 0.4:.3f} .. {T0 + 0.6:.3f} s, the tracked frames {T0}.000 .. {T0}.900 s" in line
    assert "do not overlap" not in line and "no reference sample lies within 50 ms (half a frame)" in line, line


@pytest.mark.parametrize("name", ["1706255621.100000", "1706255621.3", "1717243800005000", "1706255621.614239"])
def test_a_frame_named_by_its_time_starts_at_that_time_exactly(tmp_path, name):
    # the float nearest the name's exact seconds, what a user reads back in the track CSV: ns * 1e-9
    # rounded twice, and 1706255621.100000.npy started at 1706255621.1000001 s
    from fractions import Fraction

    from foveatrack.sources.npy_folder import NpyFolderSource
    from foveatrack.sources.stamps import ns_from_file_stem

    np.save(tmp_path / f"{name}.npy", np.array([[20.0, 0.0, 2.0]]))
    (_, frame), = NpyFolderSource(tmp_path, rate_hz=10.0)
    ns = ns_from_file_stem(name)
    assert frame.t_start_s == float(Fraction(ns, 10**9))
    assert frame.t_end_s == float(Fraction(ns + 100_000_000, 10**9))
    if name == "1706255621.100000":
        assert repr(frame.t_start_s) == "1706255621.1"
