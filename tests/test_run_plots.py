"""The plot helpers' choices that decide what a run's plots show (not how they look)."""

import numpy as np

from foveatrack.cli.sim_plots import main_axis


def test_points_plot_follows_the_axis_the_target_moves_along():
    """Paper Fig. 14a plots points along a horizontal crossing (y); a target flying overhead toward
    the lidar moves along x with y constant, so a y axis would stack every frame on one line."""
    t = np.linspace(0, 10, 50)[:, None]
    crossing = np.hstack([np.full_like(t, 10.0), 5 - t, np.zeros_like(t)])
    overhead = np.hstack([16 - t, np.full_like(t, 0.5), np.full_like(t, 12.0)])
    climbing = np.hstack([np.full_like(t, 10.0), 0.1 * t, 2 * t])
    assert [main_axis(p) for p in (crossing, overhead, climbing)] == [1, 0, 2]
    overhead[::3] = np.nan       # frames without a position are skipped
    assert main_axis(overhead) == 0 and main_axis(np.full((4, 3), np.nan)) == 1


def test_a_plot_cut_by_a_full_disk_is_named_and_leaves_nothing(tmp_path, monkeypatch):
    """`simulate --plot` on a disk that filled ended on "foveatrack: error: No space left on device",
    naming no file.  Simulated: matplotlib's write raising the OS's ENOSPC (an OSError without a
    file name, as a write's is) after half the PNG."""
    import errno

    import pytest

    from foveatrack.cli.scan_plots import _plt, _save

    plt = _plt()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])

    def full(target, **kw):
        with open(target, "wb") as fh:
            fh.write(b"\x89PNG half a plot")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(fig, "savefig", full)
    out = tmp_path / "error.png"
    with pytest.raises(OSError) as exc:
        _save(fig, out)
    assert exc.value.filename == str(out) and exc.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []
