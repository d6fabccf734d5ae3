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
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130, bbox_inches="tight")
    _plt().close(fig)
    return path


def plot_pattern(az_deg, el_deg, channel, title: str, path) -> Path:
    """Scan pattern in azimuth/elevation (paper Fig. 4, 8, 9c)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 7 * max(0.35, np.ptp(el_deg) / max(np.ptp(az_deg), 1e-9))))
    if channel.max() > 0:
        sc = ax.scatter(az_deg, el_deg, c=channel, s=0.3, cmap="tab10", linewidths=0)
        fig.colorbar(sc, ax=ax, label="channel (line id)")
    else:
        ax.plot(az_deg, el_deg, lw=0.25, color="tab:red")
    ax.set_aspect("equal")
    ax.set_xlabel("azimuth [deg] (+ = left)")
    ax.set_ylabel("elevation [deg]")
    ax.set_title(title)
    return _save(fig, path)


def plot_density(density, exact_density, title: str, path) -> Path:
    """Simulated radial density against eq. (4) (paper Fig. 5)."""
    plt = _plt()
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True, height_ratios=[2, 1])
    x = density.centers_deg / density.r_scale_deg
    ax.semilogy(x, density.analytic, "k-", lw=1.5, label="eq. (4), analytic")
    ax.semilogy(x, density.simulated, "o", ms=3, label=f"simulated, {density.model} model")
    if exact_density is not None:
        ax.semilogy(x, exact_density.simulated, "s", ms=3, mfc="none", label=f"simulated, {exact_density.model} model")
    ax.set_ylabel("points per deg$^2$ (fraction of all)")
    ax.legend()
    ax.set_title(title)
    ax2.axhspan(-0.05, 0.05, color="0.9")
    ax2.plot(x, density.relative_error, "o", ms=3, label=density.model)
    if exact_density is not None:
        ax2.plot(x, exact_density.relative_error, "s", ms=3, mfc="none", label=exact_density.model)
    ax2.set_ylim(-0.6, 0.6)
    ax2.set_xlabel("off-axis angle r / R   (R = (n-1)α, one prism's paraxial deflection)")
    ax2.set_ylabel("simulated / eq. (4) − 1")
    ax2.legend()
    return _save(fig, path)


def plot_coverage(curves, title: str, path) -> Path:
    """Coverage against accumulation time (paper Fig. 6e)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, curve in curves:
        ax.plot(curve.times_s, 100 * curve.coverage, label=label)
    ax.axhline(90, color="0.6", ls=":")
    ax.axhline(50, color="0.6", ls=":")
    ax.set_xlabel("accumulation time [s]")
    ax.set_ylabel("coverage [%]")
    ax.set_ylim(0, 101)
    ax.legend()
    ax.set_title(title)
    return _save(fig, path)


def plot_coverage_map(cmap, title: str, path) -> Path:
    """Time to 90 % coverage over the two prism speeds, with and without noise (paper Fig. 7)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    extent = [cmap.rpm1[0], cmap.rpm1[-1], cmap.rpm2[0], cmap.rpm2[-1]]
    for ax, data, name in ((axes[0], cmap.t90_noise_s, "(a) 1 % speed noise"), (axes[1], cmap.t90_clean_s, "(b) no noise")):
        im = ax.imshow(np.minimum(data, cmap.cap_s), origin="lower", extent=extent, aspect="auto",
                       vmin=0, vmax=cmap.cap_s, cmap="viridis")
        ax.set_xlabel("prism 1 speed [rpm]")
        ax.set_ylabel("prism 2 speed [rpm]")
        ax.set_title(name)
    fig.colorbar(im, ax=axes, label=f"time to {int(cmap.level * 100)} % coverage [s] (capped at {cmap.cap_s:g} s)")
    fig.suptitle(title)
    return _save(fig, path)
