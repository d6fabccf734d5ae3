"""Plots of the scan model's analyses (matplotlib, Agg, PNG).  Only the CLI calls these."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` (its format from the suffix), under its name only when whole: a plot
    cut by a full disk leaves nothing, and the error names the plot (it said only "No space left on
    device", after the run's recording and summary were written)."""
    from foveatrack.atomic_file import written_whole

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with written_whole(path) as tmp:
            fig.savefig(tmp, dpi=130, bbox_inches="tight", format=path.suffix[1:].lower() or "png")
    finally:
        _plt().close(fig)
    return path


def plot_pattern(az_deg, el_deg, channel, title: str, path) -> Path:
    """Scan pattern in azimuth/elevation (paper Fig. 4, 8, 9c), as seen from behind the lidar."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 7 * max(0.35, np.ptp(el_deg) / max(np.ptp(az_deg), 1e-9))))
    if channel.max() > 0:
        from matplotlib.colors import BoundaryNorm, ListedColormap

        n = int(channel.max()) + 1      # one colour band per channel, centred on its id
        cmap = ListedColormap(plt.get_cmap("tab10").colors[:n]) if n <= 10 else plt.get_cmap("viridis", n)
        sc = ax.scatter(az_deg, el_deg, c=channel, s=0.3, cmap=cmap, norm=BoundaryNorm(np.arange(n + 1) - 0.5, n),
                        linewidths=0)
        fig.colorbar(sc, ax=ax, label="channel (line id)", ticks=np.arange(n))
    else:
        ax.plot(az_deg, el_deg, lw=0.25, color="tab:red")
    ax.set_aspect("equal")
    ax.invert_xaxis()   # +az = left drawn on the left: the pattern as seen from behind the lidar, not mirrored
    ax.set_xlabel("azimuth [deg] (+ = left; seen from behind the lidar)")
    ax.set_ylabel("elevation [deg]")
    ax.set_title(title)
    return _save(fig, path)


def plot_density(density, exact_density, title: str, path) -> Path:
    """Simulated radial density against eq. (4) (paper Fig. 5)."""
    plt = _plt()
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True, height_ratios=[2, 1])
    x = density.centers_deg / density.r_scale_deg
    # eq. (4) is 0 past the rim (r > 2R): on a log axis that drew a vertical drop that reads as data
    analytic = np.where(density.analytic > 0, density.analytic, np.nan)
    ax.semilogy(x, analytic, "k-", lw=1.5, label="eq. (4), analytic")
    ax.semilogy(x, density.simulated, "o", ms=3, label=f"simulated, {density.model} model")
    if exact_density is not None:
        ax.semilogy(x, exact_density.simulated, "s", ms=3, mfc="none", label=f"simulated, {exact_density.model} model")
    ax.set_ylabel("points per deg$^2$ (fraction of all)")
    ax.legend()
    ax.set_title(title)
    # eq. (4) is the paraxial model's density: the 5 % band is its bar.  Exact refraction is not
    # paraxial, so it departs from eq. (4) by design (the band is not its bar; it looked like a failure)
    ax2.axhspan(-0.05, 0.05, color="0.9", label="within 5 % (the paraxial model's bar)")
    ax2.plot(x, density.relative_error, "o", ms=3, label=density.model)
    if exact_density is not None:
        ax2.plot(x, exact_density.relative_error, "s", ms=3, mfc="none",
                 label=f"{exact_density.model} (eq. 4 is paraxial: not held to the band)")
    errs = [d.relative_error for d in (density, exact_density) if d is not None]
    worst = max((float(np.nanmax(np.abs(e[np.isfinite(e)]))) for e in errs if np.isfinite(e).any()), default=0.0)
    lim = min(1.05, max(0.6, 1.1 * worst))     # every point shown (to -100 %: nothing in a bin)
    ax2.set_ylim(-lim, lim)
    ax2.set_xlabel("off-axis angle r / R   (R = (n-1)α, one prism's paraxial deflection)")
    ax2.set_ylabel("simulated / eq. (4) − 1")
    ax2.legend()
    return _save(fig, path)


def plot_coverage(curves, title: str, path) -> Path:
    """Coverage against accumulation time (paper Fig. 6e), the times to 50 % and 90 % marked
    (the paper's device: 0.3 s and 0.8 s)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, curve in curves:
        (line,) = ax.plot(curve.times_s, 100 * curve.coverage, label=label)
        for level, t in ((50, curve.t50_s), (90, curve.t90_s)):
            if t is not None:
                ax.plot([t, t], [0, level], ":", color=line.get_color(), lw=1)
                ax.annotate(f"{level} % at {t:.2f} s", (t, level), xytext=(5, -12), textcoords="offset points",
                            fontsize="small", color=line.get_color())
    ax.axhline(90, color="0.6", ls=":")
    ax.axhline(50, color="0.6", ls=":")
    ax.set_xlabel("accumulation time [s]")
    ax.set_ylabel("coverage [%]")
    ax.set_ylim(0, 101)
    ax.set_xlim(left=0)
    ax.legend(loc="lower right")
    ax.set_title(title)
    return _save(fig, path)


def plot_coverage_vs_published(curve, published, title: str, path) -> Path:
    """Our coverage curve against Livox's published one (read off its figure; error bars: the reading's
    +-), the +-0.03 band the presets are held to, and the largest deviation at the compared points."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    idx = published.compared_points()
    t_pub, c_pub = published.times_s[idx], published.coverage[idx]
    ours = np.array([curve.coverage[np.argmin(np.abs(curve.times_s - t))] for t in t_pub])
    dev = ours - c_pub
    worst = int(np.argmax(np.abs(dev)))
    ax.fill_between(t_pub, 100 * (c_pub - 0.03), 100 * np.minimum(c_pub + 0.03, 1.0), color="0.85",
                    label="Livox +- 0.03")
    ax.errorbar(t_pub, 100 * c_pub, yerr=100 * published.plus_minus[idx], fmt="o", ms=3, color="k",
                label="Livox (read off its figure)")
    ax.plot(curve.times_s, 100 * curve.coverage, color="C0", label="ours (footprint, exact refraction)")
    ax.annotate(f"largest deviation {dev[worst]:+.3f} at {t_pub[worst]:g} s", (t_pub[worst], 100 * ours[worst]),
                xytext=(10, -30), textcoords="offset points", fontsize="small",
                arrowprops=dict(arrowstyle="->", color="C3"), color="C3")
    ax.set_xlabel("integration time [s]")
    ax.set_ylabel("FoV coverage [%]")
    ax.set_ylim(0, 101)
    ax.set_xlim(0, float(t_pub.max()) * 1.02)
    ax.legend(loc="lower right")
    ax.set_title(title, fontsize="medium")
    return _save(fig, path)


def matplotlib_cmap(name: str):
    import matplotlib

    return matplotlib.colormaps[name]


def plot_coverage_map(cmap, title: str, path, device_rpm=None) -> Path:
    """Time to 90 % coverage over the two prism speeds, with and without noise (paper Fig. 7).

    device_rpm : (rpm1, rpm2) of the scanner's own prisms: a red + there, and a red square around the
    map's cell nearest it (the paper rings it), whose speeds the title gives.
    """
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)

    def edges(c):   # each cell centred on its speed (the grid's ends were the image's edges)
        h = 0.5 * (c[-1] - c[0]) / max(len(c) - 1, 1)
        return c[0] - h, c[-1] + h

    extent = [*edges(cmap.rpm1), *edges(cmap.rpm2)]
    r1, r2 = np.asarray(cmap.rpm1, float), np.asarray(cmap.rpm2, float)
    # cells that did not reach the level within the cap get a colour of their own (white, "over"):
    # clipped to the cap they shared the colour of a cell that took exactly the cap
    colours = matplotlib_cmap("viridis").with_extremes(over="white")
    inside = device_rpm is not None and (extent[0] <= device_rpm[0] <= extent[1]
                                         and extent[2] <= device_rpm[1] <= extent[3])
    cell = None
    if inside:   # the map's cell nearest the scanner's speeds: the ring goes on the cell, not between cells
        cell = (float(r1[np.argmin(np.abs(r1 - device_rpm[0]))]), float(r2[np.argmin(np.abs(r2 - device_rpm[1]))]))
    for ax, data, name in ((axes[0], cmap.t90_noise_s, "(a) 1 % speed noise"), (axes[1], cmap.t90_clean_s, "(b) no noise")):
        d = np.asarray(data, float)
        shown = np.where(np.isfinite(d) & (d < cmap.cap_s), d, np.inf)
        im = ax.imshow(shown, origin="lower", extent=extent, aspect="auto", vmin=0, vmax=cmap.cap_s, cmap=colours)
        if cell is not None:   # no legend box over the map: the title says what these are
            from matplotlib.patches import Rectangle

            w1 = (extent[1] - extent[0]) / len(r1)
            w2 = (extent[3] - extent[2]) / len(r2)
            ax.add_patch(Rectangle((cell[0] - w1 / 2, cell[1] - w2 / 2), w1, w2, fill=False, ec="red", lw=2))
            ax.plot(*device_rpm, "+", ms=9, color="red", mew=1.5)
        ax.set_xlabel("prism 1 speed [rpm]")
        ax.set_ylabel("prism 2 speed [rpm]")
        ax.set_title(name)
    fig.colorbar(im, ax=axes, extend="max",
                 label=f"time to {int(cmap.level * 100)} % coverage [s] (white: not reached in {cmap.cap_s:g} s)")
    if cell is not None:
        title += (f"\nred +: this scanner ({device_rpm[0]:g}, {device_rpm[1]:g} rpm); "
                  f"red square: the map's cell nearest it ({cell[0]:.0f}, {cell[1]:.0f} rpm)")
    fig.suptitle(title)
    return _save(fig, path)
