"""Each confirmed track's path over a run, for the plots of ``simulate`` and ``replay``
(:func:`foveatrack.cli.sim_plots.plot_sky_tracks`): built once from the frames' track views, whether
the run's own (:class:`foveatrack.sky.tracks.TrackView`) or a recording's
(:class:`foveatrack.recording.records.TrackEntry`)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def confirmed_paths(frames: Iterable[Iterable[tuple]], n_frames: int) -> dict:
    """``frames``: per frame, ``(id, confirmed, label, xyz_m, hit)`` of each track.  Returns id ->
    ``(labels (T,) str, "" where not confirmed; xyz (T, 3) while confirmed, NaN elsewhere; hit (T,)
    bool)``: each frame's label (a track's label changes over its life, and one coloured by its
    last label hid the frames it was a drone), and ``hit`` says the frame measured it (elsewhere the
    filter coasted: a predicted position, not a measured one)."""
    paths: dict[int, list] = {}
    for k, views in enumerate(frames):
        if k >= n_frames:
            break
        for tid, confirmed, label, xyz, hit in views:
            if not confirmed:
                continue
            p = paths.get(tid)
            if p is None:
                p = paths[tid] = [np.full(n_frames, "", dtype=object), np.full((n_frames, 3), np.nan),
                                  np.zeros(n_frames, bool)]
            p[0][k] = label
            p[1][k] = xyz
            p[2][k] = bool(hit)
    return {tid: (labels, xyz, hit) for tid, (labels, xyz, hit) in paths.items()}


def last_label(labels: np.ndarray) -> str:
    """A track's label in its last confirmed frame (``confirmed_paths``' labels)."""
    held = labels[labels != ""]
    return str(held[-1]) if held.size else "unknown"
